"""mjzoo.motion.retarget: clips onto another character by IK, and its quality measures.

The known answer: the DeepMimic humanoid's own walk retargeted onto the humanoid with
the identity body map (every body, position and orientation, scale 1, no contact
locking) must give back the clip's joint angles and body positions (lifted only where
the recorded feet dip a few mm under the floor).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from mjzoo import motion
from mjzoo.envs import deepmimic
from mjzoo.motion import retarget
from mjzoo.motion.retarget import Link
from mjzoo.robots import scenes

G1_CLIPS = Path(__file__).resolve().parents[2] / "envs" / "assets" / "motions" / "g1"
FEET = retarget.DEEPMIMIC_FEET


@pytest.fixture(scope="module")
def human() -> mujoco.MjModel:
    return deepmimic.humanoid_model()


@pytest.fixture(scope="module")
def g1() -> mujoco.MjModel:
    return scenes.spec("g1").compile()


@pytest.fixture(scope="module")
def walk(human) -> motion.Clip:
    return motion.deepmimic_format.load(deepmimic.motion_path("walk"), human, deepmimic.character_joints())


@pytest.fixture(scope="module")
def g1_walk(human, g1, walk) -> retarget.Retargeted:
    return retarget.retarget(walk, human, g1, retarget.DEEPMIMIC_TO_G1, retarget.Config(feet=FEET))


def _poses(m: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    d = mujoco.MjData(m)
    out = []
    for q in qpos:
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        out.append(d.xpos[1:].copy())
    return np.array(out)  # [T, nbody - 1, 3]


def test_the_humanoid_retargeted_onto_itself_gives_its_own_clip_back(human, walk):
    clip = walk.replace(qpos=walk.qpos[:8], qvel=walk.qvel[:8])
    identity = {human.body(b).name: Link(human.body(b).name, 1.0, 1.0) for b in range(1, human.nbody)}
    config = retarget.Config(feet=FEET, scale=1.0, lock_contacts=False, tolerance=1e-10)
    out = retarget.retarget(clip, human, human, identity, config)

    assert out.clip.joint_names == clip.joint_names
    got, expected = _poses(human, out.clip.qpos), _poses(human, clip.qpos)
    # the same body, in the same place, but lifted where the recorded feet dip under the floor (5 mm)
    np.testing.assert_allclose(got - got[:, :1], expected - expected[:, :1], atol=5e-3)  # m
    lift = got[:, 0] - expected[:, 0]
    np.testing.assert_allclose(lift[:, :2], 0.0, atol=5e-3)
    assert np.all((lift[:, 2] > -1e-3) & (lift[:, 2] < 0.01))
    for j in range(human.njnt):  # each joint's rotation: hinge angles, ball and root quaternions
        a = human.jnt_qposadr[j]
        if human.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            np.testing.assert_allclose(out.clip.qpos[:, a], clip.qpos[:, a], atol=0.02)
        else:
            q = a + (3 if human.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE else 0)
            dots = np.abs(np.sum(out.clip.qpos[:, q : q + 4] * clip.qpos[:, q : q + 4], axis=1))
            assert np.all(2 * np.arccos(np.minimum(dots, 1.0)) < 0.03), human.joint(j).name
    assert max(out.quality.residual_max_cm.values()) < 1.0
    assert out.quality.penetration_cm < 1e-6


def test_the_walk_on_the_g1_keeps_its_feet_planted_and_above_the_floor(human, g1, walk, g1_walk):
    locked = g1_walk
    free = retarget.retarget(walk, human, g1, retarget.DEEPMIMIC_TO_G1, retarget.Config(feet=FEET, lock_contacts=False))
    motion.check(locked.clip, g1)
    assert locked.contacts.any(axis=0).all()  # each foot stands on the floor at some frame
    assert locked.quality.foot_skating_cm < 1.0 < free.quality.foot_skating_cm
    assert locked.quality.penetration_cm < 1e-6
    # every foot in contact is on the floor: its ankle at the G1's standing ankle height
    ankles = [locked.clip.body_names.index(f"{side}_ankle_roll_link") for side in ("right", "left")]
    heights = locked.clip.body_pos[:, ankles, 2][locked.contacts]
    np.testing.assert_allclose(heights, heights.mean(), atol=0.01)


def _segments(m: mujoco.MjModel, qpos: np.ndarray, anchor: str, chain: list[str]) -> np.ndarray:
    """[T, len(chain) - 1, 3] unit vectors along the chain's segments, in the anchor's frame."""
    d, out = mujoco.MjData(m), []
    for q in qpos:
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        points = d.xpos[[m.body(b).id for b in chain]]
        local = np.diff(points, axis=0) @ d.xmat[m.body(anchor).id].reshape(3, 3)
        out.append(local / np.linalg.norm(local, axis=-1, keepdims=True))
    return np.array(out)


def test_the_g1s_arms_take_the_human_arms_shape(human, g1, walk, g1_walk):
    # Upper arm and forearm point where the human's do, seen from the torso (the chest),
    # though the G1's arms are 0.7 of the human's length and its torso another shape.
    turn = _rest_rotation(g1, "torso_link").T @ _rest_rotation(human, "chest")  # chest axes -> torso axes
    for side in ("right", "left"):
        person = _segments(human, walk.qpos, "chest", [f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist"]) @ turn.T
        links = [f"{side}_shoulder_roll_link", f"{side}_elbow_link", f"{side}_wrist_yaw_link"]
        robot = _segments(g1, g1_walk.clip.qpos, "torso_link", links)
        degrees = np.degrees(np.arccos(np.clip(np.sum(person * robot, axis=-1), -1.0, 1.0)))  # [T, 2]
        assert degrees.mean() < 3.0 and degrees.max() < 6.0, (side, degrees.mean(), degrees.max())
        assert g1_walk.quality.residual_mean_cm[f"{side}_wrist_yaw_link"] < 1.0


def _rest_rotation(m: mujoco.MjModel, body: str) -> np.ndarray:
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    return d.xmat[m.body(body).id].reshape(3, 3)


def test_a_limb_whose_root_is_not_above_it_is_one_clear_error(human, g1, walk):
    body_map = {"chest": "torso_link", "left_shoulder": "left_shoulder_roll_link"}
    body_map["right_wrist"] = Link("right_wrist_yaw_link", limb=("chest", "left_shoulder"))
    with pytest.raises(ValueError, match=r"root 'left_shoulder' is not above 'right_wrist'"):
        retarget.retarget(walk, human, g1, body_map)


def test_foot_skating_is_the_path_of_a_foot_in_contact():
    pos = np.zeros((8, 2, 3))
    pos[:, 0, 0] = [0.0, 0.01, 0.02, 0.03, 0.5, 0.9, 0.9, 0.9]  # slides 3 cm in contact, then steps
    contacts = np.zeros((8, 2), bool)
    contacts[:4, 0] = contacts[5:, 0] = True
    contacts[:, 1] = True  # the other foot never moves
    assert retarget.foot_skating(pos, contacts) == pytest.approx(3.0)
    assert retarget.foot_skating(pos, np.zeros_like(contacts)) == 0.0
    assert retarget.contact_phases(contacts[:, 0]) == [(0, 4), (5, 8)]


def test_penetration_is_the_deepest_point_under_the_floor_in_cm():
    assert retarget.penetration(np.array([[0.02, -0.01], [0.0, -0.004]])) == pytest.approx(1.0)
    assert retarget.penetration(np.array([0.05, 0.0])) == 0.0


def test_limit_hits_count_joint_values_at_a_limit():
    m = mujoco.MjModel.from_xml_string("""<mujoco><compiler angle="radian"/><worldbody><body><joint name="a" range="-1 1"/>
        <geom size="0.1"/><body><joint name="b"/><geom size="0.1"/></body></body></worldbody></mujoco>""")
    qpos = np.array([[1.0, 5.0], [0.5, 5.0], [-0.995, 0.0], [0.0, 0.0]])  # b is unlimited
    assert retarget.limit_hits(qpos, m) == (2, 0.5)


@pytest.mark.parametrize(
    "body_map, config, message",
    [
        (
            {"right_ankel": "pelvis"},
            retarget.Config(),
            r"source model has no body 'right_ankel' .*did you mean 'right_ankle'",
        ),
        ({"root": "pelvs"}, retarget.Config(), r"robot model has no body 'pelvs' .*did you mean 'pelvis'"),
        ({"root": "pelvis"}, retarget.Config(feet=("left_ankle",)), r"Config.feet names 'left_ankle'"),
    ],
)
def test_a_body_map_naming_a_missing_body_is_one_clear_error(human, g1, walk, body_map, config, message):
    with pytest.raises(ValueError, match=message) as raised:
        retarget.retarget(walk, human, g1, body_map, config)
    assert "\n" not in str(raised.value)


def test_config_rejects_bad_numbers():
    with pytest.raises(ValueError, match=r"scale=-1.0 is invalid"):
        retarget.Config(scale=-1.0)


def test_the_committed_g1_clips_load_against_the_g1(g1):
    paths = sorted(G1_CLIPS.glob("*.npz"))
    assert {"walk", "run"} <= {p.stem for p in paths}
    for path in paths:
        clip = motion.load(path, g1)
        assert clip.num_frames >= 20
        assert clip.body_pos[:, :, 2].min() > 0.0  # nothing of the mapped bodies under the floor
