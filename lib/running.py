"""Running a task: `reset`, `transition` and `rollout`, for one environment.

`transition` is the single place where a step becomes a transition (dynamics, then
reward terms, then termination); it is defined next to `Task` (mjzoo.types), whose
`reset` needs its structure, and exported here. Reinforcement learning and sampling-based planners
both go through it, so one reward serves learning and planning. Batch with
`jax.vmap`; jit with the task as an ordinary argument.
"""

from __future__ import annotations

from typing import Any
from typing import Callable

import jax
import jax.numpy as jnp

from mjzoo import checks
from mjzoo.types import State
from mjzoo.types import Task
from mjzoo.types import Trajectory
from mjzoo.types import fill_transition_entries
from mjzoo.types import transition
from mjzoo.types import transition_with_terms

__all__ = [
    "reset",
    "fill_transition_entries",
    "transition",
    "transition_with_terms",
    "rollout",
    "reward_terms",
    "control_dt",
    "episode_steps",
    "Policy",
]

Array = jax.Array
Policy = Callable[[Any, Array], Array]  # (obs, key) -> action


def reward_terms(state: State) -> dict[str, Array]:
    """The weighted reward terms of the transition that produced `state`, by name, as
    recorded in its metrics by the outermost `transition`."""
    prefix = "reward/"
    return {k[len(prefix) :]: v for k, v in state.metrics.items() if k.startswith(prefix)}


def reset(task: Task, key: Array) -> State:
    """Starts an episode of `task`: ``task.reset(task.model, key)``, a state `fill_transition_entries`
    for it."""
    return task.reset(task.model, key)


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


def episode_steps(task: Task, who: str = "episode_steps", instead: str = "num_steps") -> int:
    """The task's own episode length, ``int(task.time_limit)``, read on the host: the one
    place every evaluation, CLI command and closed loop reads it (`learning.evaluate`'s
    default length).

    Raises ValueError (``"{who}: ...; give {instead}"``) if the task has no time limit,
    TypeError if it is traced (under jit the limit is not a number yet: read it outside,
    pass it as a static argument).
    """
    if task.time_limit is None:
        raise ValueError(
            f"{who}: the task has no time limit (mjzoo.with_time_limit) to end its episodes; give {instead}"
        )
    if isinstance(task.time_limit, jax.core.Tracer):
        raise TypeError(
            "episode_steps: the task's time limit is traced (inside jit); read it outside "
            "with int(task.time_limit) and pass num_steps as a static argument"
        )
    return int(task.time_limit)
