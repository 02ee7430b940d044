"""Plans and how planners sample them: control splines around a nominal plan,
receding-horizon warm start, and the update rules of MPPI and CEM.

A plan is `K` knots of `nu` controls at evenly spaced positions over `horizon_steps`
control steps of the *planning* task (`mjzoo.planning.splines`). `PlannerState.time`
anchors the plan in the environment's clock (`data.time`, seconds) and `PlannerState.dt`
is the planning task's control step, measured from its rollouts, so a simulation with a
different timestep can ask for the control at any time (`control_at`). Samples are
costed by `mjzoo.planning.ensembles`: the negative return of the planning task's
rewards up to a rollout's first termination, plus an optional termination cost.

A planner's settings come in two parts. Its `Config` is structure (sizes, the spline
kind, the risk measure): a static argument of `plan`, so a new value compiles again. Its
`Hyperparams` are numbers (noise scale, MPPI's temperature, CEM's std bounds): leaves of
`PlannerState.hyperparams`, so `jax.vmap` over planner states sweeps them in one program
and a new value runs without compiling. `configure` splits one flat dict of fields, the
form env registries and the command line give, into the two.

`predictive_sampling`, `cem` and `mppi` in `mjzoo.algorithms` combine these pieces;
each is a few lines on top of `sample_around`.
"""

from __future__ import annotations

import dataclasses
import numbers
import typing
from types import ModuleType
from typing import Any
from typing import Callable
from typing import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo import checks
from mjzoo.planning import native
from mjzoo.planning import splines
from mjzoo.planning.ensembles import RISKS
from mjzoo.planning.ensembles import Ensemble
from mjzoo.planning.ensembles import aggregate
from mjzoo.planning.ensembles import base_task
from mjzoo.planning.ensembles import rollout_costs
from mjzoo.planning.learned import TerminalValue
from mjzoo.planning.learned import committed
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "SamplingConfig",
    "SamplingHyperparams",
    "PlannerState",
    "configure",
    "noise_std",
    "noise_ramp_profile",
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
    """The structure every sampling planner shares (each algorithm's `Config` extends it):
    sizes and kinds, a static argument of `plan`. The numbers are `SamplingHyperparams`.

    Attributes:
      num_samples: rollouts per replan (N), the nominal included where the method keeps it.
      horizon_steps: control steps of the planning task per rollout (H).
      num_knots: spline knots over the horizon (K).
      interpolation: "zero", "linear" or "cubic" (`mjzoo.planning.splines`).
      risk: how costs over an `Ensemble` of models become one: "mean", "worst" or "cvar".
      unroll: `lax.scan` unroll of the rollout loop (a GPU latency knob).
    """

    num_samples: int = 128
    horizon_steps: int = 25
    num_knots: int = 4
    interpolation: str = "cubic"
    risk: str = "mean"
    unroll: int = 1

    def __post_init__(self) -> None:
        checks.fields(
            _name(self),
            self,
            {
                "num_samples": (self.num_samples >= 2, ">= 2"),
                "horizon_steps": (self.horizon_steps >= 1, ">= 1"),
                "num_knots": (
                    1 <= self.num_knots <= self.horizon_steps,
                    f"in [1, horizon_steps = {self.horizon_steps}]",
                ),
                "interpolation": (self.interpolation in splines.METHODS, f"one of {splines.METHODS}"),
                "risk": (self.risk in RISKS, f"one of {RISKS}"),
                "unroll": (self.unroll >= 1, ">= 1"),
            },
        )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class SamplingHyperparams:
    """The numbers every sampling planner shares (each algorithm's `Hyperparams` extends
    it): pytree leaves, kept in `PlannerState.hyperparams`, so they are swept by vmapping
    over planner states and changed without compiling again.

    Each field is a number or an array of them ([] for one planner; [B] for a batch that
    `jax.vmap` maps over). Values that are concrete are checked at construction; traced
    ones (inside a jit or vmap) are not.

    Attributes:
      noise_scale: sampling std as a fraction of half of each action's range
        (`control_limits`: the ctrlrange, or [-1, 1] for an actuator's own actions), at
        the plan's first knot.
      noise_ramp: how much wider the noise grows along the horizon: knot k of K samples
        with noise_scale x (1 + noise_ramp x k / (K - 1)) (`noise_ramp_profile`), so the
        far knots, which later replans revisit and the warm start holds only as a
        guess, are searched widely while the controls about to be applied stay near the
        nominal; 0: the same noise at every knot.
      cvar_alpha: the worst fraction of models CVaR averages over (with risk="cvar").
      termination_cost: cost added once to a rollout whose task terminates (a fall);
        its rewards stop counting there either way (`mjzoo.planning.masked_cost`).
    """

    noise_scale: float | Array = 0.3
    noise_ramp: float | Array = 0.0
    cvar_alpha: float | Array = 0.25
    termination_cost: float | Array = 0.0

    def __post_init__(self) -> None:
        names = [f.name for f in dataclasses.fields(self)]
        checks.fields(
            _name(self), self, {n: (not isinstance(getattr(self, n), (str, bool)), "a number") for n in names}
        )
        if _concrete(self):
            checks.fields(_name(self), self, self._checks())

    def _checks(self) -> dict[str, tuple[Any, str]]:
        """Field -> (whether its value is in range, elementwise for arrays; the range)."""
        return {
            "noise_scale": (np.greater_equal(self.noise_scale, 0), ">= 0"),
            "noise_ramp": (np.greater_equal(self.noise_ramp, 0), ">= 0"),
            "cvar_alpha": (
                np.logical_and(np.greater(self.cvar_alpha, 0), np.less_equal(self.cvar_alpha, 1)),
                "in (0, 1]",
            ),
            "termination_cost": (np.isfinite(self.termination_cost), "finite"),
        }


