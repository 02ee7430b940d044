"""CMA-ES over a plan's spline knots: a Gaussian search whose covariance and step size adapt.

    config = cma_es.Config(num_samples=64, iterations=1)      # structure: static under jit
    hyperparams = cma_es.Hyperparams(noise_scale=0.3)         # numbers: pytree leaves
    state = cma_es.init(config, task, hyperparams)
    state, controls = jax.jit(cma_es.plan, static_argnums=0)(config, task, state, env_state, key)

The covariance matrix adaptation evolution strategy (Hansen's tutorial, arXiv:1604.00772,
positive recombination weights) over the D = K nu knots, in units of each actuator's half
control range. The search distribution N(m, sigma^2 C) and its evolution paths carry over
from replan to replan (m shifted to the current time, as every planner's nominal is), and
each replan runs `iterations` generations of lambda = num_samples plans:
    x_i = clip(m + sigma L z_i),  z_i ~ N(0, I),  C = L L^T   (x_0 = m)
    y_i = (x_i - m) / sigma,  y_w = sum_{i<=mu} w_i y_{i:lambda}  (ranked by cost J)
    m' = m + sigma y_w
    p_s' = (1 - c_s) p_s + sqrt(c_s (2 - c_s) mu_eff) C^{-1/2} y_w
    h = [|p_s'| / sqrt(1 - (1 - c_s)^(2 (g + 1))) < (1.4 + 2 / (D + 1)) E|N(0, I)|]
    p_c' = (1 - c_c) p_c + h sqrt(c_c (2 - c_c) mu_eff) y_w
    C' = (1 - c_1 - c_mu + (1 - h) c_1 c_c (2 - c_c)) C + c_1 p_c' p_c'^T + c_mu sum w_i y_i y_i^T
    sigma' = clip(sigma exp(c_s / d_s (|p_s'| / E|N(0, I)| - 1)), sigma_min, sigma_max)
with w_i proportional to ln((lambda + 1) / 2) - ln i and the rates c_s, d_s, c_c, c_1, c_mu
the tutorial's defaults for D and mu_eff (`constants`). Sample 0 is the mean itself, so the
nominal plan competes, as in every planner here; its step y_0 is zero. The bounds on sigma
keep a long receding-horizon run from collapsing its search or blowing it up. J is a
rollout's cost (`mjzoo.planning.masked_cost`). Defaults: 64 samples, mu = lambda / 2, one
generation per replan, 25 planning steps, 4 cubic knots, sigma_0 = 0.3, sigma in
[0.02, 1].
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo import checks
from mjzoo import planning
from mjzoo.planning import Ensemble
from mjzoo.planning import PlannerState
from mjzoo.planning import TerminalValue
from mjzoo.planning.learned import committed
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Config", "Hyperparams", "CMAState", "Constants", "constants", "sample", "update", "init", "plan"]

Array = jax.Array


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config(planning.SamplingConfig):
    """`planning.SamplingConfig` plus the parents mu (`num_elites`; 0: half the samples)
    and the generations per replan (`iterations`)."""

    num_samples: int = 64
    num_elites: int = 0
    iterations: int = 1

    def __post_init__(self) -> None:
        super().__post_init__()
        elites = (0 <= self.num_elites <= self.num_samples, f"in [0, num_samples = {self.num_samples}]")
        checks.fields("cma_es.Config", self, {"num_elites": elites, "iterations": (self.iterations >= 1, ">= 1")})

    @property
    def parents(self) -> int:
        """mu: the ranked samples recombined (`num_elites`, or half the samples)."""
        return self.num_elites or self.num_samples // 2


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams(planning.SamplingHyperparams):
    """`planning.SamplingHyperparams` (noise_scale: the initial step size sigma_0) plus
    the bounds on sigma, all in units of half the control range. noise_ramp must stay 0:
    the adapted covariance shapes the noise along the horizon."""

    sigma_min: float | Array = 0.02
    sigma_max: float | Array = 1.0

    def _checks(self) -> dict[str, tuple[np.ndarray, str]]:
        return {
            **super()._checks(),
            "sigma_min": (np.greater_equal(self.sigma_min, 0), ">= 0"),
            "sigma_max": (np.less_equal(self.sigma_min, self.sigma_max), ">= sigma_min"),
            "noise_ramp": (np.equal(self.noise_ramp, 0), "0 (the covariance adapts along the horizon)"),
        }


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class CMAState(PlannerState):
    """`PlannerState` (knots: the mean m; std: sigma sqrt(diag C) in control units) plus
    the search distribution: cov [D, D] (C), path_sigma and path_c [D], sigma [] and the
    generation count g []."""

    cov: Array
    path_sigma: Array
    path_c: Array
    sigma: Array
    generation: Array


class Constants(NamedTuple):
    """The tutorial's default rates for dimension D with mu parents of lambda samples."""

    weights: tuple[float, ...]  # [mu] recombination weights, summing to 1 (hashable: static)
    mu_eff: float
    c_sigma: float
    d_sigma: float
    c_c: float
    c_1: float
    c_mu: float
    chi_n: float  # E|N(0, I_D)|


