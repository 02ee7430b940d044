"""Reset items and `with_resets` (`mjzoo.catalog.resets`), on the base-and-arm task of
catalog_tasks.py (base qpos 0..6, qvel 0..5; hip qpos 7, qvel 6, range [-1, 0.5] rad;
wrist qpos 8, qvel 7, range [-0.1, 0.2] m; spin qpos 9, qvel 8, unlimited), whose reset
puts qpos / qvel at its leaves and observes [qpos, qvel] (19,). All resets run through
one jitted, vmapped function, one compile per stack of items.
"""

from __future__ import annotations

import chex
import jax
import mujoco
import numpy as np
import pytest
from catalog_tasks import BASE_AND_ARM as PHYSICS
from catalog_tasks import MJ
from catalog_tasks import QPOS0
from catalog_tasks import QVEL0
from catalog_tasks import make_task
from catalog_tasks import observe
from mujoco import mjx

import mjzoo
import mjzoo.envs
from mjzoo import motion
from mjzoo import physics as physics_lib
from mjzoo.catalog import resets
from mjzoo.types import State
from mjzoo.types import Task

N = 512  # resets per vmapped batch


@jax.jit
@chex.assert_max_traces(n=3)  # one per stack of items below; numbers never retrace
def resets_of(task: Task, keys: jax.Array) -> State:
    return jax.vmap(lambda key: mjzoo.reset(task, key))(keys)


KEYS = jax.random.split(jax.random.key(0), N)


def joints_stack(fraction=0.5, qpos=QPOS0, qvel=QVEL0, velocity_scale=(0.1, 0.2, 0.3)) -> Task:
    return resets.with_resets(
        make_task(qpos, qvel),
        resets.joint_positions(MJ, fraction),
        resets.joint_velocities(MJ, velocity_scale),
        observe=observe,
    )


def pose(hip=0.0, wrist=0.0, spin=0.0) -> np.ndarray:
    return np.concatenate([QPOS0[:7], [hip, wrist, spin]]).astype(np.float32)


# --- joint items ----------------------------------------------------------------------


def test_joint_positions_within_a_fraction_of_the_range_around_the_reset_pose():
    # hip reset at 0.4, range [-1, 0.5], fraction 0.5: [0.4 - 0.5 * 1.4, 0.4 + 0.5 * 0.1] = [-0.3, 0.45].
    # wrist at 0, range [-0.1, 0.2]: [-0.05, 0.1]. spin has no range: untouched (0).
    s = resets_of(joints_stack(0.5, qpos=pose(hip=0.4)), KEYS)
    hip, wrist, spin = np.asarray(s.data.qpos[:, 7]), np.asarray(s.data.qpos[:, 8]), np.asarray(s.data.qpos[:, 9])
    assert hip.min() >= -0.3 and hip.max() <= 0.45 and hip.min() < -0.25 and hip.max() > 0.4
    assert wrist.min() >= -0.05 and wrist.max() <= 0.1 and wrist.min() < -0.04 and wrist.max() > 0.09
    np.testing.assert_array_equal(spin, 0.0)
    np.testing.assert_array_equal(s.data.qpos[:, :7], np.broadcast_to(QPOS0[:7], (N, 7)))  # base untouched
    # The observation is recomputed from the randomized state.
    np.testing.assert_array_equal(s.obs, np.concatenate([s.data.qpos, s.data.qvel], axis=1))


def test_joint_positions_fraction_zero_keeps_the_pose_and_one_spans_the_range():
    # Same structure (fraction is a leaf): no new trace.
    s = resets_of(joints_stack(0.0, qpos=pose(hip=0.4, wrist=0.1)), KEYS)
    np.testing.assert_allclose(s.data.qpos[:, 7:9], np.broadcast_to([0.4, 0.1], (N, 2)), atol=1e-7)
    s = resets_of(joints_stack(1.0, qpos=pose(hip=0.4)), KEYS)
    hip = np.asarray(s.data.qpos[:, 7])
    assert hip.min() >= -1.0 and hip.max() <= 0.5 and hip.min() < -0.95 and hip.max() > 0.49


