"""Rollout costs respect the task's `terminate` (`mjzoo.planning.masked_cost`): no reward
after a rollout's first terminated step, its terminal value dropped, and the planner's
`termination_cost` added once; against hand sums, in MJX and in C MuJoCo alike."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.tree_util import Partial

import mjzoo
from mjzoo import envs
from mjzoo import planning
from mjzoo.algorithms import mppi
from mjzoo.planning import native

# --- masked_cost, by hand ------------------------------------------------------------------

REWARDS = jnp.array([1.0, 2.0, 3.0, 4.0, 5.0])


@pytest.mark.parametrize(
    "terminated, value, cost, expected",
    [
        ([0, 0, 0, 0, 0], 10.0, 7.0, -(15.0 + 10.0)),  # never ends: every reward and the value
        ([0, 0, 1, 0, 0], 10.0, 7.0, -(1.0 + 2.0 + 3.0) + 7.0),  # the terminal step's reward counts
        ([0, 0, 1, 0, 1], 10.0, 0.0, -(1.0 + 2.0 + 3.0)),  # the cost is paid once, alive stays off
        ([1, 1, 1, 1, 1], 10.0, 7.0, -1.0 + 7.0),
    ],
)
def test_masked_cost_stops_at_the_first_termination(terminated, value, cost, expected):
    terminated = jnp.asarray(terminated, bool)
    np.testing.assert_allclose(jax.jit(planning.masked_cost)(REWARDS, terminated, value, cost), expected)


def test_masked_cost_vmaps_and_keeps_nan_after_a_termination_out():
    rewards = jnp.stack([REWARDS, REWARDS.at[3:].set(jnp.nan)])  # physics diverged after the fall
    terminated = jnp.array([[0, 0, 0, 0, 0], [0, 1, 0, 0, 0]], bool)
    costs = jax.vmap(planning.masked_cost, in_axes=(0, 0, None, None))(rewards, terminated, jnp.nan, 1.0)
    np.testing.assert_allclose(costs[1], -3.0 + 1.0)
    assert np.isnan(costs[0])  # no termination: the NaN value is the cost, as before


# --- a task that terminates at a known step, planned in MJX and in C ------------------------

H = 5
CTRL_DT = 0.02  # point_mass's control step


def _clock_reward(model, state, action, next_state):
    """2, 4, 6, ... at control steps 1, 2, 3, ...: which steps counted shows in the sum."""
    return {"clock": 100.0 * next_state.data.time}


def _terminates_at(time, model, state):
    """Terminated only at `time` (s): a mask that is not cumulative would count on after it."""
    return jnp.abs(state.data.time - time) < 0.25 * CTRL_DT, jnp.zeros((), bool)


@functools.cache
def _task(end_time: float) -> mjzoo.Task:
    task = envs.make("point_mass", iterations=1, ls_iterations=1, episode_steps=10**9)
    return task.replace(reward=Partial(_clock_reward), terminate=Partial(_terminates_at, jnp.float32(end_time)))


@functools.cache
def _sample_around():
    return jax.jit(planning.sample_around, static_argnums=0)


@pytest.mark.parametrize("backend", ["mjx", "native"])
def test_a_rollout_returns_the_hand_sum_up_to_its_termination(backend):
    config = planning.SamplingConfig(num_samples=2, horizon_steps=H, num_knots=2)
    costs = {}
    for end_time, termination_cost in [(3 * CTRL_DT, 0.0), (3 * CTRL_DT, 5.0), (1.0, 5.0)]:
        task = _task(end_time)  # the end time is a leaf: one compile for all three
        plan_task = native.wrap(task) if backend == "native" else task
        env_state = mjzoo.reset(task, jax.random.key(0))
        assert float(env_state.data.time) == 0.0
        hyperparams = mppi.Hyperparams(termination_cost=termination_cost)
        state = planning.initial_state(config, plan_task, hyperparams)
        costs[end_time, termination_cost] = _sample_around()(config, plan_task, state, env_state, jax.random.key(1))[2]
    # Terminated at step 3: rewards 2 + 4 + 6 (not 8 + 10 after it), and the cost once.
    np.testing.assert_allclose(costs[3 * CTRL_DT, 0.0], [-12.0, -12.0], rtol=1e-4)
    np.testing.assert_allclose(costs[3 * CTRL_DT, 5.0], [-7.0, -7.0], rtol=1e-4)
    # Never terminated within the horizon: the whole return, no termination cost.
    np.testing.assert_allclose(costs[1.0, 5.0], [-30.0, -30.0], rtol=1e-4)


def test_the_termination_cost_is_a_checked_hyperparameter():
    _, hyperparams = planning.configure(mppi, {"termination_cost": 50})
    assert hyperparams.termination_cost == 50.0 and mppi.Hyperparams().termination_cost == 0.0
    with pytest.raises(ValueError, match="termination_cost"):
        mppi.Hyperparams(termination_cost=float("inf"))
