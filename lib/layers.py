"""The records stateful combinators keep in `State.layers`, and `find`, which reads one.

A combinator that keeps per-episode state (a step count, a command, a history) owns a
record type: a NamedTuple whose last field, ``inner``, holds the record of the next
stateful combinator inside it (``()`` below the innermost), as optax's
``MaskedState(inner_state)`` wraps its inner transformation's state:

    task = mjzoo.with_time_limit(mjzoo.with_auto_reset(mjzoo.with_time_limit(task, 3)), 10)
    state.layers  # TimeLimitState(steps=7, inner=AutoResetState(final_obs=..., inner=TimeLimitState(steps=1, inner=())))

Its step hands the task it wraps the state with its own record peeled off (`peel`) and
wraps what comes back (`wrap`); its reward and terminate peel the states they pass on.
Each level sees only its own record and those inside it, so any combinator can be
applied twice. Readers (a reward that tracks the command a command combinator draws,
a learner that needs auto-reset's final observation) ask for a record by its type:

    mjzoo.find(state, mjzoo.combinators.AutoResetState).final_obs

which returns the outermost record of that type the state holds.
"""

from __future__ import annotations

from typing import Any
from typing import Protocol
from typing import TypeVar

import jax

from mjzoo import tree
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Layer", "find", "peel", "wrap", "layered"]

Partial = jax.tree_util.Partial

R = TypeVar("R")


class Layer(Protocol):
    """What every combinator record has: the record of the combinator inside it."""

    inner: Any


def _records(layers: Any):
    while hasattr(layers, "inner"):
        yield layers
        layers = layers.inner


_MISSING = object()


def find(state: State, record_type: type[R], default: Any = _MISSING) -> R:
    """The outermost record of `record_type` in ``state.layers``, the one a reader at
    this level sees. Without one: `default` if given, else LookupError naming the
    records the state holds. Works on batched states too (a type, not a leaf)."""
    for record in _records(state.layers):
        if isinstance(record, record_type):
            return record
    if default is not _MISSING:
        return default
    held = [type(r).__name__ for r in _records(state.layers)] or "none"
    raise LookupError(
        f"find: the state holds no {record_type.__name__} (its combinators' records, outermost first: {held}); "
        f"wrap the task with the combinator that keeps it, inside the one that reads it"
    )


def peel(state: State, record_type: type[R]) -> tuple[R, State]:
    """This level's record (the outermost of `record_type` in ``state.layers``) and the
    state the wrapped task sees (``layers`` = the record's ``inner``).

    A combinator's own step always gets its record on top. Its reward or terminate may
    also be called on a state of an outer level, as when ``rewards.alive(task)`` is added
    to a task wrapped around `task`: the outer records, which this level cannot know,
    are skipped. Raises TypeError when the state holds no `record_type` at all."""
    record = find(state, record_type, None)
    if record is None:  # a task built wrongly, found while tracing
        held = [type(r).__name__ for r in _records(state.layers)]
        raise TypeError(f"expected this combinator's {record_type.__name__} in state.layers, which holds {held}")
    return record, state.replace(layers=record.inner)


def wrap(state: State, record: Layer) -> State:
    """`state` (as the wrapped task returned it) under this level's `record`, whose
    ``inner`` must be left out: it becomes ``state.layers``."""
    return state.replace(layers=record._replace(inner=state.layers))


def layered(
    task: Task,
    record_type: type,
    start: Partial,
    step: Partial,
    reward: Partial | None = None,
    terminate: Partial | None = None,
) -> Task:
    """`task` with this combinator's `start` and `step`, which keep a `record_type`
    record, and its `reward` and `terminate` (which peel the states they pass on);
    None: the wrapped task's own, handed the states with the record peeled off."""
    kind = tree.StaticValue(record_type)
    return task.replace(
        start=start,
        step=step,
        reward=Partial(_peeled_reward, task.reward, kind) if reward is None else reward,
        terminate=Partial(_peeled_terminate, task.terminate, kind) if terminate is None else terminate,
    )


def _peeled_reward(reward_fn, kind: tree.StaticValue, model, state: State, action, next_state: State):
    return reward_fn(model, peel(state, kind.value)[1], action, peel(next_state, kind.value)[1])


def _peeled_terminate(terminate_fn, kind: tree.StaticValue, model, state: State):
    return terminate_fn(model, peel(state, kind.value)[1])
