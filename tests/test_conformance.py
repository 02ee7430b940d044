"""Conformance: every registered env, bare and under a stack of every combinator, and
every combinator alone on the cheapest env, must jit, vmap, keep its shapes and dtypes,
stay finite, be deterministic per key, and accept new numbers (weights, masses) without
retracing. (The full env x combinator matrix costs a compile per cell: the stack puts
every env through every combinator at the price of one.)"""

from __future__ import annotations

import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
import mjzoo.envs

BATCH, STEPS = 3, 12


def _heavier(model, key):
    return {"body_mass": model.body_mass * jax.random.uniform(key, model.body_mass.shape, minval=0.8, maxval=1.2)}


def _alive(model, state, action, next_state):
    return jnp.float32(1.0)


def _head(obs):
    return obs[:2]


COMBINATORS = {
    "bare": lambda t: t,
    "time_limit": lambda t: mjzoo.with_time_limit(t, 5),
    "auto_reset": lambda t: mjzoo.with_auto_reset(mjzoo.with_time_limit(t, 5)),
    "action_repeat": lambda t: mjzoo.with_action_repeat(t, 2),
    "reward": lambda t: mjzoo.with_reward(t, "alive", _alive, 0.5),
    "observation_noise": lambda t: mjzoo.with_observation_noise(t, 0.1),
    "action_noise": lambda t: mjzoo.with_action_noise(t, 0.1),
    "domain_randomization": lambda t: mjzoo.with_domain_randomization(t, _heavier),
    "divergence_guard": lambda t: mjzoo.with_divergence_guard(t, 1e3),
    "observation": lambda t: mjzoo.with_observation(t, _head),
}
_EACH = tuple(COMBINATORS.values())
COMBINATORS["all"] = lambda t: functools.reduce(lambda task, comb: comb(task), _EACH, t)
CASES = [(env, comb) for env in mjzoo.envs.names() for comb in ("bare", "all")]
CASES += [("pendulum_swingup", comb) for comb in COMBINATORS if comb not in ("bare", "all")]


@functools.cache
def task_for(env: str, comb: str) -> mjzoo.Task:
    return COMBINATORS[comb](mjzoo.envs.make(env))


@functools.cache
def batched_rollout(env: str, comb: str):
    """A jitted, vmapped rollout of BATCH envs for STEPS random actions (one compile per
    case, shared by the tests); `run.traces` counts how often it was traced."""
    nu = task_for(env, comb).action_size

    def policy(obs, key):
        return jax.random.uniform(key, (nu,), minval=-1.0, maxval=1.0)

    @jax.jit
    def run(task, keys):
        traces.append(None)  # runs only while tracing

        def one(key):
            reset_key, run_key = jax.random.split(key)
            state = mjzoo.reset(task, reset_key)
            final, trajectory = mjzoo.rollout(task, policy, state, run_key, STEPS)
            return state, trajectory

        return jax.vmap(one)(keys)

    traces: list = []
    run.traces = traces
    return run


def _keys(seed: int = 0):
    return jax.random.split(jax.random.key(seed), BATCH)


@pytest.mark.parametrize("env,comb", CASES)
def test_conformance(env, comb):
    task = task_for(env, comb)
    run = batched_rollout(env, comb)
    first, trajectory = run(task, _keys())

    # vmap over keys: a leading batch axis everywhere, [BATCH, STEPS] per transition.
    chex.assert_shape(trajectory.next_state.reward, (BATCH, STEPS))
    chex.assert_shape(trajectory.action, (BATCH, STEPS, task.action_size))
    # Shapes and dtypes of the reset state equal those of every later state.
    for reset_leaf, step_leaf in zip(jax.tree.leaves(first), jax.tree.leaves(trajectory.next_state)):
        assert step_leaf.shape == (BATCH, STEPS) + reset_leaf.shape[1:]
        assert step_leaf.dtype == reset_leaf.dtype
    assert jax.tree.structure(first) == jax.tree.structure(trajectory.next_state)
    assert trajectory.next_state.reward.dtype == jnp.float32
    assert trajectory.next_state.terminated.dtype == jnp.bool_
    # Finite observations and rewards.
    assert all(np.isfinite(leaf).all() for leaf in jax.tree.leaves(trajectory.next_state.obs))
    assert np.isfinite(trajectory.next_state.reward).all()
    # The summed reward equals its recorded terms.
    terms = mjzoo.reward_terms(trajectory.next_state)
    np.testing.assert_allclose(sum(terms.values()), trajectory.next_state.reward, rtol=1e-5, atol=1e-5)
    # Different keys give different episodes; the same key the same trajectory.
    assert not np.allclose(trajectory.action[0], trajectory.action[1])
    _, again = run(task, _keys())
    chex.assert_trees_all_equal(trajectory.next_state.obs, again.next_state.obs)
    chex.assert_trees_all_equal(trajectory.next_state.reward, again.next_state.reward)


@pytest.mark.parametrize("env,comb", CASES)
def test_new_numbers_do_not_retrace(env, comb):
    """A task with other weights and a heavier body runs under the same trace."""
    run = batched_rollout(env, comb)
    run(task_for(env, comb), _keys())  # the one trace (cached if already run)
    base = mjzoo.envs.make(env, effort_weight=0.5)
    base = base.replace(model=base.model.replace(body_mass=base.model.body_mass * 1.5))
    changed = COMBINATORS[comb](base)
    _, trajectory = run(changed, _keys())
    assert len(run.traces) == 1
    assert np.isfinite(trajectory.next_state.reward).all()


@pytest.mark.parametrize("env", mjzoo.envs.names())
def test_time_limit_truncates_and_never_terminates(env):
    """With a short limit, an episode is truncated exactly at its last step unless it
    terminated first; truncated and terminated are never both set."""
    limit = 6
    task = mjzoo.envs.make(env, episode_steps=limit)
    nu = task.action_size

    def policy(obs, key):
        return jnp.zeros((nu,))

    @jax.jit
    def run(task, key):
        state = mjzoo.reset(task, key)
        return mjzoo.rollout(task, policy, state, key, limit)[1].next_state

    states = run(task, jax.random.key(1))
    terminated, truncated = np.asarray(states.terminated), np.asarray(states.truncated)
    assert not (terminated & truncated).any()
    assert not truncated[: limit - 1].any()
    assert truncated[limit - 1] or terminated.any()
    np.testing.assert_array_equal(states.info["time_limit"], np.arange(1, limit + 1))
