"""`mjzoo.rewards.tolerance` against hand-computed values.

Notation: d = (distance outside [lower, upper]) / margin, v = value_at_margin. The four
shapes, as defined in the DeepMind Control Suite, are
  gaussian:   exp(-0.5 (d s)^2),  s = sqrt(-2 ln v)   -> exp(ln(v) d^2) = v^(d^2)
  long_tail:  1 / ((d s)^2 + 1),  s = sqrt(1/v - 1)   -> 1 / ((1/v - 1) d^2 + 1)
  linear:     clip(1 - (1 - v) d, 0, 1)
  quadratic:  clip(1 - (1 - v) d^2, 0, 1)
so every shape is 1 at d = 0 and v at d = 1. The numbers below are derived from these
closed forms by hand, not by calling the implementation.
"""

from __future__ import annotations

import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.rewards import SIGMOIDS, tolerance

# A band [1, 2] with margin 0.5 and value_at_margin 0.1 unless a test says otherwise.
LOWER, UPPER, MARGIN, V = 1.0, 2.0, 0.5, 0.1


def tol(x, sigmoid, margin=MARGIN, value_at_margin=V):
    return tolerance(x, lower=LOWER, upper=UPPER, margin=margin, sigmoid=sigmoid, value_at_margin=value_at_margin)


def test_sigmoids_are_the_four_documented_shapes():
    assert set(SIGMOIDS) == {"gaussian", "long_tail", "linear", "quadratic"}


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_inside_band_is_one(sigmoid):
    # Both edges and the interior of [1, 2] are inside: exactly 1.
    np.testing.assert_array_equal(tol(jnp.array([1.0, 1.3, 1.5, 2.0]), sigmoid), np.ones(4, np.float32))


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
@pytest.mark.parametrize("x", [UPPER + MARGIN, LOWER - MARGIN])
def test_at_margin_is_value_at_margin(sigmoid, x):
    # distance == margin  =>  d = 1  =>  every shape equals v, on either side of the band.
    for v in (0.1, 0.5, 0.9):
        np.testing.assert_allclose(tol(x, sigmoid, value_at_margin=v), v, rtol=1e-5)


# d = 0.5 (half a margin outside the band), v = 0.1:
#   gaussian:  v^(0.5^2) = 0.1^0.25                        = 0.56234...
#   long_tail: 1 / ((1/0.1 - 1) * 0.25 + 1) = 1 / 3.25     = 0.30769...
#   linear:    1 - (1 - 0.1) * 0.5 = 1 - 0.45              = 0.55
#   quadratic: 1 - (1 - 0.1) * 0.25 = 1 - 0.225            = 0.775
HALF_MARGIN = {
    "gaussian": 0.1**0.25,
    "long_tail": 1.0 / 3.25,
    "linear": 0.55,
    "quadratic": 0.775,
}


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_half_margin_hand_values(sigmoid):
    above = tol(UPPER + 0.5 * MARGIN, sigmoid)
    below = tol(LOWER - 0.5 * MARGIN, sigmoid)
    np.testing.assert_allclose(above, HALF_MARGIN[sigmoid], rtol=1e-5)
    np.testing.assert_allclose(below, HALF_MARGIN[sigmoid], rtol=1e-5)


# d = 2 (two margins outside), v = 0.1:
#   gaussian:  0.1^4                          = 1e-4
#   long_tail: 1 / (9 * 4 + 1) = 1 / 37       = 0.027027...
#   linear:    1 - 0.9 * 2 = -0.8 -> clipped  = 0   (reaches 0 at d = 1/0.9)
#   quadratic: 1 - 0.9 * 4 = -2.6 -> clipped  = 0   (reaches 0 at d = 1/sqrt(0.9))
TWO_MARGINS = {"gaussian": 1e-4, "long_tail": 1.0 / 37.0, "linear": 0.0, "quadratic": 0.0}


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_two_margins_hand_values(sigmoid):
    np.testing.assert_allclose(tol(UPPER + 2 * MARGIN, sigmoid), TWO_MARGINS[sigmoid], rtol=1e-4, atol=1e-7)


def test_linear_and_quadratic_reach_zero_where_the_formula_says():
    # linear is 0 from d = 1/(1 - v) = 1/0.9 = 1.111 margins on, positive just before.
    assert float(tol(UPPER + 1.10 * MARGIN, "linear")) > 0.0
    assert float(tol(UPPER + 1.12 * MARGIN, "linear")) == 0.0
    # quadratic is 0 from d = 1/sqrt(0.9) = 1.054 margins on.
    assert float(tol(UPPER + 1.04 * MARGIN, "quadratic")) > 0.0
    assert float(tol(UPPER + 1.06 * MARGIN, "quadratic")) == 0.0


