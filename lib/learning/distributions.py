"""The tanh-squashed diagonal Gaussian, the usual policy distribution for bounded
continuous actions, as pure functions of its parameters.

raw ~ N(loc, scale) elementwise and action = tanh(raw) in (-1, 1). Functions take
the pre-tanh sample `raw` rather than the action: tanh saturates in float32 for
|raw| > ~9, so recovering raw by atanh(action) would give inf and a NaN density. PPO
stores `raw` at collection time and evaluates `log_prob(loc, scale, raw)` later.

The squashing's log-det-Jacobian log(1 - tanh(u)^2) is computed in the stable form
2 * (log 2 - u - softplus(-2u)). (These few formulas are written out rather than taken
from a distributions library: importing one cost 1.5 s of every launch on a GPU host.)
"""

from __future__ import annotations

import math

import chex
import jax
import jax.numpy as jnp

__all__ = ["split_params", "sample", "log_prob", "entropy", "mode"]

Array = jax.Array

_HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)


def _gaussian_log_prob(loc: Array, scale: Array, x: Array) -> Array:
    """log N(x; loc, scale), elementwise."""
    return -0.5 * jnp.square((x - loc) / scale) - (_HALF_LOG_2PI + jnp.log(scale))


def _squash_log_det(raw: Array) -> Array:
    """log|det J| of tanh on each element, summed over the last (action) axis: [..., A] -> [...]."""
    return jnp.sum(2 * (jnp.log(2.0) - raw - jax.nn.softplus(-2 * raw)), axis=-1)


def _check_shapes(loc: Array, scale: Array, raw: Array) -> None:
    chex.assert_equal_shape([loc, scale, raw])
    if jnp.ndim(raw) < 1:
        raise ValueError("loc, scale and raw need an action axis [..., A]; got scalars")


def split_params(output: Array, min_std: float = 1e-3) -> tuple[Array, Array]:
    """Network output to the Gaussian's loc and scale.

    Args:
      output: [..., 2 * A]; the first half is the loc, the second half passes through
        softplus to the scale.
      min_std: scalar >= 0 added to the scale, so it never collapses to 0.

    Returns:
      (loc, scale), both [..., A]; scale = softplus(second half) + min_std.
    """
    size = jnp.shape(output)[-1] if jnp.ndim(output) else 0
    if size == 0 or size % 2:
        raise ValueError(
            f"split_params: the last axis of output must have even size 2 * A > 0, got shape {jnp.shape(output)}"
        )
    loc, raw_scale = jnp.split(output, 2, axis=-1)
    return loc, jax.nn.softplus(raw_scale) + min_std


def sample(loc: Array, scale: Array, key: Array) -> tuple[Array, Array]:
    """Draws a squashed action and its pre-tanh value.

    Args:
      loc, scale: [..., A] the Gaussian's mean and standard deviation.
      key: PRNG key.

    Returns:
      (action, raw), both [..., A]: raw ~ N(loc, scale), action = tanh(raw).
    """
    chex.assert_equal_shape([loc, scale])
    raw = scale * jax.random.normal(key, jnp.shape(loc), jnp.result_type(loc, scale)) + loc
    return jnp.tanh(raw), raw


def log_prob(loc: Array, scale: Array, raw: Array) -> Array:
    """Log density of the action tanh(raw), given its pre-tanh value.

    By the change of variables a = tanh(u),

      log p(a) = sum_i [log N(u_i; loc_i, scale_i) - log(1 - tanh(u_i)^2)]

    with the second term in a form that stays finite for any finite u.

    Args:
      loc, scale: [..., A].
      raw: [..., A] pre-tanh values (as returned by `sample`).

    Returns:
      [...] log density, summed over the action axis.
    """
    _check_shapes(loc, scale, raw)
    return jnp.sum(_gaussian_log_prob(loc, scale, raw), axis=-1) - _squash_log_det(raw)


def entropy(loc: Array, scale: Array, noise: Array) -> Array:
    """One-sample estimate of the squashed distribution's entropy, at u = loc + scale * noise.

    The entropy of a = tanh(u) is H[u] + E_u[log|det J_tanh(u)|]; it has no closed
    form, so the expectation is replaced by its value at one reparameterized sample.
    Draw `noise` afresh for each estimate (as PPO does per minibatch): then the
    estimate and its gradient are unbiased, and the gradient reaches the log-det term,
    which caps the scale near 1 and pulls the loc out of tanh's flat tails. (Reusing the
    action's recorded pre-tanh value instead goes wrong once the parameters move: that
    stale sample makes the estimate grow without bound with the scale, and Adam follows
    it to bang-bang actions in one PPO update.)

    Args:
      loc, scale: [..., A].
      noise: [..., A] standard normal draws.

    Returns:
      [...] entropy estimate, summed over the action axis.
    """
    _check_shapes(loc, scale, noise)
    gaussian = jnp.sum(0.5 + (_HALF_LOG_2PI + jnp.log(scale)), axis=-1)
    return gaussian + _squash_log_det(loc + scale * noise)


def mode(loc: Array) -> Array:
    """The deterministic action, tanh(loc), [..., A] -> [..., A], for evaluation.

    tanh is monotone, so this is exactly the median of each squashed component; it is
    close to the squashed density's mode and mean when the scale is small.
    """
    return jnp.tanh(loc)
