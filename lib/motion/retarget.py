"""Retargeting: a clip of one character (a human's) onto another (a robot), by inverse
kinematics on key bodies with `mink`, on the CPU.

    from mjzoo.envs import deepmimic
    from mjzoo.motion import retarget
    from mjzoo.robots import scenes
    human, g1 = deepmimic.humanoid_model(), scenes.spec("g1").compile()
    walk = deepmimic.walk_clips(("walk",))[0]
    out = retarget.retarget(walk, human, g1, retarget.DEEPMIMIC_TO_G1, retarget.Config(feet=retarget.DEEPMIMIC_FEET))
    out.clip            # a checked Clip of the G1: qpos [T, 36], qvel [T, 35]
    print(out.quality.row())

How. A body map names, for each key body of the source, the robot body that follows it
and how (`Link`: a cost on its position, one on its orientation). Every frame of the
source is posed (`mj_kinematics`) and turned into targets for those robot bodies:

- positions scaled by `Config.scale` about the world origin (so the floor stays at z = 0;
  default: the ratio of the two root bodies' standing heights), a foot's raised by the
  difference of the two feet's standing heights (ankles sit at different heights);
- orientations ``R_source(t) R_source_rest^T R_robot_rest``: the source body's turn from
  its standing pose applied to the robot body's standing pose (both characters stand at
  their qpos0, lowered or raised until their lowest sole touches the floor);
- a foot in contact in the source (its sole within `Config.contact_height` of the floor
  and its horizontal speed under `Config.contact_speed`) stays put: over each contact
  phase its target is one place, the phase's mean, on the floor, flat, at the phase's
  mean heading.
- a limb's bodies (`Link.limb`: the G1's knees, elbows and hands) are targeted relative
  to an anchor (the pelvis, the torso), not the world: e.g. from the robot's shoulder,
  along the human's upper arm and forearm as the human's chest sees them, each scaled
  to the robot's segment;
  a world target after one global scale asks arms of another length for the human's
  reach (8-20 cm misses, and a bent arm where the human's is straight).

mink then solves each frame (quadratic programs under the robot's joint limits, a small
posture cost pulling unmapped joints to the standing pose), warm-started from the
previous frame's solution (the first frame from the standing pose, every step taken); a
frame whose lowest sole ends below the floor is lifted by that depth. Velocities come from the positions by backward differences
(`motion.velocities_from_positions`, ``mj_differentiatePos``, as the source clips'), and the clip is checked against the robot (`motion.check`).

Quality (`Quality`, per clip): foot skating (the longest horizontal travel of one foot
during one source contact phase, cm), ground penetration (the deepest sole below the
floor, cm), joint-limit hits (frames x joints within `LIMIT_MARGIN` of a limit: count and
fraction) and the IK residuals (mean and max distance from target, cm, per body whose
position is tracked; a limb's target placed by its anchor's reached pose). `foot_skating`, `penetration` and `limit_hits` compute them from
arrays.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from collections.abc import Sequence
from typing import NamedTuple

import mink
import mujoco
import numpy as np

from mjzoo import checks
from mjzoo import names
from mjzoo.motion.checking import check
from mjzoo.motion.checking import velocities_from_positions
from mjzoo.motion.clips import Clip

__all__ = [
    "Link",
    "Config",
    "Quality",
    "Retargeted",
    "retarget",
    "foot_skating",
    "penetration",
    "limit_hits",
    "contact_phases",
    "LIMIT_MARGIN",
    "DEEPMIMIC_TO_G1",
    "DEEPMIMIC_FEET",
]

LIMIT_MARGIN = 0.01  # rad (m for slides): a joint value this close to a limit is a hit
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
_G = mujoco.mjtGeom
_SOLES = {int(_G.mjGEOM_SPHERE), int(_G.mjGEOM_CAPSULE), int(_G.mjGEOM_ELLIPSOID), int(_G.mjGEOM_CYLINDER)}
_SOLES |= {int(_G.mjGEOM_BOX)}


@dataclasses.dataclass(frozen=True)
class Link:
    """The robot body that follows one source body: `position_cost` and
    `orientation_cost` weigh its position (per m) and orientation (per rad) errors.

    `limb` = (anchor, root), two keys of the body map (e.g. ``("chest", "right_shoulder")``),
    makes the target one of a limb held relative to the anchor's robot body (mink's
    `RelativeFrameTask`) instead of the world: the robot root's place in the anchor's
    frame as it stands (a shoulder, which moves a cm or two in the torso) plus the source's segments from the root to
    this body through the mapped bodies between them, each scaled to the length of the
    robot's, as seen from the source's anchor. A hand so follows the human arm's shape
    with the robot's arm lengths, wherever the robot's torso ends up."""

    body: str
    position_cost: float = 1.0
    orientation_cost: float = 0.0
    limb: tuple[str, str] | None = None


# The DeepMimic humanoid (`mjzoo.envs.deepmimic.humanoid_model`) onto Playground's G1
# (`mjzoo.robots.scenes.spec("g1")`). The G1 has no head: the chest turns its torso. The
# pelvis and feet are held in place and orientation. Its limbs have other proportions
# than the scaled human's (arms 0.7 of the human's, not 0.9): knees follow the human leg
# from the hip, relative to the pelvis, and elbows and wrists the arm from the shoulder,
# relative to the torso; knees only steer (a low cost: the feet and pelvis decide).
_RIGHT_ARM, _LEFT_ARM = ("chest", "right_shoulder"), ("chest", "left_shoulder")
DEEPMIMIC_TO_G1: dict[str, Link] = {
    "root": Link("pelvis", 2.0, 2.0),
    "chest": Link("torso_link", 0.0, 0.5),
    "right_ankle": Link("right_ankle_roll_link", 10.0, 2.5),
    "left_ankle": Link("left_ankle_roll_link", 10.0, 2.5),
    "right_hip": Link("right_hip_roll_link", 0.0),
    "left_hip": Link("left_hip_roll_link", 0.0),
    "right_knee": Link("right_knee_link", 0.5, limb=("root", "right_hip")),
    "left_knee": Link("left_knee_link", 0.5, limb=("root", "left_hip")),
    "right_shoulder": Link("right_shoulder_roll_link", 0.0),  # the arms' roots: no cost of their own
    "left_shoulder": Link("left_shoulder_roll_link", 0.0),
    "right_elbow": Link("right_elbow_link", 0.5, limb=_RIGHT_ARM),
    "left_elbow": Link("left_elbow_link", 0.5, limb=_LEFT_ARM),
    "right_wrist": Link("right_wrist_yaw_link", 1.0, limb=_RIGHT_ARM),
    "left_wrist": Link("left_wrist_yaw_link", 1.0, limb=_LEFT_ARM),
}
DEEPMIMIC_FEET = ("right_ankle", "left_ankle")


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config:
    """How to retarget (module docstring). Lengths in the source's metres unless said."""

    feet: tuple[str, ...] = ()  # source bodies (keys of the body map) that stand on the floor
    scale: float | None = None  # robot metres per source metre; None: ratio of the roots' standing heights
    contact_height: float = 0.03  # m: a source sole this close to the floor ...
    contact_speed: float = 0.6  # m/s: ... and slower than this horizontally is in contact
    lock_contacts: bool = True  # a foot in contact in the source stays put
    posture_cost: float = 1e-3  # per rad, pulling every joint to the robot's standing pose
    iterations: int = 20  # IK steps per frame at most (the first frame: 10x)
    tolerance: float = 1e-6  # stop a frame's steps when the squared error falls by less
    damping: float = 1e-3  # Levenberg-Marquardt damping of each step
    solver: str = "daqp"  # qpsolvers' name of the QP solver

    def __post_init__(self):
        inf = float("inf")
        checks.ranges(
            "retarget.Config",
            self,
            dict(
                contact_height=(0, inf, "[)"),
                contact_speed=(0, inf, "[)"),
                posture_cost=(0, inf, "[)"),
                tolerance=(0, inf, "[)"),
                damping=(0, inf, "[)"),
                iterations=(1, inf, "[)"),
                **({} if self.scale is None else dict(scale=(0, inf, "()"))),
            ),
        )


