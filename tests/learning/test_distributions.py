"""`mjzoo.learning.distributions`: the squashed Gaussian's density against distrax and against a
change of variables by hand, normalization of the density, stability where tanh
saturates, sampling statistics, the entropy estimate, jit / vmap."""

from __future__ import annotations

import math

import chex
import distrax
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from mjzoo.learning.distributions import entropy
from mjzoo.learning.distributions import log_prob
from mjzoo.learning.distributions import mode
from mjzoo.learning.distributions import sample
from mjzoo.learning.distributions import split_params

HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def test_split_params_hand_checked():
    # softplus(0) = ln 2; softplus(-100) ~ 4e-44 -> scale = min_std; softplus(3) = 3 + ln(1 + e^-3).
    loc, scale = split_params(jnp.array([0.5, -1.0, 2.0, 0.0, -100.0, 3.0]))
    np.testing.assert_allclose(loc, [0.5, -1.0, 2.0])
    np.testing.assert_allclose(scale, [math.log(2.0) + 1e-3, 1e-3, 3.0 + math.log1p(math.exp(-3.0)) + 1e-3], rtol=1e-6)
    loc, scale = split_params(jnp.zeros((5, 3, 4)), min_std=0.1)
    chex.assert_shape([loc, scale], (5, 3, 2))
    np.testing.assert_allclose(scale, math.log(2.0) + 0.1, rtol=1e-6)
    with pytest.raises(ValueError, match="even size"):
        split_params(jnp.zeros((2, 3)))


def test_log_prob_1d_change_of_variables_by_hand():
    # u = 0.7, loc = 0.3, scale = 0.5:
    #   log N(u) = -0.5 ((0.7 - 0.3) / 0.5)^2 - ln 0.5 - 0.5 ln(2 pi) = -0.32 + ln 2 - 0.9189385
    #   log p(a) = log N(u) - ln(1 - tanh(0.7)^2)
    expected = -0.32 + math.log(2.0) - HALF_LOG_2PI - math.log(1.0 - math.tanh(0.7) ** 2)
    out = log_prob(jnp.array([0.3]), jnp.array([0.5]), jnp.array([0.7]))
    np.testing.assert_allclose(out, expected, rtol=1e-6)
    assert out.shape == ()


def test_log_prob_matches_distrax_transformed():
    rng = np.random.default_rng(0)
    loc = jnp.asarray(rng.normal(size=(8, 3)), jnp.float32)
    scale = jnp.asarray(rng.uniform(0.2, 1.5, size=(8, 3)), jnp.float32)
    raw = jnp.asarray(rng.uniform(-2.0, 2.0, size=(8, 3)), jnp.float32)  # moderate: atanh is accurate
    squashed = distrax.Transformed(distrax.MultivariateNormalDiag(loc, scale), distrax.Block(distrax.Tanh(), 1))
    np.testing.assert_allclose(log_prob(loc, scale, raw), squashed.log_prob(jnp.tanh(raw)), rtol=1e-4, atol=1e-4)


def test_density_integrates_to_one_and_matches_sample_frequencies():
    loc, scale = jnp.array([0.4]), jnp.array([0.6])
    a = np.linspace(-0.99999, 0.99999, 40001)  # |u| < 6.1: beyond, N(0.4, 0.6) has no mass in float32
    raw = jnp.arctanh(jnp.asarray(a, jnp.float32))[:, None]
    density = np.exp(np.asarray(log_prob(jnp.broadcast_to(loc, raw.shape), jnp.broadcast_to(scale, raw.shape), raw)))
    np.testing.assert_allclose(np.trapezoid(density, a), 1.0, atol=2e-3)
    # P(0 < a < 0.5) from the density vs from 20000 samples (binomial std ~0.0035).
    inside = (a > 0.0) & (a < 0.5)
    p_density = np.trapezoid(density[inside], a[inside])
    actions, _ = sample(jnp.broadcast_to(loc, (20000, 1)), jnp.broadcast_to(scale, (20000, 1)), jax.random.key(1))
    p_samples = float(jnp.mean((actions > 0.0) & (actions < 0.5)))
    np.testing.assert_allclose(p_samples, p_density, atol=0.015)


