"""`motion.check` / `load` / `velocities_from_positions` on the TORSO model of
motion_models.py (free root, hinges h1, h2) and its closed-form motion."""

from __future__ import annotations

import re

import mujoco
import numpy as np
import pytest
from motion_models import JOINTS
from motion_models import TORSO
from motion_models import TORSO_XML
from motion_models import analytic

from mjzoo import motion

FPS = 50.0


def test_a_smooth_recorded_clip_passes():
    clip = analytic(FPS, 100, name="walk")
    assert motion.check(clip, TORSO) is clip


def test_a_simulated_clip_passes_and_matches_the_semi_implicit_alignment_exactly():
    # Euler: qpos[t+1] = qpos[t] (+) dt qvel[t+1]; the difference d[t] equals qvel[t+1].
    euler = '<option timestep="0.01" integrator="Euler"/><worldbody>'
    m = mujoco.MjModel.from_xml_string(TORSO_XML.replace("<worldbody>", euler))
    d = mujoco.MjData(m)
    d.qvel[:] = [0.3, 0, 1.0, 0.5, -2.0, 1.0, 3.0, -1.0]
    qpos, qvel = [], []
    for _ in range(60):
        mujoco.mj_step(m, d)
        qpos.append(d.qpos.copy()), qvel.append(d.qvel.copy())
    clip = motion.Clip(name="sim", fps=100.0, qpos=np.array(qpos), qvel=np.array(qvel), joint_names=JOINTS)
    motion.check(clip, m)
    diffs = motion.checking.differences(clip.qpos, clip.fps, m)
    np.testing.assert_allclose(diffs, clip.qvel[1:], atol=1e-8)


@pytest.mark.parametrize("factor", [1.5, 1 / 1.5, 3.0])
def test_a_wrong_fps_by_a_factor_of_1_5_or_more_fails_with_the_scale(factor):
    clip = analytic(FPS, 100, name="walk").replace(fps=FPS * factor)
    # qvel stays per second of the true rate: it is 1/factor the differences at the claimed rate.
    with pytest.raises(ValueError, match=rf"motion clip 'walk': qvel is {1 / factor:.3g}x the qpos differences"):
        motion.check(clip, TORSO)


def test_a_velocity_per_frame_is_named():
    clip = analytic(FPS, 100, name="walk")
    per_frame = clip.replace(qvel=clip.qvel / FPS)
    message = re.escape("'walk': qvel is 0.02x the qpos differences over 1/fps = 0.02 s") + ".*velocity per frame"
    with pytest.raises(ValueError, match=message):
        motion.check(per_frame, TORSO)
    with pytest.raises(ValueError, match="'walk': qvel is 0x .*velocities_from_positions"):
        motion.check(clip.replace(qvel=np.zeros_like(clip.qvel)), TORSO)


def test_velocities_from_positions_are_second_order_accurate_and_pass():
    clip = analytic(FPS, 100)
    qvel = motion.velocities_from_positions(clip.qpos, FPS, TORSO)
    assert qvel.shape == (100, 8)
    # Central differences inside: error ~ dt^2 |q'''| / 6 = 4e-4 * 8 / 6 for h1 = sin 2t.
    np.testing.assert_allclose(qvel[1:-1], clip.qvel[1:-1], atol=1e-3)
    motion.check(clip.replace(qvel=qvel), TORSO)
    with pytest.raises(ValueError, match=r"give \[T >= 2, nq=9\]"):
        motion.velocities_from_positions(clip.qpos[:, :8], FPS, TORSO)


def test_backward_velocities_carry_each_frame_to_the_next_as_a_step_would():
    clip = analytic(FPS, 20)
    qvel = motion.velocities_from_positions(clip.qpos, FPS, TORSO, backward=True)
    for t in (1, 10, 19):  # integrating qpos[t-1] with qvel[t] over 1/fps lands on qpos[t]
        q = clip.qpos[t - 1].copy()
        mujoco.mj_integratePos(TORSO, q, qvel[t], 1.0 / FPS)
        np.testing.assert_allclose(q, clip.qpos[t], atol=1e-9)
    np.testing.assert_array_equal(qvel[0], qvel[1])
    motion.check(clip.replace(qvel=qvel), TORSO)


def test_joints_in_another_order_or_missing_are_named():
    clip = analytic(FPS, 10, name="walk")
    with pytest.raises(ValueError, match="'walk': joint 1 is 'h2' but the model's joint 1 is 'h1'"):
        motion.check(clip.replace(joint_names=("root", "h2", "h1")), TORSO)
    with pytest.raises(ValueError, match="'walk': the clip has 2 joints and the model 3"):
        motion.check(clip.replace(joint_names=("root", "h1")), TORSO)


def test_wrong_widths_frames_and_values_are_named():
    clip = analytic(FPS, 10, name="walk")
    with pytest.raises(ValueError, match=re.escape("'walk': qpos has shape (10, 8); the model needs [T, nq=9]")):
        motion.check(clip.replace(qpos=clip.qpos[:, :8]), TORSO)
    with pytest.raises(ValueError, match=re.escape("'walk': qvel has shape (10, 9); the model needs [T, nv=8]")):
        motion.check(clip.replace(qvel=np.zeros((10, 9))), TORSO)
    with pytest.raises(ValueError, match="'walk': qpos has 1 frames and qvel 1"):
        motion.check(clip.replace(qpos=clip.qpos[:1], qvel=clip.qvel[:1]), TORSO)
    qpos = clip.qpos.copy()
    qpos[3, 8] = np.nan
    with pytest.raises(ValueError, match=re.escape("'walk': qpos[3, 8] is nan")):
        motion.check(clip.replace(qpos=qpos), TORSO)
    with pytest.raises(ValueError, match="'walk': fps=0.0 must be"):
        motion.check(clip.replace(fps=0.0), TORSO)


def test_a_non_unit_quaternion_is_named():
    clip = analytic(FPS, 10, name="walk")
    qpos = clip.qpos.copy()
    qpos[4, 3:7] *= 1.01
    with pytest.raises(ValueError, match=re.escape("'walk': the quaternion qpos[:, 3:7] has norm 1.01 at frame 4")):
        motion.check(clip.replace(qpos=qpos), TORSO)
    qpos[4, 3:7] = clip.qpos[4, 3:7] * 1.0009  # within 1e-3 of unit norm: accepted
    motion.check(clip.replace(qpos=qpos), TORSO)


def test_save_then_load_round_trips_and_checks(tmp_path):
    clip = analytic(FPS, 20, name="walk")
    clip = clip.replace(body_names=("torso",), body_pos=clip.qpos[:, None, :3], body_quat=clip.qpos[:, None, 3:7])
    path = motion.save(tmp_path / "walk.npz", clip)
    loaded = motion.load(path, TORSO)
    assert (loaded.name, loaded.fps, loaded.joint_names, loaded.body_names) == ("walk", FPS, JOINTS, ("torso",))
    for field in ("qpos", "qvel", "body_pos", "body_quat"):
        np.testing.assert_array_equal(getattr(loaded, field), getattr(clip, field))
    assert motion.load(path, TORSO, name="w2").name == "w2"
    motion.save(tmp_path / "bad.npz", clip.replace(joint_names=("root", "h2", "h1")))
    with pytest.raises(ValueError, match="motion clip 'bad': joint 1 is 'h2'"):
        motion.load(tmp_path / "bad.npz", TORSO)
    with pytest.raises(ValueError, match="no clip file at"):
        motion.load(tmp_path / "missing.npz", TORSO)
