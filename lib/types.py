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
from typing import Any
from typing import NamedTuple
from typing import Protocol

import jax
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from mjzoo import checks
from mjzoo import tree

__all__ = ["Task", "State", "Outcome", "Trajectory", "StartFn", "StepFn", "RewardFn", "TerminateFn"]

Array = jax.Array
PyTree = Any
FUNCTIONS = ("start", "step", "reward", "terminate")  # a Task's functions, where its named numbers live
PHYSICS = (mjx.Model, mjx.Data)  # physics is edited through task.model, not by name
UNNAMED = ("time_limit",)  # the time limit of a Task held inside a combinator is not a parameter


class Outcome(NamedTuple):
    """A whole transition's result, handed from a step that ran transitions of an inner
    task (auto-reset, action repeat, the divergence guard) to its own reward and
    terminate (`mjzoo.combinators.runs_transitions`).

    Attributes:
      terms: the reward terms by name, float32 scalars.
      terminated: bool scalar.
      truncated: bool scalar.
    """

    terms: dict[str, Array]
    terminated: Array
    truncated: Array


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
      info: dict of the task's own per-episode entries, those its start and reset items
        write (a goal, a target, a reference frame).
      metrics: dict of scalars describing the last transition, for logging; holds each
        reward term under ``"reward/<name>"``.
      layers: the records of the stateful combinators wrapped around the task, nested:
        the outermost combinator's record, holding the next one's as its ``inner``
        field, down to ``()`` (a bare task has ``()``). Each combinator hands the task it
        wraps the state with its own record peeled off, so it sees only its own level
        and below; find a record by its type with `mjzoo.find`.
      outcome: None in every state a reset or transition returns. Set only between a
        step that ran whole transitions of an inner task and the `mjzoo.transition`
        that consumes it (`Outcome`).
    """

    data: mjx.Data
    obs: PyTree
    reward: Array
    terminated: Array
    truncated: Array
    info: dict[str, PyTree]
    metrics: dict[str, Array]
    layers: PyTree = ()
    outcome: Outcome | None = None

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
        writes (the reward terms); each combinator's start adds its record to `layers`.
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
    """

    model: mjx.Model
    start: StartFn
    step: StepFn
    reward: RewardFn
    terminate: TerminateFn
    mj_model: mujoco.MjModel = dataclasses.field(metadata=dict(static=True))
    action_dim: int | None = dataclasses.field(default=None, metadata=dict(static=True))
    time_limit: Array | None = None

    def replace(self, **changes: Any) -> "Task":
        return dataclasses.replace(self, **changes)

    def reset(self, model: mjx.Model, key: jax.Array) -> State:
        """A new episode: ``start(model, key)`` with every `info` and `metrics` entry a
        transition of this task writes added as zeros (`mjzoo.fill_transition_entries`)."""
        checks.key("mjzoo.reset", key)
        return fill_transition_entries(self.replace(model=model), self.start(model, key))

    def with_params(self, **values: Any) -> "Task":
        """This task with its named numbers changed (`mjzoo.with_params`): same pytree
        structure, so jitted functions of it do not recompile."""
        functions = {f: getattr(self, f) for f in FUNCTIONS}
        return self.replace(**tree.with_named(functions, values, "with_params", skip=PHYSICS, unnamed=UNNAMED))

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


# --- one transition: what a Task's four functions mean together ----------------------
# Here, not in `running`, because `Task.reset` completes its state with the structure of
# a transition: the core stays free of import cycles. `mjzoo.running` exports them.


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
        outcome=None,  # consumed: carried states never hold one
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


def fill_transition_entries(task: Task, state: State) -> State:
    """`state` with every `info` and `metrics` entry a transition of `task` writes.

    Entries it lacks are added as zeros, so that the state has the same pytree
    structure as every state `transition` can produce from it (same keys, shapes and
    dtypes). This is what lets states be carried through `lax.scan` and selected
    between with `jnp.where` (auto-reset). The combinators' records (`layers`) come
    whole from their resets: a difference there is an error. Adds no computation: the
    structure comes from `jax.eval_shape`.
    """
    shape = _transition_shape(task, state)
    checks.same_observation(state.obs, shape.obs)
    _check_layers(state.layers, shape.layers)
    return state.replace(
        info=tree.fill_missing(state.info, shape.info),
        metrics=tree.fill_missing(state.metrics, shape.metrics),
    )


def _check_layers(reset_layers, step_layers) -> None:
    """Raises unless a step returns the combinators' records its reset made (same
    types, nesting, shapes and dtypes): a combinator's start and step disagree."""
    signature = lambda x: (jnp.shape(x), jnp.result_type(x))  # noqa: E731
    reset_sig = jax.tree.map(signature, reset_layers)
    step_sig = jax.tree.map(signature, step_layers)
    if jax.tree.structure(reset_layers) != jax.tree.structure(step_layers) or reset_sig != step_sig:
        raise ValueError(
            "the combinators' records (state.layers) differ between reset and step: "
            f"reset {reset_sig}, step {step_sig}; each combinator's step must return the record its start makes"
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
