"""`motion.isaaclab_npz` on files the tests write in IsaacLab's humanoid-AMP layout,
from the closed-form TORSO motion of motion_models.py: loaded, compared with the truth."""

from __future__ import annotations

import numpy as np
import pytest
from motion_models import JOINTS
from motion_models import TORSO
from motion_models import analytic
from motion_models import world_angular_velocity

from mjzoo import motion

TRUTH = analytic(60.0, 90, name="walk")


def write(path, clip=TRUTH, dof_names=("h2", "h1"), body_names=("shin", "torso"), drop=()):
    """`clip` in IsaacLab's layout: DOFs in `dof_names` order, the root pose as the body
    "torso" (second), velocities in the world frame, rotations w-first."""
    t = clip.num_frames
    columns = {"h1": clip.qpos[:, 7], "h2": clip.qpos[:, 8]}
    rates = {"h1": clip.qvel[:, 6], "h2": clip.qvel[:, 7]}
    root = [body_names.index("torso")] if "torso" in body_names else [1]
    body_pos, body_rot = np.zeros((t, 2, 3)), np.tile([1.0, 0, 0, 0], (t, 2, 1))
    lin, ang = np.zeros((t, 2, 3)), np.zeros((t, 2, 3))
    body_pos[:, root[0]], body_rot[:, root[0]] = clip.qpos[:, :3], clip.qpos[:, 3:7]
    lin[:, root[0]], ang[:, root[0]] = clip.qvel[:, :3], world_angular_velocity(clip)
    arrays = dict(
        fps=np.float64(clip.fps),
        dof_names=np.array(dof_names),
        body_names=np.array(body_names),
        dof_positions=np.stack([columns.get(n, columns["h1"]) for n in dof_names], axis=1),
        dof_velocities=np.stack([rates.get(n, rates["h1"]) for n in dof_names], axis=1),
        body_positions=body_pos,
        body_rotations=body_rot,
        body_linear_velocities=lin,
        body_angular_velocities=ang,
    )
    np.savez(path, **{k: v for k, v in arrays.items() if k not in drop})
    return path


def test_an_isaaclab_motion_loads_as_the_truth(tmp_path):
    clip = motion.isaaclab_npz(write(tmp_path / "walk.npz"), TORSO)
    assert (clip.name, clip.fps, clip.joint_names, clip.num_frames) == ("walk", 60.0, JOINTS, 90)
    np.testing.assert_allclose(clip.qpos, TRUTH.qpos, atol=1e-12)
    # The angular velocity is rotated from the world frame into the body frame.
    np.testing.assert_allclose(clip.qvel, TRUTH.qvel, atol=1e-12)
    assert np.abs(world_angular_velocity(TRUTH) - TRUTH.qvel[:, 3:6]).max() > 0.1  # the frames differ here
    assert clip.body_names == ("shin", "torso")
    np.testing.assert_allclose(clip.body_quat[:, 1], TRUTH.qpos[:, 3:7], atol=1e-12)


def test_missing_and_extra_dofs_are_named_and_joint_map_renames(tmp_path):
    path = write(tmp_path / "knee.npz", dof_names=("h2", "knee"))
    with pytest.raises(ValueError, match=r"the model lacks the DOFs \['knee'\] and the file lacks the joints \['h1'\]"):
        motion.isaaclab_npz(path, TORSO)
    clip = motion.isaaclab_npz(path, TORSO, joint_map={"knee": "h1"})
    np.testing.assert_allclose(clip.qpos, TRUTH.qpos, atol=1e-12)
    with pytest.raises(ValueError, match=r"joint_map renames \['hip'\], which are not DOFs"):
        motion.isaaclab_npz(path, TORSO, joint_map={"hip": "h1"})


def test_the_root_body_is_named_or_found(tmp_path):
    path = write(tmp_path / "pelvis.npz", body_names=("shin", "pelvis"))
    with pytest.raises(ValueError, match=r"no body 'torso' in the file \(root_body\); its bodies: \['shin', 'pel"):
        motion.isaaclab_npz(path, TORSO)
    clip = motion.isaaclab_npz(path, TORSO, root_body="pelvis")
    np.testing.assert_allclose(clip.qpos, TRUTH.qpos, atol=1e-12)


def test_a_file_lacking_fields_or_with_wrong_fps_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"the file lacks \['body_rotations'\]"):
        motion.isaaclab_npz(write(tmp_path / "a.npz", drop=("body_rotations",)), TORSO)
    with pytest.raises(ValueError, match="no such file"):
        motion.isaaclab_npz(tmp_path / "none.npz", TORSO)
    # The loaded clip is checked: velocities at twice the claimed rate are refused.
    with pytest.raises(ValueError, match="motion clip 'fast': qvel is 0.5x"):
        motion.isaaclab_npz(write(tmp_path / "fast.npz", clip=TRUTH.replace(fps=120.0)), TORSO)
