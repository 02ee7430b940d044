"""Predictive sampling: keep the best of N perturbed plans.

    config = predictive_sampling.Config(num_samples=64, horizon_steps=25)
    state = predictive_sampling.init(config, task)
    plan = jax.jit(predictive_sampling.plan, static_argnums=0)
    state, controls = plan(config, task, state, env_state, key)   # controls: [H, nu]

At every replan, with the nominal knots mu shifted to the current time:
    theta_0 = mu,   theta_i = clip(mu + sigma * eps_i),  eps_i ~ N(0, I),  i = 1..N-1
    mu' = theta_{i*},  i* = argmin_i J(theta_i)
where J is the rollout cost (`mjzoo.planning`). Keeping mu as a sample makes the plan's
cost non-increasing along a deterministic receding horizon.
Defaults: 128 samples, 25 planning steps, 4 cubic knots, sigma = 0.3 x half ctrl range.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from mjzoo import planning
from mjzoo.planning import Ensemble, PlannerState
from mjzoo.types import State, Task

__all__ = ["Config", "init", "plan"]


@dataclasses.dataclass(frozen=True)
class Config(planning.SamplingConfig):
    """Predictive sampling has only the shared sampling settings (`planning.SamplingConfig`)."""


def init(config: Config, task: Task | Ensemble, knots: jax.Array | None = None) -> PlannerState:
    """A zero plan, or the warm-start `knots` [K, nu] a task supplies."""
    return planning.initial_state(config, task, knots)


def plan(
    config: Config, task: Task | Ensemble, state: PlannerState, env_state: State, key: jax.Array
) -> tuple[PlannerState, jax.Array]:
    """One replan from `env_state`: returns the new planner state and the plan's [H, nu] controls."""
    sample_key, rollout_key = jax.random.split(key)
    state = planning.shift(config, state, env_state.data.time)
    low, high = planning.control_limits(task)
    samples = planning.sample_knots(sample_key, state.knots, state.std, config.num_samples, low, high)
    costs, dt = planning.sample_costs(config, task, env_state, samples, rollout_key)
    best = jnp.argmin(costs)
    state = state.replace(knots=samples[best], cost=costs[best], dt=dt)
    return state, planning.controls(config, state.knots, low, high)
