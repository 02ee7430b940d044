"""Where tracking episodes start: reference-state initialization at a sampled clip and
time, and adaptive sampling of those starts where the policy fails most (BeyondMimic).

    reset = start_sampling.reference_start(ref, bin_seconds=0.25)   # a reset item of mjzoo.task
    task = start_sampling.with_adaptive_starts(mjzoo.with_auto_reset(task), ref, bin_seconds=0.25)

Each clip's start frames (all but its last) fall in bins of `bin_seconds`: a [C, K] table
of cells (clip, bin), K the most bins of any clip, `valid` marking the cells a clip has.
`reference_start` draws a cell from the task's parameter ``start_probabilities`` [C, K]
(uniform over clips by their weights, then over a clip's bins, until adapted), a frame
uniform in the cell, and puts the robot on the reference there (qpos, qvel, and
``data.time``, the tracking clock; `tracking.clock`).

`with_adaptive_starts` sits OUTSIDE `with_auto_reset` (as a curriculum does) and keeps,
per environment, an exponential average of where its episodes failed: at each episode
end ``failures <- (1 - rate) failures + rate * onehot(clip, bin of the failure frame)``
(the one-hot only for a termination; a clip played to its end adds nothing). Before
each transition it sets the inner task's ``start_probabilities`` to

    smoothed[c, b] = sum_{k=0..kernel} smoothing^k failures[c, b + k]   (start just before a failure)
    p = (1 - uniform) smoothed / sum(smoothed) + uniform * p_uniform     (p_uniform where nothing failed)

so every start stays possible (`uniform`, the floor). Its metrics, means over the batch
that a ratio turns into per-clip rates (`summary`):

    tracking/mpjpe_mm               MPJPE (mm) of the state each action was taken from
    tracking/<clip>/ended           1 on a transition that ended an episode of the clip
    tracking/<clip>/succeeded       1 when that episode played the clip to its end (no termination)
    tracking/<clip>/episode_mpjpe_mm   that episode's mean MPJPE (mm) on its end, else 0
"""

from __future__ import annotations

import math
import re
from typing import Any
from typing import Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial

from mjzoo import checks
from mjzoo import tree
from mjzoo.catalog import tracking
from mjzoo.combinators import record
from mjzoo.combinators import runs_transitions
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.parameters import params
from mjzoo.running import transition_with_terms
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "bins",
    "uniform_probabilities",
    "start_probabilities",
    "record_failure",
    "sample_start",
    "reference_start",
    "with_adaptive_starts",
    "AdaptiveStartState",
    "summary",
]

Array = jax.Array
PARAMETER = "start_probabilities"  # the reset item's named leaf that the sampler sets


def bins(lengths, frames_per_bin: int) -> np.ndarray:
    """bool [C, K]: which (clip, bin) cells exist, for clips of `lengths` [C] frames with
    start frames 0 .. length - 2 in bins of `frames_per_bin`; K = the most bins of any."""
    counts = [math.ceil((int(n) - 1) / frames_per_bin) for n in np.asarray(lengths)]
    return np.arange(max(counts))[None, :] < np.asarray(counts)[:, None]


def _frames_per_bin(ref: tracking.Motion, bin_seconds: float, who: str) -> int:
    seconds = checks.number(who, "bin_seconds", bin_seconds, 0.0, open_low=True)
    return max(1, round(float(seconds) / float(ref.clips.dt)))


def uniform_probabilities(valid: Array, weight: Array) -> Array:
    """float32 [C, K]: clip c with probability weight[c] ([C], summing to 1), then its
    valid bins ([C, K] bool) equally likely."""
    valid = jnp.asarray(valid, jnp.float32)
    return jnp.asarray(weight, jnp.float32)[:, None] * valid / jnp.sum(valid, axis=1, keepdims=True)


def start_probabilities(
    failures: Array, valid: Array, weight: Array, uniform: Array, smoothing: Array, kernel: int
) -> Array:
    """float32 [C, K]: the start distribution of the module docstring from `failures`
    [C, K] (>= 0), `valid` [C, K] bool, clip `weight` [C], the floor `uniform` in [0, 1],
    `smoothing` >= 0 and `kernel` (static int >= 0) bins looked ahead."""
    floor = uniform_probabilities(valid, weight)
    smoothed = sum(smoothing**k * jnp.pad(failures, ((0, 0), (0, k)))[:, k:] for k in range(kernel + 1)) * jnp.asarray(
        valid, failures.dtype
    )
    total = jnp.sum(smoothed)
    adapted = (1.0 - uniform) * smoothed / jnp.maximum(total, 1e-30) + uniform * floor
    return jnp.where(total > 0, adapted, floor).astype(jnp.float32)