def _concrete(hyperparams: SamplingHyperparams) -> bool:
    """Whether every field holds a concrete number or array (not a tracer, nor the
    placeholders JAX builds pytree nodes with)."""
    values = [getattr(hyperparams, f.name) for f in dataclasses.fields(hyperparams)]
    return all(
        isinstance(v, (numbers.Real, np.ndarray)) or (isinstance(v, jax.Array) and not isinstance(v, jax.core.Tracer))
        for v in values
    )


def _name(settings: Any) -> str:
    """ "mppi.Config", "cem.Hyperparams", ...: the name users write."""
    return f"{type(settings).__module__.rsplit('.', 1)[-1]}.{type(settings).__name__}"


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PlannerState:
    """A planner's memory between replans.

    Attributes:
      knots: [K, nu] the nominal plan (CEM: the sampling mean).
      std: [K, nu] sampling std in control units (fixed for predictive sampling and
        MPPI, noise_ramp included; CEM: the elite fit, which its samples widen by the
        ramp).
      time: [] environment time (s) at the plan's first knot.
      dt: [] control step of the planning task (s); 0 until the first replan.
      cost: [] cost of the plan chosen at the last replan (inf before).
      hyperparams: the planner's `Hyperparams` (float32 [] leaves), which `plan` reads:
        a batch of states vmapped over is a sweep (None: a bare plan, for the pieces
        here that only evaluate it).
    """

    knots: Array
    std: Array
    time: Array
    dt: Array
    cost: Array
    hyperparams: Any = None

    def replace(self, **changes) -> "PlannerState":
        return dataclasses.replace(self, **changes)


def control_limits(task: Task | Ensemble | native.Native) -> tuple[np.ndarray, np.ndarray]:
    """([A], [A]) lower and upper bounds of the task's actions: each actuator's ctrlrange
    (+-inf where unlimited), or [-1, 1] where the actions are the task's actuator's own
    (``Task.action_dim`` set: `mjzoo.task` with a catalog actuator such as
    `actuators.position_targets`, whose actions are offsets from a pose in [-1, 1])."""
    task = base_task(task)
    if task.action_dim is not None:
        ones = np.ones(task.action_size, np.float32)
        return -ones, ones
    mj_model = task.mj_model
    limited = np.asarray(mj_model.actuator_ctrllimited, bool)
    bounds = np.asarray(mj_model.actuator_ctrlrange, np.float32)
    return np.where(limited, bounds[:, 0], -np.inf), np.where(limited, bounds[:, 1], np.inf)


def half_range(task: Task | Ensemble | native.Native) -> np.ndarray:
    """[A] half of each action's range (`control_limits`; 1 where unlimited): the unit of noise."""
    low, high = control_limits(task)
    return np.where(np.isfinite(high - low), (high - low) / 2, 1.0).astype(np.float32)


def noise_ramp_profile(noise_ramp: float | Array, num_knots: int) -> Array:
    """[K] each knot's noise multiplier, 1 + noise_ramp x k / (K - 1) for knots
    k = 0..K-1 evenly spaced over the horizon: 1 at the plan's start, 1 + noise_ramp at
    its end (all 1 for one knot). `noise_ramp` is [] (vmap for a batch)."""
    along = jnp.linspace(0.0, 1.0, num_knots) if num_knots > 1 else jnp.zeros((1,))
    return 1.0 + jnp.asarray(noise_ramp, jnp.float32) * along.astype(jnp.float32)


