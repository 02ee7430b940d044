"""The learner loop of PPO-like algorithms: several epochs over a batch of collected
data, each in shuffled minibatches, one gradient step (or any update) per minibatch.

    carry, metrics = learn(step, (params, opt_state), data, key,
                           num_epochs=4, num_minibatches=8)

Minibatches are either independent samples (time and env axes flattened and shuffled
together) or, with ``sequences=True``, whole env sequences (envs shuffled, time kept in
order), which a recurrent policy needs to rebuild its carry. A policy that records the
carry each step started from (`collection`'s extras) finds a sequence's initial carry
at time 0 of its minibatch.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec

from mjzoo import batching
from mjzoo import checks

__all__ = ["learn"]

Array = jax.Array
PyTree = Any


def learn(
    step: Callable[[PyTree, PyTree], tuple[PyTree, dict[str, Array]]],
    carry: PyTree,
    data: PyTree,
    key: Array,
    *,
    num_epochs: int,
    num_minibatches: int,
    sequences: bool = False,
    split_over_devices: bool = False,
) -> tuple[PyTree, dict[str, Array]]:
    """Runs ``step(carry, minibatch) -> (carry, metrics)`` over `num_epochs` epochs of
    `num_minibatches` shuffled minibatches of `data`, with `lax.scan` (both static).

    Args:
      step: one update; `metrics` a dict of scalars.
      carry: what the updates change (parameters, optimizer state, ...).
      data: pytree whose leaves are [T, N, ...] (time, env).
      key: PRNG key for the shuffles (a new order every epoch).
      num_epochs: passes over the data.
      num_minibatches: minibatches per epoch; it must divide T * N (samples) or N
        (sequences).
      sequences: False: each minibatch holds T * N / num_minibatches samples, leaves
        [T * N / m, ...]. True: N / num_minibatches whole env sequences, leaves
        [T, N / m, ...].
      split_over_devices: under a mesh with axis `mjzoo.batching.AXIS` (the training
        harness sets one while it traces), split each minibatch's samples over its
        devices, so that each computes its share of every step and XLA sums the
        gradients. Otherwise XLA gathers the shuffled batch onto every device, and each
        computes every step whole. Either way the result is the same, up to the order
        of float sums.

    Returns:
      (carry, metrics): the carry after every step, and each metric's mean over all
      num_epochs * num_minibatches steps.
    """
    num_epochs = checks.integer("learn", "num_epochs", num_epochs)
    m = checks.integer("learn", "num_minibatches", num_minibatches)
    leaves = jax.tree.leaves(data)
    if not leaves or any(jnp.ndim(x) < 2 or jnp.shape(x)[:2] != jnp.shape(leaves[0])[:2] for x in leaves):
        raise ValueError(
            f"learn: every leaf of data must be [T, N, ...] with the same T and N; got shapes "
            f"{[jnp.shape(x) for x in leaves]}"
        )
    t, n = jnp.shape(leaves[0])[:2]
    size = n if sequences else t * n
    if size % m:
        what = "N (the number of env sequences)" if sequences else "T * N (the number of samples)"
        raise ValueError(f"learn: num_minibatches={m} must divide {what} = {size}")

    def minibatches(key: Array) -> PyTree:
        """[m, ...] stacked minibatches in a new random order."""
        order = jax.random.permutation(key, size).reshape(m, -1)
        if sequences:
            return jax.tree.map(lambda x: jnp.moveaxis(x[:, order], 1, 0), data)  # [m, T, N / m, ...]
        return jax.tree.map(lambda x: x.reshape((t * n,) + x.shape[2:])[order], data)

    def epoch(carry: PyTree, key: Array):
        batches = minibatches(key)
        if split_over_devices:
            batches = _split_over_devices(batches, 2 if sequences else 1)
        return jax.lax.scan(step, carry, batches)

    carry, metrics = jax.lax.scan(epoch, carry, jax.random.split(key, num_epochs))
    return carry, jax.tree.map(jnp.mean, metrics)


def _split_over_devices(batches: PyTree, axis: int) -> PyTree:
    """Stacked minibatches with each minibatch's samples (`axis`) split over the devices of
    the env mesh (`mjzoo.batching.AXIS`); without such a mesh, or where the samples do not
    split evenly, as given."""
    devices = batching.mesh_devices()
    if devices == 1 or any(jnp.shape(x)[axis] % devices for x in jax.tree.leaves(batches)):
        return batches
    spec = PartitionSpec(*(None,) * axis, batching.AXIS)
    sharding = NamedSharding(jax.sharding.get_abstract_mesh(), spec)
    return jax.tree.map(lambda x: jax.lax.with_sharding_constraint(x, sharding), batches)
