"""Curricula, `Task -> Task`: a level in [0, 1], per environment, that moves the task's
numbers (push size, noise, latency, terrain roughness, ...) from easy to hard.

    def make(level: float) -> Task:
        pushed = events.with_velocity_pushes(base, linear=(level * 1.0, level * 1.0, 0.0))
        return mjzoo.with_auto_reset(mjzoo.with_time_limit(pushed, 1000))

    task = curriculum.with_curriculum(make, curriculum.by_episode_length(1000))

How the level reaches the numbers: `make(level)` builds the task at a level; it is called
on the host at levels 0, 0.5 and 1 (so constructors validate plain floats as usual), and
the float leaves that differ between levels 0 and 1 are interpolated at run time,
``leaf(level) = leaf(0) + level * (leaf(1) - leaf(0))``. Each such leaf must therefore be
affine in the level (checked with level 0.5: a ValueError names any leaf that is not),
integer and bool leaves must not depend on it, and the pytree structure must not either.
Only the leaves that move are batched per environment under `jax.vmap`; physics model
fields may move too.

Where it sits: OUTSIDE `with_auto_reset` (inside `make`), so the level survives episode
ends. Keeps a `CurriculumState` (``level``: float32 [], ``memory``: the rule's state);
the level of a new environment (`reset`) is the rule's `initial`. Metric:
``curriculum/level``, the level the transition ran at.

Rules say how the level moves after each transition (`by_steps`, `by_episode_length`,
`by_distance`); a `Rule` is data, so new ones are easy to write.
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import checks
from mjzoo import names
from mjzoo import tree
from mjzoo.combinators import record
from mjzoo.combinators import runs_transitions
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.running import transition_with_terms
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["with_curriculum", "CurriculumState", "Rule", "by_steps", "by_episode_length", "by_distance"]

Array = jax.Array
PyTree = Any
_LEVELS = (0.0, 0.5, 1.0)  # make() is called at these levels


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Rule:
    """How a curriculum level moves.

    Attributes:
      initial: float32 [], the level of a new environment.
      start: ``(model, state) -> memory``, the rule's state at reset (a pytree).
      update: ``(memory, level, model, state, next_state) -> (level, memory)``, after each
        transition (`next_state` carries its terminated / truncated flags; with an
        auto-reset inside, an ended episode's `next_state` is the next episode's start).
    """

    initial: Array
    start: Callable[[mjx.Model, State], PyTree]
    update: Callable[..., tuple[Array, PyTree]]


# --- the combinator -----------------------------------------------------------------


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class _Ramp:
    """The leaves of a pytree that move with the level: leaf i -> leaf i + level * delta."""

    delta: tuple[Array, ...]
    index: tuple[int, ...] = dataclasses.field(metadata=dict(static=True))

    def at(self, tree: PyTree, level: Array) -> PyTree:
        leaves, treedef = jax.tree.flatten(tree)
        for i, delta in zip(self.index, self.delta):
            leaves[i] = leaves[i] + (level * delta).astype(leaves[i].dtype)
        return jax.tree.unflatten(treedef, leaves)


def _ramp(trees: list[PyTree], what: str) -> _Ramp:
    """Which leaves of `trees` (the same pytree at levels 0, 0.5, 1) move, and how much."""
    leaves = [[np.asarray(x) for x in jax.tree.leaves(t)] for t in trees]
    index, delta = [], []
    for i, name in enumerate(_leaf_names(trees[0], what)):
        a, m, b = (level[i] for level in leaves)
        if not a.shape == m.shape == b.shape or not a.dtype == m.dtype == b.dtype:
            raise ValueError(f"with_curriculum: {name} changes shape or dtype with the level")
        if np.array_equal(a, b) and np.array_equal(a, m):
            continue
        if not np.issubdtype(a.dtype, np.floating):
            raise ValueError(
                f"with_curriculum: {name} is a {a.dtype} number that changes with the level; "
                "only float numbers can follow a curriculum"
            )
        if not np.allclose(m, a + 0.5 * (b - a), rtol=1e-5, atol=1e-6):
            raise ValueError(f"with_curriculum: {name} is not affine in the level: {a} at 0, {m} at 0.5, {b} at 1")
        index.append(i)
        delta.append(jnp.asarray(b - a, a.dtype))
    return _Ramp(tuple(delta), tuple(index))


def _leaf_names(tree: PyTree, prefix: str) -> list[str]:
    """A readable path to every leaf, naming the function each bound number belongs to."""
    partial = jax.tree_util.Partial
    names = []
    for path, node in jax.tree_util.tree_flatten_with_path(tree, is_leaf=lambda x: isinstance(x, partial))[0]:
        here = prefix + jax.tree_util.keystr(path)
        if isinstance(node, partial):
            bound = (node.args, node.keywords) if node.keywords else node.args  # same leaf order
            names += _leaf_names(bound, f"{here}<{getattr(node.func, '__name__', 'fn')}>")
        else:
            names.append(here)
    return names


def with_curriculum(make: Callable[[float], Task], rule: Rule) -> Task:
    """The task ``make(level)`` with the level kept per environment and moved by `rule`.

    `make(level) -> Task` gives the task at a level in [0, 1]; see the module docstring
    for how its numbers follow the level. Raises ValueError when the tasks of different
    levels differ in structure or in a way the level cannot interpolate.
    """
    if not callable(make):
        raise TypeError(f"with_curriculum: make must be callable (level -> Task), got {type(make).__name__}")
    if not isinstance(rule, Rule):
        raise TypeError(f"with_curriculum: rule must be a curriculum.Rule (e.g. by_steps), got {type(rule).__name__}")
    tasks = [make(level) for level in _LEVELS]
    for level, task in zip(_LEVELS, tasks):
        if not isinstance(task, Task):
            raise TypeError(f"with_curriculum: make({level}) must return a Task, got {type(task).__name__}")
        if jax.tree.structure(task) != jax.tree.structure(tasks[0]):
            raise ValueError(
                f"with_curriculum: make({level}) and make(0.0) give tasks of different structure; "
                "the level may change numbers only"
            )
    functions = _ramp([t.replace(model=None) for t in tasks], "task")
    model = _ramp([t.model for t in tasks], "model")
    easy = tasks[0]
    stepped = runs_transitions(easy, _curriculum_step, functions, model, rule)
    return stepped.replace(start=Partial(_curriculum_reset, easy.replace(model=None), functions, model, rule))


def _at(inner: Task, functions: _Ramp, model_ramp: _Ramp, model: mjx.Model, level: Array) -> Task:
    return functions.at(inner, level).replace(model=model_ramp.at(model, level))


class CurriculumState(NamedTuple):
    """`with_curriculum`'s record: ``level``, float32 [] in [0, 1], and ``memory``, the
    rule's state."""

    level: Array
    memory: PyTree
    inner: Any = ()