def noise_std(
    noise_scale: float | Array,
    task: Task | Ensemble | native.Native,
    shape: tuple[int, int],
    noise_ramp: float | Array = 0.0,
) -> Array:
    """[K, nu] sampling std in control units: `noise_scale` ([]) x half of each actuator's
    control range (x 1 where unlimited), grown along the horizon by `noise_ramp` ([];
    `noise_ramp_profile`), for the plan's `shape` (K, nu)."""
    ramp = noise_ramp_profile(noise_ramp, shape[0])[:, None]
    return jnp.broadcast_to(jnp.asarray(noise_scale, jnp.float32) * ramp * half_range(task), shape)


def initial_state(
    config: SamplingConfig,
    task: Task | Ensemble | native.Native,
    hyperparams: SamplingHyperparams | None = None,
    knots: Array | None = None,
) -> PlannerState:
    """A plan of `knots` ([K, nu]; default: zero controls, clipped into the limits) with
    std = noise_scale x half the control range (x 1 for unlimited actuators; each
    planner grows it along the horizon by noise_ramp when it samples), holding
    `hyperparams` (default `SamplingHyperparams()`) as float32 leaves.

    Committed to the device (unless traced), like the states `plan` returns: a host loop
    of ``jax.jit(planner.plan, static_argnums=0)`` then compiles once."""
    hyperparams = SamplingHyperparams() if hyperparams is None else hyperparams
    if not isinstance(hyperparams, SamplingHyperparams):
        raise TypeError(
            f"hyperparams must be a planner's Hyperparams (e.g. mppi.Hyperparams), got {type(hyperparams).__name__}; "
            "warm-start knots go by knots="
        )
    low, high = control_limits(task)
    shape = (config.num_knots, low.shape[0])
    if knots is None:
        knots = jnp.clip(jnp.zeros(shape, jnp.float32), low, high)
    elif jnp.shape(knots) != shape:
        raise ValueError(f"warm-start knots must have shape {shape} (num_knots, nu), got {jnp.shape(knots)}")
    hyperparams = jax.tree.map(lambda x: jnp.asarray(x, jnp.float32), hyperparams)
    std = noise_std(hyperparams.noise_scale, task, shape)
    zero, inf = jnp.zeros((), jnp.float32), jnp.full((), jnp.inf, jnp.float32)
    return committed(PlannerState(jnp.asarray(knots, jnp.float32), std, zero, zero, inf, hyperparams))


def check_hyperparams(hyperparams: Any, expected: type) -> None:
    """TypeError unless `hyperparams` is an `expected` (the planner's own `Hyperparams`):
    another planner's would fail only when traced, on a missing field."""
    if not isinstance(hyperparams, expected):
        raise TypeError(
            f"{expected.__module__.rsplit('.', 1)[-1]}.init: hyperparams must be a {expected.__qualname__} "
            f"of that module, got {type(hyperparams).__module__}.{type(hyperparams).__qualname__}; "
            "warm-start knots go by knots="
        )


def planner_init(
    expected: type, config: SamplingConfig, task: Any, hyperparams: Any = None, knots: Array | None = None
) -> PlannerState:
    """What a planner's `init` does with its own `Hyperparams` class `expected`: the
    default `expected()` for None, `check_hyperparams`, then `initial_state`."""
    hyperparams = expected() if hyperparams is None else hyperparams
    check_hyperparams(hyperparams, expected)
    return initial_state(config, task, hyperparams, knots)


def configure(planner: ModuleType, fields: Mapping[str, Any]) -> tuple[SamplingConfig, SamplingHyperparams]:
    """`planner`'s (Config, Hyperparams) from one flat dict of their fields, the form env
    registries and ``--config NAME=VALUE`` give: ``{"num_samples": 128, "temperature": 0.1}``.

    Each value is checked against its field's type first (an int field takes 1e3, not
    1.5; a number field takes ints, floats and, for a sweep, arrays), then by the
    classes' own range checks. Raises ValueError naming an unknown field or a bad value.
    """
    name = planner.__name__.rsplit(".", 1)[-1]
    classes = (planner.Config, planner.Hyperparams)
    owner = {f.name: cls for cls in classes for f in dataclasses.fields(cls)}
    unknown = sorted(set(fields) - set(owner))
    if unknown:
        raise ValueError(
            f"{name}: unknown field(s) {unknown}{checks.did_you_mean(unknown, owner)}; fields: {sorted(owner)}"
        )
    split: dict[type, dict[str, Any]] = {cls: {} for cls in classes}
    for field, value in fields.items():
        hint = typing.get_type_hints(owner[field])[field]
        split[owner[field]][field] = _as_field(name, field, value, hint)
    return planner.Config(**split[planner.Config]), planner.Hyperparams(**split[planner.Hyperparams])