def record_failure(failures: Array, clip: Array, bin: Array, ended: Array, failed: Array, rate: Array) -> Array:
    """`failures` [C, K] after a transition: where an episode `ended` (bool []), decayed
    by (1 - rate) and, if it `failed` (bool []), raised by `rate` at (clip, bin) (int32 [])."""
    hit = jnp.zeros_like(failures).at[clip, bin].set(jnp.where(failed, rate, 0.0))
    return jnp.where(ended, (1.0 - rate) * failures + hit, failures)


def sample_start(key: Array, probabilities: Array, lengths: Array, frames_per_bin: Array) -> tuple[Array, Array]:
    """(clip, frame), int32 []: a cell drawn from `probabilities` [C, K], then a frame
    uniform among the cell's start frames (below each clip's last, `lengths` [C])."""
    cell_key, frame_key = jax.random.split(key)
    k = probabilities.shape[1]
    cell = jax.random.categorical(cell_key, jnp.log(probabilities.ravel()))
    clip, b = cell // k, cell % k
    first = b * frames_per_bin
    count = jnp.clip(lengths[clip] - 1 - first, 1, frames_per_bin)
    return clip.astype(jnp.int32), (first + jax.random.randint(frame_key, (), 0, count)).astype(jnp.int32)


# --- reference-state initialization ---------------------------------------------------


def reference_start(ref: tracking.Motion, bin_seconds: float = 0.25) -> Partial:
    """Reset item: the robot on the reference at a start drawn by `sample_start` from the
    task's parameter ``start_probabilities`` [C, K] (uniform until `with_adaptive_starts`
    sets it): qpos and qvel of that frame, ``data.time = frame * dt``. Writes
    ``info["reference_clip"]`` and ``info["reference_frame"]`` (int32 [], the start)."""
    who = "start_sampling.reference_start"
    if not isinstance(ref, tracking.Motion):
        raise TypeError(f"{who}: ref must be a tracking.Motion (tracking.motion(...)), got {type(ref).__name__}")
    per_bin = _frames_per_bin(ref, bin_seconds, who)
    table = uniform_probabilities(bins(ref.clips.length, per_bin), ref.clips.weight)
    return Partial(_reference_start, ref, jnp.int32(per_bin), **{PARAMETER: table})  # a keyword: a named leaf


def _reference_start(ref, per_bin, model, data, key, start_probabilities):
    clip, frame = sample_start(key, start_probabilities, ref.clips.length, per_bin)
    index = ref.clips.start[clip] + frame
    data = data.replace(
        qpos=ref.clips.qpos[index].astype(data.qpos.dtype),
        qvel=ref.clips.qvel[index].astype(data.qvel.dtype),
        time=(frame * ref.clips.dt).astype(jnp.result_type(data.time)),
    )
    return data, {"reference_clip": clip, "reference_frame": frame}


# --- adaptive sampling ----------------------------------------------------------------


class AdaptiveStartState(NamedTuple):
    """`with_adaptive_starts`' record, per environment: ``failures`` float32 [C, K] (the
    module docstring's average), and this episode's ``mpjpe_sum`` (mm, float32 []) and
    ``steps`` (int32 []) so far."""

    failures: Array
    mpjpe_sum: Array
    steps: Array
    inner: Any = ()


