"""The cross-entropy method: refit a Gaussian over plans to its lowest-cost samples.

    config = cem.Config(num_samples=128, num_elites=16)
    state = cem.init(config, task)
    state, controls = jax.jit(cem.plan, static_argnums=0)(config, task, state, env_state, key)

At every replan, with mean mu and std s shifted to the current time:
    theta_0 = mu
    theta_i = clip(mu + s * eps_i)            for the first (1 - f) of the samples
    theta_i = clip(mu + sigma_max * eps_i)    for an explore fraction f of them
    E = the num_elites samples of lowest cost J
    mu' = mean_{i in E} theta_i,   s' = clip(std_{i in E} theta_i, sigma_min, sigma_max)
sigma_min keeps the search from collapsing; the explore fraction keeps wide samples in
play after it has narrowed. sigma_min / sigma_max are fractions of each actuator's half
control range (like noise_scale, the initial std). Defaults: 128 samples, 16 elites,
25 planning steps, 4 cubic knots, s0 = 0.3, sigma_min = 0.05, sigma_max = 1.0, f = 0.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from mjzoo import planning
from mjzoo.planning import Ensemble, PlannerState, TerminalValue
from mjzoo.types import State, Task

__all__ = ["Config", "init", "plan"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config(planning.SamplingConfig):
    """`planning.SamplingConfig` plus the elite count, std bounds and explore fraction."""

    num_elites: int = 16
    sigma_min: float = 0.05
    sigma_max: float = 1.0
    explore_fraction: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        checks = {
            "num_elites": 1 <= self.num_elites <= self.num_samples,
            "sigma_min": 0 <= self.sigma_min,
            "sigma_max": self.sigma_min <= self.sigma_max,
            "explore_fraction": 0 <= self.explore_fraction < 1,
        }
        for field, ok in checks.items():
            if not ok:
                raise ValueError(f"cem.Config: invalid {field}={getattr(self, field)!r}")


init = planning.initial_state  # (config, task, knots=None): mean = a zero plan or warm-start knots


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
    half_range = planning.half_range(task)
    num_explore = int(config.explore_fraction * config.num_samples)
    stds = jnp.concatenate(
        [
            jnp.broadcast_to(state.std, (config.num_samples - num_explore,) + state.std.shape),
            jnp.broadcast_to(config.sigma_max * half_range, (num_explore,) + state.std.shape),
        ]
    )  # [N, K, nu]
    state, samples, costs = planning.sample_around(config, task, state, env_state, key, stds, terminal_value)
    mean, std = planning.cem_update(
        samples, costs, config.num_elites, config.sigma_min * half_range, config.sigma_max * half_range
    )
    state = state.replace(knots=mean, std=std, cost=jnp.sort(costs)[: config.num_elites].mean())
    return state, planning.controls(config, mean, *planning.control_limits(task))
