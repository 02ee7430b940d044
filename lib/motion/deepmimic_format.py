"""DeepMimic motion files (the ``humanoid3d_*.txt`` clips pybullet ships), read as `Clip`s.

A DeepMimic motion is JSON: ``"Loop"`` ("wrap" or "none") and ``"Frames"``, one list of
numbers per frame:

    [duration, root position (3), root rotation (4: w, x, y, z),
     then per joint of the character, in its order: a quaternion (4: w, x, y, z) for a
     spherical joint, an angle (1, rad) for a revolute one; fixed joints take nothing]

``duration`` is the time (s) from this frame to the next (the last frame's is 0).
Positions are metres, rotations local to the parent link, the world y axis up.

`load` maps the frames onto a MuJoCo model of the character: a free joint (the root),
then one ball joint per spherical joint and one hinge per revolute joint, matched to
the file's order by name (`joints`: MuJoCo numbers joints depth-first, a character
file need not). MuJoCo's world is z-up, so with ``up="y"`` every quantity is
expressed in the basis turned by +90 degrees about x (`to_z_up`: y becomes z, z becomes
-y): positions ``(x, y, z) -> (x, -z, y)`` and every quaternion conjugated by that turn,
which keeps its angle and turns its axis the same way, ``(w, x, y, z) -> (w, x, -z, y)``.
The model must be the character built in that same basis (hinge axes and body frames
turned alike), as `mjzoo.envs.deepmimic.humanoid_model` is; hinge angles are unchanged.

The files hold no velocities: `load` computes them from the positions by backward
differences, ``qvel[t] = mj_differentiatePos(qpos[t-1], qpos[t]) / duration`` per
second (``qvel[0] = qvel[1]``), so that, as after a MuJoCo step, integrating qpos[t-1]
with qvel[t] over one frame gives qpos[t] exactly. Central differences would smooth
more, but the shipped clips have one-frame jumps (walk: both shoulders turn ~0.5 rad
between frames 18 and 19) that they would spread over two frames, out of step with
the positions. Frames of unequal duration are first interpolated onto a uniform grid
(linear for positions and angles, slerp for quaternions): a `Clip` has one frame rate.

    from mjzoo.motion import deepmimic_format
    from mjzoo.envs import deepmimic as humanoid  # the model, built from pybullet_data
    m = humanoid.humanoid_model()
    clip = deepmimic_format.load(humanoid.motion_path("walk"), m, humanoid.character_joints())
    clip.qpos.shape, clip.qvel.shape, clip.fps  # (39, 43), (39, 34), 30.0
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from mjzoo import names
from mjzoo.motion.checking import check
from mjzoo.motion.checking import velocities_from_positions
from mjzoo.motion.clips import Clip
from mjzoo.motion.resampling import slerp

__all__ = ["Y_UP_TO_Z_UP", "load", "read", "to_z_up"]

_FREE, _BALL, _HINGE = (
    int(mujoco.mjtJoint.mjJNT_FREE),
    int(mujoco.mjtJoint.mjJNT_BALL),
    int(mujoco.mjtJoint.mjJNT_HINGE),
)
# The turn from DeepMimic's y-up world to MuJoCo's z-up one: +90 degrees about x.
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_UNIFORM = 1e-3  # relative spread of frame durations still taken as one frame rate


def read(path: str | Path) -> tuple[np.ndarray, str]:
    """float64 frames [T, 1 + D] (column 0: durations, s) and the "Loop" mode of the
    DeepMimic motion file `path`; ValueError naming the file if it is not one."""
    who = f"motion.deepmimic_format.read({str(path)!r})"
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{who}: no such file")
    try:
        data = json.loads(path.read_text())
        frames = np.asarray(data["Frames"], np.float64)
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as e:
        raise ValueError(
            f"{who}: not a DeepMimic motion (JSON with a 'Frames' list of equal-length "
            f"number lists): {type(e).__name__}: {e}"
        ) from None
    if frames.ndim != 2 or frames.shape[0] < 2 or frames.shape[1] < 8:
        raise ValueError(f"{who}: 'Frames' has shape {frames.shape}; need [T >= 2, 1 + 7 + joint values]")
    if not np.isfinite(frames).all():
        raise ValueError(f"{who}: 'Frames' holds non-finite numbers")
    return frames, str(data.get("Loop", "none"))


def load(
    path: str | Path,
    mj_model: mujoco.MjModel,
    joints: Sequence[str] | None = None,
    *,
    name: str | None = None,
    up: str = "y",
    scale: float = 1.0,
) -> Clip:
    """The DeepMimic motion in `path` as a checked `Clip` of `mj_model`.

    Args:
      path: a DeepMimic motion file (format in the module docstring).
      mj_model: the character: a free joint first (the root), then a ball joint per
        spherical joint and a hinge per revolute joint.
      joints: the model's joint names (root excluded) in the file's order, which MuJoCo's
        depth-first joint order need not match (DeepMimic's humanoid lists the hips
        between the neck and the shoulders); None: the model's order.
      name: the clip's name; default: the file's stem.
      up: "y" (DeepMimic's files): expressed in the z-up basis (`to_z_up`); "z": as is.
      scale: factor on the root position (m), for a character built at another size.

    Returns:
      a `Clip` with qpos [T', nq], qvel [T', nv] (per second), fps = 1 / the frame
      duration; T' = T unless unequal durations were interpolated onto a uniform grid.
    """
    who = f"motion.deepmimic_format.load({str(path)!r})"
    if up not in ("y", "z"):
        raise ValueError(f"{who}: up={up!r}; expected 'y' (DeepMimic's files) or 'z'")
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"{who}: scale={scale!r} must be a finite number > 0")
    frames, _ = read(path)
    columns, quats = _layout(who, mj_model, joints, frames.shape[1] - 1)
    qpos = frames[:, 1:][:, columns]
    qpos[:, :3] *= scale
    if up == "y":
        qpos[:, :3] = qpos[:, :3] @ Y_UP_TO_Z_UP.T
        for a in quats:
            qpos[:, a : a + 4] = to_z_up(qpos[:, a : a + 4])
    qpos = _continuous(qpos, quats)
    qpos, dt = _uniform(who, frames[:, 0], qpos, quats)
    qvel = velocities_from_positions(qpos, 1.0 / dt, mj_model, backward=True)
    clip = Clip(
        name=name or Path(path).stem,
        fps=1.0 / dt,
        qpos=qpos,
        qvel=qvel,
        joint_names=tuple(names.all_names(mj_model, "joint")),
    )
    return check(clip, mj_model)


def to_z_up(quat: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z) [..., 4] of DeepMimic's y-up basis expressed in the
    z-up one: ``r q r*`` with r the +90 degree turn about x, i.e. ``(w, x, -z, y)``."""
    quat = np.asarray(quat, np.float64)
    return np.stack([quat[..., 0], quat[..., 1], -quat[..., 3], quat[..., 2]], axis=-1)


def _layout(who: str, m: mujoco.MjModel, joints: Sequence[str] | None, width: int) -> tuple[np.ndarray, list[int]]:
    """(for each qpos entry of the model, its column among a frame's values after the
    duration; the qpos addresses of the quaternions, the root's included), after
    checking the model's joints against `joints` and the `width` of a frame."""
    kinds = [int(k) for k in m.jnt_type]
    model_names = names.all_names(m, "joint")
    if not kinds or kinds[0] != _FREE or _FREE in kinds[1:]:
        raise ValueError(
            f"{who}: the model's first joint must be its only free joint (the root); its joints: {model_names}"
        )
    odd = [n for n, k in zip(model_names, kinds) if k not in (_FREE, _BALL, _HINGE)]
    if odd:
        raise ValueError(
            f"{who}: the model has slide joints {odd}; DeepMimic characters have spherical "
            "(ball) and revolute (hinge) joints only"
        )
    order = list(model_names[1:] if joints is None else joints)
    if sorted(order) != sorted(model_names[1:]):
        raise ValueError(
            f"{who}: joints={order} must name each of the model's joints but the root once: {model_names[1:]}"
        )
    if m.nq != width:
        raise ValueError(
            f"{who}: a frame holds {width} numbers after its duration, but the model's joints take "
            f"{m.nq} (root 7, ball 4, hinge 1 each: {model_names}); the model must be the file's "
            "character"
        )
    columns, column = np.zeros(m.nq, np.int64), 7
    columns[:7] = np.arange(7)
    for joint_name in order:
        j = model_names.index(joint_name)
        size = 4 if kinds[j] == _BALL else 1
        columns[m.jnt_qposadr[j] : m.jnt_qposadr[j] + size] = np.arange(column, column + size)
        column += size
    return columns, [3] + [int(m.jnt_qposadr[j]) for j, k in enumerate(kinds) if k == _BALL]


def _continuous(qpos: np.ndarray, quats: list[int]) -> np.ndarray:
    """Unit quaternions, each frame's sign flipped to the previous frame's hemisphere (q
    and -q are one rotation; a clip that jumps between them is harder to interpolate)."""
    qpos = qpos.copy()
    for a in quats:
        q = qpos[:, a : a + 4] / np.linalg.norm(qpos[:, a : a + 4], axis=1, keepdims=True)
        for t in range(1, q.shape[0]):
            if np.dot(q[t], q[t - 1]) < 0:
                q[t] = -q[t]
        qpos[:, a : a + 4] = q
    return qpos


def _uniform(who: str, durations: np.ndarray, qpos: np.ndarray, quats: list[int]) -> tuple[np.ndarray, float]:
    """(qpos at equal time steps, the step in s): as recorded when the durations agree,
    else interpolated at the most common duration."""
    steps = durations[:-1]
    if not (steps > 0).all():
        bad = int(np.flatnonzero(steps <= 0)[0])
        raise ValueError(f"{who}: frame {bad} has duration {steps[bad]}; every frame but the last needs one > 0")
    if np.ptp(steps) <= _UNIFORM * np.min(steps):
        return qpos, float(np.mean(steps))
    values, counts = np.unique(np.round(steps, 6), return_counts=True)
    dt = float(values[np.argmax(counts)])
    times = np.concatenate([[0.0], np.cumsum(steps)])
    grid = np.arange(0.0, times[-1] + 1e-9, dt)
    i0 = np.clip(np.searchsorted(times, grid, side="right") - 1, 0, len(times) - 2)
    blend = np.clip((grid - times[i0]) / (times[i0 + 1] - times[i0]), 0.0, 1.0)
    out = qpos[i0] + blend[:, None] * (qpos[i0 + 1] - qpos[i0])
    for a in quats:
        out[:, a : a + 4] = slerp(qpos[i0, a : a + 4], qpos[i0 + 1, a : a + 4], blend)
    return out, dt