def test_log_prob_stable_where_tanh_saturates():
    # u = 20 in float32: tanh(u) == 1, so log(1 - tanh(u)^2) = log 0 = -inf. The stable
    # form: ln 4 - 40 - 2 softplus(-40) = -38.6137056. With loc 0, scale 1:
    #   log p = -0.5 * 400 - 0.5 ln(2 pi) + 38.6137056 = -162.3052333
    with np.errstate(divide="ignore"):
        assert np.isneginf(np.log(1.0 - np.tanh(np.float32(20.0)) ** 2))
    for u in (20.0, -20.0):
        out = log_prob(jnp.zeros(1), jnp.ones(1), jnp.array([u]))
        np.testing.assert_allclose(out, -200.0 - HALF_LOG_2PI - (math.log(4.0) - 40.0), rtol=1e-6)
    grads = jax.grad(log_prob, argnums=(0, 1, 2))(jnp.zeros(2), jnp.ones(2), jnp.array([20.0, -20.0]))
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in grads)
    # d/du [log N(u) - log(1 - tanh^2 u)] = -(u - loc)/scale^2 + 2 tanh(u) -> -20 + 2, 20 - 2.
    np.testing.assert_allclose(grads[2], [-18.0, 18.0], rtol=1e-5)
    ent = entropy(jnp.zeros(2), jnp.ones(2), jnp.array([20.0, -20.0]))  # u = +-20
    assert bool(jnp.isfinite(ent))


def test_sample_statistics_and_determinism():
    loc = jnp.array([0.5, -1.0, 0.0])
    scale = jnp.array([0.3, 1.0, 2.0])
    n = 20000
    key = jax.random.key(2)
    actions, raw = sample(jnp.broadcast_to(loc, (n, 3)), jnp.broadcast_to(scale, (n, 3)), key)
    chex.assert_shape([actions, raw], (n, 3))
    np.testing.assert_array_equal(actions, jnp.tanh(raw))
    # Mean within 4 standard errors (scale / sqrt(n)); std within 3%.
    np.testing.assert_array_less(np.abs(raw.mean(0) - loc), 4.0 * scale / math.sqrt(n))
    np.testing.assert_allclose(raw.std(0), scale, rtol=0.03)
    assert bool(jnp.all(jnp.abs(actions) <= 1.0))
    # tanh is monotone: the median action is tanh(loc) = mode(loc).
    np.testing.assert_allclose(np.median(actions, 0), mode(loc), atol=0.02)
    # Same key, same draw; a different key, a different one.
    chex.assert_trees_all_equal(sample(loc, scale, key), sample(loc, scale, key))
    assert not np.allclose(sample(loc, scale, key)[1], sample(loc, scale, jax.random.key(3))[1])


def test_entropy_hand_checked_and_unbiased():
    # At u = loc + scale * noise = 0 the Jacobian term is ln(1 - 0) = 0: the Gaussian entropy
    # 0.5 ln(2 pi e) + ln scale per dimension, here scales 1 and 2.
    gaussian = 2 * (0.5 * math.log(2 * math.pi * math.e)) + math.log(2.0)
    np.testing.assert_allclose(entropy(jnp.zeros(2), jnp.array([1.0, 2.0]), jnp.zeros(2)), gaussian, rtol=1e-6)
    # At u = [1, 0] (noise [1, 0]) the estimate adds ln(1 - tanh(1)^2) = ln sech(1)^2.
    np.testing.assert_allclose(
        entropy(jnp.zeros(2), jnp.array([1.0, 2.0]), jnp.array([1.0, 0.0])),
        gaussian + math.log(1.0 - math.tanh(1.0) ** 2),
        rtol=1e-6,
    )
    # Averaged over samples it estimates the same entropy as -log_prob does.
    loc, scale = jnp.array([0.3, -0.8]), jnp.array([0.5, 1.2])
    n = 20000
    _, raw = sample(jnp.broadcast_to(loc, (n, 2)), jnp.broadcast_to(scale, (n, 2)), jax.random.key(4))
    est = entropy(jnp.broadcast_to(loc, (n, 2)), jnp.broadcast_to(scale, (n, 2)), (raw - loc) / scale)
    nll = -log_prob(jnp.broadcast_to(loc, (n, 2)), jnp.broadcast_to(scale, (n, 2)), raw)
    np.testing.assert_allclose(est.mean(), nll.mean(), atol=0.03)
    # Squashing into (-1, 1) can only lower the entropy: the Jacobian term is <= 0.
    assert float(est.mean()) < gaussian_entropy(scale)


