"""Policy-gradient losses (vanilla, PPO's clipped surrogate and the KL-penalized one of
Schulman et al., 2017), the value loss, and advantage normalization.

Every function reduces over all elements of its inputs, so a [T, B] minibatch and a
flattened [T * B] one give the same loss. Targets that come from data collection
(old log-probabilities, advantages, returns, old values) are wrapped in
`jax.lax.stop_gradient`: a loss differentiates only through what the current
parameters produce.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp

__all__ = [
    "clipped_surrogate_loss",
    "kl_penalty_loss",
    "normalize_advantages",
    "policy_gradient_loss",
    "temperature_loss",
    "value_loss",
]

Array = jax.Array


def policy_gradient_loss(log_prob: Array, advantages: Array) -> Array:
    """The vanilla (REINFORCE / A2C) policy-gradient loss, to be minimized.

      loss = -mean(log_prob * A)

    Its gradient is the score-function estimate -mean(A * grad log pi(a|s)). It is only
    unbiased on-policy: the actions must come from the current parameters (one step per
    batch, as in A2C); reuse the batch with a ratio loss instead.

    Args:
      log_prob: [...] log pi(a|s) under the current parameters.
      advantages: [...] advantage estimates (no gradient flows into them).

    Returns:
      Scalar loss.
    """
    chex.assert_equal_shape([log_prob, advantages])
    return -jnp.mean(log_prob * jax.lax.stop_gradient(advantages))


def _approx_kl(log_ratio: Array) -> Array:
    """mean((r - 1) - log r), r = pi / pi_old: Schulman's "k3" estimate of KL(pi_old || pi)
    from samples of pi_old; unbiased (E[r] = 1) and non-negative per sample."""
    return jnp.mean(jnp.expm1(log_ratio) - log_ratio)


def clipped_surrogate_loss(
    log_prob: Array,
    old_log_prob: Array,
    advantages: Array,
    clip_epsilon: float | Array,
) -> tuple[Array, dict[str, Array]]:
    """PPO's clipped surrogate objective, negated to be minimized.

      ratio = exp(log_prob - old_log_prob)
      loss  = -mean(min(ratio * A, clip(ratio, 1 - eps, 1 + eps) * A))

    The min makes the objective pessimistic: once the ratio has moved past 1 + eps
    (for A > 0) or below 1 - eps (for A < 0) the clipped term is the smaller one and its
    gradient is zero, so a step cannot profit from moving the policy further.

    Args:
      log_prob: [...] log pi(a|s) under the current parameters.
      old_log_prob: [...] log pi_old(a|s) recorded when the action was taken.
      advantages: [...] advantage estimates (usually normalized).
      clip_epsilon: scalar > 0.

    Returns:
      (loss, aux): loss a scalar; aux holds scalars
        "clip_fraction": fraction of elements with |ratio - 1| > eps,
        "approx_kl": mean((ratio - 1) - log ratio), an unbiased, non-negative estimate
          of KL(pi_old || pi) (Schulman's "k3" estimator).
    """
    chex.assert_equal_shape([log_prob, old_log_prob, advantages])
    chex.assert_rank(clip_epsilon, 0)
    old_log_prob = jax.lax.stop_gradient(old_log_prob)
    advantages = jax.lax.stop_gradient(advantages)

    log_ratio = log_prob - old_log_prob
    ratio = jnp.exp(log_ratio)
    clipped_ratio = jnp.clip(ratio, 1.0 - clip_epsilon, 1.0 + clip_epsilon)
    loss = -jnp.mean(jnp.minimum(ratio * advantages, clipped_ratio * advantages))

    stopped_ratio = jax.lax.stop_gradient(ratio)
    aux = {
        "clip_fraction": jnp.mean((jnp.abs(stopped_ratio - 1.0) > clip_epsilon).astype(loss.dtype)),
        "approx_kl": _approx_kl(jax.lax.stop_gradient(log_ratio)),
    }
    return loss, aux


def kl_penalty_loss(
    log_prob: Array,
    old_log_prob: Array,
    advantages: Array,
    beta: float | Array,
) -> tuple[Array, dict[str, Array]]:
    """PPO's KL-penalized surrogate objective, negated to be minimized.

      ratio = exp(log_prob - old_log_prob)
      loss  = -mean(ratio * A) + beta * mean((ratio - 1) - log ratio)

    The penalty is the "k3" estimate of KL(pi_old || pi) from the collected actions
    (which pi_old sampled): unbiased, non-negative for every sample, and with gradient
    beta * (ratio - 1) * grad log pi, zero where the policy has not moved. Where the
    clipped surrogate stops the gradient past the clip range, this pulls back smoothly;
    adapt `beta` to a target KL between updates (Schulman et al., 2017, section 4).

    Args:
      log_prob: [...] log pi(a|s) under the current parameters.
      old_log_prob: [...] log pi_old(a|s) recorded when the action was taken.
      advantages: [...] advantage estimates.
      beta: scalar >= 0, the penalty's weight (a leaf: adapting it does not recompile).

    Returns:
      (loss, aux): loss a scalar; aux holds the scalar "approx_kl", the penalty's KL
      estimate (without gradient).
    """
    chex.assert_equal_shape([log_prob, old_log_prob, advantages])
    chex.assert_rank(beta, 0)
    log_ratio = log_prob - jax.lax.stop_gradient(old_log_prob)
    kl = _approx_kl(log_ratio)
    loss = -jnp.mean(jnp.exp(log_ratio) * jax.lax.stop_gradient(advantages)) + beta * kl
    return loss, {"approx_kl": jax.lax.stop_gradient(kl)}


def value_loss(
    values: Array,
    returns: Array,
    old_values: Array | None = None,
    clip_epsilon: float | Array | None = None,
) -> Array:
    """Half mean squared error of the value function, optionally clipped.

    Unclipped:  0.5 * mean((v - R)^2)
    Clipped:    0.5 * mean(max((v - R)^2, (v_old + clip(v - v_old, -eps, eps) - R)^2))

    The clipped variant (as in OpenAI baselines' PPO2) keeps the value function from
    moving more than eps away from the values it had at collection time; it is used
    when both `old_values` and `clip_epsilon` are given.

    Args:
      values: [...] V(s) under the current parameters.
      returns: [...] value targets (e.g. GAE returns).
      old_values: [...] V(s) at collection time, or None.
      clip_epsilon: scalar > 0, or None; in the units of the values.

    Returns:
      Scalar loss.
    """
    chex.assert_equal_shape([values, returns])
    if (old_values is None) != (clip_epsilon is None):
        raise ValueError(
            "value_loss: pass both old_values and clip_epsilon for the clipped loss, or neither "
            f"(got old_values={'None' if old_values is None else 'an array'}, clip_epsilon={clip_epsilon!r})"
        )
    returns = jax.lax.stop_gradient(returns)
    squared_error = jnp.square(values - returns)
    if old_values is None:
        return 0.5 * jnp.mean(squared_error)

    chex.assert_equal_shape([values, old_values])
    chex.assert_rank(clip_epsilon, 0)
    old_values = jax.lax.stop_gradient(old_values)
    clipped_values = old_values + jnp.clip(values - old_values, -clip_epsilon, clip_epsilon)
    clipped_error = jnp.square(clipped_values - returns)
    return 0.5 * jnp.mean(jnp.maximum(squared_error, clipped_error))


def normalize_advantages(advantages: Array, eps: float = 1e-8) -> Array:
    """Shifts and scales to zero mean and unit standard deviation over all elements.

      (A - mean(A)) / (std(A) + eps)

    `eps` keeps a constant batch (std 0) finite: it maps to zeros.

    Args:
      advantages: [...] any shape.
      eps: scalar >= 0 added to the (population) standard deviation.

    Returns:
      [...] same shape and dtype.
    """
    mean = jnp.mean(advantages)
    std = jnp.std(advantages)
    return (advantages - mean) / (std + eps)


def temperature_loss(log_alpha: Array, log_prob: Array, target_entropy: float | Array) -> Array:
    """SAC's automatic entropy tuning: -mean(log_alpha * (log pi(a|s) + target_entropy)),
    the log-probabilities held fixed.

    Its gradient in log_alpha is -(target_entropy - H), H = -mean(log_prob) the policy's
    entropy estimate: alpha grows while the entropy is below the target and shrinks
    above it. (Learning log alpha keeps alpha > 0.)

    Args:
      log_alpha: [] the learned log-temperature.
      log_prob: [B] log-probabilities of actions freshly sampled from the policy.
      target_entropy: scalar, e.g. -action_size.

    Returns:
      [] the loss.
    """
    chex.assert_rank([log_alpha, log_prob], [0, 1])
    return -jnp.mean(log_alpha * jax.lax.stop_gradient(log_prob + target_entropy))
