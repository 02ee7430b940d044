"""Resampling a clip to another frame rate, and the quaternion interpolation it needs.

A clip recorded at 30 fps drives a task stepped at 50 Hz once it holds a frame every
0.02 s. `resample` evaluates the clip at the new frame times, from t = 0 to the last
time within its duration: linearly between neighbouring frames for positions of hinge
and slide joints, free-joint translations and velocities, spherically (`slerp`, the
constant-rate rotation between two orientations) for the quaternions of free and ball
joints and of body poses.

    clip50 = motion.resample(clip, fps=50.0, mj_model=mj_model)

Both interpolations reproduce their kind of motion exactly: a constant-velocity
translation or joint motion (linear) and a constant-rate rotation about a fixed axis
(slerp). A clip resampled to its own fps is unchanged.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjzoo.motion.checking import quaternion_addresses
from mjzoo.motion.clips import Clip

__all__ = ["resample", "slerp", "frame_times"]


def resample(clip: Clip, fps: float, mj_model: mujoco.MjModel) -> Clip:
    """`clip` at `fps` frames per second: floor(duration * fps) + 1 frames, the k-th at
    time k / fps (s); the last frame time is within the clip's duration. Quaternions of
    `mj_model`'s free and ball joints (and the body poses, if any) are slerped, the
    rest interpolated linearly. Host numpy; the clip should be `check`ed first."""
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"motion.resample: fps={fps!r} must be a finite number > 0")
    if clip.num_frames < 2:
        raise ValueError(f"motion.resample: clip {clip.name!r} has {clip.num_frames} frame; give at least 2")
    i0, blend = frame_times(clip.num_frames, clip.fps, float(fps))
    quats = quaternion_addresses(mj_model)
    qpos = _lerp(clip.qpos, i0, blend)
    for adr in quats:
        qpos[:, adr : adr + 4] = slerp(clip.qpos[i0, adr : adr + 4], clip.qpos[i0 + 1, adr : adr + 4], blend)
    changes = dict(fps=float(fps), qpos=qpos, qvel=_lerp(clip.qvel, i0, blend))
    if clip.body_names:
        b = np.asarray(clip.body_quat)
        changes.update(body_pos=_lerp(clip.body_pos, i0, blend), body_quat=slerp(b[i0], b[i0 + 1], blend[:, None]))
    return clip.replace(**changes)


def frame_times(num_frames: int, fps: float, new_fps: float) -> tuple[np.ndarray, np.ndarray]:
    """For the frames at `new_fps` of a clip of `num_frames` at `fps`: the index i0 [K]
    of the frame before each (0 <= i0 <= num_frames - 2) and the blend [K] in [0, 1]
    towards frame i0 + 1."""
    ratio = fps / new_fps  # old frames per new frame
    count = int(np.floor((num_frames - 1) / ratio + 1e-9)) + 1
    u = np.arange(count) * ratio  # exact integers when ratio is 1
    nearest = np.round(u)
    u = np.where(np.abs(u - nearest) < 1e-9, nearest, u)  # no 0.9999999 blends at whole frames
    i0 = np.minimum(np.floor(u).astype(np.int64), num_frames - 2)
    return i0, u - i0


def slerp(q0: np.ndarray, q1: np.ndarray, blend: np.ndarray) -> np.ndarray:
    """Spherical interpolation of unit quaternions (w, x, y, z) [..., 4] by `blend` [...]
    in [0, 1], along the shorter arc; returns unit quaternions [..., 4]."""
    q0, end = np.asarray(q0, np.float64), np.asarray(q1, np.float64)
    blend = np.asarray(blend, np.float64)[..., None]
    dot = np.sum(q0 * end, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -end, end)  # q and -q are one rotation: take the short way
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    angle = np.arccos(dot)
    sin = np.sin(angle)
    close = sin < 1e-6  # nearly equal: the linear blend is exact to rounding
    safe = np.where(close, 1.0, sin)
    w0 = np.where(close, 1 - blend, np.sin((1 - blend) * angle) / safe)
    w1 = np.where(close, blend, np.sin(blend * angle) / safe)
    out = w0 * q0 + w1 * q1
    out = out / np.linalg.norm(out, axis=-1, keepdims=True)
    return np.where(blend == 0, q0, np.where(blend == 1, end, out))  # whole frames exactly as recorded


def _lerp(array, i0: np.ndarray, blend: np.ndarray) -> np.ndarray:
    a = np.asarray(array, np.float64)
    w = blend.reshape((-1,) + (1,) * (a.ndim - 1))
    return (1 - w) * a[i0] + w * a[i0 + 1]
