"""The two data types everything else is written against: `Task` and `State`.

A `Task` is an immutable pytree holding a physics model and four pure functions.
The functions are `jax.tree_util.Partial`s over module-level functions, so every
number they use (weights, targets, limits, noise scales) is a pytree leaf: a Task
passes through `jax.jit` as an ordinary argument, changing a weight or a mass does
not recompile, and tasks can be stacked and vmapped.

Everything is written for ONE environment; algorithms batch with `jax.vmap`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Protocol

import jax
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from mjzoo import checks

__all__ = ["Task", "State", "Trajectory", "StartFn", "StepFn", "RewardFn", "TerminateFn"]

Array = jax.Array
PyTree = Any


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class State:
    """The state of one environment after a reset or a transition.

    Attributes:
      data: the MJX physics state.
      obs: the observation the next action is chosen from (any pytree of arrays).
      reward: scalar float32, the summed reward of the transition that produced this
        state (0 after a reset).
      terminated: scalar bool, the episode ended in a terminal state (no bootstrap).
      truncated: scalar bool, the episode was cut short (e.g. a time limit): bootstrap.
      info: dict of per-episode state kept by the task and its combinators, each under
        its own key (goal, step count, randomized physics, ...).
      metrics: dict of scalars describing the last transition, for logging; holds each
        reward term under ``"reward/<name>"``.
    """

    data: mjx.Data
    obs: PyTree
    reward: Array
    terminated: Array
    truncated: Array
    info: dict[str, PyTree]
    metrics: dict[str, Array]

    def replace(self, **changes: Any) -> "State":
        return dataclasses.replace(self, **changes)

    @classmethod
    def create(cls, data: mjx.Data, obs: PyTree, info: dict | None = None) -> "State":
        """A freshly reset state: zero reward, not done, empty metrics."""
        return cls(
            data=data,
            obs=obs,
            reward=jnp.zeros((), jnp.float32),
            terminated=jnp.zeros((), bool),
            truncated=jnp.zeros((), bool),
            info=dict(info or {}),
            metrics={},
        )


class StartFn(Protocol):
    def __call__(self, model: mjx.Model, key: Array) -> State: ...


class StepFn(Protocol):
    def __call__(self, model: mjx.Model, state: State, action: Array, key: Array) -> State: ...


class RewardFn(Protocol):
    def __call__(self, model: mjx.Model, state: State, action: Array, next_state: State) -> dict[str, Array]: ...


class TerminateFn(Protocol):
    def __call__(self, model: mjx.Model, state: State) -> tuple[Array, Array]: ...


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Task:
    """A control problem as data: physics plus four pure functions.

    Start an episode with ``task.reset(model, key)`` (or ``mjzoo.reset(task, key)``):
    the `start` function's state, completed so that it has the pytree structure of
    every state a transition makes from it. `lax.scan` over `mjzoo.transition` from it
    just works; combinators wrap `start`, the function a task's own code writes.

    Attributes:
      model: the MJX model the functions are called with.
      start: ``(model, key) -> State``, how an episode starts, as the task's own code
        writes it: it need not hold the `info` and `metrics` entries only a transition
        writes (the reward terms, an inner combinator's records).
      step: ``(model, state, action, key) -> State``, dynamics and observation. The
        action has shape ``(action_size,)``: by default a control per actuator, in its
        ctrlrange.
      reward: ``(model, state, action, next_state) -> {name: weighted term}``, each term
        a float32 scalar; `mjzoo.transition` sums them.
      terminate: ``(model, state) -> (terminated, truncated)``, two bool scalars kept
        apart because value bootstrapping differs between them.
      mj_model: the host `mujoco.MjModel` the MJX model was made from (static: names,
        rendering). Never traced; treat it as read-only.
      action_dim: static length of an action where it is not one control per actuator
        (PD position and velocity targets take 2 nu); None: nu. Read `action_size`.
      time_limit: int32 scalar, the number of this task's steps after which an episode
        is truncated, set by `with_time_limit` (and kept in step units by
        `with_action_repeat`); None: episodes have no limit. A leaf, so tasks with
        other limits share a trace; read it on the host (`int(task.time_limit)`) for a
        static length, e.g. how long evaluation runs.
      motion: the motion the task's agent should move like (`mjzoo.motion.Reference`:
        clips at the task's control rate, as JAX arrays), set by
        `mjzoo.motion.with_reference`; AMP's discriminator learns from it and style
        measures compare with it. None: the task has none.
    """

    model: mjx.Model
    start: StartFn
    step: StepFn
    reward: RewardFn
    terminate: TerminateFn
    mj_model: mujoco.MjModel = dataclasses.field(metadata=dict(static=True))
    action_dim: int | None = dataclasses.field(default=None, metadata=dict(static=True))
    time_limit: Array | None = None
    motion: Any = None

    def replace(self, **changes: Any) -> "Task":
        return dataclasses.replace(self, **changes)

    def reset(self, model: mjx.Model, key: jax.Array) -> State:
        """A new episode: ``start(model, key)`` with every `info` and `metrics` entry a
        transition of this task writes added as zeros (`mjzoo.complete`)."""
        from mjzoo.running import complete  # running is built on this module

        checks.key("mjzoo.reset", key)
        return complete(self.replace(model=model), self.start(model, key))

    def with_params(self, **values: Any) -> "Task":
        """This task with its named numbers changed (`mjzoo.with_params`): same pytree
        structure, so jitted functions of it do not recompile."""
        from mjzoo.parameters import with_params  # built on this module

        return with_params(self, **values)

    @property
    def action_size(self) -> int:
        """Length of the action vector: one control per actuator unless `action_dim` says."""
        return int(self.mj_model.nu) if self.action_dim is None else self.action_dim


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Trajectory:
    """A stacked sequence of T transitions, as returned by `mjzoo.rollout`.

    Attributes:
      obs: [T, ...] observation each action was chosen from.
      action: [T, nu] the actions taken.
      next_state: `State` with a leading [T] axis on every leaf: the state after each
        action, carrying that transition's reward, terminated, truncated and metrics.
    """

    obs: PyTree
    action: Array
    next_state: State


def bind(fn: Callable, *params: PyTree) -> jax.tree_util.Partial:
    """Binds a module-level function to its parameters so they become pytree leaves."""
    return jax.tree_util.Partial(fn, *params)
