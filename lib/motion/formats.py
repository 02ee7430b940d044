"""Public motion formats, read into checked `Clip`s.

IsaacLab's humanoid AMP motions (`isaaclab_tasks/direct/humanoid_amp/motions/*.npz`,
the layout MimicKit-style retargeting scripts write for it) are one .npz per clip:

    fps                      scalar, frames per second
    dof_names                str [D]       one name per 1-dof joint
    body_names               str [B]
    dof_positions            [T, D]        rad (m for prismatic joints)
    dof_velocities           [T, D]        per second
    body_positions           [T, B, 3]     world frame
    body_rotations           [T, B, 4]     world frame, quaternion w, x, y, z
    body_linear_velocities   [T, B, 3]     world frame
    body_angular_velocities  [T, B, 3]     world frame

`isaaclab_npz` maps the DOFs onto the model's hinge and slide joints by name and builds
the free joint of the floating base from the root body's pose and velocities:

    clip = motion.isaaclab_npz("humanoid_walk.npz", mj_model, root_body="pelvis")

MuJoCo's free joint wants the body-frame angular velocity: the file's world-frame one
is rotated into the root body's frame. Its linear velocity (world frame) is taken as
the velocity of the root body's origin; IsaacLab records the velocity of the body's
center of mass, which differs by w x r where the root body's inertial frame is offset
from its origin by r (check `mj_model.body_ipos` of the root body).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import mujoco
import numpy as np

from mjzoo import names
from mjzoo.motion.checking import check
from mjzoo.motion.clips import Clip

__all__ = ["isaaclab_npz", "ISAACLAB_FIELDS"]

ISAACLAB_FIELDS = (
    "fps",
    "dof_names",
    "body_names",
    "dof_positions",
    "dof_velocities",
    "body_positions",
    "body_rotations",
    "body_linear_velocities",
    "body_angular_velocities",
)
_FREE, _BALL = int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL)


def isaaclab_npz(
    path: str | Path, mj_model: mujoco.MjModel, root_body: str | None = None, joint_map: Mapping[str, str] | None = None
) -> Clip:
    """The IsaacLab humanoid-AMP motion in `path` as a `Clip` of `mj_model`, checked.

    Args:
      path: the .npz file (layout in the module docstring).
      mj_model: a model with hinge/slide joints and at most one free joint (the
        floating base); ball joints are not supported by the format.
      root_body: the file's body whose pose and velocities drive the free joint; None:
        the name of the model's free-joint body. Unused for a fixed-base model.
      joint_map: {file DOF name: model joint name} for DOFs named differently; the
        rest keep their names.

    Every 1-dof joint of the model must get a DOF and every DOF a joint: the error
    names the DOFs the model lacks and the joints the file lacks. The clip's bodies
    are the file's (world poses, quaternions normalized).
    """
    who = f"motion.isaaclab_npz({str(path)!r})"
    f = _read(Path(path), who)
    dof_names = [str(n) for n in f["dof_names"]]
    joint_map = dict(joint_map or {})
    unknown = sorted(set(joint_map) - set(dof_names))
    if unknown:
        raise ValueError(f"{who}: joint_map renames {unknown}, which are not DOFs of the file: {dof_names}")
    dof_names = [joint_map.get(n, n) for n in dof_names]
    t = f["dof_positions"].shape[0]
    qpos, qvel = np.zeros((t, mj_model.nq)), np.zeros((t, mj_model.nv))
    _fill_joints(who, f, dof_names, mj_model, qpos, qvel)
    free = np.flatnonzero(mj_model.jnt_type == _FREE)
    body_names = [str(n) for n in f["body_names"]]
    if free.size:
        _fill_root(who, f, body_names, mj_model, int(free[0]), root_body, qpos, qvel)
    body_quat = np.asarray(f["body_rotations"], np.float64)
    clip = Clip(
        name=Path(path).stem,
        fps=float(f["fps"]),
        qpos=qpos,
        qvel=qvel,
        joint_names=tuple(names.all_names(mj_model, "joint")),
        body_names=tuple(body_names),
        body_pos=np.asarray(f["body_positions"], np.float64),
        body_quat=body_quat / np.linalg.norm(body_quat, axis=-1, keepdims=True),
    )
    return check(clip, mj_model)


def _read(path: Path, who: str) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise ValueError(f"{who}: no such file")
    with np.load(path, allow_pickle=False) as f:
        missing = [k for k in ISAACLAB_FIELDS if k not in f]
        if missing:
            raise ValueError(f"{who}: the file lacks {missing}; an IsaacLab motion holds {list(ISAACLAB_FIELDS)}")
        data = {k: np.asarray(f[k]) for k in ISAACLAB_FIELDS}
    t, d, b = data["dof_positions"].shape[0], len(data["dof_names"]), len(data["body_names"])
    shapes = dict(
        dof_positions=(t, d),
        dof_velocities=(t, d),
        body_positions=(t, b, 3),
        body_rotations=(t, b, 4),
        body_linear_velocities=(t, b, 3),
        body_angular_velocities=(t, b, 3),
    )
    for k, shape in shapes.items():
        if data[k].shape != shape:
            raise ValueError(f"{who}: {k} has shape {data[k].shape}; with T={t}, D={d}, B={b} it must be {shape}")
    return data


def _fill_joints(who: str, f, dof_names: list[str], m: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray) -> None:
    kinds = [int(k) for k in m.jnt_type]
    if _BALL in kinds:
        balls = names.all_names(m, "joint", [j for j, k in enumerate(kinds) if k == _BALL])
        raise ValueError(f"{who}: the model has ball joints {balls}; IsaacLab motions hold 1-dof joints only")
    one_dof = [j for j, k in enumerate(kinds) if k != _FREE]
    joint_names = names.all_names(m, "joint", one_dof)
    lacking_in_model = [n for n in dof_names if n not in joint_names]
    lacking_in_file = [n for n in joint_names if n not in dof_names]
    if lacking_in_model or lacking_in_file:
        raise ValueError(
            f"{who}: the model lacks the DOFs {lacking_in_model} and the file lacks the joints "
            f"{lacking_in_file}; rename with joint_map={{file DOF: model joint}}"
        )
    for j, name in zip(one_dof, joint_names):
        column = dof_names.index(name)
        qpos[:, m.jnt_qposadr[j]] = f["dof_positions"][:, column]
        qvel[:, m.jnt_dofadr[j]] = f["dof_velocities"][:, column]


def _fill_root(
    who: str,
    f,
    body_names: list[str],
    m: mujoco.MjModel,
    joint: int,
    root_body: str | None,
    qpos: np.ndarray,
    qvel: np.ndarray,
) -> None:
    if int(np.sum(m.jnt_type == _FREE)) > 1:
        raise ValueError(f"{who}: the model has several free joints; IsaacLab motions drive one floating base")
    root = root_body or names.all_names(m, "body", [m.jnt_bodyid[joint]])[0]
    if root not in body_names:
        raise ValueError(f"{who}: no body {root!r} in the file (root_body); its bodies: {body_names}")
    b = body_names.index(root)
    quat = np.asarray(f["body_rotations"][:, b], np.float64)
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    p, v = m.jnt_qposadr[joint], m.jnt_dofadr[joint]
    qpos[:, p : p + 3] = f["body_positions"][:, b]
    qpos[:, p + 3 : p + 7] = quat
    qvel[:, v : v + 3] = f["body_linear_velocities"][:, b]
    qvel[:, v + 3 : v + 6] = rotate_inverse(quat, np.asarray(f["body_angular_velocities"][:, b], np.float64))


def rotate_inverse(quat: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """[..., 3]: world vectors `vec` [..., 3] in the frame of unit quaternions `quat`
    [..., 4] (w, x, y, z), i.e. R(quat)^T vec."""
    u = -quat[..., 1:]  # the conjugate rotates world -> body
    w = quat[..., :1]
    uv = np.cross(u, vec)
    return vec + 2 * w * uv + 2 * np.cross(u, uv)