@dataclasses.dataclass(frozen=True)
class Quality:
    """How well one clip was retargeted (module docstring); lengths in cm of the robot."""

    clip: str
    frames: int
    foot_skating_cm: float
    penetration_cm: float
    limit_hits: int
    limit_fraction: float
    residual_mean_cm: dict[str, float]  # robot body -> mean distance from its target
    residual_max_cm: dict[str, float]
    seconds: float  # wall-clock time of the retargeting

    HEADER = "clip        frames  skate cm  depth cm  limit hits  resid mean/max cm (worst body)    s"

    def row(self) -> str:
        """One line under `HEADER`."""
        worst = max(self.residual_mean_cm, key=self.residual_mean_cm.get)
        resid = f"{self.residual_mean_cm[worst]:5.1f} / {self.residual_max_cm[worst]:5.1f} ({worst})"
        hits = f"{self.limit_hits} ({100 * self.limit_fraction:.1f}%)"
        return (
            f"{self.clip:<11} {self.frames:>6}  {self.foot_skating_cm:8.2f}  {self.penetration_cm:8.2f}  "
            f"{hits:>10}  {resid:<33} {self.seconds:4.1f}"
        )


class Retargeted(NamedTuple):
    clip: Clip  # the robot's, checked
    quality: Quality
    contacts: np.ndarray  # bool [T, F]: each foot (Config.feet) in contact in the source


