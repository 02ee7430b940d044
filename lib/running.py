"""Running a task: `reset`, `transition` and `rollout`, for one environment.

`transition` is the single place where a step becomes a transition (dynamics, then
reward terms, then termination). Reinforcement learning and sampling-based planners
both go through it, so one reward serves learning and planning. Batch with
`jax.vmap`; jit with the task as an ordinary argument.
"""

from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp

from mjzoo import checks, tree
from mjzoo.types import State, Task, Trajectory

__all__ = [
    "reset",
    "complete",
    "transition",
    "transition_with_terms",
    "rollout",
    "reward_terms",
    "control_dt",
    "Policy",
]

Array = jax.Array
OUTCOME = "outcome"  # info key through which a step may hand a whole transition's outcome
# to its own reward and terminate (see combinators.py); `transition` consumes it.
Policy = Callable[[Any, Array], Array]  # (obs, key) -> action


def transition(task: Task, state: State, action: Array, key: Array) -> State:
    """Steps `task` once from `state` with `action` ([nu]).

    Returns the next state with `reward` = the sum of the task's reward terms, each term
    also in `metrics["reward/<name>"]`, and `terminated` / `truncated` from the task.
    """
    return transition_with_terms(task, state, action, key)[0]


def transition_with_terms(task: Task, state: State, action: Array, key: Array) -> tuple[State, dict[str, Array]]:
    """`transition`, also returning this task's reward terms by name (float32 scalars)."""
    if jnp.shape(action) != (task.action_size,):  # no silent broadcasting of a wrong action
        raise ValueError(
            f"transition: the action has shape {jnp.shape(action)}, but the task takes "
            f"({task.action_size},): one number per actuator of its model"
        )
    next_state = task.step(task.model, state, action, key)
    terms = _scalar_terms(task.reward(task.model, state, action, next_state))
    terminated, truncated = _two_flags(task.terminate(task.model, next_state))
    reward = sum(terms.values(), jnp.zeros((), jnp.float32))
    next_state = next_state.replace(
        info={k: v for k, v in next_state.info.items() if k != OUTCOME},
        reward=reward,
        terminated=jnp.asarray(terminated, bool),
        truncated=jnp.asarray(truncated, bool),
        metrics={**next_state.metrics, **{f"reward/{k}": v for k, v in terms.items()}},
    )
    return next_state, terms


def _scalar_terms(terms: dict) -> dict[str, Array]:
    """The reward terms as float32 scalars; a term of another shape is named (summing it
    would broadcast the reward, found only later as a `lax.scan` carry mismatch)."""
    if not isinstance(terms, dict):
        raise TypeError(f"transition: the task's reward must return a dict of named terms, got {type(terms).__name__}")
    for name, value in terms.items():
        if jnp.shape(value) != ():
            raise ValueError(
                f"transition: reward term {name!r} has shape {jnp.shape(value)}; each term must be "
                "a scalar (reduce it, e.g. jnp.sum or jnp.mean)"
            )
    return {k: jnp.asarray(v, jnp.float32) for k, v in terms.items()}


def _two_flags(flags) -> tuple[Array, Array]:
    """terminate's (terminated, truncated) as bool scalars, or a clear error."""
    shapes = [jnp.shape(f) for f in flags] if isinstance(flags, (tuple, list)) else None
    if shapes is None or len(shapes) != 2 or any(s != () for s in shapes):
        got = f"shapes {shapes}" if shapes is not None else f"one value of shape {jnp.shape(flags)}"
        raise ValueError(f"transition: the task's terminate must return two scalars (terminated, truncated), got {got}")
    return jnp.asarray(flags[0], bool), jnp.asarray(flags[1], bool)


def reward_terms(state: State) -> dict[str, Array]:
    """The weighted reward terms of the transition that produced `state`, by name, as
    recorded in its metrics by the outermost `transition`."""
    prefix = "reward/"
    return {k[len(prefix) :]: v for k, v in state.metrics.items() if k.startswith(prefix)}


