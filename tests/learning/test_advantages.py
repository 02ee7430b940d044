"""`mjzoo.learning.advantages.gae` against hand-computed numbers, its two limits (Monte-Carlo
returns at lambda = discount = 1, TD errors at lambda = 0), a plain-python reference on
random data, and jit / vmap / batch-axis agreement."""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.learning.advantages import gae

F, T_ = False, True

REWARDS = np.array([1.0, 2.0, 3.0, 4.0], np.float32)
VALUES = np.array([0.5, 1.0, 1.5, 2.0], np.float32)


def _call(next_values, terminated, truncated, discount=0.9, gae_lambda=0.5):
    return gae(
        jnp.asarray(REWARDS),
        jnp.asarray(VALUES),
        jnp.asarray(next_values, jnp.float32),
        jnp.asarray(terminated),
        jnp.asarray(truncated),
        discount,
        gae_lambda,
    )


# discount = 0.9, lambda = 0.5, so discount * lambda = 0.45 in every case below.
# next_values[1] = 10 is the value of the FINAL observation of the episode that ends at
# t = 1 (the reset observation's value is values[2] = 1.5); next_values[2] = 2 = values[3].
#
# Termination at t = 1, next_values = [1, 10, 2, 5]:
#   delta_0 = 1 + 0.9*1 - 0.5   = 1.4
#   delta_1 = 2 + 0     - 1.0   = 1.0      (terminal: no bootstrap from 10)
#   delta_2 = 3 + 0.9*2 - 1.5   = 3.3
#   delta_3 = 4 + 0.9*5 - 2.0   = 6.5      (window end: bootstraps)
#   A_3 = 6.5
#   A_2 = 3.3 + 0.45*6.5 = 6.225
#   A_1 = 1.0                              (episode ends: A_2 does not flow back)
#   A_0 = 1.4 + 0.45*1.0 = 1.85
#   R = A + V = [2.35, 2.0, 7.725, 8.5]
#
# Truncation at t = 1, same next_values: only delta_1 and what it feeds change.
#   delta_1 = 2 + 0.9*10 - 1.0  = 10.0     (truncation bootstraps from the final obs)
#   A_1 = 10.0, A_0 = 1.4 + 0.45*10 = 5.9
#   R = [6.4, 11.0, 7.725, 8.5]
#
# Termination at t = 1 AND truncation at t = 2, next_values = [1, 10, 3, 5]:
#   delta_2 = 3 + 0.9*3 - 1.5   = 4.2      (truncated: bootstraps from 3, its final obs)
#   A_3 = 6.5, A_2 = 4.2 (cut), A_1 = 1.0 (cut), A_0 = 1.85
#   R = [2.35, 2.0, 5.7, 8.5]
HAND = [
    ([1, 10, 2, 5], [F, T_, F, F], [F, F, F, F], [1.85, 1.0, 6.225, 6.5], [2.35, 2.0, 7.725, 8.5]),
    ([1, 10, 2, 5], [F, F, F, F], [F, T_, F, F], [5.9, 10.0, 6.225, 6.5], [6.4, 11.0, 7.725, 8.5]),
    ([1, 10, 3, 5], [F, T_, F, F], [F, F, T_, F], [1.85, 1.0, 4.2, 6.5], [2.35, 2.0, 5.7, 8.5]),
]


@pytest.mark.parametrize("next_values,terminated,truncated,advantages,returns", HAND)
def test_hand_computed(next_values, terminated, truncated, advantages, returns):
    adv, ret = _call(next_values, terminated, truncated)
    np.testing.assert_allclose(adv, advantages, rtol=1e-6)
    np.testing.assert_allclose(ret, returns, rtol=1e-6)
    assert adv.dtype == jnp.float32 and ret.dtype == jnp.float32


def test_monte_carlo_returns_at_lambda_one_discount_one():
    # Episodes [0, 1] and [2, 3], both terminated: the returns are the reward sums to
    # the episode's end, [1+2, 2, 3+4, 4], whatever the values are. Values inside an
    # episode are consistent (next_values[t] = values[t+1]) so they telescope away.
    values = np.array([7.0, -3.0, 0.25, 11.0], np.float32)
    next_values = np.array([-3.0, 42.0, 11.0, -8.0], np.float32)  # 42, -8: final obs, unused
    terminated = jnp.array([F, T_, F, T_])
    truncated = jnp.zeros(4, bool)
    adv, ret = gae(jnp.asarray(REWARDS), jnp.asarray(values), jnp.asarray(next_values), terminated, truncated, 1.0, 1.0)
    np.testing.assert_allclose(ret, [3.0, 2.0, 7.0, 4.0], rtol=1e-6)
    np.testing.assert_allclose(adv, np.array([3.0, 2.0, 7.0, 4.0]) - values, rtol=1e-6)


