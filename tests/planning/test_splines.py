"""`mjzoo.planning.splines` against hand-computed numbers: zero-order hold, linear and cubic
(Catmull-Rom Hermite) interpolation, end values held outside the knots, one knot,
`knot_positions`, construction errors, and jit / vmap agreement."""

from __future__ import annotations

import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.planning import splines

# The line y = s sampled at three knots: knots [[0], [2], [4]] at positions [0, 2, 4].
LINE_KNOTS = np.array([[0.0], [2.0], [4.0]], np.float32)
LINE_POSITIONS = np.array([0.0, 2.0, 4.0], np.float32)


def _eval(knots, positions, queries, method):
    knots, positions, queries = jnp.asarray(knots), jnp.asarray(positions), jnp.asarray(queries, jnp.float32)
    return np.asarray(splines.interpolate(knots, positions, queries, method))


# --- zero-order hold ---------------------------------------------------------------------


def test_zero_order_hold_takes_the_last_knot_at_or_before_the_query():
    # Segment [0, 2) holds 0, [2, 4) holds 2, and the last knot itself is 4.
    queries = [0.0, 1.0, 1.99, 2.0, 3.0, 3.99, 4.0]
    np.testing.assert_array_equal(_eval(LINE_KNOTS, LINE_POSITIONS, queries, "zero")[:, 0], [0, 0, 0, 2, 2, 2, 4])


# --- linear -------------------------------------------------------------------------------


def test_linear_interpolates_between_neighbouring_knots():
    # On the line y = s linear interpolation is exact: at 1 -> 1, at 2.5 -> 2.5.
    queries = [0.0, 1.0, 2.0, 2.5, 3.25, 4.0]
    np.testing.assert_allclose(_eval(LINE_KNOTS, LINE_POSITIONS, queries, "linear")[:, 0], queries, rtol=1e-6)


def test_linear_on_a_tent_with_uneven_positions_and_two_controls():
    # Control 0 is a tent 0 -> 1 -> 0 over positions [0, 1, 3]: at 0.5 -> 0.5,
    # at 2 -> 1 + (2 - 1)/(3 - 1) * (0 - 1) = 0.5, at 2.5 -> 0.25.
    # Control 1 is the constant -3.
    knots = np.array([[0.0, -3.0], [1.0, -3.0], [0.0, -3.0]], np.float32)
    out = _eval(knots, [0.0, 1.0, 3.0], [0.5, 1.0, 2.0, 2.5], "linear")
    chex.assert_shape(out, (4, 2))
    np.testing.assert_allclose(out[:, 0], [0.5, 1.0, 0.5, 0.25], rtol=1e-6)
    np.testing.assert_allclose(out[:, 1], -3.0)


# --- cubic --------------------------------------------------------------------------------


def test_cubic_hand_computed_hump():
    # knots [0, 1, 0] at [0, 1, 2]. Catmull-Rom tangents (per step): one-sided first
    # (1 - 0)/1 = 1, centred (0 - 0)/2 = 0, one-sided last (0 - 1)/1 = -1.
    # Hermite at u = 1/2: h00 = 1/2, h10 = 1/8, h01 = 1/2, h11 = -1/8, width 1:
    #   segment 0: 1/2*0 + 1/8*1 + 1/2*1 - 1/8*0    = 0.625
    #   segment 1: 1/2*1 + 1/8*0 + 1/2*0 - 1/8*(-1) = 0.625
    # At u = 1/4 of segment 0: h10 = 9/64, h01 = 5/32: 9/64 + 10/64 = 19/64.
    out = _eval([[0.0], [1.0], [0.0]], [0.0, 1.0, 2.0], [0.25, 0.5, 1.5], "cubic")[:, 0]
    np.testing.assert_allclose(out, [19 / 64, 0.625, 0.625], rtol=1e-6)