def retarget(
    clip: Clip,
    source: mujoco.MjModel,
    robot: mujoco.MjModel,
    body_map: Mapping[str, str | Link],
    config: Config = Config(),
    *,
    name: str | None = None,
) -> Retargeted:
    """`clip` (of the `source` model) retargeted onto `robot` by `body_map` (source body ->
    robot body, or a `Link` with costs; a bare name tracks the position only).

    Both models need a free joint first (their roots); `config.feet` names the source
    feet. Returns the robot's clip (named `name`, default the source clip's; qpos
    [T, robot.nq], qvel [T, robot.nv], and the mapped robot bodies' world poses), its
    `Quality` and the source contacts. Raises ValueError naming a body no model has.
    """
    start = time.perf_counter()
    check(clip, source)
    links = {k: v if isinstance(v, Link) else Link(v) for k, v in body_map.items()}
    src_ids = _body_ids(source, "source", list(links), "body_map's keys")
    rob_ids = _body_ids(robot, "robot", [link.body for link in links.values()], "body_map's values")
    foot_index = [_index_of(list(links), f, "Config.feet") for f in config.feet]
    src_feet, rob_feet = [src_ids[i] for i in foot_index], [rob_ids[i] for i in foot_index]
    src_soles, rob_soles = _sole_geoms(source, src_feet), _sole_geoms(robot, rob_feet)
    src_root, rob_root = _root_body(source, "source"), _root_body(robot, "robot")

    src_rest, rob_rest = _standing(source, src_soles), _standing(robot, rob_soles)
    scale = config.scale or float(rob_rest.xpos[rob_root, 2] / src_rest.xpos[src_root, 2])

    # Source poses [T, K, 3] / [T, K, 3, 3] and soles [T, F].
    src = mujoco.MjData(source)
    pos = np.zeros((clip.num_frames, len(links), 3))
    rot = np.zeros((clip.num_frames, len(links), 3, 3))
    soles = np.zeros((clip.num_frames, len(src_feet)))
    for t in range(clip.num_frames):
        src.qpos[:] = clip.qpos[t]
        mujoco.mj_kinematics(source, src)
        pos[t], rot[t] = src.xpos[src_ids], src.xmat[src_ids].reshape(-1, 3, 3)
        soles[t] = _lowest(src, src_soles)
    speed = np.linalg.norm(np.gradient(pos[:, foot_index, :2], axis=0), axis=-1) * clip.fps
    contacts = (soles < config.contact_height) & (speed < config.contact_speed)

    # Targets: scaled positions, rest-calibrated orientations, feet raised to the robot's ankles.
    target_pos = scale * pos
    calib = np.einsum(
        "kji,kjl->kil", src_rest.xmat[src_ids].reshape(-1, 3, 3), rob_rest.xmat[rob_ids].reshape(-1, 3, 3)
    )
    target_rot = rot @ calib
    rest_z = rob_rest.xpos[rob_feet, 2]
    target_pos[:, foot_index, 2] += rest_z - scale * src_rest.xpos[src_feet, 2]
    if config.lock_contacts:
        for f, k in enumerate(foot_index):
            rest = rob_rest.xmat[rob_ids[k]].reshape(3, 3)
            for a, b in contact_phases(contacts[:, f]):
                turn = target_rot[a:b, k] @ rest.T
                yaw = np.arctan2(turn[:, 1, 0].mean(), turn[:, 0, 0].mean())
                target_pos[a:b, k, :2] = target_pos[a:b, k, :2].mean(axis=0)
                target_pos[a:b, k, 2] = rest_z[f]
                target_rot[a:b, k] = _yaw(yaw) @ rest
    # Limbs: targets in their anchor's frame (Link.limb), orientations relative to the anchor's target.
    anchors = {}
    for k, link in enumerate(links.values()):
        if link.limb is not None:
            anchor, root = (_index_of(list(links), b, f"{list(links)[k]}'s Link.limb") for b in link.limb)
            path = _limb_path(source, src_ids, root, k)
            frames = (src_rest, rob_rest, src_ids, rob_ids)
            anchors[k] = anchor
            target_pos[:, k] = _limb_target(pos, rot, frames, anchor, path)
            target_rot[:, k] = np.swapaxes(target_rot[:, anchor], -1, -2) @ target_rot[:, k]

    qpos, reached, goal = _solve(
        robot, rob_rest.qpos, rob_ids, links, anchors, target_pos, target_rot, rob_soles, config
    )
    qvel = velocities_from_positions(qpos, clip.fps, robot, backward=True)

    rob = mujoco.MjData(robot)
    body_pos = np.zeros((clip.num_frames, len(rob_ids), 3))
    body_quat = np.zeros((clip.num_frames, len(rob_ids), 4))
    lowest = np.zeros((clip.num_frames, len(rob_feet)))
    for t in range(clip.num_frames):
        rob.qpos[:] = qpos[t]
        mujoco.mj_kinematics(robot, rob)
        body_pos[t], body_quat[t] = rob.xpos[rob_ids], rob.xquat[rob_ids]
        lowest[t] = _lowest(rob, rob_soles)
    out = Clip(
        name=name or clip.name,
        fps=clip.fps,
        qpos=qpos,
        qvel=qvel,
        joint_names=tuple(names.all_names(robot, "joint")),
        body_names=tuple(link.body for link in links.values()),
        body_pos=body_pos,
        body_quat=body_quat,
    )
    check(out, robot)

    tracked = [k for k, link in enumerate(links.values()) if link.position_cost > 0]
    error = 100 * np.linalg.norm(reached[:, tracked] - goal[:, tracked], axis=-1)  # [T, K'] cm
    hits, fraction = limit_hits(qpos, robot)
    quality = Quality(
        clip=out.name,
        frames=out.num_frames,
        foot_skating_cm=foot_skating(body_pos[:, foot_index], contacts),
        penetration_cm=penetration(lowest),
        limit_hits=hits,
        limit_fraction=fraction,
        residual_mean_cm={out.body_names[k]: float(e) for k, e in zip(tracked, error.mean(axis=0))},
        residual_max_cm={out.body_names[k]: float(e) for k, e in zip(tracked, error.max(axis=0))},
        seconds=time.perf_counter() - start,
    )
    return Retargeted(out, quality, contacts)