def test_lambda_zero_gives_one_step_td_errors():
    rng = np.random.default_rng(0)
    r, v, nv = (rng.normal(size=6).astype(np.float32) for _ in range(3))
    term = rng.random(6) < 0.3
    trunc = (rng.random(6) < 0.3) & ~term
    adv, ret = gae(*map(jnp.asarray, (r, v, nv, term, trunc)), 0.97, 0.0)
    np.testing.assert_allclose(adv, r + 0.97 * (1.0 - term) * nv - v, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(ret, r + 0.97 * (1.0 - term) * nv, rtol=1e-5, atol=1e-6)


def _reference(r, v, nv, term, trunc, discount, lam):
    """Plain-python GAE over the time axis of 1-D arrays, in float64."""
    adv, next_adv = np.zeros(len(r)), 0.0
    for t in reversed(range(len(r))):
        delta = r[t] + discount * (0.0 if term[t] else nv[t]) - v[t]
        next_adv = delta + discount * lam * (0.0 if (term[t] or trunc[t]) else next_adv)
        adv[t] = next_adv
    return adv


def _random_batch(seed, shape):
    rng = np.random.default_rng(seed)
    r, v, nv = (rng.normal(size=shape).astype(np.float32) for _ in range(3))
    term = rng.random(shape) < 0.15
    trunc = (rng.random(shape) < 0.15) & ~term
    return r, v, nv, term, trunc


def test_time_by_batch_equals_per_column_reference():
    r, v, nv, term, trunc = _random_batch(1, (12, 5))
    adv, ret = gae(*map(jnp.asarray, (r, v, nv, term, trunc)), 0.99, 0.95)
    chex.assert_shape([adv, ret], (12, 5))
    for b in range(5):
        expected = _reference(r[:, b], v[:, b], nv[:, b], term[:, b], trunc[:, b], 0.99, 0.95)
        np.testing.assert_allclose(adv[:, b], expected, rtol=1e-5, atol=1e-5)
        col_adv, _ = gae(*(jnp.asarray(x[:, b]) for x in (r, v, nv, term, trunc)), 0.99, 0.95)
        np.testing.assert_allclose(adv[:, b], col_adv, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(ret, adv + v, rtol=1e-6)


def test_jit_with_traced_hyperparameters_and_vmap_over_batch_axis():
    r, v, nv, term, trunc = map(jnp.asarray, _random_batch(2, (8, 3)))
    direct = gae(r, v, nv, term, trunc, 0.99, 0.9)
    jitted = jax.jit(gae)(r, v, nv, term, trunc, jnp.float32(0.99), jnp.float32(0.9))
    # vmap over the batch axis (axis 1) of unbatched [T] calls.
    vmapped = jax.vmap(gae, in_axes=(1, 1, 1, 1, 1, None, None), out_axes=1)(r, v, nv, term, trunc, 0.99, 0.9)
    chex.assert_trees_all_close(direct, jitted, rtol=1e-6)
    chex.assert_trees_all_close(direct, vmapped, rtol=1e-6)


def test_vmap_over_hyperparameters():
    # Traced discount: a sweep of discounts in one call, each equal to its own call.
    r, v, nv, term, trunc = map(jnp.asarray, _random_batch(3, (6,)))
    discounts = jnp.array([0.0, 0.5, 0.99])
    adv, _ = jax.vmap(lambda d: gae(r, v, nv, term, trunc, d, 0.9))(discounts)
    for i, d in enumerate([0.0, 0.5, 0.99]):
        expected = _reference(*map(np.asarray, (r, v, nv, term, trunc)), d, 0.9)
        np.testing.assert_allclose(adv[i], expected, rtol=1e-5, atol=1e-6)


def test_rejects_float_flags_and_mismatched_shapes():
    x = jnp.zeros(4)
    with pytest.raises(AssertionError, match="bool"):
        gae(x, x, x, jnp.zeros(4), jnp.zeros(4, bool), 0.9, 0.9)
    with pytest.raises(AssertionError):
        gae(x, jnp.zeros(5), x, jnp.zeros(4, bool), jnp.zeros(4, bool), 0.9, 0.9)
