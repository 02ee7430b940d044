"""Resolving names to indices, once, at construction.

Catalog constructors take the host `mujoco.MjModel` (``task.mj_model``) and element
names, and turn the names into indices with these functions before binding them as
int32 leaves. A name the model lacks raises a ValueError that names it and lists what
exists, prefixed by `who` (the constructor the user called):

    names.ids(mj_model, "geom", ["foot_fl", "foot_fr"], "trackers.with_feet")  # int32 [2]
    names.free_joint(mj_model, body="torso", who="resets.base_velocity")  # joint index

The floating base: items that need one take ``body: str | None``; None means the body
of the model's FIRST free joint (in a scene the robot usually comes before free props;
name the body otherwise).
"""

from __future__ import annotations

from typing import Sequence

import mujoco
import numpy as np

__all__ = ["Names", "ids", "index", "base_body", "free_joint", "free_joint_addresses", "joints", "joint_addresses"]

Names = str | Sequence[str]
# kind -> (MuJoCo object type, attribute of MjModel counting them)
KINDS = {
    "body": (mujoco.mjtObj.mjOBJ_BODY, "nbody"),
    "joint": (mujoco.mjtObj.mjOBJ_JOINT, "njnt"),
    "geom": (mujoco.mjtObj.mjOBJ_GEOM, "ngeom"),
    "site": (mujoco.mjtObj.mjOBJ_SITE, "nsite"),
    "sensor": (mujoco.mjtObj.mjOBJ_SENSOR, "nsensor"),
    "actuator": (mujoco.mjtObj.mjOBJ_ACTUATOR, "nu"),
    "hfield": (mujoco.mjtObj.mjOBJ_HFIELD, "nhfield"),
}
_FREE, _BALL = int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL)
_ONE_DOF = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
_QPOS_WIDTH, _DOF_WIDTH = {_FREE: 7, _BALL: 4}, {_FREE: 6, _BALL: 3}  # hinge, slide: 1


def all_names(mj_model: mujoco.MjModel, kind: str, index: Sequence[int] | None = None) -> list[str]:
    """Names of the elements of `kind` (all, or those at `index`); "<kind i>" if unnamed."""
    obj, count = _kind(kind)
    index = range(getattr(mj_model, count)) if index is None else index
    return [mujoco.mj_id2name(mj_model, obj, int(i)) or f"<{kind} {int(i)}>" for i in index]


def ids(mj_model: mujoco.MjModel, kind: str, names: Names | None, who: str, *, world: bool = True) -> np.ndarray:
    """int32 [n] indices of the named elements of `kind`, in the order given.

    `names`: one name, a non-empty list of distinct names, or None for every element
    of `kind` (every body but the world). With ``world=False`` naming the world body
    is an error (for items that move or edit a body).
    """
    obj, count = _kind(kind)
    first = 1 if kind == "body" else 0
    if names is None:
        if getattr(mj_model, count) <= first:
            raise ValueError(f"{who}: the model has no {kind}")
        return np.arange(first, getattr(mj_model, count), dtype=np.int32)
    names = [names] if isinstance(names, str) else list(names)
    if not names:
        raise ValueError(f"{who}: give at least one {kind} name")
    if len(set(names)) != len(names):
        raise ValueError(f"{who}: {kind} names repeat: {names}")
    found = [mujoco.mj_name2id(mj_model, obj, n) if isinstance(n, str) else -1 for n in names]
    for name, i in zip(names, found):
        if i < 0:
            raise ValueError(f"{who}: no {kind} named {name!r}; {kind} names: {all_names(mj_model, kind)}")
        if kind == "body" and i == 0 and not world:
            raise ValueError(f"{who}: body {name!r} is the world, which does not move; name another body")
    return np.asarray(found, np.int32)


def index(mj_model: mujoco.MjModel, kind: str, name: str, who: str, *, world: bool = True) -> int:
    """The index of ONE named element of `kind`, checked as by `ids`."""
    if not isinstance(name, str):
        raise ValueError(f"{who}: give one {kind} name, got {name!r}")
    return int(ids(mj_model, kind, name, who, world=world)[0])