def constants(dim: int, num_samples: int, parents: int) -> Constants:
    """`Constants` for D = `dim`, lambda = `num_samples`, mu = `parents` (host numbers)."""
    w = np.log((num_samples + 1) / 2) - np.log(np.arange(1, parents + 1))
    w = np.maximum(w, 0.0)  # mu > lambda / 2: the worse half gets no weight
    w = w / w.sum()
    mu_eff = 1.0 / np.sum(w**2)
    c_sigma = (mu_eff + 2) / (dim + mu_eff + 5)
    d_sigma = 1 + 2 * max(0.0, np.sqrt((mu_eff - 1) / (dim + 1)) - 1) + c_sigma
    c_c = (4 + mu_eff / dim) / (dim + 4 + 2 * mu_eff / dim)
    c_1 = 2 / ((dim + 1.3) ** 2 + mu_eff)
    c_mu = min(1 - c_1, 2 * (mu_eff - 2 + 1 / mu_eff) / ((dim + 2) ** 2 + mu_eff))
    chi_n = np.sqrt(dim) * (1 - 1 / (4 * dim) + 1 / (21 * dim**2))
    return Constants(tuple(float(v) for v in w), *(float(v) for v in (mu_eff, c_sigma, d_sigma, c_c, c_1, c_mu, chi_n)))


def _eigen(cov: Array) -> tuple[Array, Array]:
    """(B [D, D], d [D]) with C = B diag(d^2) B^T, eigenvalues floored above zero."""
    values, vectors = jnp.linalg.eigh((cov + cov.T) / 2)
    return vectors, jnp.sqrt(jnp.maximum(values, 1e-12 * jnp.max(values)))


def update(
    c: Constants,
    samples: Array,
    costs: Array,
    mean: Array,
    sigma: Array,
    cov: Array,
    path_sigma: Array,
    path_c: Array,
    generation: Array,
) -> tuple[Array, Array, Array, Array, Array]:
    """One CMA-ES generation's update (the module docstring's equations).

    Args:
      c: `constants(D, lambda, mu)`.
      samples: [lambda, D] the evaluated points x_i (clipped: y_i is taken from them).
      costs: [lambda] their costs J (lower is better).
      mean, path_sigma, path_c: [D]; sigma, generation: []; cov: [D, D].

    Returns:
      (mean [D], sigma [] unclipped, cov [D, D], path_sigma [D], path_c [D]).
    """
    dim = mean.shape[0]
    weights = jnp.asarray(c.weights, mean.dtype)
    ranked = jnp.argsort(costs)[: weights.shape[0]]
    ys = (samples[ranked] - mean) / sigma  # [mu, D]
    y_w = weights @ ys
    vectors, d = _eigen(cov)
    inv_sqrt_y = vectors @ ((vectors.T @ y_w) / d)  # C^{-1/2} y_w
    path_sigma = (1 - c.c_sigma) * path_sigma + np.sqrt(c.c_sigma * (2 - c.c_sigma) * c.mu_eff) * inv_sqrt_y
    norm = jnp.linalg.norm(path_sigma)
    correction = jnp.sqrt(1 - (1 - c.c_sigma) ** (2 * (generation + 1)))
    h = (norm / correction < (1.4 + 2 / (dim + 1)) * c.chi_n).astype(mean.dtype)
    path_c = (1 - c.c_c) * path_c + h * np.sqrt(c.c_c * (2 - c.c_c) * c.mu_eff) * y_w
    rank_mu = jnp.einsum("i,ij,ik->jk", weights, ys, ys)
    decay = 1 - c.c_1 - c.c_mu + (1 - h) * c.c_1 * c.c_c * (2 - c.c_c)
    cov = decay * cov + c.c_1 * jnp.outer(path_c, path_c) + c.c_mu * rank_mu
    new_sigma = sigma * jnp.exp(c.c_sigma / c.d_sigma * (norm / c.chi_n - 1))
    return mean + sigma * y_w, new_sigma, cov, path_sigma, path_c


