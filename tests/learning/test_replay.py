"""`mjzoo.learning.replay`: hand-worked insert sequences (ring wrap-around, more samples
than capacity), keep probabilities 0, 1 and 1/2, sampling only from filled slots and
uniformly, the empty buffer, errors, a vmapped batch of buffers, and no retracing.

Samples carry distinct labels (sample i holds the value i), so the buffer's contents
show which samples were kept and where they went."""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo import learning
from mjzoo.learning import replay

KEY = jax.random.key(0)


def labels(start: int, stop: int) -> jax.Array:
    """Samples [stop - start, 2]: sample i is [i, -i]."""
    i = jnp.arange(start, stop, dtype=jnp.float32)
    return jnp.stack([i, -i], axis=1)


@pytest.fixture(scope="module")
def jit_insert():
    return jax.jit(replay.insert)


@pytest.fixture(scope="module")
def jit_sample():
    return jax.jit(replay.sample, static_argnums=2)


def test_create():
    buffer = replay.create(5, {"x": jnp.zeros(3), "n": jnp.zeros((), jnp.int32)})
    assert buffer.capacity == 5
    chex.assert_trees_all_equal(buffer.data, {"x": np.zeros((5, 3), np.float32), "n": np.zeros(5, np.int32)})
    for field in (buffer.size, buffer.cursor, buffer.inserted):
        assert field.shape == () and field.dtype == jnp.int32 and field == 0


def test_ring_wraps_around_in_fifo_order(jit_insert):
    buffer = replay.create(4, jnp.zeros(2))
    # [0, 1, 2] -> slots 0..2.
    buffer = jit_insert(buffer, labels(0, 3), KEY)
    np.testing.assert_array_equal(buffer.data[:, 0], [0, 1, 2, 0])
    assert (buffer.size, buffer.cursor, buffer.inserted) == (3, 3, 3)
    # [3, 4] -> slot 3, then wraps to slot 0 (overwriting 0, the oldest).
    buffer = jit_insert(buffer, labels(3, 5), KEY)
    np.testing.assert_array_equal(buffer.data, [[4, -4], [1, -1], [2, -2], [3, -3]])
    assert (buffer.size, buffer.cursor, buffer.inserted) == (4, 1, 5)


def test_more_samples_than_capacity_keeps_the_last(jit_insert):
    # 5 samples into 4 slots leave [4, 1, 2, 3], cursor 1. Then [5..14] one by one would go to
    # slots 1, 2, 3, 0, 1, 2, 3, 0, 1, 2: the last write of each slot is 12, 13, 14, 11.
    buffer = jit_insert(replay.create(4, jnp.zeros(2)), labels(0, 5), KEY)
    np.testing.assert_array_equal(buffer.data[:, 0], [4, 1, 2, 3])
    buffer = jit_insert(buffer, labels(5, 15), KEY)
    np.testing.assert_array_equal(buffer.data[:, 0], [12, 13, 14, 11])
    assert (buffer.size, buffer.cursor, buffer.inserted) == (4, 3, 15)


def test_more_kept_than_capacity_with_random_keeping(jit_insert):
    # The keep decisions depend on the key and the batch only: a roomy buffer shows every
    # kept sample; a small one must hold the last 8 of them, the last one at cursor - 1.
    samples, key = labels(0, 100), jax.random.key(3)
    roomy = jit_insert(replay.create(200, jnp.zeros(2)), samples, key, 0.5)
    small = jit_insert(replay.insert(replay.create(8, jnp.zeros(2)), labels(-3, 0), KEY), samples, key, 0.5)
    kept = np.asarray(roomy.data[: roomy.size, 0])
    assert roomy.inserted == kept.size and kept.size > 8 and np.all(np.diff(kept) > 0)
    ring = np.roll(np.asarray(small.data[:, 0]), -int(small.cursor))  # oldest first
    np.testing.assert_array_equal(ring, kept[-8:])
    assert (small.size, small.cursor, small.inserted) == (8, (3 + kept.size) % 8, 3 + kept.size)


def test_keep_probability_zero_and_one(jit_insert):
    start = jit_insert(replay.create(6, jnp.zeros(2)), labels(1, 4), KEY)
    none = jit_insert(start, labels(10, 20), jax.random.key(1), 0.0)
    chex.assert_trees_all_equal(none, start)
    everything = jit_insert(start, labels(10, 13), jax.random.key(1), 1.0)
    np.testing.assert_array_equal(everything.data[:, 0], [1, 2, 3, 10, 11, 12])
    assert (everything.size, everything.cursor, everything.inserted) == (6, 0, 6)


