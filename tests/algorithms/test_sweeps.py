"""Sweeps are one program: `jax.vmap` of `ppo.train` over hyperparameters (and seeds)
gives each separate run's parameters, traced once. On a block on a rail: that holds of
any task, and its programs compile in a fraction of cart-pole's time."""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.algorithms import ppo
from tests.harness.test_distributed import block_task

CONFIG = ppo.Config(num_envs=8, unroll_length=8, num_minibatches=2, num_epochs=1, total_steps=8 * 8 * 3)
RATES = (1e-4, 3e-4, 1e-3, 3e-3)
# Batched and lone runs sum in other orders, and Adam's normalized steps carry a rounding
# difference on, growing with the rate (a few of 4096 weights: ~1e-5 at 1e-2, 2e-4 at
# 3e-2, after 3 updates); the rates' own differences are over 5x the tolerance (checked),
# so the comparison still tells the runs apart.
TOLERANCE = dict(rtol=1e-3, atol=1e-4)


def max_difference(a, b) -> float:
    return max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


@pytest.fixture(scope="module")
def block():
    return block_task()


def batched(hyperparams: ppo.Hyperparams, n: int, **swept) -> ppo.Hyperparams:
    """`hyperparams` with every leaf [n]: the `swept` ones as given, the rest repeated."""
    return jax.tree.map(lambda x: jnp.full((n,), x, jnp.float32), hyperparams).replace(
        **{k: jnp.asarray(v, jnp.float32) for k, v in swept.items()}
    )


@pytest.fixture(scope="module")
def separate(block):
    """Each (rate, seed) run on its own: one program, since the numbers are not static."""
    run = jax.jit(ppo.train, static_argnums=0)
    return lambda rate, key: run(CONFIG, block, ppo.Hyperparams(learning_rate=rate), key)[0].params


def test_a_sweep_over_learning_rates_and_seeds_is_one_program_of_the_separate_runs(block, separate):
    """4 rates x 2 seeds, a vmap over seeds inside one over rates (docs/sweeps.md's grid):
    one trace, and each of the 8 runs equals its run alone."""

    @chex.assert_max_traces(n=1)
    def train(hyperparams, key):
        return ppo.train(CONFIG, block, hyperparams, key)

    keys = jax.random.split(jax.random.key(2), 2)
    grid = jax.jit(jax.vmap(jax.vmap(train, in_axes=(None, 0)), in_axes=(0, None)))  # [rate, seed]
    states, metrics = grid(batched(ppo.Hyperparams(), len(RATES), learning_rate=RATES), keys)
    chex.assert_shape(metrics["loss/total"], (len(RATES), len(keys), CONFIG.num_updates))
    np.testing.assert_allclose(states.hyperparams.learning_rate[:, 0], np.float32(RATES))
    for i, rate in enumerate(RATES):
        runs = [jax.tree.map(lambda x, i=i, j=j: x[i, j], states.params) for j in range(len(keys))]
        for run, key in zip(runs, keys):
            chex.assert_trees_all_close(run, separate(rate, key), **TOLERANCE)
        assert max_difference(*runs) > 1e-3  # each seed made a run of its own
    rows = [jax.tree.map(lambda x, i=i: x[i, 0], states.params) for i in range(len(RATES))]
    for one, other in zip(rows, rows[1:]):  # and each rate
        assert max_difference(one, other) > 5 * TOLERANCE["atol"]
    grid(batched(ppo.Hyperparams(), len(RATES), learning_rate=RATES[::-1]), keys[::-1])  # no retrace
