"""Closed-loop control with a sampling planner: simulate one task, plan with another.

The *simulation* task is the world; the *planning* task is the planner's model of it and
may differ (a coarser timestep, wrong masses, an `Ensemble` of models). Every
`replan_every` control steps of the simulation the planner replans from the current
simulated state; in between, the simulation applies the plan's control at its own time
(`sampling.control_at`), so a planning task with a different timestep still lines up.

The whole run is one `jax.jit` of one `lax.scan` over replans (each an inner scan over
simulation steps): an evaluation episode costs one compile. The planner's `Hyperparams`
are an argument of the run, not a constant: `jax.vmap` over a batch of them is a sweep
of whole closed-loop runs in one program. A learned terminal value
(`mjzoo.planning.learned`) is an argument of the run like the tasks: new critic weights
run without compiling again.

Judo's task hooks, as pure functions in `Hooks`:
  to_planner(sim_state) -> State            what the planner sees of the simulation
                                            (information flowing sim -> planner)
  pre_rollout(plan_task, start) -> plan_task  adjust the planning view before each
                                            rollout batch (e.g. a task phase)
  warm_start(plan_task, start, K) -> [K, nu]   the first plan's knots
  pre_sim_step(sim_task, sim_state, key) -> sim_state    before each simulation step
                                            (e.g. a gust, a moving target)
  post_sim_step(sim_task, sim_state, key) -> sim_state   simulation-side events
                                            (e.g. a new goal once one is reached)
  post_rollout(sim_state, planner_state) -> sim_state    after each batch of rollouts,
                                            with what they found (the chosen plan and
                                            its predicted cost), e.g. to log or move a goal
  to_control(sim_task, sim_state, control) -> control  the control the simulation applies for the
                                            plan's (information flowing planner -> sim;
                                            a policy plus the plan as its offset,
                                            `mjzoo.planning.prior.guided`). The planning
                                            view (`pre_rollout`) must apply the same in
                                            its rollouts, so such a problem plans in JAX.
"""

from __future__ import annotations

import dataclasses
import functools
from types import ModuleType
from typing import Any
from typing import Callable

import jax

from mjzoo.planning import sampling
from mjzoo.planning.ensembles import Ensemble
from mjzoo.planning.ensembles import base_task
from mjzoo.planning.ensembles import with_base
from mjzoo.planning.learned import TerminalValue
from mjzoo.planning.native import Native
from mjzoo.planning.native import transition_native
from mjzoo.planning.sampling import PlannerState
from mjzoo.planning.sampling import SamplingConfig
from mjzoo.running import fill_transition_entries
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Hooks", "Result", "run", "replan"]

Array = jax.Array
# Why a policy in the loop cannot plan natively: `replan` and `realtime.Problem` both say it.
NEEDS_JAX_ROLLOUTS = (
    "a to_control hook (a policy in the loop: mjzoo.planning.prior.guided) needs the planner's "
    "rollouts in JAX, which C MuJoCo's cannot run; plan on MJX (backend 'mjx' or 'auto')"
)


def _as_partial(fn: Callable | None) -> jax.tree_util.Partial | None:
    if fn is None or isinstance(fn, jax.tree_util.Partial):
        return fn
    if not callable(fn):
        raise TypeError(f"Hooks: expected a callable, got {type(fn).__name__}")
    return jax.tree_util.Partial(fn)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Hooks:
    """Optional task hooks (see the module docstring); None means the identity / zeros.
    Plain functions are wrapped as `jax.tree_util.Partial`s, so numbers bound in a
    Partial are leaves and changing them does not recompile."""

    to_planner: Callable | None = None
    pre_rollout: Callable | None = None
    warm_start: Callable | None = None
    post_sim_step: Callable | None = None
    pre_sim_step: Callable | None = None
    post_rollout: Callable | None = None
    to_control: Callable | None = None

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            object.__setattr__(self, field.name, _as_partial(getattr(self, field.name)))


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Result:
    """A closed-loop run of T = num_replans x replan_every simulation steps.

    Attributes:
      states: `State` with a leading [T] axis: the simulation after each step.
      controls: [T, nu] the controls the simulation executed.
      costs: [T] -reward of each simulation step.
      plan_costs: [R] the planner's cost of its chosen plan at each replan.
      planner_state: the planner's state after the last replan.
    """

    states: State
    controls: Array
    costs: Array
    plan_costs: Array
    planner_state: PlannerState


