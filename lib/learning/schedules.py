"""Schedules that steer a PPO run as it goes: the KL-adaptive learning rate, the early
stop of an update's epochs on a KL bound, and the entropy coefficient's decay.

Each is a pure function of scalars that may be traced, so a sweep can `jax.vmap` one
over a batch of targets or bounds, and an update can carry them through `lax.scan`
without Python control flow:

    def sgd_step(carry, minibatch):
        params, opt_state, stopped = carry
        grads, metrics = grad_fn(params, minibatch)          # metrics["approx_kl"]
        updates, new_opt_state = optimizer.update(grads, opt_state, params)
        stopped = kl_early_stop(stopped, metrics["approx_kl"], max_kl)
        params, opt_state = skip_when_stopped(
            stopped, (params, opt_state), (optax.apply_updates(params, updates), new_opt_state)
        )
        return (params, opt_state, stopped), metrics
"""

from __future__ import annotations

import math
from typing import Any
from typing import Literal

import jax
import jax.numpy as jnp

from mjzoo import tree

__all__ = ["ENTROPY_SCHEDULES", "entropy_coef_schedule", "kl_adaptive_lr", "kl_early_stop", "skip_when_stopped"]

Array = jax.Array
PyTree = Any

ENTROPY_SCHEDULES = ("constant", "linear", "cosine")


def kl_adaptive_lr(
    lr: float | Array,
    kl: float | Array,
    target_kl: float | Array,
    factor: float | Array = 1.5,
    min_lr: float | Array = 1e-5,
    max_lr: float | Array = 1e-2,
) -> Array:
    """The learning rate after a step whose measured KL was `kl` (rsl_rl's "adaptive"
    schedule):

      lr' = lr / factor   if kl > 2 * target_kl
      lr' = lr * factor   if 0 < kl < target_kl / 2
      lr' = lr            otherwise
      then clipped to [min_lr, max_lr].

    A KL of exactly 0 leaves the rate as it is, as in rsl_rl: it is what the first
    minibatch of an update measures (the policy has not moved yet), not evidence that
    the steps are too small. A NaN KL fails every comparison and so also leaves it.

    Args:
      lr: scalar, the current learning rate.
      kl: scalar, the approximate KL(pi_old || pi) of the last step or update (e.g. the
        losses' "approx_kl").
      target_kl: scalar > 0.
      factor: scalar > 1, the multiplicative step of the rate.
      min_lr, max_lr: scalars, 0 < min_lr <= max_lr.

    Returns:
      float32 scalar, the new learning rate. All arguments may be traced, and vmapped
      together or separately.
    """
    lr, kl, target_kl = (jnp.asarray(x, jnp.float32) for x in (lr, kl, target_kl))
    factor, min_lr, max_lr = (jnp.asarray(x, jnp.float32) for x in (factor, min_lr, max_lr))
    too_far = kl > 2.0 * target_kl
    too_timid = (kl < 0.5 * target_kl) & (kl > 0.0)
    new_lr = jnp.where(too_far, lr / factor, jnp.where(too_timid, lr * factor, lr))
    return jnp.clip(new_lr, min_lr, max_lr)


def kl_early_stop(stopped: bool | Array, kl: float | Array, max_kl: float | Array = math.inf) -> Array:
    """Whether an update's remaining minibatch steps are skipped, after one more step:

      stopped' = stopped or kl > max_kl

    The flag only ever turns on, so once a step measured too large a KL every later step
    of the update is skipped (pass the flag to `skip_when_stopped`). As in
    Stable-Baselines3's `target_kl`, the step that measured the KL is itself skipped
    when the flag is computed before it is applied: the KL is measured at the
    parameters the step starts from. Start each update from False.

    Args:
      stopped: bool scalar, the flag so far.
      kl: scalar, the approximate KL(pi_old || pi) the step just measured.
      max_kl: scalar, the bound; inf (the default) never stops. (SB3 uses
        1.5 * target_kl.)

    Returns:
      bool scalar. A NaN KL does not stop the update (guard non-finite steps with
      `mjzoo.learning.guards`).
    """
    return jnp.asarray(stopped, jnp.bool_) | (jnp.asarray(kl) > max_kl)


def skip_when_stopped(stopped: bool | Array, old: PyTree, new: PyTree) -> PyTree:
    """`old` where `stopped`, else `new`, leaf by leaf: a masked update, so a `lax.scan`
    over minibatches skips its remaining steps without Python control flow (the steps
    are still computed; their results are dropped).

    Args:
      stopped: bool scalar (from `kl_early_stop`).
      old, new: pytrees of the same structure and shapes (e.g. (params, opt_state)
        before and after the step).

    Returns:
      A pytree like `new`.
    """
    if jax.tree.structure(old) != jax.tree.structure(new):
        raise ValueError(
            f"skip_when_stopped: old and new differ in structure: {jax.tree.structure(old)} vs "
            f"{jax.tree.structure(new)}"
        )
    return tree.where(jnp.asarray(stopped, jnp.bool_), old, new)


def entropy_coef_schedule(
    kind: Literal["constant", "linear", "cosine"],
    progress: float | Array,
    initial: float | Array,
    final: float | Array,
) -> Array:
    """The entropy coefficient at `progress` through the run, p = clip(progress, 0, 1):

      constant: c = initial
      linear:   c = initial + (final - initial) * p
      cosine:   c = final + (initial - final) * (1 + cos(pi * p)) / 2

    Both decays start at `initial` (p = 0) and end at `final` (p = 1); the cosine one
    stays near `initial` longer and flattens out onto `final`.

    Args:
      kind: static, one of "constant", "linear", "cosine".
      progress: scalar, the fraction of the run done (e.g. step / total_steps); values
        outside [0, 1] are clipped.
      initial, final: scalars, the coefficients at the start and at the end (`final`
        is unused by "constant").

    Returns:
      float32 scalar. progress, initial and final may be traced.
    """
    if kind not in ENTROPY_SCHEDULES:
        raise ValueError(f"entropy_coef_schedule: kind={kind!r} must be one of {', '.join(ENTROPY_SCHEDULES)}")
    p = jnp.clip(jnp.asarray(progress, jnp.float32), 0.0, 1.0)
    initial, final = jnp.asarray(initial, jnp.float32), jnp.asarray(final, jnp.float32)
    if kind == "constant":
        return initial
    if kind == "linear":
        return initial + (final - initial) * p
    return final + (initial - final) * 0.5 * (1.0 + jnp.cos(jnp.pi * p))
