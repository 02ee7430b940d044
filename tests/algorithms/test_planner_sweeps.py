"""Planner sweeps are one program: a planner's numbers (`Hyperparams`: MPPI's temperature,
the noise scale, CEM's std floor and explore fraction) live in its state, so `jax.vmap`
over a batch of them runs B planners side by side, traced once, and each gives, to float
tolerance, the plan it gives alone. On the point mass, two replans from `init` (the
second warm-started from the first), with one config and one key for every member."""

from __future__ import annotations

import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
from mjzoo import envs
from mjzoo import planning
from mjzoo.algorithms import cem
from mjzoo.algorithms import mppi
from mjzoo.algorithms import predictive_sampling

H, K = 5, 3
CONFIGS = {
    mppi: mppi.Config(num_samples=8, horizon_steps=H, num_knots=K),
    cem: cem.Config(num_samples=8, horizon_steps=H, num_knots=K, num_elites=2),
    predictive_sampling: predictive_sampling.Config(num_samples=8, horizon_steps=H, num_knots=K),
}
# Each sweep: a planner, the field swept and its 4 values (the other fields at defaults).
SWEEPS = {
    "mppi temperature": (mppi, "temperature", [0.01, 0.1, 1.0, 10.0]),
    "mppi noise_scale": (mppi, "noise_scale", [0.05, 0.2, 0.5, 1.0]),
    "cem sigma_min": (cem, "sigma_min", [0.0, 0.2, 0.4, 0.8]),
    "cem explore_fraction": (cem, "explore_fraction", [0.0, 0.25, 0.5, 0.75]),  # 0, 2, 4, 6 of 8 samples
    "predictive_sampling noise_scale": (predictive_sampling, "noise_scale", [0.05, 0.2, 0.5, 1.0]),
}


@functools.cache
def _task():
    # One solver iteration and one line-search step: a third less compile time.
    return envs.make("point_mass", iterations=1, ls_iterations=1)


def _two_replans(planner):
    """(hyperparams, env_state, key) -> [H, nu] controls of `planner`'s second replan
    from `init` (both from `env_state`); a new function each call, for its trace count."""
    config, task = CONFIGS[planner], _task()

    def two_replans(hyperparams, env_state, key):
        state = planner.init(config, task, hyperparams)
        state, _ = planner.plan(config, task, state, env_state, jax.random.fold_in(key, 0))
        return planner.plan(config, task, state, env_state, jax.random.fold_in(key, 1))[1]

    return two_replans


# chex counts the traces of a function by its source and the call stack it was wrapped
# from: the swept and the separate runs wrap it in helpers of their own.
def _swept(planner):
    """One jit of a vmap over a batch of hyperparameters, traced at most once."""
    return jax.jit(jax.vmap(chex.assert_max_traces(_two_replans(planner), n=1), (0, None, None)))


def _alone(planner):
    """One jit for one member at a time, traced at most once for every member."""
    return jax.jit(chex.assert_max_traces(_two_replans(planner), n=1))


def _stack(trees):
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *trees)


@pytest.mark.parametrize("sweep", list(SWEEPS))
def test_a_vmapped_sweep_is_one_program_with_each_members_own_plan(sweep):
    planner, field, values = SWEEPS[sweep]
    members = [planner.Hyperparams(**{field: v}) for v in values]
    env_state, key = mjzoo.reset(_task(), jax.random.key(0)), jax.random.key(1)

    chex.clear_trace_counter()  # each parametrized case counts its own traces
    # The sweep: one jit of a vmap over a [4] batch of hyperparameters, traced once.
    together = _swept(planner)(_stack(members), env_state, key)
    chex.assert_shape(together, (len(values), H, 2))

    # Alone: the same jitted function for every member, also traced once (the numbers
    # are arguments, not constants: a new temperature does not compile again).
    alone_fn = _alone(planner)
    alone = np.stack([alone_fn(member, env_state, key) for member in members])

    np.testing.assert_allclose(together, alone, rtol=1e-5, atol=1e-5)
    # The field matters (two explore fractions may still pick the same elites).
    assert len({np.asarray(a).tobytes() for a in alone}) > 1, "the swept field changed nothing"


def test_a_traced_cvar_alpha_gives_the_static_tail():
    # Costs over 5 models of 3 samples; alpha 0.28 * 5 = 1.4 -> the 2 worst models.
    costs = jnp.asarray(np.random.default_rng(0).normal(size=(5, 3)), jnp.float32)
    alphas = [0.01, 0.2, 0.28, 0.5, 0.6, 1.0]
    traced = jax.jit(jax.vmap(lambda a: planning.aggregate(costs, "cvar", a)))(jnp.asarray(alphas))
    static = np.stack([planning.aggregate(costs, "cvar", a) for a in alphas])
    np.testing.assert_allclose(traced, static, rtol=1e-6)


def test_init_under_vmap_holds_each_members_numbers():
    hyperparams = _stack([mppi.Hyperparams(temperature=t, noise_scale=s) for t, s in [(0.1, 0.2), (1.0, 0.4)]])
    states = jax.vmap(lambda h: mppi.init(CONFIGS[mppi], _task(), h))(hyperparams)
    np.testing.assert_allclose(states.hyperparams.temperature, [0.1, 1.0], rtol=1e-6)
    np.testing.assert_allclose(states.std[:, 0, 0], [0.2, 0.4], rtol=1e-6)  # ctrlrange [-1, 1]
    chex.assert_shape(states.knots, (2, K, 2))
