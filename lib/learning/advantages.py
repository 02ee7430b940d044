"""Generalized advantage estimation (Schulman et al., 2016) with termination and
truncation kept apart.

A transition that *terminates* lands in a terminal state whose value is 0: its target
does not bootstrap. A transition that is *truncated* (a time limit, a divergence
guard) lands in an ordinary state that was merely cut off: its target bootstraps from
the value of the true next observation. Either way the episode ends there, so the
advantage recursion never carries information across it. With auto-reset
environments the observation that follows an ended episode is the first one of the
next episode, which is why `next_values` is passed explicitly instead of being read
off `values[t + 1]`.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp

__all__ = ["gae"]

Array = jax.Array


def gae(
    rewards: Array,
    values: Array,
    next_values: Array,
    terminated: Array,
    truncated: Array,
    discount: float | Array,
    gae_lambda: float | Array,
) -> tuple[Array, Array]:
    """GAE(lambda) advantages and value targets over a time-major batch of transitions.

    For each t, with done_t = terminated_t | truncated_t:

      delta_t = r_t + discount * (1 - terminated_t) * next_values_t - values_t
      A_t     = delta_t + discount * gae_lambda * (1 - done_t) * A_{t+1},  A_T = 0
      R_t     = A_t + values_t

    The last transition of the window bootstraps through `next_values[T-1]` (unless it
    terminated), so windows cut in the middle of an episode need no special care.
    gae_lambda = 1 gives discounted Monte-Carlo returns minus values (bootstrapped at
    truncations and at the window's end); gae_lambda = 0 gives one-step TD errors.

    Gradients flow through every input; wrap the call in `jax.lax.stop_gradient` (or
    pass stopped values) when the targets must be constants.

    Args:
      rewards: [T, ...] float reward of transition t.
      values: [T, ...] V(obs_t), the value of the observation transition t started in.
      next_values: [T, ...] V of the true next observation of transition t (for an
        ended episode, its final observation, not the one after the reset).
      terminated: [T, ...] bool, transition t entered a terminal state.
      truncated: [T, ...] bool, the episode was cut off after transition t.
      discount: scalar in [0, 1], python float or traced.
      gae_lambda: scalar in [0, 1], python float or traced.

    Returns:
      (advantages, returns), both [T, ...] with the dtype of `values`.
    """
    chex.assert_equal_shape([rewards, values, next_values, terminated, truncated])
    if values.ndim < 1:
        raise ValueError(f"gae: inputs need a leading time axis, got shape {values.shape}")
    chex.assert_type([terminated, truncated], bool)
    chex.assert_rank([discount, gae_lambda], 0)

    dtype = values.dtype
    not_terminated = 1.0 - terminated.astype(dtype)
    not_done = 1.0 - (terminated | truncated).astype(dtype)
    deltas = rewards + discount * not_terminated * next_values - values
    decay = discount * gae_lambda * not_done  # [T, ...], how much of A_{t+1} reaches A_t

    def backward(next_advantage: Array, step: tuple[Array, Array]) -> tuple[Array, Array]:
        delta, decay_t = step
        advantage = delta + decay_t * next_advantage
        return advantage, advantage

    _, advantages = jax.lax.scan(backward, jnp.zeros_like(deltas[0]), (deltas, decay), reverse=True)
    advantages = advantages.astype(dtype)
    return advantages, advantages + values
