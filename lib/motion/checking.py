"""Checking a clip against a MuJoCo model, and velocities for a clip that lacks them.

A clip is only useful for the model it was recorded for: same joints in the same
order, positions and velocities of the model's widths, unit quaternions, and velocities
that agree with how the positions change. `check` tests all of that and raises one
ValueError that names the clip and the first thing wrong; `load` reads a file and
checks it.

    clip = motion.load("walk.npz", mj_model)  # load_file + check
    qvel = motion.velocities_from_positions(qpos, fps=30.0, mj_model=mj_model)

The velocity check compares `qvel` with the finite differences of `qpos` over 1/fps
(`mujoco.mj_differentiatePos`, which handles quaternions), at the two alignments a real
clip has: a simulated one (semi-implicit Euler, ``qpos[t+1] = qpos[t] + dt qvel[t+1]``)
matches the difference d[t] = (qpos[t+1] - qpos[t]) / dt with qvel[t+1] exactly, a
smooth recorded one matches it with the mean of qvel[t] and qvel[t+1] to second order.
The relative error ``|d - v| / max(|d|, |v|)`` (norms over the whole clip) must be at
most `VELOCITY_TOLERANCE` = 0.25 at one of them: a clip whose fps is wrong by a factor
1.5 is 1/3 off and fails, a velocity per frame instead of per second is ~100% off.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from mjzoo import names
from mjzoo.motion.clips import Clip
from mjzoo.motion.clips import load_file

__all__ = ["check", "load", "velocities_from_positions", "differences", "quaternion_addresses", "VELOCITY_TOLERANCE"]

VELOCITY_TOLERANCE = 0.25  # relative; a factor 1.5 in fps gives 1/3
QUAT_TOLERANCE = 1e-3  # | |q| - 1 |


def load(path: str | Path, mj_model: mujoco.MjModel, name: str | None = None) -> Clip:
    """The clip in `path` (written by `save`), checked against `mj_model` (`check`).
    `name` defaults to the file's stem."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"motion.load: no clip file at {str(path)!r}")
    return check(load_file(path, name), mj_model)


def check(clip: Clip, mj_model: mujoco.MjModel) -> Clip:
    """Returns `clip` if it fits `mj_model`, else raises one ValueError naming the clip
    and the first problem: joint names or order, qpos [T, nq] / qvel [T, nv] widths,
    T >= 2 frames, finite values, unit quaternions of free and ball joints (within
    1e-3), fps > 0, and qvel consistent with the qpos differences (module docstring)."""
    who = f"motion clip {clip.name!r}"
    expected = names.all_names(mj_model, "joint")
    _check_joints(who, tuple(clip.joint_names), expected)
    if not (np.isfinite(clip.fps) and clip.fps > 0):
        raise ValueError(f"{who}: fps={clip.fps!r} must be a finite number > 0")
    qpos, qvel = np.asarray(clip.qpos), np.asarray(clip.qvel)
    for field, array, width, what in (("qpos", qpos, mj_model.nq, "nq"), ("qvel", qvel, mj_model.nv, "nv")):
        if array.ndim != 2 or array.shape[1] != width:
            raise ValueError(f"{who}: {field} has shape {array.shape}; the model needs [T, {what}={width}]")
        if not np.isfinite(array).all():
            bad = np.argwhere(~np.isfinite(array))[0]
            raise ValueError(f"{who}: {field}[{bad[0]}, {bad[1]}] is {array[tuple(bad)]}; values must be finite")
    if qpos.shape[0] != qvel.shape[0] or qpos.shape[0] < 2:
        raise ValueError(
            f"{who}: qpos has {qpos.shape[0]} frames and qvel {qvel.shape[0]}; give the same number, at least 2"
        )
    _check_bodies(who, clip)
    _check_quaternions(who, qpos, mj_model)
    _check_velocities(who, clip, mj_model)
    return clip