def replan(
    planner: ModuleType,
    config: SamplingConfig,
    plan_task: Task | Ensemble,
    planner_state: PlannerState,
    sim_state: State,
    key: Array,
    hooks: Hooks = Hooks(),
    terminal_value: TerminalValue | None = None,
) -> PlannerState:
    """One replan from the simulated state, through the hooks, valuing final states by
    `terminal_value` if given."""
    if hooks.to_control is not None and isinstance(plan_task, Native):
        raise ValueError(f"closed_loop: {NEEDS_JAX_ROLLOUTS}")
    start = hooks.to_planner(sim_state) if hooks.to_planner else sim_state
    view = with_base(plan_task, lambda t: hooks.pre_rollout(t, start)) if hooks.pre_rollout else plan_task
    return planner.plan(config, view, planner_state, start, key, terminal_value=terminal_value)[0]


def after_rollout(hooks: Hooks, sim_state: State, planner_state: PlannerState) -> State:
    """The simulation state after a replan: through the post-rollout hook, if any."""
    return hooks.post_rollout(sim_state, planner_state) if hooks.post_rollout is not None else sim_state


def first_plan(
    planner: ModuleType,
    config: SamplingConfig,
    plan_task: Task | Ensemble,
    sim_state: State,
    hooks: Hooks = Hooks(),
    hyperparams: Any | None = None,
) -> PlannerState:
    """The planner's initial state holding `hyperparams` (None: the planner's defaults),
    with the task's warm-start knots if it supplies them."""
    if hooks.warm_start is None:
        return planner.init(config, plan_task, hyperparams)
    start = hooks.to_planner(sim_state) if hooks.to_planner else sim_state
    knots = hooks.warm_start(base_task(plan_task), start, config.num_knots)
    return planner.init(config, plan_task, hyperparams, knots=knots)


def sim_step(
    config: SamplingConfig,
    sim_task: Task | Native,
    planner_state: PlannerState,
    sim_state: State,
    key: Array,
    hooks: Hooks,
) -> tuple[State, Array]:
    """One simulation control step under the current plan: (next state, executed control);
    a `Native` simulation steps in C MuJoCo."""
    step_key, hook_key, pre_key = jax.random.split(key, 3)
    if hooks.pre_sim_step is not None:
        sim_state = hooks.pre_sim_step(base_task(sim_task), sim_state, pre_key)
    action = sampling.control_at(config, planner_state, sim_state.data.time, *sampling.control_limits(sim_task))
    if hooks.to_control is not None:
        action = hooks.to_control(base_task(sim_task), sim_state, action)
    step = transition_native if isinstance(sim_task, Native) else transition
    next_state = step(sim_task, sim_state, action, step_key)
    if hooks.post_sim_step is not None:
        next_state = hooks.post_sim_step(base_task(sim_task), next_state, hook_key)
    return next_state, action


@functools.partial(jax.jit, static_argnames=("planner", "config", "num_replans", "replan_every"))
def run(
    planner: ModuleType,
    config: SamplingConfig,
    sim_task: Task | Native,
    plan_task: Task | Ensemble | Native,
    sim_state: State,
    key: Array,
    num_replans: int,
    replan_every: int = 1,
    hooks: Hooks = Hooks(),
    terminal_value: TerminalValue | None = None,
    hyperparams: Any | None = None,
) -> Result:
    """Simulates `sim_task` from `sim_state` for `num_replans x replan_every` control
    steps, replanning with `planner` (a module: `predictive_sampling`, `cem`, `mppi`, `dial`, `cma_es`)
    on `plan_task` every `replan_every` steps (either may be `Native`: its physics in C
    MuJoCo, `mjzoo.planning.native`). One jit; `planner`, `config` and the
    counts are static. `terminal_value`: None or a `jax.tree_util.Partial`
    (`mjzoo.planning.as_terminal_value`), whose weights are arguments, not constants.
    `hyperparams`: the planner's `Hyperparams` (None: its defaults), also an argument:
    vmap the run over a batch of them to sweep them in one program."""
    sim_state = fill_transition_entries(base_task(sim_task), sim_state)
    planner_state = first_plan(planner, config, plan_task, sim_state, hooks, hyperparams)

    def period(carry, key):
        sim_state, planner_state = carry
        plan_key, sim_key = jax.random.split(key)
        planner_state = replan(planner, config, plan_task, planner_state, sim_state, plan_key, hooks, terminal_value)
        sim_state = after_rollout(hooks, sim_state, planner_state)

        def step(state: State, key: Array):
            next_state, control = sim_step(config, sim_task, planner_state, state, key, hooks)
            return next_state, (next_state, control)

        sim_state, (states, controls) = jax.lax.scan(step, sim_state, jax.random.split(sim_key, replan_every))
        return (sim_state, planner_state), (states, controls, planner_state.cost)

    (_, planner_state), (states, controls, plan_costs) = jax.lax.scan(
        period, (sim_state, planner_state), jax.random.split(key, num_replans)
    )
    flat = lambda x: x.reshape((num_replans * replan_every,) + x.shape[2:])  # noqa: E731
    states, controls = jax.tree.map(flat, states), flat(controls)
    return Result(states, controls, -states.reward, plan_costs, planner_state)
