"""A trained policy as a planner's prior: the planner searches offsets to the policy's
own actions, applied in closed loop, and the horizon's end is valued by the policy's critic.

    prior = prior_lib.policy_prior(act, value)           # act: obs -> [nu]; value: obs -> []
    hooks = prior_lib.guided(hooks, prior)               # plans are offsets to the policy
    problem = Problem(mppi, config, sim, plan_task, seconds, hooks=hooks,
                      terminal_value=prior_lib.terminal_value(prior))

The plan is a *residual*: every rollout, and the simulation, applies
``policy(obs) + offset`` at each step, the policy reading the state it is in (the planning
view `residual`, and `closed_loop.Hooks.to_control` for the world). A zero offset is the
policy itself, exactly, whatever the knots, and perturbed rollouts keep its feedback; the
first plan is zero offsets. An open-loop replay of the policy's rollout read at the
knots, this module's former nominal plan, was neither: measured on the pendulum with 2
knots over the planning horizon, it lost the swing-up the policy makes (the numbers in
`benchmarks/guided_mpc.py`). The critic's value of a rollout's final state is added to
its return (`mjzoo.planning.learned`): the planner optimizes the horizon plus what the
policy expects to collect after it. Nothing here is per planner: every sampling planner
and `ilqr` plan offsets on the residual view, whose rollouts must run in JAX (MJX, not
C MuJoCo). The prior is a pytree whose network weights are leaves, so new weights run
without compiling again. `mjzoo.harness.cli.runs.policy_prior` builds one from a PPO or
AMP run directory.
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo.planning.closed_loop import Hooks
from mjzoo.planning.learned import committed
from mjzoo.planning.sampling import control_limits
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "PolicyPrior",
    "policy_prior",
    "from_learner",
    "centre",
    "applied",
    "residual",
    "terminal_value",
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


def centre(task: Task) -> np.ndarray:
    """[nu] the middle of each actuator's control range (0 where unlimited): the plan's
    zero offset on the `residual` view."""
    low, high = control_limits(task)
    return np.where(np.isfinite(high - low), (low + high) / 2, 0.0).astype(np.float32)


def applied(prior: PolicyPrior, middle: Array, state: State, control: Array) -> Array:
    """[nu] the control applied in `state` for a plan's `control` [nu] on the `residual`
    view: the policy's deterministic action on ``state.obs`` plus the offset ``control -
    middle`` ([nu] `centre`: the planner's control range, which it clips its plans to,
    bounds the offsets to +- half of it, and its middle is the policy itself)."""
    return prior.act(state.obs) + control - middle


def _residual_step(prior: PolicyPrior, middle: Array, step: Callable, model: Any, state: State, control, key) -> State:
    return step(model, state, applied(prior, middle, state, control), key)


def _residual_reward(prior: PolicyPrior, middle: Array, reward: Callable, model: Any, state: State, control, after):
    return reward(model, state, applied(prior, middle, state, control), after)


def residual(task: Task, prior: PolicyPrior) -> Task:
    """`task` whose control is an offset to `prior`'s action: its step and reward see the
    control `applied` in the state they start from, so a plan at the `centre` of the
    control range steps as the policy. The planning view of `guided`; the state is the
    task's own."""
    middle = jnp.asarray(centre(task))
    return task.replace(
        step=jax.tree_util.Partial(_residual_step, prior, middle, task.step),
        reward=jax.tree_util.Partial(_residual_reward, prior, middle, task.reward),
    )


def _value_of_state(value: jax.tree_util.Partial, model: Any, state: State) -> Array:
    return jnp.asarray(value(state.obs), jnp.float32)


def terminal_value(prior: PolicyPrior) -> jax.tree_util.Partial | None:
    """The critic as a planner's `terminal_value` ``(model, state) -> []`` (None without one)."""
    if prior.value is None:
        return None
    return jax.tree_util.Partial(_value_of_state, prior.value)


def _view(prior: PolicyPrior, inner: Callable | None, plan_task: Task, start: State) -> Task:
    """`pre_rollout`: the task's own view (if any), as a residual of the policy."""
    return residual(inner(plan_task, start) if inner is not None else plan_task, prior)


def _to_control(prior: PolicyPrior, sim_task: Task, sim_state: State, control: Array) -> Array:
    """`to_control`: the world applies the policy plus the plan's offset."""
    return applied(prior, jnp.asarray(centre(sim_task)), sim_state, control)


def _policy_first(plan_task: Task, start: State, num_knots: int) -> Array:
    """`warm_start`: the first plan is the policy itself (zero offsets)."""
    return jnp.broadcast_to(jnp.asarray(centre(plan_task)), (num_knots, plan_task.action_size))


def guided(hooks: Hooks, prior: PolicyPrior) -> Hooks:
    """`hooks` with which a planner plans offsets to `prior`'s actions, applied in closed
    loop: its rollouts on the `residual` view (after the task's own `pre_rollout`), the
    world applying the policy plus the plan (`to_control`), the first plan the policy
    itself (in place of the task's own warm start, which is in controls). The planning
    task must step in JAX: `closed_loop.run` and `realtime.Problem` refuse C MuJoCo's."""
    if hooks.to_control is not None:
        raise ValueError("planning.prior.guided: these hooks guide the planner already")
    return dataclasses.replace(
        hooks,
        pre_rollout=jax.tree_util.Partial(_view, prior, hooks.pre_rollout),
        warm_start=jax.tree_util.Partial(_policy_first),
        to_control=jax.tree_util.Partial(_to_control, prior),
    )
