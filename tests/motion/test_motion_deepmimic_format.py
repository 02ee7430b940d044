"""mjzoo.motion.deepmimic_format: DeepMimic motion files read onto a MuJoCo character.

The character is the smallest with both joint kinds: a free root, a spherical
"shoulder" and a revolute "elbow" (DeepMimic's revolute axis is z of the y-up link
frame, so the z-up model's hinge turns about (0, -1, 0)). The file's three frames,
0.1 s apart, are written by hand in DeepMimic's y-up basis; the expected numbers are
the same motion worked out by hand in MuJoCo's z-up basis.
"""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from mjzoo import motion
from mjzoo.motion import deepmimic_format

C, S = np.cos(np.pi / 4), np.sin(np.pi / 4)
SHOULDER = '<body name="upper" pos="0 0 -0.1"><joint name="shoulder" type="ball"/><geom size="0.05"/>'
ELBOW = '<body name="lower" pos="0 0 -0.3"><joint name="elbow" axis="0 -1 0"/><geom size="0.05"/></body>'


def _model(nested: bool = True) -> mujoco.MjModel:
    """root > upper (ball) > lower (hinge); `nested=False`: both children of the root,
    the hinge's body first, so MuJoCo orders the elbow before the shoulder."""
    inner = SHOULDER + ELBOW + "</body>" if nested else ELBOW + SHOULDER + "</body>"
    return mujoco.MjModel.from_xml_string(f"""<mujoco><worldbody><body name="root" pos="0 0 1">
        <freejoint name="root"/><geom size="0.1"/>{inner}</body></worldbody></mujoco>""")


def _quat_about(axis: str, angle: float) -> list[float]:
    q = [np.cos(angle / 2), 0.0, 0.0, 0.0]
    q["xyz".index(axis) + 1] = np.sin(angle / 2)
    return q


# Frames in DeepMimic's layout, y-up: [duration, root pos, root quat, shoulder quat, elbow].
FRAMES = [
    [0.1, 1.0, 2.0, 3.0, 1.0, 0.0, 0.0, 0.0, *_quat_about("y", np.pi / 2), 0.3],
    [0.1, 1.5, 2.0, 3.0, *_quat_about("y", 0.2), *_quat_about("y", np.pi / 2 + 0.1), 0.5],
    # the same rotations written as -q: one rotation, the loader keeps the sign continuous
    [0.0, 2.0, 2.0, 2.0, *(-np.array(_quat_about("y", 0.2))), *(-np.array(_quat_about("y", np.pi / 2 + 0.1))), 0.5],
]


def _write(tmp_path, frames, name="clip.txt", **extra) -> str:
    path = tmp_path / name
    path.write_text(json.dumps({"Loop": "wrap", "Frames": [list(map(float, f)) for f in frames], **extra}))
    return str(path)


def test_positions_are_turned_to_z_up_and_quaternions_conjugated(tmp_path):
    clip = deepmimic_format.load(_write(tmp_path, FRAMES), _model())
    assert clip.name == "clip" and clip.fps == pytest.approx(10.0) and clip.qpos.shape == (3, 12)
    # (x, y, z) y-up -> (x, -z, y); a turn about y-up's up axis is a turn about z.
    np.testing.assert_allclose(clip.qpos[0], [1, -3, 2, 1, 0, 0, 0, C, 0, 0, S, 0.3], atol=1e-12)
    np.testing.assert_allclose(clip.qpos[1, :7], [1.5, -3, 2, *_quat_about("z", 0.2)], atol=1e-12)
    np.testing.assert_allclose(clip.qpos[1, 7:11], _quat_about("z", np.pi / 2 + 0.1), atol=1e-12)
    np.testing.assert_allclose(
        clip.qpos[2], [2, -2, 2, *_quat_about("z", 0.2), *_quat_about("z", np.pi / 2 + 0.1), 0.5], atol=1e-12
    )
    assert clip.joint_names == ("root", "shoulder", "elbow")


