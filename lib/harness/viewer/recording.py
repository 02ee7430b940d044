"""Recorded states played back: a `mjzoo collect` dataset or a motion clip, or clips of
different models in step (a retargeted clip beside its source).

No simulation runs: `advance()` moves a frame index (looping or stopping at the end);
`seek(t)` is the timeline scrubber. Body poses are the recording's own where it holds
them (a dataset's xpos / xquat), else forward kinematics of its qpos.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from mjzoo import motion
from mjzoo.harness.viewer.sources import Frame
from mjzoo.harness.viewer.sources import host_poses

__all__ = ["Recording", "SideBySide", "from_dataset", "from_clip"]


class _Timeline:
    """A frame index over `num_frames` frames `dt` apart: the scrubber, loop and playback."""

    num_frames: int
    dt: float

    def __init__(self) -> None:
        self.index, self.loop, self.traces, self.steps = 0, True, 0, 0

    def reset(self, seed: int = 0) -> None:
        self.index = 0

    def seek(self, index: int) -> None:
        self.index = int(np.clip(index, 0, self.num_frames - 1))

    def advance(self) -> int:
        """The next frame (back to the first one after the last when looping)."""
        last = self.num_frames - 1
        self.index = (self.index + 1) % self.num_frames if self.loop else min(self.index + 1, last)
        self.steps += 1
        return 1

    def parameters(self) -> dict[str, np.ndarray]:
        return {}


class Recording(_Timeline):
    """E recorded episodes of T frames, shown side by side.

    Args:
      mj_model: the model the states belong to.
      qpos: [E, T, nq].
      dt: seconds between frames.
      xpos, xquat: optional [E, T, nbody, 3] and [E, T, nbody, 4] recorded body poses.
      terms: {name: [E, T]} reward terms per frame (a dataset's, steps aligned to the
        state they lead to), or {}.
      lengths: [E] frames of each episode that are its own (the rest: past its end).
    """

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        qpos: np.ndarray,
        dt: float,
        xpos: np.ndarray | None = None,
        xquat: np.ndarray | None = None,
        terms: dict[str, np.ndarray] | None = None,
    ):
        if qpos.ndim != 3 or qpos.shape[-1] != mj_model.nq:
            raise ValueError(
                f"recording: qpos has shape {qpos.shape}; the model needs [episodes, frames, {mj_model.nq}]"
            )
        super().__init__()
        self.mj_model, self.qpos, self.dt = mj_model, qpos, dt
        self.xpos, self.xquat, self.terms = xpos, xquat, terms or {}
        self.num_envs, self.num_frames = qpos.shape[0], qpos.shape[1]

    def frame(self) -> Frame:
        i, m = self.index, self.mj_model
        qpos = self.qpos[:, i]
        mocap_pos = np.broadcast_to(m.body_pos[m.body_mocapid >= 0], (self.num_envs, m.nmocap, 3))
        mocap_quat = np.broadcast_to(m.body_quat[m.body_mocapid >= 0], (self.num_envs, m.nmocap, 4))
        if self.xpos is not None:
            xpos, xquat = self.xpos[:, i], self.xquat[:, i]
        else:
            xpos, xquat = host_poses(m, qpos, mocap_pos, mocap_quat)
        terms = {k: v[:, max(i - 1, 0)] for k, v in self.terms.items()}
        return Frame(qpos, mocap_pos, mocap_quat, xpos, xquat, i * self.dt, terms)


class SideBySide(_Timeline):
    """Recordings of different models played in step in one scene, each drawn beside the
    one before it along x (slot e of the viewer's batch is recording e).

    The timeline runs at the first recording's frame rate over the longest one; at time
    t every recording shows its frame nearest t (its last one once it has ended), so
    clips of other frame rates stay in step.

    Args:
      recordings: one `Recording` of one episode per model.
      spacing: metres between neighbours; 0: the largest model's extent (about a body's height).

    Attributes:
      models: [E] the models, in order; `mj_model` is the first (its bodies name the
        camera's targets).
    """

    def __init__(self, recordings: Sequence[Recording], spacing: float = 0.0):
        if len(recordings) < 2 or any(r.num_envs != 1 for r in recordings):
            raise ValueError("side by side: give two or more recordings of one episode each")
        super().__init__()
        self.parts = list(recordings)
        self.models = [r.mj_model for r in self.parts]
        self.mj_model, self.dt, self.num_envs = self.models[0], self.parts[0].dt, len(self.parts)
        self.num_frames = max(round((r.num_frames - 1) * r.dt / self.dt) + 1 for r in self.parts)
        self.spacing = spacing or max(float(m.stat.extent) for m in self.models)

    def indices(self) -> list[int]:
        """Each recording's frame at the current time."""
        time = self.index * self.dt
        return [min(round(time / r.dt), r.num_frames - 1) for r in self.parts]

    def frame(self) -> Frame:
        """A frame whose per-environment fields are lists, entry e of model e (their
        nq and nbody differ)."""
        frames = []
        for part, index in zip(self.parts, self.indices()):
            part.index = index
            frames.append(part.frame())
        one = {k: [getattr(f, k)[0] for f in frames] for k in ("qpos", "mocap_pos", "mocap_quat", "xpos", "xquat")}
        return Frame(**one, time=self.index * self.dt, terms={})


def from_dataset(mj_model: mujoco.MjModel, dataset, episodes: int = 1) -> Recording:
    """The first `episodes` episodes of a `mjzoo.harness.datasets.Dataset`."""
    names = tuple(mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(mj_model.njnt))
    if tuple(dataset.joint_names) != names:
        raise ValueError(
            f"recording: the dataset's joints {list(dataset.joint_names)} are not the model's {list(names)}"
        )
    e = max(1, min(episodes, dataset.num_episodes))
    terms = {k: np.asarray(v[:e]) for k, v in dataset.reward_terms.items()}
    return Recording(
        mj_model,
        np.asarray(dataset.qpos[:e]),
        dataset.dt,
        np.asarray(dataset.xpos[:e]),
        np.asarray(dataset.xquat[:e]),
        terms,
    )


def from_clip(mj_model: mujoco.MjModel, clip: motion.Clip) -> Recording:
    """One motion clip (`mjzoo.motion.load_file`), checked against the model's joints."""
    names = tuple(mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(mj_model.njnt))
    if tuple(clip.joint_names) != names or clip.qpos.shape[-1] != mj_model.nq:
        raise ValueError(
            f"recording: clip {clip.name!r} has joints {list(clip.joint_names)}; the model has {list(names)}"
        )
    return Recording(mj_model, np.asarray(clip.qpos)[None], 1.0 / clip.fps)
