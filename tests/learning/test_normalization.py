"""`mjzoo.learning.normalization`: running moments against numpy on the concatenated data,
independence from how the data is chunked, hand-checked normalization, jit."""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.learning.normalization import RunningStats
from mjzoo.learning.normalization import init_stats
from mjzoo.learning.normalization import normalize
from mjzoo.learning.normalization import update_stats

EXAMPLE = {"joints": jnp.zeros(3), "image": jnp.zeros((2, 2))}


def _batch(rng, lead):
    # Offset, unequal-scale data: an offset of 50 with spread ~3 stresses float32 if the
    # merge were done through raw sums of squares.
    return {
        "joints": (50.0 + 3.0 * rng.normal(size=lead + (3,)) * np.array([1.0, 0.1, 5.0])).astype(np.float32),
        "image": rng.uniform(-1.0, 2.0, size=lead + (2, 2)).astype(np.float32),
    }


def test_init_stats():
    stats = init_stats(EXAMPLE)
    chex.assert_trees_all_equal(stats.mean, {"joints": np.zeros(3, np.float32), "image": np.zeros((2, 2), np.float32)})
    chex.assert_trees_all_equal(stats.var, {"joints": np.ones(3, np.float32), "image": np.ones((2, 2), np.float32)})
    assert stats.count.shape == () and stats.count.dtype == jnp.float32 and stats.count == 0.0


def test_matches_numpy_after_several_updates():
    rng = np.random.default_rng(0)
    # Chunks of different layouts: [T, B, ...], [N, ...] and a single observation.
    chunks = [(_batch(rng, (5, 4)), 2), (_batch(rng, (7,)), 1), (_batch(rng, ()), 0), (_batch(rng, (3, 2)), 2)]
    stats = init_stats(EXAMPLE)
    for batch, num_batch_dims in chunks:
        stats = update_stats(stats, batch, num_batch_dims)
    for name, size in (("joints", (3,)), ("image", (2, 2))):
        data = np.concatenate([np.reshape(b[name], (-1,) + size) for b, _ in chunks]).astype(np.float64)
        np.testing.assert_allclose(stats.mean[name], data.mean(0), rtol=1e-5)
        np.testing.assert_allclose(stats.var[name], data.var(0), rtol=2e-4)
    assert stats.count == 20 + 7 + 1 + 6


def test_first_update_takes_the_batch_moments():
    batch = {"joints": jnp.array([[1.0, 2.0, 3.0], [3.0, 2.0, -1.0]]), "image": jnp.ones((2, 2, 2))}
    stats = update_stats(init_stats(EXAMPLE), batch, 1)
    # joints: mean [2, 2, 1], population var [1, 0, 4]; image is constant: var 0.
    np.testing.assert_allclose(stats.mean["joints"], [2.0, 2.0, 1.0])
    np.testing.assert_allclose(stats.var["joints"], [1.0, 0.0, 4.0])
    np.testing.assert_array_equal(stats.var["image"], 0.0)
    assert stats.count == 2.0


def test_split_update_equals_whole_update():
    rng = np.random.default_rng(1)
    start = update_stats(init_stats(EXAMPLE), _batch(rng, (9,)), 1)  # not the initial stats
    whole = _batch(rng, (6, 4))
    at_once = update_stats(start, whole, 2)
    first, second = jax.tree.map(lambda x: x[:2], whole), jax.tree.map(lambda x: x[2:], whole)
    halves = update_stats(update_stats(start, first, 2), second, 2)
    # The same data flattened differently: 24 observations with one batch dim.
    flat = update_stats(start, jax.tree.map(lambda x: x.reshape((24,) + x.shape[2:]), whole), 1)
    chex.assert_trees_all_close(at_once, halves, rtol=1e-5)
    chex.assert_trees_all_close(at_once, flat, rtol=1e-5)
    assert at_once.count == 9 + 24