def base_body(mj_model: mujoco.MjModel, body: str | None, who: str) -> int:
    """The named body (any body), or by default the body of the first free joint."""
    if body is not None:
        return index(mj_model, "body", body, who)
    return int(mj_model.jnt_bodyid[free_joint(mj_model, None, who)])


def free_joint(mj_model: mujoco.MjModel, body: str | None, who: str) -> int:
    """Index of the free joint of `body` (None: the model's first free joint)."""
    free = np.flatnonzero(mj_model.jnt_type == _FREE)
    floating = all_names(mj_model, "body", mj_model.jnt_bodyid[free])
    if body is None:
        if free.size == 0:
            bodies = all_names(mj_model, "body", range(1, mj_model.nbody))
            raise ValueError(f"{who}: the model has no free joint (floating base); pass body= one of {bodies}")
        return int(free[0])
    chosen = free[mj_model.jnt_bodyid[free] == index(mj_model, "body", body, who)]
    if chosen.size == 0:
        raise ValueError(f"{who}: body {body!r} has no free joint (floating base); bodies with one: {floating}")
    return int(chosen[0])


def free_joint_addresses(mj_model: mujoco.MjModel, body: str | None, who: str) -> tuple[np.ndarray, np.ndarray]:
    """int32 indices of the free joint of `body` (see `free_joint`): qpos [7] (position
    m, then orientation quaternion wxyz) and qvel [6] (linear velocity m/s in the world
    frame, then angular velocity rad/s in the body frame: MuJoCo's convention)."""
    j = free_joint(mj_model, body, who)
    qpos, qvel = int(mj_model.jnt_qposadr[j]), int(mj_model.jnt_dofadr[j])
    return np.arange(qpos, qpos + 7, dtype=np.int32), np.arange(qvel, qvel + 6, dtype=np.int32)


def joints(mj_model: mujoco.MjModel, names: Names | None, who: str, *, limited: bool = False) -> np.ndarray:
    """int32 indices of hinge or slide joints (one dof each): the named ones, or every
    such joint (with a range, if `limited`) when `names` is None. With `limited`, each
    named joint must have a range."""
    movable = [j for j in range(mj_model.njnt) if int(mj_model.jnt_type[j]) in _ONE_DOF]
    if names is None:
        found = [j for j in movable if mj_model.jnt_limited[j] or not limited]
        if not found:
            raise ValueError(f"{who}: the model has no {'limited ' if limited else ''}hinge or slide joint")
        return np.asarray(found, np.int32)
    found = ids(mj_model, "joint", names, who)
    for j in found:
        name = all_names(mj_model, "joint", [j])[0]
        if j not in movable:
            raise ValueError(
                f"{who}: {name!r} is not a hinge or slide joint; those are {all_names(mj_model, 'joint', movable)}"
            )
        if limited and not mj_model.jnt_limited[j]:
            raise ValueError(f"{who}: joint {name!r} has no range; give joints with a range (limited)")
    return found


def joint_addresses(mj_model: mujoco.MjModel, joint_ids: Sequence[int], velocity: bool) -> np.ndarray:
    """int32 indices into qpos (qvel if `velocity`) of every entry of the given joints,
    joint by joint: 1 per hinge or slide, 4 (3) per ball, 7 (6) per free joint."""
    start, widths = (mj_model.jnt_dofadr, _DOF_WIDTH) if velocity else (mj_model.jnt_qposadr, _QPOS_WIDTH)
    spans = [start[j] + np.arange(widths.get(int(mj_model.jnt_type[j]), 1)) for j in joint_ids]
    return np.concatenate(spans).astype(np.int32) if spans else np.zeros(0, np.int32)


def _kind(kind: str) -> tuple[mujoco.mjtObj, str]:
    if kind not in KINDS:
        raise ValueError(f"unknown element kind {kind!r}; expected one of {sorted(KINDS)}")
    return KINDS[kind]
