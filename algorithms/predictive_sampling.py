"""Predictive sampling: keep the best of N perturbed plans.

    config = predictive_sampling.Config(num_samples=64, horizon_steps=25)
    state = predictive_sampling.init(config, task, predictive_sampling.Hyperparams(noise_scale=0.2))
    plan = jax.jit(predictive_sampling.plan, static_argnums=0)
    state, controls = plan(config, task, state, env_state, key)   # controls: [H, nu]

At every replan, with the nominal knots mu shifted to the current time:
    theta_0 = mu,   theta_i = clip(mu + sigma * eps_i),  eps_i ~ N(0, I),  i = 1..N-1
    mu' = theta_{i*},  i* = argmin_i J(theta_i)
where J is a rollout's cost (`mjzoo.planning.masked_cost`): minus its return up to and
including its first terminated step (nothing after it), plus the `termination_cost`
hyperparameter (default 0) if a step terminated. Keeping mu as a sample makes the
plan's cost non-increasing along a deterministic receding horizon. sigma (the noise scale) is a
hyperparameter kept in the planner state: vmapping over states sweeps it.
Defaults: 128 samples, 25 planning steps, 4 cubic knots, sigma = 0.3 x half ctrl range.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from mjzoo import planning
from mjzoo.planning import Ensemble
from mjzoo.planning import PlannerState
from mjzoo.planning import TerminalValue
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Config", "Hyperparams", "init", "plan"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config(planning.SamplingConfig):
    """Predictive sampling has only the shared sampling structure (`planning.SamplingConfig`)."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams(planning.SamplingHyperparams):
    """Predictive sampling has only the shared numbers (`planning.SamplingHyperparams`)."""


def init(
    config: Config, task: Task | Ensemble, hyperparams: Hyperparams | None = None, *, knots: jax.Array | None = None
) -> PlannerState:
    """A zero plan, or the warm-start `knots` [K, nu], holding `hyperparams` (default
    `Hyperparams()`)."""
    hyperparams = Hyperparams() if hyperparams is None else hyperparams
    planning.sampling.check_hyperparams(hyperparams, Hyperparams)
    return planning.initial_state(config, task, hyperparams, knots)


def plan(
    config: Config,
    task: Task | Ensemble,
    state: PlannerState,
    env_state: State,
    key: jax.Array,
    terminal_value: TerminalValue | None = None,
) -> tuple[PlannerState, jax.Array]:
    """One replan from `env_state`: returns the new planner state and the plan's [H, nu]
    controls. `terminal_value` (model, state) -> [] values each rollout's final state
    (`planning.as_terminal_value`: a Partial whose weights are leaves, not recompiled)."""
    hyperparams = state.hyperparams
    std = planning.noise_std(hyperparams.noise_scale, task, state.knots.shape, hyperparams.noise_ramp)
    state = state.replace(std=std)
    state, samples, costs = planning.sample_around(config, task, state, env_state, key, terminal_value=terminal_value)
    best = jnp.argmin(costs)
    state = state.replace(knots=samples[best], cost=costs[best])
    return state, planning.controls(config, state.knots, *planning.control_limits(task))