def _curriculum_reset(inner, functions, model_ramp, rule, model, key) -> State:
    level = rule.initial
    task = _at(inner, functions, model_ramp, model, level)
    state = task.start(task.model, key)
    memory = rule.start(task.model, state)
    return wrap(state, CurriculumState(level=level, memory=memory))


def _curriculum_step(functions, model_ramp, rule, inner, model, state, action, key) -> State:
    own, state = peel(state, CurriculumState)
    task = _at(inner, functions, model_ramp, model, own.level)
    next_state, terms = transition_with_terms(task, state, action, key)
    level, memory = rule.update(own.memory, own.level, task.model, state, next_state)
    next_state = wrap(next_state, CurriculumState(level=jnp.clip(level, 0.0, 1.0), memory=memory)).replace(
        metrics={**next_state.metrics, "curriculum/level": own.level}
    )
    return record(next_state, terms, next_state.terminated, next_state.truncated)


# --- rules --------------------------------------------------------------------------


def _check(who: str, **values: float) -> dict[str, Array]:
    """Each value finite and >= 0; `initial` a level in [0, 1]."""
    return {
        k: checks.number(f"curriculum.{who}", k, v, 0.0, 1.0 if k == "initial" else np.inf) for k, v in values.items()
    }


def by_steps(ramp_steps: int) -> Rule:
    """level = min(1, steps / ramp_steps), steps = transitions this environment took
    (its own count: multiply by the number of environments for the total)."""
    ramp_steps = checks.integer("curriculum.by_steps", "ramp_steps", ramp_steps)
    return Rule(jnp.float32(0.0), Partial(_count_start), Partial(_by_steps, jnp.float32(ramp_steps)))