def test_joint_velocities_add_uniform_noise_per_joint():
    # qvel 6, 7, 8 (hip, wrist, spin) start at 1, 2, 3; scales 0.1, 0.2, 0.3.
    qvel = np.array([0, 0, 0, 0, 0, 0, 1, 2, 3], np.float32)
    s = resets_of(joints_stack(0.5, qvel=qvel), KEYS)
    offset = np.asarray(s.data.qvel[:, 6:]) - [1, 2, 3]
    assert np.all(np.abs(offset) <= np.array([0.1, 0.2, 0.3]) + 1e-6)
    np.testing.assert_allclose(np.abs(offset).max(axis=0), [0.1, 0.2, 0.3], rtol=0.05)
    np.testing.assert_allclose(offset.mean(axis=0), 0.0, atol=0.03)
    np.testing.assert_array_equal(s.data.qvel[:, :6], 0.0)


def test_joint_position_noise_is_clipped_to_limited_ranges_only():
    noise = resets.joint_position_noise(MJ, (0.3, 0.3, 2.0))
    task = resets.with_resets(make_task(pose(hip=0.4)), noise, observe=observe)
    s = resets_of(task, KEYS)
    hip, wrist, spin = (np.asarray(s.data.qpos[:, i]) for i in (7, 8, 9))
    # hip: 0.4 + U(-0.3, 0.3) = U(0.1, 0.7) clipped at 0.5: about a third sits exactly on 0.5.
    assert hip.min() >= 0.1 and hip.max() == np.float32(0.5) and 0.25 < np.mean(hip == np.float32(0.5)) < 0.42
    # wrist: U(-0.3, 0.3) clipped to [-0.1, 0.2].
    assert wrist.min() == np.float32(-0.1) and wrist.max() == np.float32(0.2)
    # spin is unlimited: U(-2, 2), unclipped.
    assert np.abs(spin).max() <= 2.0 and np.abs(spin).max() > 1.9


# --- base items -----------------------------------------------------------------------


def base_stack(
    yaw=(-np.pi, np.pi), height=(0.5, 0.5), roll=0.0, pitch=0.0, qvel=QVEL0, linear=(0, 0, 0), angular=(0, 0, 0)
) -> Task:
    return resets.with_resets(
        make_task(qvel=qvel),
        resets.base_heading(MJ, yaw),
        resets.base_height(MJ, height),
        resets.base_tilt(MJ, roll, pitch),
        resets.base_velocity(MJ, linear, angular),
        observe=observe,
    )


def test_base_heading_turns_orientation_and_linear_velocity():
    # A quarter turn: quat (cos 45deg, 0, 0, sin 45deg); the velocity (1, 0, 0) becomes
    # (0, 1, 0); the body-frame angular velocity (0, 0, 2) stays; the position stays.
    qvel = np.array([1, 0, 0, 0, 0, 2, 0, 0, 0], np.float32)
    s = resets_of(base_stack(yaw=(np.pi / 2, np.pi / 2), qvel=qvel), KEYS)
    c = np.cos(np.pi / 4)
    np.testing.assert_allclose(s.data.qpos[:, 3:7], np.broadcast_to([c, 0, 0, c], (N, 4)), atol=1e-6)
    np.testing.assert_allclose(s.data.qvel[:, :6], np.broadcast_to([0, 1, 0, 0, 0, 2], (N, 6)), atol=1e-6)
    np.testing.assert_allclose(s.data.qpos[:, :3], np.broadcast_to([0, 0, 0.5], (N, 3)), atol=1e-7)
    # mjx.forward ran: the body's x axis (first column of xmat) points along world y.
    np.testing.assert_allclose(s.data.xmat[:, 1, :, 0], np.broadcast_to([0, 1, 0], (N, 3)), atol=1e-6)


def test_base_heading_uniform_yaw():
    qvel = np.array([1, 0, 0, 0, 0, 0, 0, 0, 0], np.float32)
    s = resets_of(base_stack(yaw=(-1.0, 2.0), qvel=qvel), KEYS)
    w, z = np.asarray(s.data.qpos[:, 3]), np.asarray(s.data.qpos[:, 6])
    yaw = 2 * np.arctan2(z, w)
    assert yaw.min() >= -1.0 - 1e-6 and yaw.max() <= 2.0 + 1e-6 and yaw.min() < -0.95 and yaw.max() > 1.95
    # The velocity turned with the body: (cos yaw, sin yaw, 0).
    np.testing.assert_allclose(s.data.qvel[:, :2], np.stack([np.cos(yaw), np.sin(yaw)], 1), atol=1e-5)


