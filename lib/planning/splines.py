"""Control splines: a plan is a few knots, the controls between them are interpolated.

Sampling planners search over `K` knots of `nu` controls instead of every control step
of the horizon: fewer dimensions to sample, smoother controls. Knots sit at positions
measured in control steps of the planning task (`knot_positions`); a query at position
`s` returns the interpolated control. Outside ``[p_0, p_{K-1}]`` the end knots are held.

Interpolation methods:
  ``"zero"``    zero-order hold: the value of the last knot at or before `s`.
  ``"linear"``  piecewise linear between neighbouring knots.
  ``"cubic"``   cubic Hermite through every knot, with Catmull-Rom tangents
                (centred differences inside, one-sided at the ends), so it is C1.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["METHODS", "knot_positions", "interpolate"]

Array = jax.Array
METHODS = ("zero", "linear", "cubic")


def knot_positions(num_knots: int, horizon_steps: int) -> Array:
    """[K] float32 knot positions, evenly spaced from step 0 to step `horizon_steps - 1`."""
    if num_knots < 1 or horizon_steps < 1 or (num_knots > 1 and horizon_steps < 2):
        raise ValueError(
            f"knot_positions: need num_knots >= 1, horizon_steps >= 1 and distinct positions "
            f"(several knots need horizon_steps >= 2), got {num_knots}, {horizon_steps}"
        )
    if num_knots == 1:
        return jnp.zeros((1,), jnp.float32)
    return jnp.linspace(0.0, horizon_steps - 1, num_knots, dtype=jnp.float32)


def interpolate(knots: Array, positions: Array, queries: Array, method: str = "cubic") -> Array:
    """Interpolated controls at `queries`.

    Args:
      knots: [K, nu] control values at the knots.
      positions: [K] strictly increasing knot positions (control steps).
      queries: [T] positions to evaluate at (held at the ends outside the knots).
      method: one of `METHODS`.

    Returns:
      [T, nu] controls.
    """
    if method not in METHODS:
        raise ValueError(f"splines.interpolate: unknown method {method!r}; choose one of {METHODS}")
    knots, positions, queries = jnp.asarray(knots), jnp.asarray(positions), jnp.asarray(queries)
    if knots.ndim != 2 or positions.shape != knots.shape[:1]:
        raise ValueError(
            f"splines.interpolate: knots must be [K, nu] and positions [K], got {knots.shape} and {positions.shape}"
        )
    if knots.shape[0] == 1:
        return jnp.broadcast_to(knots[0], queries.shape + knots.shape[1:])
    s = jnp.clip(queries, positions[0], positions[-1])
    # Segment i holds p_i <= s < p_{i+1}; the last knot itself belongs to the last segment.
    # compare_all: K is a handful of knots, so no while loop (a loop per call costs ~0.1 ms on a CPU).
    i = jnp.clip(jnp.searchsorted(positions, s, side="right", method="compare_all") - 1, 0, positions.shape[0] - 2)
    p0, p1 = positions[i], positions[i + 1]
    u = ((s - p0) / (p1 - p0))[:, None]  # [T, 1] in [0, 1]
    y0, y1 = knots[i], knots[i + 1]
    if method == "zero":
        return jnp.where(u >= 1.0, y1, y0)
    if method == "linear":
        return y0 + u * (y1 - y0)
    tangents = _catmull_rom_tangents(knots, positions)  # [K, nu], per step
    width = (p1 - p0)[:, None]
    m0, m1 = tangents[i] * width, tangents[i + 1] * width
    u2, u3 = u * u, u * u * u
    return (2 * u3 - 3 * u2 + 1) * y0 + (u3 - 2 * u2 + u) * m0 + (-2 * u3 + 3 * u2) * y1 + (u3 - u2) * m1


def _catmull_rom_tangents(knots: Array, positions: Array) -> Array:
    """[K, nu] slopes dy/ds: centred differences inside, one-sided at both ends."""
    inner = (knots[2:] - knots[:-2]) / (positions[2:] - positions[:-2])[:, None]
    first = (knots[1] - knots[0]) / (positions[1] - positions[0])
    last = (knots[-1] - knots[-2]) / (positions[-1] - positions[-2])
    return jnp.concatenate([first[None], inner, last[None]])