def test_keep_probability_half_keeps_about_half_in_order(jit_insert):
    buffer = jit_insert(replay.create(20_000, jnp.zeros(2)), labels(0, 10_000), jax.random.key(7), 0.5)
    # Binomial(10000, 1/2): mean 5000, std 50; 4 std either side.
    assert 4800 <= int(buffer.inserted) <= 5200 and buffer.size == buffer.inserted == buffer.cursor
    kept = np.asarray(buffer.data[: buffer.size])
    assert np.all(np.diff(kept[:, 0]) > 0), "kept samples must stay in their order"
    np.testing.assert_array_equal(kept[:, 1], -kept[:, 0])  # whole samples, not mixed rows
    np.testing.assert_array_equal(buffer.data[buffer.size :], 0.0)


def test_sample_only_from_filled_slots_and_uniformly(jit_insert, jit_sample):
    buffer = jit_insert(replay.create(10, jnp.zeros(2)), labels(1, 4), KEY)  # slots 0..2 hold 1, 2, 3
    drawn = np.asarray(jit_sample(buffer, jax.random.key(5), 1000))
    values, counts = np.unique(drawn[:, 0], return_counts=True)
    np.testing.assert_array_equal(values, [1, 2, 3])
    # Each ~ Binomial(1000, 1/3): mean 333, std 15; 5 std either side.
    assert np.all((counts > 258) & (counts < 408)), counts
    np.testing.assert_array_equal(drawn[:, 1], -drawn[:, 0])


def test_sample_pytree_and_empty_buffer(jit_sample):
    buffer = replay.create(4, {"a": jnp.zeros(3), "b": jnp.zeros((), jnp.int32)})
    empty = jit_sample(buffer, KEY, 5)
    chex.assert_trees_all_equal(empty, {"a": np.zeros((5, 3), np.float32), "b": np.zeros(5, np.int32)})
    one = replay.insert(buffer, {"a": jnp.ones((1, 3)), "b": jnp.array([7])}, KEY)
    drawn = jit_sample(one, KEY, 5)
    chex.assert_trees_all_equal(drawn, {"a": np.ones((5, 3), np.float32), "b": np.full(5, 7, np.int32)})


def test_vmapped_batch_of_buffers():
    buffers = jax.vmap(lambda _: replay.create(8, jnp.zeros(2)))(jnp.arange(3))
    keys = jax.random.split(KEY, 3)
    samples = jnp.stack([labels(0, 6), labels(10, 16), labels(20, 26)])
    buffers = jax.jit(jax.vmap(replay.insert))(buffers, samples, keys, jnp.array([0.0, 1.0, 0.5]))
    assert buffers.size.tolist()[:2] == [0, 6] and 0 <= buffers.size[2] <= 6
    np.testing.assert_array_equal(buffers.data[1, :6, 0], np.arange(10, 16))
    drawn = jax.jit(jax.vmap(replay.sample, in_axes=(0, 0, None)), static_argnums=2)(buffers, keys, 50)
    assert drawn.shape == (3, 50, 2)
    np.testing.assert_array_equal(drawn[0], 0.0)  # the empty buffer gives zeros
    assert set(np.asarray(drawn[1, :, 0]).tolist()) <= set(range(10, 16))
    if buffers.size[2] > 0:
        assert set(np.asarray(drawn[2, :, 0]).tolist()) <= set(np.asarray(buffers.data[2, : buffers.size[2], 0]))


def test_no_retracing():
    insert = jax.jit(chex.assert_max_traces(replay.insert, n=1))
    sample = jax.jit(chex.assert_max_traces(replay.sample, n=1), static_argnums=2)
    buffer = replay.create(5, jnp.zeros(2))
    for i, p in enumerate([1.0, 0.5, 0.0, 0.25]):  # a new probability, key, data, fill each time
        buffer = insert(buffer, labels(3 * i, 3 * i + 3), jax.random.key(i), jnp.float32(p))
        sample(buffer, jax.random.key(i), 4)


def test_errors():
    buffer = replay.create(4, jnp.zeros(2))
    with pytest.raises(ValueError, match="capacity=0 must be an int >= 1"):
        replay.create(0, jnp.zeros(2))
    with pytest.raises(ValueError, match=r"samples of shape \(3, 5\) must be \[B, \*\(2,\)\]"):
        replay.insert(buffer, jnp.zeros((3, 5)), KEY)
    with pytest.raises(ValueError, match=r"samples of shape \(2,\)"):
        replay.insert(buffer, jnp.zeros(2), KEY)
    with pytest.raises(ValueError, match="samples have structure"):
        replay.insert(buffer, {"x": jnp.zeros((3, 2))}, KEY)
    with pytest.raises(ValueError, match="keep_probability=1.5 must be in"):
        replay.insert(buffer, jnp.zeros((3, 2)), KEY, 1.5)
    with pytest.raises(ValueError, match="num=0 must be an int >= 1"):
        replay.sample(buffer, KEY, 0)