def test_base_height_tilt_and_velocity():
    task = base_stack(yaw=(0, 0), height=(0.2, 0.4), roll=0.0, pitch=0.3, linear=(1, 0, 0), angular=(0, 0, 2))
    s = resets_of(task, KEYS)
    z = np.asarray(s.data.qpos[:, 2])
    assert z.min() >= 0.2 and z.max() <= 0.4 and z.min() < 0.21 and z.max() > 0.39
    np.testing.assert_allclose(s.data.xpos[:, 1, 2], z, rtol=1e-6)  # forward ran: body pose follows qpos
    # Pitch only: quat (cos p/2, 0, sin p/2, 0), |p| <= 0.3; the body's z axis tilts by p.
    quat = np.asarray(s.data.qpos[:, 3:7])
    pitch = 2 * np.arctan2(quat[:, 2], quat[:, 0])
    np.testing.assert_allclose(quat[:, [1, 3]], 0.0, atol=1e-7)
    assert np.abs(pitch).max() <= 0.3 + 1e-6 and np.abs(pitch).max() > 0.29
    np.testing.assert_allclose(s.data.xmat[:, 1, 2, 2], np.cos(pitch), atol=1e-6)
    # Velocity: x in [-1, 1], angular z in [-2, 2], the rest 0.
    v = np.asarray(s.data.qvel[:, :6])
    assert np.abs(v[:, 0]).max() <= 1 and np.abs(v[:, 0]).max() > 0.98 and np.abs(v[:, 5]).max() > 1.95
    np.testing.assert_array_equal(v[:, [1, 2, 3, 4]], 0.0)


def test_base_heading_and_tilt_commute():
    # Heading multiplies on the left (world z), tilt on the right (body axes).
    data = mjx.make_data(PHYSICS.model)
    heading, tilt = resets.base_heading(MJ), resets.base_tilt(MJ, 0.4, 0.4)
    k1, k2 = jax.random.key(1), jax.random.key(2)
    a = tilt(PHYSICS.model, heading(PHYSICS.model, data, k1), k2).qpos[3:7]
    b = heading(PHYSICS.model, tilt(PHYSICS.model, data, k2), k1).qpos[3:7]
    np.testing.assert_allclose(a, b, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(a), 1.0, atol=1e-6)


def test_resets_leave_the_step_alone_and_redraw_per_key():
    inner = make_task()
    task = resets.with_resets(inner, resets.base_height(MJ, (0.2, 0.4)), observe=observe)
    assert task.step is inner.step and task.reward is inner.reward and task.terminate is inner.terminate
    s = resets_of(base_stack(height=(0.2, 0.4)), KEYS)
    assert len(set(np.asarray(s.data.qpos[:, 2]).tolist())) > N - 5  # a new draw per key


# --- errors at construction -------------------------------------------------------------


def test_unknown_or_wrong_joints_are_named():
    with pytest.raises(ValueError, match=r"no joint named 'knee'; joint names: \['root', 'hip', 'wrist', 'spin'\]"):
        resets.joint_velocities(MJ, 0.1, joints=["knee"])
    with pytest.raises(ValueError, match=r"'root' is not a hinge or slide joint; those are \['hip', 'wrist', 'spin'\]"):
        resets.joint_position_noise(MJ, 0.1, joints=["root"])
    with pytest.raises(ValueError, match="'spin' has no range"):
        resets.joint_positions(MJ, 0.5, joints=["spin"])
    with pytest.raises(ValueError, match="body 'arm' has no free joint.*bodies with one: \\['base'\\]"):
        resets.base_height(MJ, (0.2, 0.4), body="arm")
    pendulum = physics_lib.load(mjzoo.envs.base.ASSETS / "pendulum.xml").mj_model
    with pytest.raises(ValueError, match="the model has no free joint"):
        resets.base_heading(pendulum)


def test_bad_numbers():
    with pytest.raises(ValueError, match="fraction"):
        resets.joint_positions(MJ, 1.5)
    with pytest.raises(ValueError, match="3 of them"):
        resets.joint_velocities(MJ, (0.1, 0.2))
    with pytest.raises(ValueError, match="scale"):
        resets.joint_velocities(MJ, -0.1)
    with pytest.raises(ValueError, match="height"):
        resets.base_height(MJ, (0.4, 0.2))
    with pytest.raises(ValueError, match="linear"):
        resets.base_velocity(MJ, linear=(1, 1))