def test_velocities_are_backward_differences_per_second(tmp_path):
    clip = deepmimic_format.load(_write(tmp_path, FRAMES), _model())
    # frame 0 -> 1 in 0.1 s: root +0.5 m in x, yaw +0.2 rad (body frame z), shoulder +0.1
    # rad about its local z, elbow +0.2 rad. Frame 1 -> 2: root (+0.5, 0, -1) m y-up,
    # (+0.5, +1, 0) m z-up; nothing turns (the -q frame is the same rotation).
    first = [5, 0, 0, 0, 0, 2, 0, 0, 1, 2]
    np.testing.assert_allclose(clip.qvel, [first, first, [5, 10, 0, 0, 0, 0, 0, 0, 0, 0]], atol=1e-9)
    m = _model()
    for t in (1, 2):  # integrating frame t-1 with qvel[t] over 1/fps lands on frame t
        q = clip.qpos[t - 1].copy()
        mujoco.mj_integratePos(m, q, clip.qvel[t], 1.0 / clip.fps)
        np.testing.assert_allclose(q, clip.qpos[t], atol=1e-9)


def test_joints_map_the_file_order_onto_the_model_order(tmp_path):
    m = _model(nested=False)
    assert [m.joint(j).name for j in range(m.njnt)] == ["root", "elbow", "shoulder"]
    clip = deepmimic_format.load(_write(tmp_path, FRAMES), m, joints=["shoulder", "elbow"])
    np.testing.assert_allclose(clip.qpos[0], [1, -3, 2, 1, 0, 0, 0, 0.3, C, 0, 0, S], atol=1e-12)
    with pytest.raises(ValueError, match="joints=.*must name each"):
        deepmimic_format.load(_write(tmp_path, FRAMES), m, joints=["shoulder", "knee"])


def test_up_z_keeps_the_file_basis_and_scale_the_root_position(tmp_path):
    clip = deepmimic_format.load(_write(tmp_path, FRAMES), _model(), up="z", scale=2.0)
    np.testing.assert_allclose(clip.qpos[0], [2, 4, 6, 1, 0, 0, 0, C, 0, S, 0, 0.3], atol=1e-12)
    np.testing.assert_allclose(clip.qvel[1, :3], [10, 0, 0], atol=1e-9)


def test_unequal_durations_are_interpolated_onto_the_common_step(tmp_path):
    frames = [[d, 0, 1, 0, 1, 0, 0, 0, 1, 0, 0, 0, a] for d, a in ((0.1, 0.0), (0.2, 0.1), (0.1, 0.3), (0.0, 0.4))]
    clip = deepmimic_format.load(_write(tmp_path, frames), _model())
    assert clip.fps == pytest.approx(10.0)
    np.testing.assert_allclose(clip.qpos[:, -1], [0.0, 0.1, 0.2, 0.3, 0.4], atol=1e-12)
    np.testing.assert_allclose(clip.qvel[:, -1], [1.0, 1.0, 1.0, 1.0, 1.0], atol=1e-9)


def test_the_clip_passes_the_motion_checks_and_saves(tmp_path):
    m = _model()
    clip = deepmimic_format.load(_write(tmp_path, FRAMES), m, name="wave")
    assert motion.check(clip, m) is clip and clip.name == "wave"
    again = motion.load(motion.save(tmp_path / "wave.npz", clip), m)
    np.testing.assert_array_equal(again.qpos, clip.qpos)


@pytest.mark.parametrize(
    "frames, match",
    [
        ([[0.1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]] * 2, "frame holds 11 numbers.*take 12"),
        ([[0.0, *FRAMES[0][1:]], FRAMES[1]], "frame 0 has duration 0.0"),
        ([FRAMES[0]], r"shape \(1, 13\)"),
    ],
)
def test_malformed_files_name_the_problem(tmp_path, frames, match):
    with pytest.raises(ValueError, match=match):
        deepmimic_format.load(_write(tmp_path, frames), _model())


def test_not_a_motion_file_and_bad_arguments(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text('{"Loop": "none"}')
    with pytest.raises(ValueError, match="not a DeepMimic motion"):
        deepmimic_format.load(str(bad), _model())
    with pytest.raises(ValueError, match="no such file"):
        deepmimic_format.load(str(tmp_path / "absent.txt"), _model())
    with pytest.raises(ValueError, match="up='x'"):
        deepmimic_format.load(_write(tmp_path, FRAMES), _model(), up="x")
    slide = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body><joint type="slide"/><geom size="1"/></body></worldbody></mujoco>'
    )
    with pytest.raises(ValueError, match="first joint must be its only free joint"):
        deepmimic_format.load(_write(tmp_path, FRAMES), slide)
