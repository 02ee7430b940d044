"""envs/deepmimic.py: the DeepMimic humanoid built from the installed pybullet_data, its
walk and run clips on it, and the walk task for AMP.

Skipped where pybullet (which ships pybullet_data) is not installed, but for the clear
error a user then gets. The task is checked by tracing (`jax.eval_shape`) only:
compiling the humanoid's MJX step takes minutes on a shared 2-core CPU.
"""

from __future__ import annotations

import importlib.util

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import mjzoo
from mjzoo import motion
from mjzoo.envs import deepmimic

BALLS = ("chest", "neck", "right_hip", "right_ankle", "right_shoulder", "left_hip", "left_ankle", "left_shoulder")
HINGES = ("right_knee", "right_elbow", "left_knee", "left_elbow")


def test_without_pybullet_the_error_says_how_to_install_it(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "pybullet_data" else real(name, *a)
    )
    with pytest.raises(ModuleNotFoundError, match="pip install pybullet"):
        deepmimic.data_path()
    with pytest.raises(ModuleNotFoundError, match="pybullet_data"):
        deepmimic.motion_path("walk")


@pytest.fixture(scope="module")
def model():
    pytest.importorskip("pybullet_data")
    return deepmimic.humanoid_model()


@pytest.fixture(scope="module")
def clips(model):
    return {clip.name: clip for clip in deepmimic.walk_clips()}


def _kinds(m):
    return {m.joint(j).name: int(m.jnt_type[j]) for j in range(m.njnt)}


def test_the_humanoid_has_the_urdf_joints_masses_and_a_motor_per_dof(model):
    m = model
    kinds = _kinds(m)
    assert kinds["root"] == mujoco.mjtJoint.mjJNT_FREE and m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert all(kinds[n] == mujoco.mjtJoint.mjJNT_BALL for n in BALLS)
    assert all(kinds[n] == mujoco.mjtJoint.mjJNT_HINGE for n in HINGES)
    assert (m.nq, m.nv, m.nu) == (7 + 4 * 8 + 4, 6 + 3 * 8 + 4, 3 * 8 + 4)
    assert m.body_mass.sum() == pytest.approx(45.0)  # the URDF's links: 6 + 14 + 2 + 2 x 11.5 kg
    assert m.body("chest").mass[0] == pytest.approx(14.0)
    # knees bend the shin backwards, elbows the forearm forwards, about the z-up model's -y
    knee, elbow = m.joint("right_knee"), m.joint("left_elbow")
    np.testing.assert_allclose([knee.axis, elbow.axis], [[0, -1, 0], [0, -1, 0]])
    np.testing.assert_allclose([knee.range, elbow.range], [[-3.14, 0.0], [0.0, 3.14]])
    gear = {m.actuator(a).name: m.actuator_gear[a, :3] for a in range(m.nu)}
    np.testing.assert_allclose(gear["right_hip_y"], [0, deepmimic.MAX_TORQUE["right_hip"], 0])
    np.testing.assert_allclose(gear["left_elbow"][0], 60.0)
    assert deepmimic.character_joints() == (
        "chest",
        "neck",
        "right_hip",
        "right_knee",
        "right_ankle",
        "right_shoulder",
        "right_elbow",
        "left_hip",
        "left_knee",
        "left_ankle",
        "left_shoulder",
        "left_elbow",
    )


def _lowest_foot_points(m, qpos: np.ndarray) -> np.ndarray:
    """[T, 2] the lowest corner (world z, m) of each foot box, per frame."""
    d = mujoco.MjData(m)
    feet = [m.geom("right_ankle_box").id, m.geom("left_ankle_box").id]
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    out = np.zeros((len(qpos), 2))
    for t, q in enumerate(qpos):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        for i, g in enumerate(feet):
            points = d.geom_xpos[g] + (corners * m.geom_size[g]) @ d.geom_xmat[g].reshape(3, 3).T
            out[t, i] = points[:, 2].min()
    return out


def test_standing_pose_rests_on_its_feet(model):
    low = _lowest_foot_points(model, model.qpos0[None])
    assert np.all((low > 0.0) & (low < 0.01)), low


def test_walk_clip_fits_the_model_feet_on_the_ground(model, clips):
    walk = clips["walk"]
    assert walk.fps == pytest.approx(30.0, rel=1e-3) and walk.qpos.shape == (39, model.nq)
    assert motion.check(walk, model) is walk
    low = _lowest_foot_points(model, walk.qpos)
    stance = low.min(axis=1)  # the lower foot, each frame: on the floor to within 1-2 cm
    assert stance.min() > -0.01 and stance.max() < 0.02, (stance.min(), stance.max())
    assert np.all(low.min(axis=0) < 0.005) and np.all(low.max(axis=0) > 0.05)  # each foot stands, each swings
    root = walk.qpos[:, :3]
    assert np.all((root[:, 2] > 0.84) & (root[:, 2] < 0.88))
    speed = (root[-1] - root[0]) / walk.duration
    assert 0.9 < speed[0] < 1.1 and abs(speed[1]) < 0.05  # walks forward along +x at ~1 m/s
    d = mujoco.MjData(model)
    for q in walk.qpos:  # upright: the head above the root, every frame
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        assert d.xpos[model.body("neck").id, 2] > d.xpos[model.body("root").id, 2] + 0.4