def reset(task: Task, key: Array) -> State:
    """Starts an episode of `task`: ``task.reset(task.model, key)``, a state `complete`
    for it."""
    return task.reset(task.model, key)


def complete(task: Task, state: State) -> State:
    """`state` with every `info` and `metrics` entry a transition of `task` writes.

    Entries it lacks are added as zeros, so that the state has the same pytree
    structure as every state `transition` can produce from it (same keys, shapes and
    dtypes). This is what lets states be carried through `lax.scan` and selected
    between with `jnp.where` (auto-reset). Adds no computation: the structure comes
    from `jax.eval_shape`.
    """
    shape = _transition_shape(task, state)
    _check_observation(state.obs, shape.obs)
    return state.replace(
        info=tree.fill_missing(state.info, shape.info),
        metrics=tree.fill_missing(state.metrics, shape.metrics),
    )


def _check_observation(reset_obs, step_obs) -> None:
    """Raises unless a step observes what the episode's first state does (same pytree
    structure, shapes and dtypes), naming the first leaf that differs."""
    reset_leaves, reset_tree = jax.tree_util.tree_flatten_with_path(reset_obs)
    step_leaves, step_tree = jax.tree_util.tree_flatten_with_path(step_obs)
    if reset_tree != step_tree:
        raise ValueError(f"the observation's structure differs between reset ({reset_tree}) and step ({step_tree})")
    for (path, a), (_, b) in zip(reset_leaves, step_leaves):
        (sa, da), (sb, db) = (jnp.shape(a), jnp.result_type(a)), (jnp.shape(b), jnp.result_type(b))
        if (sa, da) != (sb, db):
            raise ValueError(
                f"the observation{jax.tree_util.keystr(path)} differs between reset ({da}{list(sa)}) "
                f"and step ({db}{list(sb)}): a step must observe what the reset does"
            )


_SHAPES: dict = {}


def _transition_shape(task: Task, state: State) -> State:
    """`jax.eval_shape` of a transition, memoized on the shapes and dtypes of its inputs:
    nested combinators ask for the same structures many times while tracing. Not on
    their shardings, which shapes do not depend on: a task replicated over devices
    would trace its step once more."""
    inputs = (task, state)
    avals = (jax.typeof(x) for x in jax.tree.leaves(inputs))
    signature = (jax.tree.structure(inputs), tuple((a.shape, a.dtype, a.weak_type) for a in avals))
    if signature not in _SHAPES:
        if len(_SHAPES) > 1024:
            _SHAPES.clear()
        action = jnp.zeros((task.action_size,), jnp.float32)
        _SHAPES[signature] = jax.eval_shape(lambda s: transition(task, s, action, jax.random.key(0)), state)
    return _SHAPES[signature]


def rollout(task: Task, policy: Policy, state: State, key: Array, num_steps: int) -> tuple[State, Trajectory]:
    """Runs `policy(obs, key) -> action` for `num_steps` transitions with `lax.scan`.

    `num_steps` must be static under jit. Returns the final state and the `Trajectory`
    ([num_steps, ...] on every leaf). Episodes are not reset unless the task does so
    (`with_auto_reset`).
    """
    checks.key("mjzoo.rollout", key)
    num_steps = checks.integer("mjzoo.rollout", "num_steps", num_steps)

    def body(state: State, key: Array) -> tuple[State, Trajectory]:
        policy_key, step_key = jax.random.split(key)
        action = policy(state.obs, policy_key)
        next_state = transition(task, state, action, step_key)
        return next_state, Trajectory(obs=state.obs, action=action, next_state=next_state)

    return jax.lax.scan(body, state, jax.random.split(key, num_steps))


def control_dt(task: Task) -> float:
    """A task's control step (s), measured on the host from one transition from a reset."""
    state = reset(task, jax.random.key(0))
    after = jax.jit(lambda s: task.step(task.model, s, jnp.zeros(task.action_size), jax.random.key(0)))(state)
    return float(after.data.time - state.data.time)
