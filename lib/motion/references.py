"""`Reference`: a task's motion clips as JAX arrays at the task's control rate.

AMP's discriminator and reference-state initialization draw frames from recorded
motion inside jitted code. A `Reference` holds every clip resampled to the task's
control step and concatenated along one frame axis, with each clip's start, length,
sampling weight and whether it loops; pure functions index it:

    ref = motion.reference([walk, run], mj_model, dt=0.02, weights=[0.8, 0.2])
    ref = motion.check_reference(task, ref)               # AMP's: amp.make(config, ref)
    clip, t = motion.sample_frame(ref, key, min_remaining=2)
    qpos, qvel = motion.frames(ref, clip, t, 2)           # [2, nq], [2, nv]

Frame times are in frames of ``ref.dt`` seconds. A looping clip wraps around (t mod
length), a clip that does not loop holds its last frame. A looping clip's root
translation is NOT offset per cycle: after the last frame the root jumps back to where
the first frame has it (fine for features in the body frame, wrong for world
positions past one cycle).
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjzoo.motion.checking import check
from mjzoo.motion.clips import Clip
from mjzoo.motion.resampling import resample
from mjzoo.running import control_dt
from mjzoo.types import Task

__all__ = ["Reference", "reference", "sample_frame", "frame_index", "frames", "check_reference"]

Array = jax.Array


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Reference:
    """C clips, M frames in all, at one frame every `dt` seconds.

    Attributes:
      qpos: float32 [M, nq] every clip's positions, clip after clip.
      qvel: float32 [M, nv] their velocities (per second).
      start: int32 [C] the index of each clip's first frame in qpos.
      length: int32 [C] each clip's number of frames.
      weight: float32 [C] each clip's sampling probability (sums to 1).
      loop: bool [C] whether each clip wraps around past its last frame.
      dt: float32 [] seconds per frame (the task's control step).
      names: static tuple of the C clip names.
    """

    qpos: Array
    qvel: Array
    start: Array
    length: Array
    weight: Array
    loop: Array
    dt: Array
    names: tuple[str, ...] = dataclasses.field(default=(), metadata=dict(static=True))

    @property
    def num_clips(self) -> int:
        return len(self.names)


def reference(
    clips: Sequence[Clip] | Clip,
    mj_model: mujoco.MjModel,
    dt: float,
    weights: Sequence[float] | None = None,
    loop: bool | Sequence[bool] = True,
) -> Reference:
    """A `Reference` of `clips`, each checked against `mj_model` and resampled to 1/`dt`
    frames per second. `weights`: C numbers >= 0, not all 0 (normalized to sum 1);
    None: every clip equally likely. `loop`: one flag for all clips or one per clip."""
    who = "motion.reference"
    clips = [clips] if isinstance(clips, Clip) else list(clips)
    if not clips or not all(isinstance(c, Clip) for c in clips):
        raise TypeError(f"{who}: clips must be a Clip or a non-empty sequence of Clips")
    if isinstance(dt, bool) or not (isinstance(dt, (int, float, np.floating)) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"{who}: dt={dt!r} must be a finite number of seconds > 0")
    weight = np.ones(len(clips)) if weights is None else np.asarray(weights, np.float64)
    if weight.shape != (len(clips),) or not (np.isfinite(weight).all() and (weight >= 0).all() and weight.sum() > 0):
        raise ValueError(f"{who}: weights={weights!r} must be {len(clips)} finite numbers >= 0, not all 0")
    loops = np.broadcast_to(np.asarray(loop, bool), (len(clips),)) if np.ndim(loop) == 0 else np.asarray(loop, bool)
    if loops.shape != (len(clips),):
        raise ValueError(f"{who}: loop={loop!r} must be one bool or {len(clips)} of them")
    resampled = [resample(check(c, mj_model), 1.0 / dt, mj_model) for c in clips]
    length = np.array([c.num_frames for c in resampled])
    return Reference(
        qpos=jnp.asarray(np.concatenate([c.qpos for c in resampled]), jnp.float32),
        qvel=jnp.asarray(np.concatenate([c.qvel for c in resampled]), jnp.float32),
        start=jnp.asarray(np.concatenate([[0], np.cumsum(length)[:-1]]), jnp.int32),
        length=jnp.asarray(length, jnp.int32),
        weight=jnp.asarray(weight / weight.sum(), jnp.float32),
        loop=jnp.asarray(loops),
        dt=jnp.float32(dt),
        names=tuple(c.name for c in clips),
    )


def sample_frame(ref: Reference, key: Array, min_remaining: int = 1) -> tuple[Array, Array]:
    """A clip drawn by `ref.weight` and a frame t uniform in [0, length - min_remaining]
    of it, so that frames t .. t + min_remaining - 1 lie in the clip (t = 0 if the clip
    is shorter). Returns (clip int32 [], t int32 [])."""
    clip_key, frame_key = jax.random.split(key)
    clip = jax.random.categorical(clip_key, jnp.log(ref.weight)).astype(jnp.int32)
    high = jnp.maximum(ref.length[clip] - min_remaining + 1, 1)
    return clip, jax.random.randint(frame_key, (), 0, high, jnp.int32)


def frame_index(ref: Reference, clip: Array, t: Array) -> Array:
    """int32 [...] index into `ref.qpos` of frame `t` [...] (int) of `clip` [...]: t
    modulo the clip's length for a looping clip (the root translation is not offset
    per cycle), t clamped to [0, length - 1] otherwise."""
    length = ref.length[clip]
    local = jnp.where(ref.loop[clip], jnp.mod(t, length), jnp.clip(t, 0, length - 1))
    return (ref.start[clip] + local).astype(jnp.int32)


def frames(ref: Reference, clip: Array, t: Array, num_frames: int) -> tuple[Array, Array]:
    """Frames t .. t + k - 1 of `clip` (each through `frame_index`), k = `num_frames`
    (static): (qpos [k, nq], qvel [k, nv])."""
    index = frame_index(ref, clip, t + jnp.arange(num_frames))
    return ref.qpos[index], ref.qvel[index]


def check_reference(task: Task, ref: Reference) -> Reference:
    """`ref`, once it has a frame per control step of `task` (``ref.dt`` ==
    `mjzoo.running.control_dt(task)`, to 1e-6 s) and the widths of its model (nq, nv);
    else a ValueError naming the mismatch. The task is only read: a reference is AMP's
    data (`amp.make(config, ref)`), not the task's. Host code: measuring the control
    step compiles one step of the task."""
    who = "motion.check_reference"
    if not isinstance(ref, Reference):
        raise TypeError(f"{who}: ref must be a motion.Reference (motion.reference(...)), got {type(ref).__name__}")
    m = task.mj_model
    if ref.qpos.shape[1] != m.nq or ref.qvel.shape[1] != m.nv:
        raise ValueError(
            f"{who}: the reference has nq={ref.qpos.shape[1]}, nv={ref.qvel.shape[1]} "
            f"but the task's model nq={m.nq}, nv={m.nv}"
        )
    step = control_dt(task)
    if abs(float(ref.dt) - step) > 1e-6:
        raise ValueError(
            f"{who}: the reference has a frame every {float(ref.dt):.6g} s but the task's control "
            f"step is {step:.6g} s; build it with motion.reference(clips, mj_model, "
            f"dt={step:.6g})"
        )
    return ref