def test_normalize_hand_checked():
    stats = RunningStats(mean=jnp.array([1.0, -2.0, 0.0]), var=jnp.array([4.0, 0.25, 1.0]), count=jnp.float32(10))
    # (5 - 1) / 2 = 2;  (-2.5 + 2) / 0.5 = -1;  (30 - 0) / 1 = 30 -> clipped to 5.
    np.testing.assert_allclose(normalize(stats, jnp.array([5.0, -2.5, 30.0])), [2.0, -1.0, 5.0], rtol=1e-6)
    # Clip 1.5 on both sides: (-9 - 1) / 2 = -5 -> -1.5.
    np.testing.assert_allclose(normalize(stats, jnp.array([-9.0, -2.5, 1.0]), clip=1.5), [-1.5, -1.0, 1.0], rtol=1e-6)
    # Any leading batch dims broadcast against the statistics.
    batched = normalize(stats, jnp.broadcast_to(jnp.array([5.0, -2.5, 30.0]), (2, 4, 3)))
    chex.assert_shape(batched, (2, 4, 3))
    np.testing.assert_allclose(batched, np.broadcast_to([2.0, -1.0, 5.0], (2, 4, 3)), rtol=1e-6)


def test_normalize_constant_feature_is_finite_and_zero_at_the_mean():
    stats = update_stats(init_stats(jnp.zeros(2)), jnp.array([[3.0, 1.0], [3.0, 2.0]]), 1)  # feature 0: var 0
    out = normalize(stats, jnp.array([[3.0, 1.5], [3.5, 1.5]]))
    np.testing.assert_allclose(out[0], [0.0, 0.0], atol=1e-6)
    assert out[1, 0] == 5.0  # 0.5 / sqrt(1e-8) is huge: clipped


def test_normalized_data_has_zero_mean_unit_variance():
    rng = np.random.default_rng(2)
    data = _batch(rng, (64, 8))
    stats = update_stats(init_stats(EXAMPLE), data, 2)
    out = normalize(stats, data, clip=100.0)
    for leaf in jax.tree.leaves(out):
        np.testing.assert_allclose(leaf.mean((0, 1)), 0.0, atol=1e-4)
        np.testing.assert_allclose(leaf.var((0, 1)), 1.0, rtol=1e-3)


def test_jit_and_scan_over_chunks():
    rng = np.random.default_rng(3)
    chunks = _batch(rng, (4, 5, 3))  # 4 chunks of [5, 3]
    stats = init_stats(EXAMPLE)

    @jax.jit
    def run(stats, chunks):
        def body(s, chunk):
            return update_stats(s, chunk, 2), None

        stats, _ = jax.lax.scan(body, stats, chunks)
        return stats, normalize(stats, jax.tree.map(lambda x: x[0], chunks))

    jit_stats, jit_out = run(stats, chunks)
    eager = update_stats(stats, chunks, 3)
    chex.assert_trees_all_close(jit_stats, eager, rtol=1e-5)
    chex.assert_trees_all_close(jit_out, normalize(eager, jax.tree.map(lambda x: x[0], chunks)), rtol=1e-4, atol=1e-5)
    assert isinstance(jit_stats, RunningStats)


def test_integer_observations_are_averaged_in_float():
    stats = update_stats(init_stats(jnp.zeros(2, jnp.int32)), jnp.array([[1, 2], [2, 2]], jnp.int32), 1)
    np.testing.assert_allclose(stats.mean, [1.5, 2.0])
    np.testing.assert_allclose(stats.var, [0.25, 0.0])
    assert stats.mean.dtype == jnp.float32


def test_clear_errors():
    stats = init_stats(EXAMPLE)
    with pytest.raises(ValueError, match=r"\['joints'\].*batch dims followed by the observation shape \(3,\)"):
        update_stats(stats, {"joints": jnp.zeros((4, 2)), "image": jnp.zeros((4, 2, 2))}, 1)
    with pytest.raises(ValueError, match="batch dims"):
        update_stats(stats, {"joints": jnp.zeros((4, 3)), "image": jnp.zeros((5, 2, 2))}, 1)
    with pytest.raises(ValueError, match="structure"):
        update_stats(stats, {"joints": jnp.zeros((4, 3))}, 1)
    with pytest.raises(ValueError, match="empty"):
        update_stats(stats, {"joints": jnp.zeros((0, 3)), "image": jnp.zeros((0, 2, 2))}, 1)
    with pytest.raises(ValueError, match="num_batch_dims"):
        update_stats(stats, EXAMPLE, -1)
    with pytest.raises(ValueError, match=r"does not end in the statistics' shape \(2, 2\)"):
        normalize(stats, {"joints": jnp.zeros(3), "image": jnp.zeros((2, 3))})