def test_with_resets_checks_items_and_observe():
    item = resets.base_height(MJ, (0.2, 0.4))
    with pytest.raises(ValueError, match="at least one"):
        resets.with_resets(make_task(), observe=observe)
    with pytest.raises(ValueError, match=r"observe gives \(\(3,\), 'float32'\), but the task observes \(\(19,\)"):
        resets.with_resets(make_task(), item, observe=lambda model, state: state.data.qpos[:3])
    with pytest.raises(ValueError, match="item 1 must return an mjx.Data"):
        resets.with_resets(make_task(), item, lambda model, data, key: data.qpos, observe=observe)
    with pytest.raises(TypeError, match="observe must be callable"):
        resets.with_resets(make_task(), item, observe=None)


# --- reference-state initialization ---------------------------------------------------


def arm_reference():
    """Two clips of the base-and-arm model at the task's 50 Hz: "glide" (20 frames: the
    base moving along x, the hip swinging) and "spin" (10 frames: the wheel turning), and
    a reference of another model (one hinge)."""
    t = np.arange(20) / 50.0
    glide = np.tile(QPOS0.astype(np.float64), (20, 1))
    glide[:, 0], glide[:, 7] = 0.4 * t, 0.3 * np.sin(3 * t)
    spin = np.tile(QPOS0.astype(np.float64), (10, 1))
    spin[:, 9] = 2.0 * t[:10]
    clips = [
        motion.Clip(
            name=name,
            fps=50.0,
            qpos=q,
            qvel=motion.velocities_from_positions(q, 50.0, MJ),
            joint_names=("root", "hip", "wrist", "spin"),
        )
        for name, q in (("glide", glide), ("spin", spin))
    ]
    hinge = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body><joint name="j"/><geom size="0.1"/></body></worldbody></mujoco>'
    )
    other = motion.Clip(name="other", fps=50.0, qpos=np.zeros((3, 1)), qvel=np.zeros((3, 1)), joint_names=("j",))
    return motion.reference(clips, MJ, dt=0.02), motion.reference(other, hinge, dt=0.02)


@jax.jit
@chex.assert_max_traces(n=1)  # probabilities are leaves
def reference_resets(task: Task, keys: jax.Array) -> State:
    return jax.vmap(lambda key: mjzoo.reset(task, key))(keys)


def test_reference_state_starts_exactly_at_a_reference_frame_or_keeps_the_default():
    ref, _ = arm_reference()

    def stack(probability):
        return resets.with_resets(make_task(), resets.reference_state(ref, probability), observe=observe)

    s = reference_resets(stack(1.0), KEYS)
    clip, frame = np.asarray(s.info["reference_clip"]), np.asarray(s.info["reference_frame"])
    assert set(clip.tolist()) == {0, 1} and frame.min() == 0 and frame[clip == 0].max() == 19
    index = np.asarray(motion.frame_index(ref, clip, frame))
    np.testing.assert_array_equal(s.data.qpos, np.asarray(ref.qpos)[index])
    np.testing.assert_array_equal(s.data.qvel, np.asarray(ref.qvel)[index])
    np.testing.assert_array_equal(s.obs, np.concatenate([s.data.qpos, s.data.qvel], axis=1))
    # Probability 0 (a leaf: same trace) keeps the task's own reset; 0.5 starts half the episodes there.
    s = reference_resets(stack(0.0), KEYS)
    np.testing.assert_array_equal(s.data.qpos, np.broadcast_to(QPOS0, (N, 10)))
    np.testing.assert_array_equal(s.data.qvel, 0.0)
    np.testing.assert_array_equal(s.info["reference_clip"], -1)
    np.testing.assert_array_equal(s.info["reference_frame"], -1)
    s = reference_resets(stack(0.5), KEYS)
    assert 0.42 < np.mean(np.asarray(s.info["reference_clip"]) >= 0) < 0.58


def test_reference_state_errors():
    ref, other = arm_reference()
    with pytest.raises(TypeError, match="reference must be a motion.Reference"):
        resets.reference_state(ref.qpos)
    with pytest.raises(ValueError, match="probability=1.5 must be"):
        resets.reference_state(ref, 1.5)
    with pytest.raises(ValueError, match="the reference has nq=1, nv=1 but the task's model nq=10, nv=9"):
        resets.with_resets(make_task(), resets.reference_state(other), observe=observe)
