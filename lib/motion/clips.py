"""Motion clips: a robot's recorded joint trajectory, and the file format that holds one.

A clip is host data (numpy), one per file:

    fps          float scalar, frames per second
    qpos         float [T, nq]  MuJoCo generalized positions (free/ball joints as
                 position + quaternion w, x, y, z), in the model's joint order
    qvel         float [T, nv]  generalized velocities, per second (MuJoCo's
                 convention: a free joint's linear velocity in the world frame, its
                 angular velocity in the body frame)
    joint_names  str [J]        every joint of the model, in order (the check that the
                                clip fits the model)
    body_names   str [B]        optional, with body_pos [T, B, 3] and body_quat
                                [T, B, 4]: world poses of those bodies (what a
                                renderer or a retargeter needs without a model)

    clip = motion.Clip(name="walk", fps=50.0, qpos=qpos, qvel=qvel, joint_names=names)
    motion.save("walk.npz", clip)
    clip = motion.load("walk.npz", mj_model)  # checked against the model
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

__all__ = ["Clip", "save", "load_file"]


@dataclasses.dataclass(frozen=True)
class Clip:
    """One motion clip (host numpy arrays; see the module docstring for the fields)."""

    name: str
    fps: float
    qpos: np.ndarray  # [T, nq]
    qvel: np.ndarray  # [T, nv]
    joint_names: tuple[str, ...]
    body_names: tuple[str, ...] = ()
    body_pos: np.ndarray | None = None  # [T, B, 3]
    body_quat: np.ndarray | None = None  # [T, B, 4]

    @property
    def num_frames(self) -> int:
        return int(self.qpos.shape[0])

    @property
    def duration(self) -> float:
        """Seconds from the first frame to the last."""
        return (self.num_frames - 1) / self.fps

    def replace(self, **changes) -> Clip:
        return dataclasses.replace(self, **changes)


def save(path: str | Path, clip: Clip) -> Path:
    """Writes `clip` to `path` (.npz) in the format above; returns the path."""
    path = Path(path)
    arrays = dict(
        fps=np.float64(clip.fps),
        qpos=np.asarray(clip.qpos, np.float64),
        qvel=np.asarray(clip.qvel, np.float64),
        joint_names=np.array(clip.joint_names, dtype=str),
    )
    if clip.body_names:
        arrays.update(
            body_names=np.array(clip.body_names, dtype=str),
            body_pos=np.asarray(clip.body_pos),
            body_quat=np.asarray(clip.body_quat),
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **arrays)
    return path


def load_file(path: str | Path, name: str | None = None) -> Clip:
    """The clip in `path` as written by `save`, unchecked (`load` checks it against a
    model). `name` defaults to the file's stem."""
    path = Path(path)
    with np.load(path, allow_pickle=False) as f:
        body_names = tuple(str(n) for n in f["body_names"]) if "body_names" in f else ()
        return Clip(
            name=name or path.stem,
            fps=float(f["fps"]),
            qpos=np.asarray(f["qpos"]),
            qvel=np.asarray(f["qvel"]),
            joint_names=tuple(str(n) for n in f["joint_names"]),
            body_names=body_names,
            body_pos=np.asarray(f["body_pos"]) if body_names else None,
            body_quat=np.asarray(f["body_quat"]) if body_names else None,
        )