@pytest.mark.parametrize("method", splines.METHODS)
def test_every_method_passes_through_every_knot(method):
    knots = np.array([[0.3, -1.0], [2.0, 0.5], [-0.7, 0.25], [1.5, 1.0]], np.float32)
    positions = np.array([0.0, 1.0, 3.5, 6.0], np.float32)
    np.testing.assert_allclose(_eval(knots, positions, positions, method), knots, rtol=1e-6, atol=1e-6)


def test_cubic_reproduces_a_straight_line_exactly():
    # Uneven spacing: the tangents are all the line's slope, so the Hermite pieces are
    # the line itself. y = 2 s - 1 on positions [0, 1, 3, 7].
    positions = np.array([0.0, 1.0, 3.0, 7.0], np.float32)
    queries = np.linspace(0.0, 7.0, 29, dtype=np.float32)
    out = _eval((2 * positions - 1)[:, None], positions, queries, "cubic")[:, 0]
    np.testing.assert_allclose(out, 2 * queries - 1, rtol=1e-5, atol=1e-5)


def test_cubic_is_c1_at_interior_knots():
    # knots [0, 2, 1, 3] at [0, 1, 3, 4]: centred tangents at the interior knots are
    # (1 - 0)/(3 - 0) = 1/3 at s = 1 and (3 - 2)/(4 - 1) = 1/3 at s = 3. One-sided
    # finite differences from the left and from the right both approach it.
    knots = np.array([[0.0], [2.0], [1.0], [3.0]], np.float32)
    positions = np.array([0.0, 1.0, 3.0, 4.0], np.float32)
    h = 1e-2
    for p in (1.0, 3.0):
        left, at, right = _eval(knots, positions, [p - h, p, p + h], "cubic")[:, 0]
        slope_left, slope_right = (at - left) / h, (right - at) / h
        np.testing.assert_allclose([slope_left, slope_right], [1 / 3, 1 / 3], atol=0.05)
        np.testing.assert_allclose(slope_left, slope_right, atol=0.05)
    # Exact one-sided derivatives (autodiff just inside each segment) agree to O(eps).
    deriv = jax.vmap(jax.grad(lambda s: splines.interpolate(knots, positions, s[None], "cubic")[0, 0]))
    np.testing.assert_allclose(deriv(jnp.array([1 - 1e-4, 1 + 1e-4, 3 - 1e-4, 3 + 1e-4])), 1 / 3, atol=1e-3)


@pytest.mark.parametrize("method", splines.METHODS)
def test_end_values_are_held_outside_the_knots(method):
    knots = np.array([[1.0, -2.0], [5.0, 0.0], [-3.0, 4.0]], np.float32)
    out = _eval(knots, [1.0, 2.0, 4.0], [-10.0, 0.0, 1.0, 4.0, 4.5, 100.0], method)
    np.testing.assert_allclose(out[:3], np.broadcast_to(knots[0], (3, 2)), rtol=1e-6)
    np.testing.assert_allclose(out[3:], np.broadcast_to(knots[-1], (3, 2)), rtol=1e-6)


@pytest.mark.parametrize("method", splines.METHODS)
def test_one_knot_is_a_constant(method):
    knots = np.array([[0.5, -0.25]], np.float32)
    out = _eval(knots, [0.0], [-1.0, 0.0, 3.0, 7.5], method)
    chex.assert_shape(out, (4, 2))
    np.testing.assert_array_equal(out, np.broadcast_to(knots, (4, 2)))


# --- knot positions -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "num_knots,horizon_steps,expected",
    [
        (3, 5, [0.0, 2.0, 4.0]),
        (4, 25, [0.0, 8.0, 16.0, 24.0]),
        (1, 10, [0.0]),
        (1, 1, [0.0]),
        (3, 2, [0.0, 0.5, 1.0]),
        (5, 5, [0.0, 1.0, 2.0, 3.0, 4.0]),
    ],
)
def test_knot_positions(num_knots, horizon_steps, expected):
    positions = splines.knot_positions(num_knots, horizon_steps)
    assert positions.dtype == jnp.float32
    np.testing.assert_allclose(positions, expected, rtol=1e-6)


