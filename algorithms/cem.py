"""The cross-entropy method: refit a Gaussian over plans to its lowest-cost samples.

    config = cem.Config(num_samples=128, num_elites=16)   # structure: static under jit
    hyperparams = cem.Hyperparams(sigma_min=0.1)          # numbers: pytree leaves
    state = cem.init(config, task, hyperparams)
    state, controls = jax.jit(cem.plan, static_argnums=0)(config, task, state, env_state, key)

At every replan, with mean mu and std s shifted to the current time:
    theta_0 = mu
    theta_i = clip(mu + s_r * eps_i)          for the first (1 - f) of the samples
    theta_i = clip(mu + sigma_max * eps_i)    for an explore fraction f of them
    E = the num_elites samples of lowest cost J
    mu' = mean_{i in E} theta_i,   s' = clip(std_{i in E} theta_i, sigma_min, sigma_max)
where s_r = min(s (1 + r k / (K - 1)), max(s, sigma_max)) at knot k widens the far knots
by the noise ramp r (default 0: s_r = s) up to sigma_max, as the fit there is the last
replan's.
J is a rollout's cost (`mjzoo.planning.masked_cost`): minus its return up to and including
its first terminated step (nothing after it), plus the `termination_cost` hyperparameter
(default 0) if a step terminated.
sigma_min keeps the search from collapsing; the explore fraction keeps wide samples in
play after it has narrowed. sigma_min / sigma_max are fractions of each actuator's half
control range (like noise_scale, the initial std). The numbers (s0, sigma_min,
sigma_max, f) are hyperparameters kept in the planner state, so vmapping over states
sweeps them; the elite count is structure. Defaults: 128 samples, 16 elites, 25
planning steps, 4 cubic knots, s0 = 0.3, sigma_min = 0.05, sigma_max = 1.0, f = 0.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo import checks
from mjzoo import planning
from mjzoo.planning import Ensemble
from mjzoo.planning import PlannerState
from mjzoo.planning import TerminalValue
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Config", "Hyperparams", "init", "plan"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config(planning.SamplingConfig):
    """`planning.SamplingConfig` plus the elite count."""

    num_elites: int = 16

    def __post_init__(self) -> None:
        super().__post_init__()
        elites = (1 <= self.num_elites <= self.num_samples, f"in [1, num_samples = {self.num_samples}]")
        checks.fields("cem.Config", self, {"num_elites": elites})


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams(planning.SamplingHyperparams):
    """`planning.SamplingHyperparams` (noise_scale: the initial std) plus the std bounds
    and the explore fraction: floor(f N) samples, the last, draw with std sigma_max."""

    sigma_min: float | jax.Array = 0.05
    sigma_max: float | jax.Array = 1.0
    explore_fraction: float | jax.Array = 0.0

    def _checks(self) -> dict[str, tuple[np.ndarray, str]]:
        explore = np.logical_and(np.greater_equal(self.explore_fraction, 0), np.less(self.explore_fraction, 1))
        return {
            **super()._checks(),
            "sigma_min": (np.greater_equal(self.sigma_min, 0), ">= 0"),
            "sigma_max": (np.less_equal(self.sigma_min, self.sigma_max), ">= sigma_min"),
            "explore_fraction": (explore, "in [0, 1)"),
        }


def init(
    config: Config, task: Task | Ensemble, hyperparams: Hyperparams | None = None, *, knots: jax.Array | None = None
) -> PlannerState:
    """Mean = a zero plan or the warm-start `knots` [K, nu], std = noise_scale x half
    range, holding `hyperparams` (default `Hyperparams()`)."""
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
    hyperparams, half_range = state.hyperparams, planning.half_range(task)
    # The explore count is traced (a swept fraction), so the last floor(f N) samples are
    # picked by a mask; the slack absorbs float32 rounding of f N (0.7 x 10 -> 6.9999995).
    num_explore = jnp.floor(hyperparams.explore_fraction * config.num_samples + 1e-4)
    explores = jnp.arange(config.num_samples) >= config.num_samples - num_explore  # [N]
    # The fit's far knots are stale after the shift: the ramp widens them, up to sigma_max.
    ramp = planning.noise_ramp_profile(hyperparams.noise_ramp, config.num_knots)[:, None]
    std = jnp.minimum(state.std * ramp, jnp.maximum(state.std, hyperparams.sigma_max * half_range))
    stds = jnp.where(explores[:, None, None], hyperparams.sigma_max * half_range, std[None])  # [N, K, nu]
    state, samples, costs = planning.sample_around(config, task, state, env_state, key, stds, terminal_value)
    mean, std = planning.cem_update(
        samples, costs, config.num_elites, hyperparams.sigma_min * half_range, hyperparams.sigma_max * half_range
    )
    state = state.replace(knots=mean, std=std, cost=jnp.sort(costs)[: config.num_elites].mean())
    return state, planning.controls(config, mean, *planning.control_limits(task))