def foot_skating(foot_pos: np.ndarray, contacts: np.ndarray) -> float:
    """cm: the longest horizontal path of one foot during one contact phase, from foot
    positions [T, F, 3] (m) and contacts bool [T, F]; 0 without contacts."""
    foot_pos, contacts = np.asarray(foot_pos, np.float64), np.asarray(contacts, bool)
    worst = 0.0
    for f in range(contacts.shape[1]):
        for a, b in contact_phases(contacts[:, f]):
            steps = np.linalg.norm(np.diff(foot_pos[a:b, f, :2], axis=0), axis=-1)
            worst = max(worst, float(steps.sum()))
    return 100 * worst


def penetration(lowest: np.ndarray) -> float:
    """cm: how deep the lowest of the points at heights `lowest` [...] (m; floor at 0) is
    below the floor; 0 if none is."""
    return 100 * max(0.0, -float(np.min(lowest)))


def limit_hits(qpos: np.ndarray, mj_model: mujoco.MjModel, margin: float = LIMIT_MARGIN) -> tuple[int, float]:
    """(count, fraction) of the values of `mj_model`'s limited hinge and slide joints in
    `qpos` [T, nq] within `margin` of a limit (the fraction over frames x those joints)."""
    kinds = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    joints = [j for j in range(mj_model.njnt) if mj_model.jnt_limited[j] and int(mj_model.jnt_type[j]) in kinds]
    if not joints:
        return 0, 0.0
    q = np.asarray(qpos)[:, mj_model.jnt_qposadr[joints]]
    low, high = mj_model.jnt_range[joints].T
    hit = (q <= low + margin) | (q >= high - margin)
    return int(hit.sum()), float(hit.mean())