def test_clip_velocities_integrate_to_the_next_frame(model, clips):
    for clip in clips.values():
        for t in range(1, clip.num_frames):
            q = clip.qpos[t - 1].copy()
            mujoco.mj_integratePos(model, q, clip.qvel[t], 1.0 / clip.fps)
            np.testing.assert_allclose(q, clip.qpos[t], atol=1e-7)
    assert 3.0 < (clips["run"].qpos[-1, 0] - clips["run"].qpos[0, 0]) / clips["run"].duration < 4.0


def test_unknown_clip_lists_the_shipped_ones(model):
    with pytest.raises(ValueError, match="no clip 'moonwalk'.*'walk'"):
        deepmimic.motion_path("moonwalk")


@pytest.fixture(scope="module")
def task(model):
    return deepmimic.walk()


@pytest.fixture(scope="module")
def traced(task):
    """Shapes of a reset state and of one transition from it (traced, not compiled)."""
    key = jax.random.PRNGKey(0)
    state = jax.eval_shape(mjzoo.reset, task, key)
    return state, jax.eval_shape(mjzoo.transition, task, state, jnp.zeros(task.action_size), key)


def test_walk_task_rewards_only_being_alive(task, traced):
    assert int(task.time_limit) == 300
    m = task.mj_model
    assert m.opt.timestep == pytest.approx(1 / 240) and m.opt.iterations == 1
    assert m.opt.solver == mujoco.mjtSolver.mjSOL_NEWTON
    state, nxt = traced
    assert task.action_size == 28 and state.obs.shape == (1 + 4 + 36 + 3 + 3 + 28,)
    assert [k for k in nxt.metrics if k.startswith("reward/")] == ["reward/alive"]


def test_walk_task_terminates_on_a_low_root_and_checks_its_arguments(traced):
    assert [k for k in traced[1].metrics if k.startswith("termination/")] == ["termination/fallen"]
    with pytest.raises(ValueError, match="min_height=nan"):
        deepmimic.walk(min_height=float("nan"))
    with pytest.raises(ValueError, match="ctrl_dt"):
        deepmimic.walk(ctrl_dt=0.01)  # not a whole number of 1/240 s physics steps


@pytest.fixture(scope="module")
def amp_task(model):
    return deepmimic.walk_amp()


@pytest.fixture(scope="module")
def amp_reference(amp_task):
    return deepmimic.WALK_AMP.reference(amp_task)


def test_walk_amps_reference_is_the_walk_clip_at_the_control_step(amp_task, amp_reference, clips):
    ref, m = amp_reference, amp_task.mj_model
    assert isinstance(ref, motion.Reference) and ref.names == ("walk",) and bool(ref.loop[0])
    assert float(ref.dt) == pytest.approx(1 / 30) == pytest.approx(8 * m.opt.timestep)  # 8 physics steps
    walk = clips["walk"]  # 39 frames at 30.0012 fps (1.2666 s): 38 at 30 fps
    assert ref.qpos.shape == (int(walk.duration * 30) + 1, m.nq)
    np.testing.assert_allclose(ref.qpos[0], walk.qpos[0], atol=1e-6)
    assert float(deepmimic.walk_amp_reference(amp_task, ctrl_dt=1 / 60).dt) == pytest.approx(1 / 60)
    for body in deepmimic.AMP["key_bodies"]:
        m.body(body)  # KeyError if the model lacks one


def test_walk_amp_resets_from_the_clip_and_traces(amp_task):
    key = jax.random.PRNGKey(0)
    state = jax.eval_shape(mjzoo.reset, amp_task, key)
    assert state.info["reference_frame"].shape == () and state.obs.shape == (75,)
    nxt = jax.eval_shape(mjzoo.transition, amp_task, state, jnp.zeros(amp_task.action_size), key)
    assert nxt.obs.shape == (75,)
    from mjzoo.algorithms import amp

    assert amp.configure(**deepmimic.AMP)[1].task_weight == 0.0


def test_walk_amp_style_error(amp_task, amp_reference, clips):
    walk = clips["walk"].qpos
    assert deepmimic.style_error(amp_task, amp_reference, walk) < 1e-3  # the clip itself, against its resampled frames
    assert (
        deepmimic.style_error(amp_task, amp_reference, np.roll(walk, 10, axis=0)) < 0.01
    )  # a loop: any phase (0.006: the seam)
    still = np.tile(walk[:1], (30, 1))  # frozen in the first frame: the knees' and elbows' swing is missed
    assert deepmimic.style_error(amp_task, amp_reference, still) > 0.1  # 0.15 rad
    with pytest.raises(ValueError, match="qpos has shape"):
        deepmimic.style_error(amp_task, amp_reference, walk[:, :5])