def _as_field(planner: str, field: str, value: Any, hint: Any) -> Any:
    """`value` as the field annotated `hint` holds it (1e3 as an int), or ValueError."""
    if hint is int:
        if isinstance(value, numbers.Integral) and not isinstance(value, bool):
            return int(value)
        if isinstance(value, float) and value.is_integer():
            return int(value)
        raise ValueError(f"{planner}: {field}={value!r} is invalid; expected an int")
    if hint is str:
        if isinstance(value, str):
            return value
        raise ValueError(f"{planner}: {field}={value!r} is invalid; expected a string")
    # A hyperparameter: a number, or an array of them for a sweep.
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, (np.ndarray, jax.Array)) and jnp.issubdtype(value.dtype, jnp.number):
        return value
    raise ValueError(f"{planner}: {field}={value!r} is invalid; expected a number")


def shift(config: SamplingConfig, state: PlannerState, now: Array) -> PlannerState:
    """Receding-horizon warm start: the plan re-anchored at time `now`, its knots read off
    the old spline that far ahead (the last knot held past the old horizon)."""
    elapsed = jnp.where(state.dt > 0, (now - state.time) / jnp.maximum(state.dt, 1e-9), 0.0)
    positions = splines.knot_positions(config.num_knots, config.horizon_steps)
    knots = splines.interpolate(state.knots, positions, positions + jnp.maximum(elapsed, 0.0), config.interpolation)
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
    evaluate = lambda k: splines.interpolate(k, positions, steps, config.interpolation)  # noqa: E731
    for _ in range(knots.ndim - 2):
        evaluate = jax.vmap(evaluate)
    return jnp.clip(evaluate(knots), low, high)


def control_at(
    config: SamplingConfig, state: PlannerState, time: Array, low: Array = -np.inf, high: Array = np.inf
) -> Array:
    """[nu] the plan's control at environment time `time` (s), clipped to [low, high]."""
    step = jnp.where(state.dt > 0, (time - state.time) / jnp.maximum(state.dt, 1e-9), 0.0)
    positions = splines.knot_positions(config.num_knots, config.horizon_steps)
    control = splines.interpolate(state.knots, positions, jnp.reshape(step, (1,)), config.interpolation)[0]
    return jnp.clip(control, low, high)


def sample_costs(
    config: SamplingConfig,
    task: Task | Ensemble | native.Native,
    state: State,
    samples: Array,
    key: Array,
    terminal_value: TerminalValue | None = None,
    cvar_alpha: float | Array = 0.25,
    termination_cost: float | Array = 0.0,
) -> tuple[Array, Array]:
    """([N] risk-aggregated costs of knot samples [N, K, nu] from `state`, [] dt), each
    less the `terminal_value` of its final state if one is given; `cvar_alpha` ([]) is
    the tail CVaR averages over when ``config.risk == "cvar"``. A rollout's rewards stop
    at its first termination, which adds `termination_cost` ([]) once."""
    sequences = controls(config, samples, *control_limits(task))
    costs_of = native.rollout_costs if isinstance(task, native.Native) else rollout_costs
    costs, dt = costs_of(task, state, sequences, key, terminal_value, config.unroll, termination_cost)
    costs = aggregate(costs, config.risk, cvar_alpha)
    # A sample whose physics blew up must never win.
    return jnp.where(jnp.isfinite(costs), costs, jnp.inf), dt


def iterate(body: Callable, carry: Any, xs: Any, *, in_python: bool = False) -> tuple[Any, Any]:
    """`jax.lax.scan(body, carry, xs)`, or with `in_python` the same loop unrolled in
    Python: a planner's iterations on a `Native` task, each running C MuJoCo, which
    `native.split` then runs from the host between jits (a scan's body is traced once,
    so its C call could only run through `jax.pure_callback`, a slower replan)."""
    if not in_python:
        return jax.lax.scan(body, carry, xs)
    ys = []
    for i in range(jax.tree.leaves(xs)[0].shape[0]):
        carry, y = body(carry, jax.tree.map(lambda x, i=i: x[i], xs))
        ys.append(y)
    return carry, jax.tree.map(lambda *y: jnp.stack(y), *ys)


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
    `terminal_value` (a `(model, state) -> []` `jax.tree_util.Partial`, or None), a
    termination costing `state.hyperparams.termination_cost`, and models aggregated
    with `state.hyperparams.cvar_alpha`.

    Returns (the shifted state with the measured dt, [N, K, nu] samples, [N] costs).
    """
    sample_key, rollout_key = jax.random.split(key)
    state = shift(config, state, env_state.data.time)
    low, high = control_limits(task)
    std = state.std if std is None else std
    samples = sample_knots(sample_key, state.knots, std, config.num_samples, low, high)
    hyperparams = state.hyperparams
    costs, dt = sample_costs(
        config,
        task,
        env_state,
        samples,
        rollout_key,
        terminal_value,
        hyperparams.cvar_alpha,
        hyperparams.termination_cost,
    )
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
