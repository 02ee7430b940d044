"""`motion.resample` and `slerp`: same rate unchanged, linear motion and constant-rate
rotation reproduced exactly, quaternions unit, hand-checked frame times."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from motion_models import JOINTS
from motion_models import TORSO
from motion_models import analytic
from motion_models import axis_quat

from mjzoo import motion


def steady(fps: float, num_frames: int) -> motion.Clip:
    """Constant velocities: root (0.5 t, -0.2 t, 1), yaw 0.8 t about z, h1 = 1 - 2 t, h2 = 0.3 t."""
    t = np.arange(num_frames) / fps
    qpos = np.zeros((num_frames, 9))
    qpos[:, :3] = np.stack([0.5 * t, -0.2 * t, np.ones_like(t)], axis=1)
    qpos[:, 3:7] = axis_quat(2, 0.8 * t)
    qpos[:, 7], qpos[:, 8] = 1 - 2 * t, 0.3 * t
    qvel = np.broadcast_to([0.5, -0.2, 0, 0, 0, 0.8, -2, 0.3], (num_frames, 8)).copy()
    return motion.Clip(
        name="steady",
        fps=fps,
        qpos=qpos,
        qvel=qvel,
        joint_names=JOINTS,
        body_names=("torso",),
        body_pos=qpos[:, None, :3].copy(),
        body_quat=qpos[:, None, 3:7].copy(),
    )


def test_frame_times_by_hand():
    # 3 frames at 10 fps (0, 0.1, 0.2 s) at 20 fps: 0, 0.05, 0.1, 0.15, 0.2 s.
    i0, blend = motion.resampling.frame_times(3, 10.0, 20.0)
    np.testing.assert_array_equal(i0, [0, 0, 1, 1, 1])
    np.testing.assert_allclose(blend, [0, 0.5, 0, 0.5, 1])
    # 5 frames at 20 fps (0.2 s) at 7 fps: 0, 1/7 s -> 2 frames; 1/7 s is old frame 20/7.
    i0, blend = motion.resampling.frame_times(5, 20.0, 7.0)
    np.testing.assert_array_equal(i0, [0, 2])
    np.testing.assert_allclose(blend, [0, 20 / 7 - 2])


def test_the_same_fps_leaves_the_clip_unchanged():
    clip = analytic(50.0, 40)
    clip = clip.replace(body_names=("torso",), body_pos=clip.qpos[:, None, :3], body_quat=clip.qpos[:, None, 3:7])
    same = motion.resample(clip, 50.0, TORSO)
    assert same.num_frames == 40 and same.fps == 50.0
    for field in ("qpos", "qvel", "body_pos", "body_quat"):
        np.testing.assert_array_equal(getattr(same, field), getattr(clip, field))


@pytest.mark.parametrize("new_fps", [50.0, 12.0, 77.0])
def test_linear_motion_and_constant_rate_rotation_are_reproduced_exactly(new_fps):
    clip = steady(30.0, 31)  # 1 s
    out = motion.resample(clip, new_fps, TORSO)
    truth = steady(new_fps, int(np.floor(new_fps + 1e-9)) + 1)
    assert out.num_frames == truth.num_frames and out.fps == new_fps
    np.testing.assert_allclose(out.qpos, truth.qpos, atol=1e-12)
    np.testing.assert_allclose(out.qvel, truth.qvel, atol=1e-12)
    np.testing.assert_allclose(out.body_quat, truth.body_quat, atol=1e-12)
    np.testing.assert_allclose(out.body_pos, truth.body_pos, atol=1e-12)
    motion.check(out, TORSO)


def test_quaternions_stay_unit_and_a_resampled_clip_checks():
    clip = analytic(30.0, 60)
    out = motion.resample(clip, 47.0, TORSO)
    np.testing.assert_allclose(np.linalg.norm(out.qpos[:, 3:7], axis=1), 1.0, atol=1e-12)
    motion.check(out, TORSO)
    # Between frames, the slerped rotation is close to the true one (small-angle steps).
    truth = analytic(47.0, out.num_frames)
    np.testing.assert_allclose(np.abs(np.sum(out.qpos[:, 3:7] * truth.qpos[:, 3:7], axis=1)), 1.0, atol=1e-5)


def test_ball_joint_quaternions_are_slerped():
    m = mujoco.MjModel.from_xml_string("""
    <mujoco><worldbody><body name="head"><joint name="neck" type="ball"/><geom size="0.1"/>
    </body></worldbody></mujoco>""")
    t = np.arange(11) / 10.0
    qpos = axis_quat(0, 1.2 * t)
    clip = motion.Clip(name="nod", fps=10.0, qpos=qpos, qvel=np.tile([1.2, 0, 0], (11, 1)), joint_names=("neck",))
    out = motion.resample(clip, 20.0, m)
    np.testing.assert_allclose(out.qpos, axis_quat(0, 1.2 * np.arange(21) / 20.0), atol=1e-12)


def test_slerp_by_hand():
    identity, quarter = np.array([1.0, 0, 0, 0]), axis_quat(2, np.array([np.pi / 2]))[0]
    np.testing.assert_allclose(motion.slerp(identity, quarter, 0.5), axis_quat(2, np.array([np.pi / 4]))[0])
    # -q is the same rotation: the short arc is taken, not the 270-degree one.
    np.testing.assert_allclose(motion.slerp(identity, -quarter, 0.5), axis_quat(2, np.array([np.pi / 4]))[0])
    np.testing.assert_array_equal(motion.slerp(identity, identity, 0.3), identity)


def test_bad_fps():
    with pytest.raises(ValueError, match="fps=0 must be"):
        motion.resample(steady(30.0, 5), 0, TORSO)