def _count_start(model, state) -> Array:
    return jnp.zeros((), jnp.int32)


def _by_steps(ramp_steps, steps, level, model, state, next_state):
    steps = steps + 1
    return jnp.minimum(1.0, steps / ramp_steps), steps


def _ended(next_state: State) -> Array:
    return next_state.terminated | next_state.truncated


def _move(level, ended, good, up, down) -> Array:
    return jnp.clip(level + jnp.where(ended, jnp.where(good, up, -down), 0.0), 0.0, 1.0)


def by_episode_length(
    max_steps: int, fraction: float = 0.8, up: float = 0.05, down: float = 0.05, initial: float = 0.0
) -> Rule:
    """At each episode end: level += up if the episode lasted >= fraction * max_steps
    transitions (of this task), else level -= down; clipped to [0, 1]. Memory: int32
    transitions of the current episode."""
    max_steps = checks.integer("curriculum.by_episode_length", "max_steps", max_steps)
    p = _check("by_episode_length", fraction=fraction, up=up, down=down, initial=initial)
    threshold = p["fraction"] * max_steps
    return Rule(p["initial"], Partial(_count_start), Partial(_by_episode_length, threshold, p["up"], p["down"]))


def _by_episode_length(threshold, up, down, steps, level, model, state, next_state):
    steps, ended = steps + 1, _ended(next_state)
    return _move(level, ended, steps >= threshold, up, down), jnp.where(ended, 0, steps)


def by_distance(
    mj_model: mujoco.MjModel,
    target: float,
    up: float = 0.05,
    down: float = 0.05,
    initial: float = 0.0,
    body: str | None = None,
    only_falls: bool = False,
) -> Rule:
    """At each episode end: level += up if the base moved >= `target` m (horizontal
    distance from where the episode started), else level -= down; clipped to [0, 1].
    With `only_falls`, an episode short of `target` lowers the level only if it ended by
    a termination (a fall), not by its time limit (the terrain curriculum's rule).

    The base is the free joint of `body` (None: the model's first). With an auto-reset
    inside, the last state of an episode is replaced by the next episode's start, so the
    distance is measured at the state before the final transition (one control step
    short). Memory: the episode's starting xy [2], m.
    """
    p = _check("by_distance", target=target, up=up, down=down, initial=initial)
    xy = jnp.asarray(names.free_joint_addresses(mj_model, body, "curriculum.by_distance")[0][:2])
    if not isinstance(only_falls, bool):
        raise TypeError(f"curriculum.by_distance: only_falls must be True or False, got {only_falls!r}")
    return Rule(
        p["initial"],
        Partial(_xy, xy),
        Partial(_by_distance, xy, p["target"], p["up"], p["down"], tree.StaticValue(only_falls)),
    )


def _xy(xy, model, state) -> Array:
    return state.data.qpos[xy]


def _by_distance(xy, target, up, down, only_falls, origin, level, model, state, next_state):
    ended = _ended(next_state)
    distance = jnp.linalg.norm(state.data.qpos[xy] - origin)
    if only_falls.value:  # short of the target and timed out: stay
        down = jnp.where(next_state.terminated, down, 0.0)
    return _move(level, ended, distance >= target, up, down), jnp.where(ended, next_state.data.qpos[xy], origin)