def velocities_from_positions(
    qpos: np.ndarray, fps: float, mj_model: mujoco.MjModel, *, backward: bool = False
) -> np.ndarray:
    """float64 [T, nv] velocities (per second) of positions `qpos` [T, nq] sampled at
    `fps` (what a clip whose velocities were never recorded gets; quaternions through
    `mj_differentiatePos`): central differences inside, one-sided at the two ends; with
    `backward`, ``qvel[t]`` carries ``qpos[t-1]`` to ``qpos[t]`` as after a MuJoCo step
    (``qvel[0] = qvel[1]``), which keeps a one-frame jump in one frame."""
    qpos = np.asarray(qpos, np.float64)
    if qpos.ndim != 2 or qpos.shape[1] != mj_model.nq or qpos.shape[0] < 2:
        raise ValueError(
            f"motion.velocities_from_positions: qpos has shape {qpos.shape}; give [T >= 2, nq={mj_model.nq}]"
        )
    d = differences(qpos, fps, mj_model)  # [T-1, nv], d[t] between frames t and t+1
    if backward:
        return np.concatenate([d[:1], d])
    return np.concatenate([d[:1], 0.5 * (d[:-1] + d[1:]), d[-1:]])


def differences(qpos: np.ndarray, fps: float, mj_model: mujoco.MjModel) -> np.ndarray:
    """float64 [T-1, nv]: (qpos[t+1] - qpos[t]) * fps, quaternions as rotation vectors."""
    out = np.zeros((qpos.shape[0] - 1, mj_model.nv))
    q = np.asarray(qpos, np.float64)
    for t in range(out.shape[0]):
        mujoco.mj_differentiatePos(mj_model, out[t], 1.0 / fps, q[t], q[t + 1])
    return out


def quaternion_addresses(mj_model: mujoco.MjModel) -> list[int]:
    """The first qpos index of each quaternion (free joints: qposadr + 3; ball: qposadr)."""
    free, ball = int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL)
    kinds = {free: 3, ball: 0}
    return [int(mj_model.jnt_qposadr[j]) + kinds[int(k)] for j, k in enumerate(mj_model.jnt_type) if int(k) in kinds]


def _check_joints(who: str, got: tuple[str, ...], expected: list[str]) -> None:
    for i, (g, e) in enumerate(zip(got, expected)):
        if g != e:
            raise ValueError(
                f"{who}: joint {i} is {g!r} but the model's joint {i} is {e!r}; the clip's joints "
                f"must be the model's, in order: {expected}"
            )
    if len(got) != len(expected):
        raise ValueError(
            f"{who}: the clip has {len(got)} joints and the model {len(expected)}; "
            f"the clip's joints must be the model's, in order: {expected}"
        )


def _check_bodies(who: str, clip: Clip) -> None:
    if not clip.body_names:
        return
    b, t = len(clip.body_names), clip.num_frames
    for field, array, width in (("body_pos", clip.body_pos, 3), ("body_quat", clip.body_quat, 4)):
        if array is None or np.shape(array) != (t, b, width):
            raise ValueError(f"{who}: {field} has shape {np.shape(array)}; give [T={t}, B={b}, {width}]")


def _check_quaternions(who: str, qpos: np.ndarray, mj_model: mujoco.MjModel) -> None:
    for adr in quaternion_addresses(mj_model):
        norm = np.linalg.norm(qpos[:, adr : adr + 4], axis=1)
        bad = np.flatnonzero(np.abs(norm - 1) > QUAT_TOLERANCE)
        if bad.size:
            raise ValueError(
                f"{who}: the quaternion qpos[:, {adr}:{adr + 4}] has norm {norm[bad[0]]:.4g} at frame "
                f"{bad[0]} ({bad.size} frames off); quaternions must have unit norm"
            )


def _check_velocities(who: str, clip: Clip, mj_model: mujoco.MjModel) -> None:
    d = differences(np.asarray(clip.qpos), clip.fps, mj_model)
    v = np.asarray(clip.qvel, np.float64)
    errors = [_relative_error(d, v[1:]), _relative_error(d, 0.5 * (v[:-1] + v[1:]))]
    if min(errors) <= VELOCITY_TOLERANCE:
        return
    mean_v = 0.5 * (v[:-1] + v[1:])
    scale = float(np.sum(mean_v * d) / max(np.sum(d * d), 1e-300))
    hint = (
        "qvel looks unrecorded: build it with motion.velocities_from_positions"
        if abs(scale) < 1e-3
        else "a velocity per frame, or the wrong fps?"
    )
    raise ValueError(
        f"{who}: qvel is {scale:.3g}x the qpos differences over 1/fps = {1 / clip.fps:.4g} s "
        f"(relative error {min(errors):.2f} > {VELOCITY_TOLERANCE}): {hint}"
    )


def _relative_error(d: np.ndarray, v: np.ndarray) -> float:
    scale = max(np.linalg.norm(d), np.linalg.norm(v))
    return 0.0 if scale < 1e-9 else float(np.linalg.norm(d - v) / scale)