@pytest.mark.parametrize("num_knots,horizon_steps", [(0, 5), (3, 0), (-1, 4)])
def test_knot_positions_rejects_counts_below_one(num_knots, horizon_steps):
    with pytest.raises(ValueError, match="knot_positions"):
        splines.knot_positions(num_knots, horizon_steps)


def test_knot_positions_rejects_several_knots_on_a_one_step_horizon():
    # BUG (library): linspace(0, 0, 2) puts two knots at position 0, which breaks
    # `evaluate`'s strictly-increasing precondition and gives NaN controls (0/0 in the
    # segment fraction) instead of a clear error at construction.
    with pytest.raises(ValueError, match="knot_positions"):
        positions = splines.knot_positions(2, 1)
        out = splines.interpolate(jnp.array([[0.0], [1.0]]), positions, jnp.array([0.0]), "linear")
        assert np.all(np.isfinite(out)), f"positions {positions} give {out}"


# --- errors -------------------------------------------------------------------------------


def test_rejects_an_unknown_method_naming_the_choices():
    with pytest.raises(ValueError, match=r"unknown method 'quadratic'.*zero.*linear.*cubic"):
        splines.interpolate(LINE_KNOTS, LINE_POSITIONS, jnp.zeros(2), "quadratic")


@pytest.mark.parametrize(
    "knots,positions",
    [
        (np.zeros(3), np.zeros(3)),
        (np.zeros((3, 1, 1)), np.zeros(3)),
        (np.zeros((3, 2)), np.zeros(2)),
        (np.zeros((3, 2)), np.zeros((3, 1))),
    ],
)
def test_rejects_mismatched_shapes(knots, positions):
    with pytest.raises(ValueError, match=r"knots must be \[K, nu\] and positions \[K\]"):
        splines.interpolate(knots, positions, jnp.zeros(2), "linear")


# --- jit and vmap -------------------------------------------------------------------------


@pytest.mark.parametrize("method", splines.METHODS)
def test_jit_and_vmap_agree_with_direct_calls(method):
    rng = np.random.default_rng(0)
    knots = jnp.asarray(rng.normal(size=(5, 4, 2)), jnp.float32)  # a batch of 5 plans
    positions = splines.knot_positions(4, 10)
    queries = jnp.linspace(-1.0, 10.0, 23)
    evaluate = functools.partial(splines.interpolate, method=method)
    direct = jnp.stack([evaluate(k, positions, queries) for k in knots])
    jitted = jnp.stack([jax.jit(evaluate)(k, positions, queries) for k in knots])
    vmapped = jax.vmap(evaluate, in_axes=(0, None, None))(knots, positions, queries)
    jit_vmapped = jax.jit(jax.vmap(evaluate, in_axes=(0, None, None)))(knots, positions, queries)
    chex.assert_shape(vmapped, (5, 23, 2))
    chex.assert_trees_all_close(direct, jitted, vmapped, jit_vmapped, rtol=1e-6, atol=1e-6)


def test_vmap_over_queries_and_positions_matches_hand_values():
    # A batch of query sets and a batch of knot placements, each against its hand value:
    # on the line y = s (knots at their own positions) linear interpolation returns s.
    queries = jnp.array([[1.0, 3.0], [0.5, 2.5]])
    per_query_set = jax.vmap(splines.interpolate, in_axes=(None, None, 0, None))
    np.testing.assert_allclose(per_query_set(LINE_KNOTS, LINE_POSITIONS, queries, "linear")[..., 0], queries, rtol=1e-6)
    positions = jnp.array([[0.0, 2.0, 4.0], [0.0, 1.0, 2.0]])  # the second squeezes the line to y = 2 s
    out = jax.jit(jax.vmap(functools.partial(splines.interpolate, method="linear"), in_axes=(None, 0, None)))(
        LINE_KNOTS, positions, jnp.array([0.5, 1.0])
    )
    np.testing.assert_allclose(out[..., 0], [[0.5, 1.0], [1.0, 2.0]], rtol=1e-6)
