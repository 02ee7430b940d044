"""Model-predictive path integral control: a softmax-weighted average of noisy plans.

    config = mppi.Config(num_samples=128)                 # structure: static under jit
    hyperparams = mppi.Hyperparams(temperature=0.1)       # numbers: pytree leaves
    state = mppi.init(config, task, hyperparams)
    state, controls = jax.jit(mppi.plan, static_argnums=0)(config, task, state, env_state, key)

The hyperparameters live in the planner state, so a sweep is one program:
``jax.vmap(lambda hp: mppi.init(config, task, hp))(mppi.Hyperparams(temperature=temps))``
gives a batch of states that `plan`, vmapped, runs side by side.

At every replan, with the nominal knots mu shifted to the current time:
    theta_i = clip(mu + sigma * eps_i),  eps_i ~ N(0, I)   (theta_0 = mu)
    w_i = exp(-(J_i - min_j J_j) / lambda) / sum_k exp(-(J_k - min_j J_j) / lambda)
    mu' = sum_i w_i theta_i
J is a rollout's cost (`mjzoo.planning.masked_cost`): minus its return up to and including
its first terminated step (nothing after it), plus the `termination_cost` hyperparameter
(default 0) if a step terminated.
The temperature lambda is in cost units: lambda -> 0 recovers predictive sampling,
large lambda averages all samples. Defaults: 128 samples, 25 planning steps, 4 cubic
knots, sigma = 0.3 x half ctrl range, lambda = 0.1.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo import planning
from mjzoo.planning import Ensemble
from mjzoo.planning import PlannerState
from mjzoo.planning import TerminalValue
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Config", "Hyperparams", "init", "plan"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config(planning.SamplingConfig):
    """MPPI's structure is the shared sampling structure (`planning.SamplingConfig`)."""


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams(planning.SamplingHyperparams):
    """`planning.SamplingHyperparams` plus the softmax temperature lambda (> 0, cost units)."""

    temperature: float | jax.Array = 0.1

    def _checks(self) -> dict[str, tuple[np.ndarray, str]]:
        return {**super()._checks(), "temperature": (np.greater(self.temperature, 0), "> 0")}


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
    state = state.replace(
        std=planning.noise_std(hyperparams.noise_scale, task, state.knots.shape, hyperparams.noise_ramp)
    )
    state, samples, costs = planning.sample_around(config, task, state, env_state, key, terminal_value=terminal_value)
    weights = planning.mppi_weights(costs, hyperparams.temperature)
    knots = jnp.tensordot(weights, samples, axes=1)
    state = state.replace(knots=knots, cost=jnp.sum(weights * jnp.where(weights > 0, costs, 0.0)))
    return state, planning.controls(config, knots, *planning.control_limits(task))