def test_default_band_is_the_point_zero_with_gaussian():
    # Defaults: lower = upper = 0, margin = 0 (indicator), gaussian.
    np.testing.assert_array_equal(tolerance(jnp.array([0.0, 1e-3, -2.0])), [1.0, 0.0, 0.0])
    # With only a margin: gaussian of |x| / margin, 0.1 at |x| = margin.
    np.testing.assert_allclose(tolerance(jnp.array([-0.3, 0.3]), margin=0.3), [0.1, 0.1], rtol=1e-5)


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_zero_margin_is_the_band_indicator(sigmoid):
    x = jnp.array([0.0, 0.999, 1.0, 1.5, 2.0, 2.001, 100.0, -1e6])
    expected = np.array([0, 0, 1, 1, 1, 0, 0, 0], np.float32)
    out = tol(x, sigmoid, margin=0.0)
    np.testing.assert_array_equal(out, expected)


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_decreases_monotonically_with_distance(sigmoid):
    d = jnp.linspace(0.0, 3.0, 61)
    out = np.asarray(tol(UPPER + d * MARGIN, sigmoid))
    assert np.all(np.diff(out) <= 0.0)
    out_below = np.asarray(tol(LOWER - d * MARGIN, sigmoid))
    np.testing.assert_allclose(out_below, out, rtol=1e-5, atol=1e-6)  # symmetric in the distance


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_output_in_unit_interval_float32_same_shape(sigmoid):
    x = jax.random.uniform(jax.random.key(0), (7, 5), minval=-100.0, maxval=100.0)
    for margin, v in [(0.0, 0.1), (0.5, 0.1), (3.0, 0.5), (1e-3, 0.9)]:
        out = tol(x, sigmoid, margin=margin, value_at_margin=v)
        chex.assert_shape(out, (7, 5))
        chex.assert_type(out, jnp.float32)
        assert bool(jnp.all((out >= 0.0) & (out <= 1.0)))
        assert bool(jnp.all(jnp.isfinite(out)))


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_jit_matches_eager(sigmoid):
    fn = jax.jit(lambda x, lower, upper, margin, v: tolerance(x, lower, upper, margin, sigmoid, v))
    x = jnp.array([0.25, 1.5, 2.25, 2.5])
    out = fn(x, LOWER, UPPER, MARGIN, V)
    # 0.25 is 0.75 = 1.5 margins below the band; 2.25 half a margin above; 2.5 one margin above.
    expected_d15 = {
        "gaussian": 0.1**2.25,  # v^(d^2), d^2 = 2.25
        "long_tail": 1.0 / (9.0 * 2.25 + 1.0),
        "linear": 0.0,  # 1 - 0.9 * 1.5 < 0
        "quadratic": 0.0,  # 1 - 0.9 * 2.25 < 0
    }[sigmoid]
    np.testing.assert_allclose(out, [expected_d15, 1.0, HALF_MARGIN[sigmoid], V], rtol=1e-5, atol=1e-7)
    # Band and margin are traced values: a different margin under the same trace.
    np.testing.assert_allclose(fn(jnp.array(2.25), LOWER, UPPER, 0.25, V), V, rtol=1e-5)


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_vmap_over_x_and_over_bounds(sigmoid):
    x = jnp.array([1.5, 2.25, 2.5, 0.5])
    out = jax.vmap(lambda xi: tol(xi, sigmoid))(x)
    np.testing.assert_allclose(out, [1.0, HALF_MARGIN[sigmoid], V, V], rtol=1e-5)
    # vmap over the upper bound: x = 2.5 is inside for upper = 2.5, d = 1 for upper = 2.0,
    # and d = 0.5 for upper = 2.25.
    uppers = jnp.array([2.5, 2.0, 2.25])
    out = jax.vmap(lambda u: tolerance(2.5, LOWER, u, MARGIN, sigmoid, V))(uppers)
    np.testing.assert_allclose(out, [1.0, V, HALF_MARGIN[sigmoid]], rtol=1e-5)


def test_gaussian_closed_form_over_a_grid():
    # v^(d^2) for a few d and v, against math.pow (independent of the implementation).
    for v in (0.01, 0.1, 0.5):
        for d in (0.1, 0.7, 1.3):
            got = float(tolerance(d * MARGIN, 0.0, 0.0, MARGIN, "gaussian", v))
            assert math.isclose(got, math.pow(v, d * d), rel_tol=1e-5)


def test_unknown_sigmoid_raises_naming_it():
    with pytest.raises(ValueError, match="cubic"):
        tolerance(jnp.array(3.0), 0.0, 1.0, 1.0, sigmoid="cubic")