def test_entropy_gradient_is_the_true_entropys_gradient():
    # The squashed entropy by Gauss-Hermite quadrature, one dimension:
    # H = 0.5 ln(2 pi e) + ln s + E_z[ln(1 - tanh(m + s z)^2)], z ~ N(0, 1).
    z, w = np.polynomial.hermite_e.hermegauss(80)
    w = w / w.sum()

    def log_sech2(u):  # ln(1 - tanh(u)^2), finite in the tails
        return 2 * (math.log(2) - u - np.logaddexp(0, -2 * u))

    def true_entropy(m, s):
        return 0.5 * math.log(2 * math.pi * math.e) + math.log(s) + np.sum(w * log_sech2(m + s * z))

    m, s, h = 0.7, 1.3, 1e-4
    expected = [
        (true_entropy(m + h, s) - true_entropy(m - h, s)) / (2 * h),
        (true_entropy(m, s + h) - true_entropy(m, s - h)) / (2 * h),
    ]
    # Averaged over fresh noise, the estimate's gradient is the true gradient; both
    # parts are far from zero here (squashing pulls loc towards 0 and caps the scale).
    n = 100_000
    loc, scale = jnp.full((n, 1), m), jnp.full((n, 1), s)
    noise = jax.random.normal(jax.random.key(6), (n, 1))
    grad = jax.grad(lambda p: jnp.mean(entropy(p[0], p[1], noise)))((loc, scale))
    got = [float(jnp.sum(grad[0])), float(jnp.sum(grad[1]))]
    assert abs(expected[0]) > 0.3 and abs(expected[1]) > 0.1, expected
    np.testing.assert_allclose(got, expected, rtol=0.03)


def test_maximizing_the_entropy_estimate_settles_at_the_squashed_maximum():
    """Adam on the estimate with fresh noise per step (PPO's use): the scale settles
    where the squashed entropy peaks (~0.87 at loc 0, by the quadrature above) and loc
    stays at 0, instead of growing without bound."""
    params = {"loc": jnp.zeros(1), "scale": jnp.zeros(1)}  # the network output's two halves
    optimizer = optax.adam(1e-2)

    def negative(p, key):
        loc, scale = (jnp.broadcast_to(x, (4096, 1)) for x in split_params(jnp.concatenate([p["loc"], p["scale"]])))
        return -jnp.mean(entropy(loc, scale, jax.random.normal(key, (4096, 1))))

    @jax.jit
    def step(carry, key):
        p, state = carry
        updates, state = optimizer.update(jax.grad(negative)(p, key), state)
        return (optax.apply_updates(p, updates), state), None

    (params, _), _ = jax.lax.scan(step, (params, optimizer.init(params)), jax.random.split(jax.random.key(7), 1500))
    loc, scale = (float(x[0]) for x in split_params(jnp.concatenate([params["loc"], params["scale"]])))
    assert abs(loc) < 0.05 and 0.8 < scale < 0.95, (loc, scale)


def gaussian_entropy(scale):
    return float(jnp.sum(0.5 * jnp.log(2 * jnp.pi * jnp.e) + jnp.log(scale)))


def test_jit_and_vmap():
    rng = np.random.default_rng(5)
    output = jnp.asarray(rng.normal(size=(6, 4)), jnp.float32)
    raw = jnp.asarray(rng.normal(size=(6, 2)), jnp.float32)

    def everything(output, raw, key):
        loc, scale = split_params(output)
        action, sampled_raw = sample(loc, scale, key)
        return action, log_prob(loc, scale, raw), entropy(loc, scale, raw), mode(loc), log_prob(loc, scale, sampled_raw)

    keys = jax.random.split(jax.random.key(6), 6)
    vmapped = jax.jit(jax.vmap(everything))(output, raw, keys)
    chex.assert_shape(vmapped[1:3], (6,))
    for i in range(6):
        row = everything(output[i], raw[i], keys[i])
        chex.assert_trees_all_close(jax.tree.map(lambda x, i=i: x[i], vmapped), row, rtol=1e-5, atol=1e-6)
    # The batched call (no vmap) agrees on the key-free outputs.
    loc, scale = split_params(output)
    np.testing.assert_allclose(vmapped[1], log_prob(loc, scale, raw), rtol=1e-6)
    np.testing.assert_allclose(vmapped[2], entropy(loc, scale, raw), rtol=1e-6)
