"""`mjzoo.learning.learn`: every sample (or env sequence) in exactly one minibatch per
epoch, in a new order each epoch, time order kept within sequences; metrics averaged."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo import learning

T, N = 4, 6
DATA = {"t": jnp.broadcast_to(jnp.arange(T)[:, None], (T, N)), "env": jnp.broadcast_to(jnp.arange(N), (T, N))}


def count_samples(counts, minibatch):
    """Counts how often each (t, env) sample is seen; reports the minibatch's size."""
    counts = counts.at[minibatch["t"], minibatch["env"]].add(1)
    return counts, {"size": jnp.float32(minibatch["t"].size)}


@pytest.mark.parametrize("sequences", [False, True])
def test_every_sample_once_per_epoch(sequences):
    run = jax.jit(
        lambda key: learning.learn(
            count_samples, jnp.zeros((T, N), jnp.int32), DATA, key, num_epochs=3, num_minibatches=3, sequences=sequences
        )
    )
    counts, metrics = run(jax.random.key(0))
    np.testing.assert_array_equal(counts, 3)
    assert float(metrics["size"]) == T * N / 3


def test_sequences_keep_time_in_order_and_samples_are_shuffled():
    def look(carry, minibatch):
        in_order = jnp.all(minibatch["t"] == jnp.arange(T)[:, None]) & jnp.all(minibatch["env"] == minibatch["env"][0])
        return carry & in_order, {}

    ok, _ = learning.learn(
        look, jnp.bool_(True), DATA, jax.random.key(0), num_epochs=2, num_minibatches=2, sequences=True
    )
    assert bool(ok)

    def order(carry, minibatch):  # minibatches of one sample: records the sample ids in order
        i, ids = carry
        return (i + 1, ids.at[i].set(minibatch["t"][0] * N + minibatch["env"][0])), {}

    def run(key):
        return learning.learn(order, (0, jnp.zeros(T * N, jnp.int32)), DATA, key, num_epochs=1, num_minibatches=T * N)

    first, second = (np.asarray(run(jax.random.key(k))[0][1]) for k in (1, 2))
    np.testing.assert_array_equal(np.sort(first), np.arange(T * N))
    assert not np.array_equal(first, np.arange(T * N)) and not np.array_equal(first, second)


def test_minibatches_must_divide_the_data():
    with pytest.raises(ValueError, match=r"num_minibatches=4 must divide N \(the number of env sequences\) = 6"):
        learning.learn(
            count_samples,
            jnp.zeros((T, N), jnp.int32),
            DATA,
            jax.random.key(0),
            num_epochs=1,
            num_minibatches=4,
            sequences=True,
        )
    with pytest.raises(ValueError, match=r"\[T, N, ...\] with the same T and N"):
        learning.learn(
            count_samples,
            (),
            {"a": jnp.zeros((T, N)), "b": jnp.zeros((T, 2))},
            jax.random.key(0),
            num_epochs=1,
            num_minibatches=1,
        )
