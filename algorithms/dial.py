"""DIAL-MPC: MPPI iterated several times per replan, its noise annealed like a diffusion.

    config = dial.Config(num_samples=128, iterations=3)   # structure: static under jit
    hyperparams = dial.Hyperparams(beta_iterations=1.0)   # numbers: pytree leaves
    state = dial.init(config, task, hyperparams)
    state, controls = jax.jit(dial.plan, static_argnums=0)(config, task, state, env_state, key)

Diffusion-Inspired Annealing for Legged MPC (Xue, Pan, Yi, Qu, Shi, 2024). At every
replan, with the nominal knots mu shifted to the current time, for iterations
j = 0..N-1 (N = `iterations`), each an MPPI step around the last one's mean:
    sigma_jk = sigma_0 exp(-j / (beta_1 N) - (K-1-k) / (beta_2 (K-1)))   knot k = 0..K-1
    theta_i = clip(mu + sigma_j * eps_i),  eps_i ~ N(0, I)   (theta_0 = mu)
    w_i = softmax_i(-(J_i - min_j J_j) / (lambda std_j J_j)),   mu <- sum_i w_i theta_i
The noise shrinks over the iterations (coarse search, then refinement: beta_1, larger
keeps it wider) and is smallest at the plan's start, which the last replans refined
already, growing to sigma_0 at its end, which is new (beta_2, larger flattens it). The
temperature lambda is in units of the samples' cost spread (their std), as DIAL-MPC
normalizes its rewards: one value serves every task and every iteration, whose cost
spreads shrink with the noise. sigma_0 is the `noise_scale` fraction of each actuator's
half control range; the shared noise_ramp r (default 0) widens knot k further by
(1 + r k / (K - 1)). J is a rollout's cost (`mjzoo.planning.masked_cost`). Defaults: 128
samples, 3 iterations, 25 planning steps, 4 cubic knots, sigma_0 = 0.5, beta_1 = beta_2
= 1, lambda = 0.1. With one iteration and a flat horizon (beta_2 -> inf) it is MPPI
with a normalized temperature.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

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

Array = jax.Array

__all__ = ["Config", "Hyperparams", "init", "plan", "noise_schedule", "normalized_weights", "anneal"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config(planning.SamplingConfig):
    """`planning.SamplingConfig` plus the MPPI iterations per replan (N)."""

    iterations: int = 3

    def __post_init__(self) -> None:
        super().__post_init__()
        checks.fields("dial.Config", self, {"iterations": (self.iterations >= 1, ">= 1")})


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams(planning.SamplingHyperparams):
    """`planning.SamplingHyperparams` (noise_scale: sigma_0, the widest noise) plus the
    normalized temperature lambda and the annealing rates beta_1 (over iterations) and
    beta_2 (along the horizon), all > 0."""

    noise_scale: float | jax.Array = 0.5
    temperature: float | jax.Array = 0.1
    beta_iterations: float | jax.Array = 1.0
    beta_horizon: float | jax.Array = 1.0

    def _checks(self) -> dict[str, tuple[np.ndarray, str]]:
        names = ("temperature", "beta_iterations", "beta_horizon")
        return {**super()._checks(), **{n: (np.greater(getattr(self, n), 0), "> 0") for n in names}}


def noise_schedule(
    noise_scale: float | jax.Array,
    beta_iterations: float | jax.Array,
    beta_horizon: float | jax.Array,
    iterations: int,
    num_knots: int,
) -> jax.Array:
    """[N, K] the noise of iteration j at knot k, as a fraction of half the control range:
    noise_scale exp(-j / (beta_iterations N) - (K-1-k) / (beta_horizon (K-1)))."""
    j = jnp.arange(iterations, dtype=jnp.float32)[:, None]
    k = jnp.arange(num_knots, dtype=jnp.float32)[None, :]
    ahead = (num_knots - 1 - k) / max(num_knots - 1, 1)  # 1 at the plan's start, 0 at its end
    return noise_scale * jnp.exp(-j / (beta_iterations * iterations) - ahead / beta_horizon)


def normalized_weights(costs: jax.Array, temperature: float | jax.Array) -> jax.Array:
    """[N] MPPI weights of costs [N] at temperature x the std of the finite costs
    (`planning.mppi_weights`); equal costs share the weight equally."""
    finite = jnp.isfinite(costs)
    count = jnp.maximum(jnp.sum(finite), 1)
    mean = jnp.sum(jnp.where(finite, costs, 0.0)) / count
    spread = jnp.sqrt(jnp.sum(jnp.where(finite, jnp.square(costs - mean), 0.0)) / count)
    return planning.mppi_weights(costs, temperature * jnp.maximum(spread, 1e-6))


def init(
    config: Config, task: Task | Ensemble, hyperparams: Hyperparams | None = None, *, knots: Array | None = None
) -> PlannerState:
    """The first `PlannerState`: knots [K, nu] from `knots` (default zero), holding
    `hyperparams` (default `Hyperparams()`)."""
    return planning.sampling.planner_init(Hyperparams, config, task, hyperparams, knots)


def anneal(
    costs_of: Callable[[jax.Array, jax.Array], tuple[jax.Array, jax.Array]],
    knots: jax.Array,
    stds: jax.Array,
    low: jax.Array,
    high: jax.Array,
    num_samples: int,
    temperature: float | jax.Array,
    key: Array,
    in_python: bool = False,
) -> tuple[Array, Array, Array]:
    """DIAL's inner loop, for any cost: an MPPI step per noise level, in a `lax.scan`
    or, with `in_python` (C MuJoCo's rollouts), unrolled (`planning.iterate`).

    Args:
      costs_of: (samples [N, K, nu], key) -> ([N] costs, [] anything carried out: dt).
      knots: [K, nu] the starting mean.
      stds: [I, K, nu] the noise of each iteration, in control units.
      low, high: [nu] the limits samples are clipped to.

    Returns:
      ([K, nu] the final mean, [] the last iteration's weighted cost, the last `costs_of` extra).
    """

    def iteration(carry, inputs):
        std, key = inputs
        sample_key, cost_key = jax.random.split(key)
        samples = planning.sample_knots(sample_key, carry[0], std, num_samples, low, high)
        costs, extra = costs_of(samples, cost_key)
        weights = normalized_weights(costs, temperature)
        cost = jnp.sum(weights * jnp.where(weights > 0, costs, 0.0))
        return (jnp.tensordot(weights, samples, axes=1), cost, extra), None

    if in_python:  # no scan: the carry's extra needs no value before the first iteration
        extra = None  # (and tracing costs_of for its shape would call C MuJoCo once more)
    else:
        _, shape = jax.eval_shape(costs_of, jnp.zeros((num_samples, *knots.shape), knots.dtype), key)
        extra = jnp.zeros(shape.shape, shape.dtype)
    start = (knots, jnp.float32(jnp.inf), extra)
    return planning.iterate(iteration, start, (stds, jax.random.split(key, stds.shape[0])), in_python=in_python)[0]


def plan(
    config: Config,
    task: Task | Ensemble,
    state: PlannerState,
    env_state: State,
    key: Array,
    terminal_value: TerminalValue | None = None,
) -> tuple[PlannerState, Array]:
    """One replan from `env_state`, N annealed MPPI iterations (`anneal`): (the new
    planner state, [H, nu] controls of its plan). `terminal_value`: None, or a
    `planning.TerminalValue` valuing each rollout's final state."""
    hp = state.hyperparams
    schedule = noise_schedule(hp.noise_scale, hp.beta_iterations, hp.beta_horizon, config.iterations, config.num_knots)
    ramp = planning.noise_ramp_profile(hp.noise_ramp, config.num_knots)  # [K], 1 unless noise_ramp > 0
    stds = (schedule * ramp)[:, :, None] * planning.half_range(task)  # [N, K, nu]
    state = planning.shift(config, state, env_state.data.time)
    low, high = planning.control_limits(task)

    def costs_of(samples: jax.Array, key: jax.Array) -> tuple[jax.Array, jax.Array]:
        return planning.sample_costs(
            config, task, env_state, samples, key, terminal_value, hp.cvar_alpha, hp.termination_cost
        )

    knots, cost, dt = anneal(
        costs_of,
        state.knots,
        stds,
        low,
        high,
        config.num_samples,
        hp.temperature,
        key,
        isinstance(task, planning.Native),
    )
    state = state.replace(knots=knots, std=stds[-1], cost=cost, dt=dt)
    return state, planning.controls(config, knots, low, high)