# --- rows of parallel env steps, n-step returns ------------------------------------


def steps(rewards, terminated, truncated):
    """A buffer's rows [T, E]: obs [t, e] labels each step, next_obs is obs + 100."""
    t_count, e_count = np.shape(rewards)
    obs = np.stack(np.meshgrid(np.arange(t_count), np.arange(e_count), indexing="ij"), -1).astype(np.float32)
    return learning.Transitions(
        obs=jnp.asarray(obs),
        action=jnp.asarray(obs[..., :1]),
        extras=(),
        reward=jnp.asarray(rewards, jnp.float32),
        terminated=jnp.asarray(terminated, bool),
        truncated=jnp.asarray(truncated, bool),
        start=jnp.zeros((t_count, e_count), bool),
        next_obs=jnp.asarray(obs + 100.0),
    )


def filled(capacity, rows):
    buffer = replay.create(capacity, jax.tree.map(lambda x: x[0], rows))
    return replay.insert(buffer, rows, KEY)


def by_label(batch):
    """{(t, e): (reward, discount, next t)} of every sampled pair."""
    obs, next_obs = np.asarray(batch.obs), np.asarray(batch.next_obs)
    return {
        (int(o[0]), int(o[1])): (float(r), float(d), int(n[0]) - 100, int(n[1]) - 100)
        for o, r, d, n in zip(obs, np.asarray(batch.reward), np.asarray(batch.discount), next_obs)
    }


def test_sample_n_step_stops_at_episode_ends_and_the_newest_row():
    """Env 0: rewards 1, 2, 4, 8, truncated at step 1; env 1: rewards 1, terminated at
    step 2; n = 3, discount 1/2, 4 rows recorded of 5."""
    rows = steps(
        [[1, 1], [2, 1], [4, 1], [8, 1]],
        terminated=[[0, 0], [0, 0], [0, 1], [0, 0]],
        truncated=[[0, 0], [1, 0], [0, 0], [0, 0]],
    )
    sample = jax.jit(replay.sample_n_step, static_argnums=(2, 3))
    got = by_label(sample(filled(5, rows), KEY, 256, 3, 0.5))
    expected = {
        (0, 0): (1 + 0.5 * 2, 0.25, 1, 0),  # up to the truncation, which bootstraps
        (1, 0): (2.0, 0.5, 1, 0),
        (2, 0): (4 + 0.5 * 8, 0.25, 3, 0),  # the newest row ends the window
        (3, 0): (8.0, 0.5, 3, 0),
        (0, 1): (1.75, 0.0, 2, 1),  # terminated: no bootstrap
        (1, 1): (1.5, 0.0, 2, 1),
        (2, 1): (1.0, 0.0, 2, 1),
        (3, 1): (1.0, 0.5, 3, 1),
    }
    assert got == expected  # every pair drawn (256 draws of 8), each as computed by hand
    action = sample(filled(5, rows), KEY, 16, 3, 0.5)
    np.testing.assert_array_equal(action.action[:, 0], action.obs[:, 0])


def test_sample_n_step_across_the_ring_wrap_and_under_vmap():
    """Capacity 3, 4 rows (rewards 1, 2, 4, 8): row 0 is overwritten by row 3, and a
    window from row 1 runs on through slot 0."""
    rows = steps([[1], [2], [4], [8]], terminated=np.zeros((4, 1)), truncated=np.zeros((4, 1)))
    buffer = filled(3, rows)
    got = by_label(replay.sample_n_step(buffer, KEY, 64, 3, 0.5))
    assert got == {(1, 0): (6.0, 0.125, 3, 0), (2, 0): (8.0, 0.25, 3, 0), (3, 0): (8.0, 0.5, 3, 0)}
    both = jax.tree.map(lambda x: jnp.stack([x, x]), buffer)
    batch = jax.vmap(replay.sample_n_step, in_axes=(0, None, None, None, 0))(both, KEY, 8, 1, jnp.array([0.5, 0.9]))
    np.testing.assert_allclose(batch.discount, [[0.5] * 8, [0.9] * 8])
    np.testing.assert_allclose(batch.reward[0], batch.reward[1])
    with pytest.raises(ValueError, match="n=0"):
        replay.sample_n_step(buffer, KEY, 8, 0, 0.5)