def contact_phases(contact: np.ndarray) -> list[tuple[int, int]]:
    """[(first, end)) frame ranges of the runs of True in `contact` [T]."""
    edges = np.diff(np.concatenate([[0], np.asarray(contact, np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))


def _limb_target(pos, rot, frames, anchor: int, path: list[int]) -> np.ndarray:
    """[T, 3] a limb body's targets in its anchor's robot frame (`Link.limb`): the robot's
    limb root where it stands, plus the source's segments along `path` (map indices, the
    root first) turned from the source anchor's frame into the robot's and scaled.
    `pos` [T, K, 3], `rot` [T, K, 3, 3]: the source's mapped bodies in the world."""
    src_rest, rob_rest, src_ids, rob_ids = frames
    src_a, rob_a = (rest.xmat[ids[anchor]].reshape(3, 3) for rest, ids in ((src_rest, src_ids), (rob_rest, rob_ids)))
    turn = rob_a.T @ src_a  # source anchor coordinates -> robot anchor coordinates (both standing)
    root = path[0]
    out = np.broadcast_to(rob_a.T @ (rob_rest.xpos[rob_ids[root]] - rob_rest.xpos[rob_ids[anchor]]), pos[:, 0].shape)
    for a, b in zip(path[:-1], path[1:]):
        src_len = np.linalg.norm(src_rest.xpos[src_ids[b]] - src_rest.xpos[src_ids[a]])
        rob_len = np.linalg.norm(rob_rest.xpos[rob_ids[b]] - rob_rest.xpos[rob_ids[a]])
        local = np.einsum("tji,tj->ti", rot[:, anchor], pos[:, b] - pos[:, a])  # in the source anchor's frame
        out = out + (rob_len / src_len) * local @ turn.T
    return out


def _limb_path(source: mujoco.MjModel, src_ids: list[int], root: int, k: int) -> list[int]:
    """Map indices of the mapped source bodies from `root` down to `k` (both included)."""
    index = {b: i for i, b in enumerate(src_ids)}
    path, body = [k], src_ids[k]
    while body != src_ids[root]:
        body = int(source.body_parentid[body])
        if body == 0:
            raise ValueError(
                f"retarget: Link.limb's root {source.body(src_ids[root]).name!r} is not above "
                f"{source.body(src_ids[k]).name!r} in the source model"
            )
        if body in index:
            path.append(index[body])
    return path[::-1]


def _solve(robot, rest_qpos, body_ids, links, anchors, target_pos, target_rot, soles, config):
    """qpos [T, nq], the reached body positions [T, K, 3] and their targets in the world
    [T, K, 3] (a limb's: where its anchor's reached pose puts it), frame by frame; the
    targets of the bodies in `anchors` (map index -> its anchor's) are in that anchor's frame."""
    configuration = mink.Configuration(robot)
    tasks = []
    for k, (b, link) in enumerate(zip(body_ids, links.values())):
        costs = (link.position_cost, link.orientation_cost)
        if k in anchors:
            root = robot.body(body_ids[anchors[k]]).name
            tasks.append(mink.RelativeFrameTask(robot.body(b).name, "body", root, "body", *costs, lm_damping=1.0))
        else:
            tasks.append(mink.FrameTask(robot.body(b).name, "body", *costs, lm_damping=1.0))
    posture = mink.PostureTask(robot, cost=config.posture_cost)
    limits = [mink.ConfigurationLimit(robot)]
    q = rest_qpos.copy()
    configuration.update(q)
    posture.set_target(rest_qpos)
    qpos = np.zeros((target_pos.shape[0], robot.nq))
    reached, goal = np.zeros_like(target_pos), target_pos.copy()
    for t in range(target_pos.shape[0]):
        for task, p, r in zip(tasks, target_pos[t], target_rot[t]):
            task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3.from_matrix(r), p))
        every = tasks + [posture]
        previous = np.inf
        for _ in range(config.iterations * (10 if t == 0 else 1)):
            step = mink.solve_ik(configuration, every, 1.0, config.solver, config.damping, limits=limits)
            configuration.integrate_inplace(step, 1.0)
            error = sum(float(np.sum(task.compute_error(configuration) ** 2)) for task in tasks)
            if previous - error < config.tolerance and t > 0:  # the first frame: every step (from rest, far)
                break
            previous = error
        q = configuration.q.copy()
        depth = -_lowest(configuration.data, soles).min() if soles else 0.0
        if depth > 0:  # a sole under the floor: lift the whole body out
            q[2] += depth
            configuration.update(q)
        qpos[t] = q
        data = configuration.data
        reached[t] = data.xpos[body_ids]
        for k, anchor in anchors.items():
            a = body_ids[anchor]
            goal[t, k] = data.xpos[a] + data.xmat[a].reshape(3, 3) @ target_pos[t, k]
    return qpos, reached, goal