def with_adaptive_starts(
    task: Task,
    ref: tracking.Motion,
    bin_seconds: float = 0.25,
    uniform: float = 0.1,
    smoothing: float = 0.8,
    kernel: int = 1,
    rate: float = 0.05,
) -> Task:
    """`task` (auto-resetting, its starts from `reference_start(ref, bin_seconds)`) with
    its starts drawn where its episodes failed, and the tracking metrics (module
    docstring). `uniform` in [0, 1], `smoothing` >= 0, `kernel` bins >= 0, `rate` in (0, 1]."""
    who = "with_adaptive_starts"
    if not isinstance(ref, tracking.Motion):
        raise TypeError(f"{who}: ref must be a tracking.Motion (tracking.motion(...)), got {type(ref).__name__}")
    valid = bins(ref.clips.length, _frames_per_bin(ref, bin_seconds, who))
    held = params(task).get(PARAMETER)
    if held is None or np.shape(held) != valid.shape:
        raise ValueError(
            f"{who}: the task must start with start_sampling.reference_start(ref, bin_seconds={bin_seconds}) "
            f"(a start_probabilities table of shape {valid.shape}), found {None if held is None else np.shape(held)}"
        )
    numbers = dict(  # named leaves: adaptive_uniform, ... (`mjzoo.with_params`)
        adaptive_uniform=checks.number(who, "uniform", uniform, 0.0, 1.0),
        adaptive_smoothing=checks.number(who, "smoothing", smoothing, 0.0),
        adaptive_rate=checks.number(who, "rate", rate, 0.0, 1.0, open_low=True),
    )
    kernel = tree.StaticValue(checks.integer(who, "kernel", kernel, 0))
    per_bin = jnp.int32(_frames_per_bin(ref, bin_seconds, who))
    stepped = runs_transitions(task, _adaptive_step, ref, jnp.asarray(valid), per_bin, numbers, kernel)
    return stepped.replace(start=Partial(_adaptive_reset, task.start, jnp.asarray(valid)))


def _adaptive_reset(start_fn, valid, model, key) -> State:
    zero = jnp.zeros((), jnp.float32)
    return wrap(start_fn(model, key), AdaptiveStartState(jnp.zeros(valid.shape, jnp.float32), zero, jnp.int32(0)))


def _adaptive_step(ref, valid, per_bin, numbers, kernel, inner, model, state, action, key) -> State:
    own, state = peel(state, AdaptiveStartState)
    probabilities = start_probabilities(
        own.failures, valid, ref.clips.weight, numbers["adaptive_uniform"], numbers["adaptive_smoothing"], kernel.value
    )
    task = inner.replace(model=model).with_params(**{PARAMETER: probabilities})
    next_state, terms = transition_with_terms(task, state, action, key)
    ended = next_state.terminated | next_state.truncated
    clip, frame, _ = tracking.clock(ref, state)  # the episode this transition belonged to
    b = jnp.minimum((frame + 1) // per_bin, valid.shape[1] - 1)
    failures = record_failure(own.failures, clip, b, ended, next_state.terminated, numbers["adaptive_rate"])
    error = tracking.mpjpe(ref, state)
    total, steps = own.mpjpe_sum + error, own.steps + 1
    metrics = {"tracking/mpjpe_mm": error}
    for c, name in enumerate(ref.clips.names):
        mine = (ended & (clip == c)).astype(jnp.float32)
        metrics[f"tracking/{name}/ended"] = mine
        metrics[f"tracking/{name}/succeeded"] = mine * (1.0 - next_state.terminated)
        metrics[f"tracking/{name}/episode_mpjpe_mm"] = mine * total / steps
    own = AdaptiveStartState(failures, jnp.where(ended, 0.0, total), jnp.where(ended, 0, steps))
    next_state = wrap(next_state, own).replace(metrics={**next_state.metrics, **metrics})
    return record(next_state, terms, next_state.terminated, next_state.truncated)


def summary(metrics: Mapping[str, Any]) -> dict[str, dict[str, float]]:
    """Per clip, from metrics averaged over the same transitions (a row of metrics.jsonl,
    or `collect`'s): ``{clip: {"episodes": share of transitions ending one, "success":
    rate, "mpjpe_mm": mean over episodes}}``; a clip with no ended episode gets NaN rates.
    Keys may carry a prefix (``env/``)."""
    out: dict[str, dict[str, float]] = {}
    for key, value in metrics.items():
        found = re.fullmatch(r"(.*)tracking/(.+)/ended", key)
        if not found:
            continue
        prefix, clip = found.groups()
        ended = float(value)
        rates = [float(metrics[f"{prefix}tracking/{clip}/{name}"]) for name in ("succeeded", "episode_mpjpe_mm")]
        success, mpjpe = (rate / ended if ended > 0 else math.nan for rate in rates)
        out[clip] = {"episodes": ended, "success": success, "mpjpe_mm": mpjpe}
    return out
