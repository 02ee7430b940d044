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

from mjzoo import tree
from mjzoo.types import State, Task, Trajectory

__all__ = ["reset", "transition", "rollout", "reward_terms", "Policy"]

Array = jax.Array
Policy = Callable[[Any, Array], Array]  # (obs, key) -> action


def transition(task: Task, state: State, action: Array, key: Array) -> State:
    """Steps `task` once from `state` with `action` ([nu]).

    Returns the next state with `reward` = the sum of the task's reward terms, each term
    also in `metrics["reward/<name>"]`, and `terminated` / `truncated` from the task.
    """
    next_state = task.step(task.model, state, action, key)
    terms = task.reward(task.model, state, action, next_state)
    terminated, truncated = task.terminate(task.model, next_state)
    reward = sum(terms.values(), jnp.zeros((), jnp.float32))
    return next_state.replace(
        reward=jnp.asarray(reward, jnp.float32),
        terminated=jnp.asarray(terminated, bool),
        truncated=jnp.asarray(truncated, bool),
        metrics={**next_state.metrics, **{f"reward/{k}": jnp.asarray(v, jnp.float32) for k, v in terms.items()}},
    )


def reward_terms(state: State) -> dict[str, Array]:
    """The weighted reward terms of the transition that produced `state`, by name."""
    prefix = "reward/"
    return {k[len(prefix) :]: v for k, v in state.metrics.items() if k.startswith(prefix)}


def reset(task: Task, key: Array) -> State:
    """Starts an episode of `task`.

    The state returned has the same pytree structure as every state `transition` can
    produce from it (same `info` and `metrics` keys, shapes and dtypes); entries that
    only a transition writes start at zero. This is what lets states be carried through
    `lax.scan` and selected between with `jnp.where` (auto-reset).
    """
    state = task.reset(task.model, key)
    action = jnp.zeros((task.action_size,), jnp.float32)
    shape = jax.eval_shape(lambda s, k: transition(task, s, action, k), state, key)
    return state.replace(
        info=tree.fill_missing(state.info, shape.info),
        metrics=tree.fill_missing(state.metrics, shape.metrics),
    )


def rollout(
    task: Task, policy: Policy, state: State, key: Array, num_steps: int
) -> tuple[State, Trajectory]:
    """Runs `policy(obs, key) -> action` for `num_steps` transitions with `lax.scan`.

    `num_steps` must be static under jit. Returns the final state and the `Trajectory`
    ([num_steps, ...] on every leaf). Episodes are not reset unless the task does so
    (`with_auto_reset`).
    """

    def body(state: State, key: Array) -> tuple[State, Trajectory]:
        policy_key, step_key = jax.random.split(key)
        action = policy(state.obs, policy_key)
        next_state = transition(task, state, action, step_key)
        return next_state, Trajectory(obs=state.obs, action=action, next_state=next_state)

    return jax.lax.scan(body, state, jax.random.split(key, num_steps))