def sample(key: Array, mean: Array, sigma: Array, cov: Array, num_samples: int, low: Array, high: Array) -> Array:
    """[lambda, D] points clip(mean + sigma L z_i), z_i ~ N(0, I), L L^T = C, the first =
    `mean` (mean, low, high: [D]; sigma: []; cov: [D, D]). Cholesky's factor, unlike an
    eigenbasis (any basis of I is one), is unique: the same draws alone and under vmap."""
    jitter = 1e-7 * jnp.max(jnp.diagonal(cov)) * jnp.eye(cov.shape[0], dtype=cov.dtype)
    factor = jnp.linalg.cholesky((cov + cov.T) / 2 + jitter)
    z = jax.random.normal(key, (num_samples, mean.shape[0]), mean.dtype).at[0].set(0.0)
    return jnp.clip(mean + sigma * z @ factor.T, low, high)


def init(
    config: Config, task: Task | Ensemble, hyperparams: Hyperparams | None = None, *, knots: Array | None = None
) -> CMAState:
    """Mean = a zero plan or the warm-start `knots` [K, nu], C = I, sigma = noise_scale,
    zero paths, holding `hyperparams` (default `Hyperparams()`)."""
    base = planning.sampling.planner_init(Hyperparams, config, task, hyperparams, knots)
    dim = base.knots.size
    zeros = jnp.zeros((dim,), jnp.float32)
    fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(PlannerState)}
    extra = dict(cov=jnp.eye(dim, dtype=jnp.float32), path_sigma=zeros, path_c=zeros, generation=jnp.float32(0))
    return CMAState(**fields, **committed(extra), sigma=base.hyperparams.noise_scale)


def plan(
    config: Config,
    task: Task | Ensemble,
    state: CMAState,
    env_state: State,
    key: Array,
    terminal_value: TerminalValue | None = None,
) -> tuple[CMAState, Array]:
    """One replan from `env_state` (`config.iterations` generations): returns the new
    planner state and the plan's [H, nu] controls. `terminal_value` (model, state) -> []
    values each rollout's final state (`planning.as_terminal_value`)."""
    hp, shape = state.hyperparams, state.knots.shape
    scale = np.broadcast_to(planning.half_range(task), shape).reshape(-1)  # [D] control units per unit
    low, high = (np.broadcast_to(b, shape).reshape(-1) / scale for b in planning.control_limits(task))
    c = constants(scale.size, config.num_samples, config.parents)
    state = planning.shift(config, state, env_state.data.time)

    def generation(state: CMAState, key: Array) -> tuple[CMAState, None]:
        sample_key, rollout_key = jax.random.split(key)
        mean = state.knots.reshape(-1) / scale
        x = sample(sample_key, mean, state.sigma, state.cov, config.num_samples, low, high)
        costs, dt = planning.sample_costs(
            config,
            task,
            env_state,
            (x * scale).reshape(-1, *shape),
            rollout_key,
            terminal_value,
            hp.cvar_alpha,
            hp.termination_cost,
        )
        mean, sigma, cov, path_sigma, path_c = update(
            c, x, costs, mean, state.sigma, state.cov, state.path_sigma, state.path_c, state.generation
        )
        sigma = jnp.clip(sigma, hp.sigma_min, hp.sigma_max)
        std = sigma * jnp.sqrt(jnp.diagonal(cov)) * scale
        state = state.replace(
            knots=(mean * scale).reshape(shape),
            std=std.reshape(shape),
            dt=dt,
            cov=cov,
            sigma=sigma,
            path_sigma=path_sigma,
            path_c=path_c,
            generation=state.generation + 1,
            cost=jnp.asarray(c.weights) @ jnp.sort(costs)[: len(c.weights)],
        )
        return state, None

    keys = jax.random.split(key, config.iterations)
    state, _ = planning.iterate(generation, state, keys, in_python=isinstance(task, planning.Native))
    return state, planning.controls(config, state.knots, *planning.control_limits(task))
