"""Plans and how planners sample them: control splines around a nominal plan,
receding-horizon warm start, and the update rules of MPPI and CEM.

A plan is `K` knots of `nu` controls at evenly spaced positions over `horizon_steps`
control steps of the *planning* task (`mjzoo.planning.splines`). `PlannerState.time`
anchors the plan in the environment's clock (`data.time`, seconds) and `PlannerState.dt`
is the planning task's control step, measured from its rollouts, so a simulation with a
different timestep can ask for the control at any time (`control_at`). Samples are
costed by `mjzoo.planning.rollouts`.

`predictive_sampling`, `cem` and `mppi` in `mjzoo.algorithms` combine these pieces;
each is a few lines on top of `sample_around`.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo.planning import native, splines
from mjzoo.planning.learned import TerminalValue, committed
from mjzoo.planning.rollouts import RISKS, Ensemble, aggregate, base_task, rollout_costs
from mjzoo.types import State, Task

__all__ = [
    "SamplingConfig",
    "PlannerState",
    "control_limits",
    "half_range",
    "initial_state",
    "shift",
    "sample_knots",
    "sample_around",
    "controls",
    "control_at",
    "sample_costs",
    "mppi_weights",
    "cem_update",
]

Array = jax.Array


@dataclasses.dataclass(frozen=True, kw_only=True)
class SamplingConfig:
    """What every sampling planner shares (each algorithm's `Config` extends it).

    Attributes:
      num_samples: rollouts per replan (N), the nominal included where the method keeps it.
      horizon_steps: control steps of the planning task per rollout (H).
      num_knots: spline knots over the horizon (K).
      interpolation: "zero", "linear" or "cubic" (`mjzoo.planning.splines`).
      noise_scale: sampling std as a fraction of each actuator's half control range.
      risk: how costs over an `Ensemble` of models become one: "mean", "worst" or "cvar".
      cvar_alpha: the worst fraction of models CVaR averages over.
      unroll: `lax.scan` unroll of the rollout loop (a GPU latency knob).
    """

    num_samples: int = 128
    horizon_steps: int = 25
    num_knots: int = 4
    interpolation: str = "cubic"
    noise_scale: float = 0.3
    risk: str = "mean"
    cvar_alpha: float = 0.25
    unroll: int = 1

    def __post_init__(self) -> None:
        name = type(self).__module__.rsplit(".", 1)[-1] + ".Config"
        checks = {
            "num_samples": self.num_samples >= 2,
            "horizon_steps": self.horizon_steps >= 1,
            "num_knots": 1 <= self.num_knots <= self.horizon_steps,
            "noise_scale": self.noise_scale >= 0,
            "interpolation": self.interpolation in splines.METHODS,
            "risk": self.risk in RISKS,
            "cvar_alpha": 0 < self.cvar_alpha <= 1,
            "unroll": self.unroll >= 1,
        }
        for field, ok in checks.items():
            if not ok:
                raise ValueError(f"{name}: invalid {field}={getattr(self, field)!r}")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PlannerState:
    """A planner's memory between replans.

    Attributes:
      knots: [K, nu] the nominal plan (CEM: the sampling mean).
      std: [K, nu] sampling std in control units (fixed for predictive sampling and
        MPPI; adapted by CEM).
      time: [] environment time (s) at the plan's first knot.
      dt: [] control step of the planning task (s); 0 until the first replan.
      cost: [] cost of the plan chosen at the last replan (inf before).
    """

    knots: Array
    std: Array
    time: Array
    dt: Array
    cost: Array

    def replace(self, **changes) -> "PlannerState":
        return dataclasses.replace(self, **changes)


def control_limits(task: Task | Ensemble | native.Native) -> tuple[np.ndarray, np.ndarray]:
    """([nu], [nu]) lower and upper control bounds; +-inf where an actuator is unlimited."""
    mj_model = base_task(task).mj_model
    limited = np.asarray(mj_model.actuator_ctrllimited, bool)
    bounds = np.asarray(mj_model.actuator_ctrlrange, np.float32)
    return np.where(limited, bounds[:, 0], -np.inf), np.where(limited, bounds[:, 1], np.inf)


def half_range(task: Task | Ensemble | native.Native) -> np.ndarray:
    """[nu] half of each actuator's control range (1 where unlimited): the unit of noise."""
    low, high = control_limits(task)
    return np.where(np.isfinite(high - low), (high - low) / 2, 1.0).astype(np.float32)


def initial_state(
    config: SamplingConfig, task: Task | Ensemble | native.Native, knots: Array | None = None
) -> PlannerState:
    """A plan of `knots` ([K, nu]; default: zero controls, clipped into the limits) with
    std = noise_scale x half the control range (x 1 for unlimited actuators).

    Committed to the device (unless traced), like the states `plan` returns: a host loop
    of ``jax.jit(planner.plan, static_argnums=0)`` then compiles once."""
    low, high = control_limits(task)
    shape = (config.num_knots, low.shape[0])
    if knots is None:
        knots = jnp.clip(jnp.zeros(shape, jnp.float32), low, high)
    elif jnp.shape(knots) != shape:
        raise ValueError(f"warm-start knots must have shape {shape} (num_knots, nu), got {jnp.shape(knots)}")
    std = jnp.broadcast_to(jnp.float32(config.noise_scale) * half_range(task), shape)
    zero, inf = jnp.zeros((), jnp.float32), jnp.full((), jnp.inf, jnp.float32)
    return committed(PlannerState(jnp.asarray(knots, jnp.float32), std, zero, zero, inf))


def shift(config: SamplingConfig, state: PlannerState, now: Array) -> PlannerState:
    """Receding-horizon warm start: the plan re-anchored at time `now`, its knots read off
    the old spline that far ahead (the last knot held past the old horizon)."""
    elapsed = jnp.where(state.dt > 0, (now - state.time) / jnp.maximum(state.dt, 1e-9), 0.0)
    positions = splines.knot_positions(config.num_knots, config.horizon_steps)
    knots = splines.evaluate(state.knots, positions, positions + jnp.maximum(elapsed, 0.0), config.interpolation)
    return state.replace(knots=knots, time=jnp.asarray(now, jnp.float32))


def sample_knots(
    key: Array, mean: Array, std: Array, num_samples: int, low: Array, high: Array, include_mean: bool = True
) -> Array:
    """[N, K, nu] samples mean + std * eps, eps ~ N(0, I), clipped to [low, high]; with
    `include_mean` sample 0 is `mean` itself (so the nominal plan competes)."""
    eps = jax.random.normal(key, (num_samples,) + mean.shape, mean.dtype)
    if include_mean:
        eps = eps.at[0].set(0.0)
    return jnp.clip(mean + std * eps, low, high)


def controls(config: SamplingConfig, knots: Array, low: Array = -np.inf, high: Array = np.inf) -> Array:
    """[..., H, nu] controls of `knots` [..., K, nu] at control steps 0..H-1, clipped to
    [low, high] (a cubic spline overshoots between knots that sit at the limits)."""
    positions = splines.knot_positions(config.num_knots, config.horizon_steps)
    steps = jnp.arange(config.horizon_steps, dtype=jnp.float32)
    evaluate = lambda k: splines.evaluate(k, positions, steps, config.interpolation)  # noqa: E731
    for _ in range(knots.ndim - 2):
        evaluate = jax.vmap(evaluate)
    return jnp.clip(evaluate(knots), low, high)


def control_at(
    config: SamplingConfig, state: PlannerState, time: Array, low: Array = -np.inf, high: Array = np.inf
) -> Array:
    """[nu] the plan's control at environment time `time` (s), clipped to [low, high]."""
    step = jnp.where(state.dt > 0, (time - state.time) / jnp.maximum(state.dt, 1e-9), 0.0)
    positions = splines.knot_positions(config.num_knots, config.horizon_steps)
    control = splines.evaluate(state.knots, positions, jnp.reshape(step, (1,)), config.interpolation)[0]
    return jnp.clip(control, low, high)


def sample_costs(
    config: SamplingConfig,
    task: Task | Ensemble | native.Native,
    state: State,
    samples: Array,
    key: Array,
    terminal_value: TerminalValue | None = None,
) -> tuple[Array, Array]:
    """([N] risk-aggregated costs of knot samples [N, K, nu] from `state`, [] dt), each
    less the `terminal_value` of its final state if one is given."""
    sequences = controls(config, samples, *control_limits(task))
    costs_of = native.rollout_costs if isinstance(task, native.Native) else rollout_costs
    costs, dt = costs_of(task, state, sequences, key, terminal_value, config.unroll)
    costs = aggregate(costs, config.risk, config.cvar_alpha)
    # A sample whose physics blew up must never win.
    return jnp.where(jnp.isfinite(costs), costs, jnp.inf), dt


def sample_around(
    config: SamplingConfig,
    task: Task | Ensemble | native.Native,
    state: PlannerState,
    env_state: State,
    key: Array,
    std: Array | None = None,
    terminal_value: TerminalValue | None = None,
) -> tuple[PlannerState, Array, Array]:
    """The step every sampling planner starts with: shift the plan to `env_state`'s time,
    sample knots around it (sample 0 = the nominal) with `std` ([K, nu] or [N, K, nu];
    default `state.std`), and cost them, with the final states valued by
    `terminal_value` (a `(model, state) -> []` `jax.tree_util.Partial`, or None).

    Returns (the shifted state with the measured dt, [N, K, nu] samples, [N] costs).
    """
    sample_key, rollout_key = jax.random.split(key)
    state = shift(config, state, env_state.data.time)
    low, high = control_limits(task)
    std = state.std if std is None else std
    samples = sample_knots(sample_key, state.knots, std, config.num_samples, low, high)
    costs, dt = sample_costs(config, task, env_state, samples, rollout_key, terminal_value)
    return state.replace(dt=dt), samples, costs


def mppi_weights(costs: Array, temperature: float | Array) -> Array:
    """[N] weights w_i = exp(-(c_i - min c) / lambda) / sum_j exp(-(c_j - min c) / lambda).

    Subtracting the minimum changes nothing mathematically and keeps exp from
    underflowing; infinite costs get weight 0. If every cost is infinite (all rollouts
    diverged) all weight goes to sample 0, the nominal plan, rather than NaN.
    """
    lowest = jnp.min(costs)
    weights = jax.nn.softmax(-(costs - jnp.where(jnp.isfinite(lowest), lowest, 0.0)) / temperature)
    return jnp.where(jnp.isfinite(lowest), weights, jax.nn.one_hot(0, costs.shape[0], dtype=weights.dtype))


def cem_update(
    samples: Array, costs: Array, num_elites: int, sigma_min: Array, sigma_max: Array
) -> tuple[Array, Array]:
    """The cross-entropy step: mean and std of the `num_elites` lowest-cost samples.

    Args:
      samples: [N, ...] sampled plans.
      costs: [N].
      sigma_min, sigma_max: bounds the elite std is clipped to (broadcast to a sample).

    Returns:
      ([...] elite mean, [...] elite std clipped to [sigma_min, sigma_max]).
    """
    elite = jax.lax.top_k(-costs, num_elites)[1]
    elites = samples[elite]
    return jnp.mean(elites, axis=0), jnp.clip(jnp.std(elites, axis=0), sigma_min, sigma_max)
