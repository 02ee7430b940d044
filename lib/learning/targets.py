"""Targets of off-policy critics: the twin-critic TD target, target-policy smoothing,
the categorical (C51) projection of a distributional target, and Polyak averaging of
target networks.

    y = twin_td_target(reward, discount, next_q1, next_q2)                   # TD3
    y = twin_td_target(reward, discount, next_q1, next_q2, next_log_prob, alpha)  # SAC
    next_action = smoothed_action(target_action, key, 0.2, 0.5)
    probs = categorical_projection(support, next_probs, reward, discount)    # C51
    target_params = polyak(target_params, params, tau)

`discount` is the per-sample factor on the bootstrapped value: `replay.sample_n_step`'s
discount^m, 0 after a terminal step.
"""

from __future__ import annotations

from typing import Any

import chex
import jax
import jax.numpy as jnp

__all__ = [
    "categorical_projection",
    "categorical_support",
    "categorical_value",
    "polyak",
    "smoothed_action",
    "twin_td_target",
]

Array = jax.Array
PyTree = Any


def twin_td_target(
    reward: Array,
    discount: Array,
    next_q1: Array,
    next_q2: Array,
    next_log_prob: Array | None = None,
    alpha: float | Array = 0.0,
) -> Array:
    """The clipped double-Q target y = r + discount * (min(q1', q2') - alpha * log pi(a'|s')),
    held fixed (no gradient flows through it).

    Args:
      reward, discount: [B] (n-step sums and their bootstrap factors).
      next_q1, next_q2: [B] the two target critics at (next_obs, next action).
      next_log_prob: [B] the log-probability of the next action (SAC's entropy bonus);
        None: no bonus (TD3).
      alpha: scalar >= 0, the entropy temperature.

    Returns:
      [B] the targets.
    """
    chex.assert_rank([reward, discount, next_q1, next_q2], 1)
    chex.assert_equal_shape([reward, discount, next_q1, next_q2])
    soft = jnp.minimum(next_q1, next_q2)
    if next_log_prob is not None:
        chex.assert_equal_shape([reward, next_log_prob])
        soft = soft - alpha * next_log_prob
    return jax.lax.stop_gradient(reward + discount * soft)


def smoothed_action(action: Array, key: Array, noise_scale: float | Array, noise_clip: float | Array) -> Array:
    """TD3's target-policy smoothing: clip(action + clip(noise_scale * eps, -c, c), -1, 1)
    with eps ~ N(0, 1), so the critic's target averages over nearby actions.

    Args:
      action: [..., A] the target policy's actions in [-1, 1].
      key: PRNG key.
      noise_scale: scalar >= 0, the noise's standard deviation.
      noise_clip: scalar >= 0, c.

    Returns:
      [..., A] in [-1, 1].
    """
    noise = noise_scale * jax.random.normal(key, jnp.shape(action), jnp.result_type(action))
    return jnp.clip(action + jnp.clip(noise, -noise_clip, noise_clip), -1.0, 1.0)


def categorical_support(v_min: float | Array, v_max: float | Array, num_atoms: int) -> Array:
    """The atoms z_i = v_min + i (v_max - v_min) / (num_atoms - 1), [num_atoms] (num_atoms >= 2, static)."""
    if isinstance(num_atoms, bool) or not isinstance(num_atoms, int) or num_atoms < 2:
        raise ValueError(f"categorical_support: num_atoms={num_atoms!r} must be an int >= 2")
    return jnp.linspace(jnp.float32(0.0), 1.0, num_atoms) * (v_max - v_min) + v_min


def categorical_value(support: Array, probs: Array) -> Array:
    """The expected value sum_i p_i z_i: support [K], probs [..., K] -> [...]."""
    return jnp.sum(probs * support, axis=-1)


def categorical_projection(support: Array, next_probs: Array, reward: Array, discount: Array) -> Array:
    """C51's projection of the target distribution onto the fixed support.

    Each next atom z_j, with probability p_j, moves to Tz_j = clip(r + discount z_j,
    z_0, z_{K-1}); its mass is split between the two atoms around it in proportion to
    closeness: atom i receives p_j max(0, 1 - |b_j - i|), with b_j = (Tz_j - z_0) /
    dz its fractional index (one atom takes it all when b_j is whole).

    Args:
      support: [K] evenly spaced atoms (`categorical_support`).
      next_probs: [B, K] the target critic's probabilities at the next state.
      reward, discount: [B].

    Returns:
      [B, K] projected probabilities (rows sum to the rows of next_probs), held fixed.
    """
    chex.assert_rank([support, next_probs, reward, discount], [1, 2, 1, 1])
    chex.assert_equal_shape_prefix([next_probs, reward, discount], 1)
    num_atoms = support.shape[0]
    v_min, v_max = support[0], support[-1]
    delta = (v_max - v_min) / (num_atoms - 1)
    moved = jnp.clip(reward[:, None] + discount[:, None] * support, v_min, v_max)  # [B, K]
    index = (moved - v_min) / delta
    weights = jnp.clip(1.0 - jnp.abs(index[:, :, None] - jnp.arange(num_atoms)), 0.0, 1.0)  # [B, K from, K to]
    return jax.lax.stop_gradient(jnp.einsum("bj,bji->bi", next_probs, weights))


def polyak(target: PyTree, online: PyTree, tau: float | Array) -> PyTree:
    """target <- (1 - tau) target + tau online, leaf by leaf (tau in [0, 1]; 1 copies)."""
    return jax.tree.map(lambda t, o: (1.0 - tau) * t + tau * o, target, online)
