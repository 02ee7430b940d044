"""`mjzoo.learning.value_normalization`: running statistics of value targets, normalize /
denormalize by hand, and PopArt keeping a small MLP's denormalized outputs unchanged
when the statistics move; under jit and vmap."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.learning.networks import mlp
from mjzoo.learning.normalization import RunningStats
from mjzoo.learning.value_normalization import denormalize_values
from mjzoo.learning.value_normalization import init_value_stats
from mjzoo.learning.value_normalization import normalize_values
from mjzoo.learning.value_normalization import popart_rescale
from mjzoo.learning.value_normalization import update_value_stats


def _stats(mean, var):
    return RunningStats(mean=jnp.float32(mean), var=jnp.float32(var), count=jnp.float32(10))


def test_update_value_stats_hand_computed():
    # Returns [[1, 3], [5, 7]]: mean 4, population var (9 + 1 + 1 + 9) / 4 = 5.
    stats = update_value_stats(init_value_stats(), jnp.array([[1.0, 3.0], [5.0, 7.0]]))
    np.testing.assert_allclose([stats.mean, stats.var, stats.count], [4.0, 5.0, 4.0], rtol=1e-6)
    # Then [10, 10]: n = 6, mean (16 + 20) / 6 = 6; var = mean of squares - mean^2
    # = (1 + 9 + 25 + 49 + 100 + 100) / 6 - 36 = 284 / 6 - 36 = 11.333...
    stats = update_value_stats(stats, jnp.array([10.0, 10.0]))
    np.testing.assert_allclose([stats.mean, stats.var, stats.count], [6.0, 284 / 6 - 36, 6.0], rtol=1e-5)


def test_update_value_stats_rejects_non_scalar_stats():
    stats = RunningStats(mean=jnp.zeros(2), var=jnp.ones(2), count=jnp.float32(0))
    with pytest.raises(ValueError, match="update_value_stats: the statistics must be scalar"):
        update_value_stats(stats, jnp.ones((3, 2)))


def test_normalize_and_denormalize_hand_computed():
    stats = _stats(2.0, 16.0)  # sigma = sqrt(16 + 1e-8) ~ 4
    # (10 - 2) / 4 = 2;  (-2 - 2) / 4 = -1;  (42 - 2) / 4 = 10 (no clipping).
    np.testing.assert_allclose(normalize_values(stats, jnp.array([10.0, -2.0, 42.0])), [2.0, -1.0, 10.0], rtol=1e-6)
    # 0.5 * 4 + 2 = 4;  -3 * 4 + 2 = -10.
    np.testing.assert_allclose(denormalize_values(stats, jnp.array([[0.5], [-3.0]])), [[4.0], [-10.0]], rtol=1e-6)
    # The initial statistics are the identity (up to the 1e-8 in sigma).
    x = jnp.array([-3.0, 0.0, 123.0])
    np.testing.assert_allclose(normalize_values(init_value_stats(), x), x, rtol=1e-6)


def test_normalize_jit_and_vmap():
    # Three statistics, three values: (6 - 0) / 1 = 6;  (6 - 2) / 2 = 2;  (6 - 6) / 3 = 0.
    stats = RunningStats(mean=jnp.array([0.0, 2.0, 6.0]), var=jnp.array([1.0, 4.0, 9.0]), count=jnp.full(3, 5.0))
    out = jax.jit(jax.vmap(normalize_values, (0, None)))(stats, jnp.float32(6.0))
    np.testing.assert_allclose(out, [6.0, 2.0, 0.0], rtol=1e-6)
    back = jax.jit(jax.vmap(denormalize_values))(stats, out)
    np.testing.assert_allclose(back, [6.0] * 3, rtol=1e-6)


def test_popart_hand_computed():
    # sigma 2 -> sigma' 4, mu 1 -> mu' 3:  W' = W * 2 / 4;  b' = (2 * 0.5 + 1 - 3) / 4 = -0.25.
    layer = {"kernel": jnp.array([[1.0], [-2.0]]), "bias": jnp.array([0.5])}
    new = popart_rescale(layer, _stats(1.0, 4.0), _stats(3.0, 16.0))
    np.testing.assert_allclose(new["kernel"], [[0.5], [-1.0]], rtol=1e-6)
    np.testing.assert_allclose(new["bias"], [-0.25], rtol=1e-6)
    # Check at h = [1, 1]: before 2 * (1 - 2 + 0.5) + 1 = 0; after 4 * (0.5 - 1 - 0.25) + 3 = 0.


def _value_net_and_inputs():
    net = mlp(1, (8, 8))
    params = net.init(jax.random.key(0), jnp.zeros(3))
    # Make the head's bias non-zero, so a wrong bias formula cannot pass.
    params = [*params[:-1], {**params[-1], "bias": jnp.array([0.7])}]
    x = jax.random.normal(jax.random.key(1), (16, 3))
    return net, params, x


def test_popart_keeps_an_mlps_denormalized_outputs():
    net, params, x = _value_net_and_inputs()
    old = update_value_stats(init_value_stats(), jnp.array([1.0, 2.0, 4.0]))
    new = update_value_stats(old, jnp.array([50.0, 80.0, -30.0, 200.0]))  # mean and spread move a lot
    assert abs(float(new.mean - old.mean)) > 10 and float(new.var / old.var) > 100
    before = denormalize_values(old, net.apply(params, x))

    rescaled = [*params[:-1], jax.jit(popart_rescale)(params[-1], old, new)]
    after = denormalize_values(new, net.apply(rescaled, x))
    np.testing.assert_allclose(after, before, rtol=1e-5, atol=1e-5)
    # Without the rescale the outputs move: the check can fail.
    moved = denormalize_values(new, net.apply(params, x))
    assert np.max(np.abs(moved - before)) > 1.0
    # Only the last layer changes.
    assert all(a is b for a, b in zip(rescaled[:-1], params[:-1]))


def test_popart_under_vmap():
    """Three statistic moves at once, each keeping the outputs of the same network."""
    net, params, x = _value_net_and_inputs()
    old = RunningStats(mean=jnp.array([0.0, 5.0, -2.0]), var=jnp.array([1.0, 9.0, 0.25]), count=jnp.full(3, 4.0))
    new = RunningStats(mean=jnp.array([3.0, 5.0, 10.0]), var=jnp.array([4.0, 1.0, 100.0]), count=jnp.full(3, 8.0))
    layers = jax.jit(jax.vmap(popart_rescale, (None, 0, 0)))(params[-1], old, new)
    assert layers["kernel"].shape == (3, 8, 1) and layers["bias"].shape == (3, 1)
    for i in range(3):
        pick = lambda s, i=i: jax.tree.map(lambda leaf: leaf[i], s)
        before = denormalize_values(pick(old), net.apply(params, x))
        after = denormalize_values(pick(new), net.apply([*params[:-1], pick(layers)], x))
        np.testing.assert_allclose(after, before, rtol=1e-5, atol=1e-5)


def test_popart_rejects_a_layer_without_kernel():
    with pytest.raises(ValueError, match=r"popart_rescale: output_layer must hold 'kernel' and 'bias'.*\['kernel'\]"):
        popart_rescale({"bias": jnp.zeros(1)}, init_value_stats(), init_value_stats())
