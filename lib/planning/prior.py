"""A trained policy as a planner's prior: every replan searches around the policy's own
plan, and the horizon's end is valued by the policy's critic.

    prior = prior_lib.policy_prior(act, value)           # act: obs -> [nu]; value: obs -> []
    hooks = prior_lib.guided(hooks, config, prior)       # each replan starts from the policy's plan
    problem = Problem(mppi, config, sim, plan_task, seconds, hooks=hooks,
                      terminal_value=prior_lib.terminal_value(prior))

At each replan the policy is rolled out deterministically for the plan's horizon through
the planning task, from the state planned from, and its actions, read at the knots,
become the nominal plan: sample 0 of every sampling planner (`mppi`, `cem`,
`predictive_sampling`, `dial`, `cma_es`) and the mean the others are drawn around, or
`ilqr`'s starting plan. The critic's value of a rollout's final state is added to its
return (`mjzoo.planning.learned`): the planner optimizes the horizon plus what the
policy expects to collect after it. Nothing here is per planner: the prior is a hook of
the closed loop (`closed_loop.Hooks.guide`) and a terminal value, both pytrees whose
network weights are leaves, so new weights run without compiling again.
`mjzoo.harness.priors.from_run` builds one from a PPO or AMP run directory.
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import Callable

import jax
import jax.numpy as jnp

from mjzoo.planning import splines
from mjzoo.planning.closed_loop import Hooks
from mjzoo.planning.learned import committed
from mjzoo.planning.sampling import PlannerState
from mjzoo.planning.sampling import control_limits
from mjzoo.running import fill_transition_entries
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "PolicyPrior",
    "policy_prior",
    "from_learner",
    "rollout_actions",
    "nominal_knots",
    "terminal_value",
    "guide",
    "guided",
]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PolicyPrior:
    """A policy and its critic, each a `jax.tree_util.Partial` of one observation (the
    task's `State.obs`) whose bound network weights are leaves.

    Attributes:
      act: obs -> [nu] the deterministic action (the policy's mean).
      value: obs -> [] the expected return from there, in the task's reward units; None
        for a policy without a critic.
    """

    act: jax.tree_util.Partial
    value: jax.tree_util.Partial | None = None


Array = jax.Array


def policy_prior(act: Callable[[Any], Array], value: Callable[[Any], Array] | None = None) -> PolicyPrior:
    """A `PolicyPrior` of `act` and `value` (plain functions are wrapped as Partials;
    a Partial's arrays are committed, as a jitted planner's arguments must be)."""
    for name, fn in (("act", act), ("value", value)):
        if fn is not None and not callable(fn):
            raise TypeError(f"policy_prior: {name} must be a callable of one observation, got {type(fn).__name__}")
    wrap = lambda fn: fn if fn is None or isinstance(fn, jax.tree_util.Partial) else jax.tree_util.Partial(fn)  # noqa: E731
    return committed(PolicyPrior(wrap(act), wrap(value)))


def from_learner(learner: Any, config: Any, task: Task, train_state: Any) -> PolicyPrior:
    """The prior of a trained learner: `learner` an algorithm module with `policy` and
    `policy_params` (`mjzoo.algorithms.ppo`, `amp`), and `value` and `value_params` for
    a critic (PPO's), its `config`, the `task` it trained on and its `train_state`."""
    act = jax.tree_util.Partial(_Deterministic(learner.policy(config, task)), learner.policy_params(train_state))
    value = None
    if hasattr(learner, "value_params"):
        value = jax.tree_util.Partial(learner.value(config, task), learner.value_params(config, train_state))
    return policy_prior(act, value)


@dataclasses.dataclass(frozen=True)
class _Deterministic:
    """A deployable ``(params, obs, key) -> action`` policy as ``(params, obs) -> action``
    (the Partial's function: static, its params the leaves)."""

    policy: Callable

    def __call__(self, params: Any, obs: Any) -> Array:
        return self.policy(params, obs, jax.random.key(0))  # a deterministic policy ignores its key


def rollout_actions(prior: PolicyPrior, task: Task, state: State, horizon_steps: int, key: Array) -> Array:
    """[H, nu] the policy's actions rolled out for `horizon_steps` through `task` from
    `state` (its observation at each step), clipped to the control limits."""
    low, high = control_limits(task)

    def body(s: State, step_key: Array) -> tuple[State, Array]:
        action = jnp.clip(prior.act(s.obs), low, high)
        return transition(task, s, action, step_key), action

    start = fill_transition_entries(task, state)
    return jax.lax.scan(body, start, jax.random.split(key, horizon_steps))[1]


def nominal_knots(config: Any, prior: PolicyPrior, task: Task, state: State, key: Array) -> Array:
    """[K, nu] the policy's plan as a planner's knots: its rollout's actions
    (`rollout_actions`, `config.horizon_steps` of them) read linearly at the knots'
    positions (`config.num_knots`; one knot per step: the actions themselves)."""
    actions = rollout_actions(prior, task, state, config.horizon_steps, key)
    positions = splines.knot_positions(config.num_knots, config.horizon_steps)
    steps = jnp.arange(config.horizon_steps, dtype=jnp.float32)
    if config.horizon_steps == 1:
        return jnp.broadcast_to(actions[0], (config.num_knots, actions.shape[1]))
    return splines.interpolate(actions, steps, positions, "linear")


def _value_of_state(value: jax.tree_util.Partial, model: Any, state: State) -> Array:
    return jnp.asarray(value(state.obs), jnp.float32)


def terminal_value(prior: PolicyPrior) -> jax.tree_util.Partial | None:
    """The critic as a planner's `terminal_value` ``(model, state) -> []`` (None without one)."""
    if prior.value is None:
        return None
    return jax.tree_util.Partial(_value_of_state, prior.value)


@dataclasses.dataclass(frozen=True)
class _Guide:
    """`guide` for one planner config: frozen, so equal configs give equal (static) hooks."""

    config: Any

    def __call__(self, prior: PolicyPrior, plan_task: Task, start: State, planner_state: PlannerState):
        return guide(self.config, prior, plan_task, start, planner_state)


def guide(config: Any, prior: PolicyPrior, plan_task: Task, start: State, planner_state: PlannerState) -> PlannerState:
    """`planner_state` with the policy's plan from `start` as its knots, anchored at
    `start`'s time (so the planner's warm-start shift leaves it as it is). The policy's
    rollout uses fixed keys: the same nominal for the same state."""
    knots = nominal_knots(config, prior, plan_task, start, jax.random.key(0))
    return planner_state.replace(knots=knots.astype(planner_state.knots.dtype), time=start.data.time)


def guided(hooks: Hooks, config: Any, prior: PolicyPrior) -> Hooks:
    """`hooks` whose `guide` starts every replan of a planner configured by `config` from
    `prior`'s plan (the task's other hooks kept)."""
    if hooks.guide is not None:
        raise ValueError("planning.prior.guided: these hooks guide the planner already")
    return dataclasses.replace(hooks, guide=jax.tree_util.Partial(_Guide(config), prior))
