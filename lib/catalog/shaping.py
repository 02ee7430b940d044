"""Reward shaping: `tolerance`, the DeepMind Control Suite's smooth tolerance, and
`wrap_angle`, the one angle wrap that costs and errors of angles go through.

`tolerance(x, lower, upper, margin)` is 1 inside ``[lower, upper]`` and falls off with
the distance outside, to `value_at_margin` at distance `margin`, along one of SIGMOIDS.
Envs build their rewards from it (``rewards.tolerance`` is the same function).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["tolerance", "wrap_angle", "SIGMOIDS"]

Array = jax.Array
SIGMOIDS = ("gaussian", "long_tail", "linear", "quadratic")


def _sigmoid(d: Array, value_at_margin: Array, kind: str) -> Array:
    """Decreasing shape of d >= 0 with value 1 at d = 0 and `value_at_margin` at d = 1."""
    if kind == "gaussian":
        scale = jnp.sqrt(-2.0 * jnp.log(value_at_margin))
        return jnp.exp(-0.5 * (d * scale) ** 2)
    if kind == "long_tail":
        scale = jnp.sqrt(1.0 / value_at_margin - 1.0)
        return 1.0 / ((d * scale) ** 2 + 1.0)
    if kind == "linear":
        return jnp.clip(1.0 - (1.0 - value_at_margin) * d, 0.0, 1.0)
    if kind == "quadratic":
        return jnp.clip(1.0 - (1.0 - value_at_margin) * d**2, 0.0, 1.0)
    raise ValueError(f"unknown sigmoid {kind!r}; expected one of {SIGMOIDS}")


def tolerance(
    x: Array,
    lower: Array | float = 0.0,
    upper: Array | float = 0.0,
    margin: Array | float = 0.0,
    sigmoid: str = "gaussian",
    value_at_margin: Array | float = 0.1,
) -> Array:
    """1 where lower <= x <= upper, else a smooth fall-off with the distance outside.

    Args:
      x: any shape; the result has the same shape, values in [0, 1].
      lower, upper: the band in which the reward is 1 (lower <= upper).
      margin: distance outside the band at which the value is `value_at_margin`
        (> 0); with margin 0 the reward is the band's indicator.
      sigmoid: the fall-off shape, one of SIGMOIDS (static).
      value_at_margin: in (0, 1) for "gaussian" and "long_tail", [0, 1) otherwise.
    """
    x = jnp.asarray(x, jnp.float32)
    inside = (x >= lower) & (x <= upper)
    distance = jnp.where(x < lower, lower - x, x - upper)
    safe_margin = jnp.maximum(margin, 1e-12)
    smooth = _sigmoid(distance / safe_margin, jnp.asarray(value_at_margin, jnp.float32), sigmoid)
    outside = jnp.where(jnp.asarray(margin) > 0, smooth, 0.0)
    return jnp.where(inside, 1.0, outside).astype(jnp.float32)


def wrap_angle(angle: Array) -> Array:
    """`angle` (rad, any shape) in [-pi, pi]: the same direction, the short way round from
    zero, so a cost of a hinge that has turned twice costs as little as an upright one."""
    return jnp.arctan2(jnp.sin(angle), jnp.cos(angle))