def _body_ids(m: mujoco.MjModel, who: str, wanted: Sequence[str], where: str) -> list[int]:
    known = names.all_names(m, "body")
    for body in wanted:
        if body not in known:
            raise ValueError(
                f"retarget: the {who} model has no body {body!r} (in {where}){checks.did_you_mean([body], known)}"
            )
    return [known.index(body) for body in wanted]


def _index_of(keys: list[str], body: str, where: str) -> int:
    if body not in keys:
        raise ValueError(
            f"retarget: {where} names {body!r}, which the body map does not map{checks.did_you_mean([body], keys)}"
        )
    return keys.index(body)


def _root_body(m: mujoco.MjModel, who: str) -> int:
    if m.njnt == 0 or int(m.jnt_type[0]) != _FREE or m.jnt_qposadr[0] != 0:
        raise ValueError(f"retarget: the {who} model's first joint must be a free joint (its root)")
    return int(m.jnt_bodyid[0])


def _sole_geoms(m: mujoco.MjModel, feet: list[int]) -> list[int]:
    """The primitive geoms (boxes, spheres, capsules, ...) of the feet's subtrees: what a foot stands on."""
    found = []
    for foot in feet:
        geoms = [g for g in mink.get_subtree_geom_ids(m, foot) if int(m.geom_type[g]) in _SOLES]
        if not geoms:
            raise ValueError(f"retarget: the foot {m.body(foot).name!r} has no box, sphere or capsule to stand on")
        found.append(geoms)
    return found


def _lowest(d: mujoco.MjData, soles: list[list[int]]) -> np.ndarray:
    """[F] the height of each foot's lowest point (posed `d`)."""
    m = d.model
    out = np.zeros(len(soles))
    for f, geoms in enumerate(soles):
        z = []
        for g in geoms:
            up, size, kind = d.geom_xmat[g].reshape(3, 3)[2], m.geom_size[g], int(m.geom_type[g])
            if kind == int(_G.mjGEOM_SPHERE):
                reach = size[0]
            elif kind == int(_G.mjGEOM_CAPSULE):
                reach = abs(up[2]) * size[1] + size[0]
            elif kind == int(_G.mjGEOM_CYLINDER):
                reach = abs(up[2]) * size[1] + size[0] * np.sqrt(max(0.0, 1 - up[2] ** 2))
            elif kind == int(_G.mjGEOM_ELLIPSOID):
                reach = np.linalg.norm(up * size)
            else:  # box
                reach = np.abs(up) @ size
            z.append(d.geom_xpos[g, 2] - reach)
        out[f] = min(z)
    return out


def _standing(m: mujoco.MjModel, soles: list[list[int]]) -> mujoco.MjData:
    """`m` posed at qpos0, its root moved up or down until its lowest sole is on the floor."""
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    if soles:
        d.qpos[2] -= _lowest(d, soles).min()
        mujoco.mj_kinematics(m, d)
    return d


def _yaw(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
