"""Named task parameters: read and change a task's numbers by name, for any task.

    mjzoo.params(task)                       # {"reach_weight": Array(1.), ...}
    task = task.with_params(reach_weight=2.0)  # same structure: no retrace

A task's numbers are pytree leaves of its four functions. A leaf has a name when the
last step of its path is a dict key or a dataclass attribute (`Params.reach_weight` in
`envs/point_mass.py`, a key of the params dict of `mjzoo.task`); numbers bound by
position (most combinators' and catalog items') have none. `with_params` replaces every
leaf of a name (a task binds its parameters into each of its functions) with an array
of the same shape and dtype, so a jitted function of the task does not recompile.

The physics model is not searched (edit ``task.model`` for masses and gains), nor the
`time_limit` of tasks held inside combinators (use `with_time_limit`).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from mjzoo.types import Task

__all__ = ["params", "with_params"]

Array = jax.Array
_FUNCTIONS = ("start", "step", "reward", "terminate")
_SKIPPED = (mjx.Model, mjx.Data)  # physics is edited through task.model, not by name


def params(task: Task) -> dict[str, Array]:
    """The task's named numbers: ``{name: value}``, in the order first found (where a name
    has several leaves, as when a task binds its parameters into all four functions, the
    first one's value)."""
    found: dict[str, Array] = {}
    for path, leaf in _named_leaves(task):
        found.setdefault(_name(path), leaf)
    return found


def with_params(task: Task, **values: Any) -> Task:
    """`task` with every leaf named like a keyword replaced by that value.

    Each value takes the shape of the leaves it replaces (a number for a [] leaf) and is
    cast to their dtype. Raises KeyError for a name the task lacks (listing the names
    it has) and ValueError for a value of another shape.
    """
    known = params(task)
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise KeyError(
            f"with_params: the task has no parameter named {', '.join(map(repr, unknown))}; "
            f"its named parameters: {', '.join(known) or 'none'}"
        )

    def replace(path, leaf):
        name = _name(path)
        if name not in values or isinstance(leaf, _SKIPPED):
            return leaf
        shape, dtype = np.shape(leaf), getattr(leaf, "dtype", None) or np.asarray(leaf).dtype
        new = np.asarray(values[name])
        if new.shape != shape:
            raise ValueError(
                f"with_params: {name}={values[name]!r} has shape {new.shape}, but the task's "
                f"{name} has shape {shape} ({jax.tree_util.keystr(path)})"
            )
        return jnp.asarray(new, dtype)

    functions = {f: getattr(task, f) for f in _FUNCTIONS}
    return task.replace(**jax.tree_util.tree_map_with_path(replace, functions, is_leaf=_is_skipped))


def _named_leaves(task: Task) -> list[tuple[tuple, Any]]:
    functions = {f: getattr(task, f) for f in _FUNCTIONS}
    leaves = jax.tree_util.tree_flatten_with_path(functions, is_leaf=_is_skipped)[0]
    return [(path, leaf) for path, leaf in leaves if not isinstance(leaf, _SKIPPED) and _name(path)]


def _is_skipped(node) -> bool:
    return isinstance(node, _SKIPPED)


def _name(path: tuple) -> str | None:
    """The leaf's name: the last key of its path if that is a dict key (a string) or a
    dataclass attribute, except the `time_limit` of a nested Task."""
    last = path[-1] if path else None
    if isinstance(last, jax.tree_util.DictKey) and isinstance(last.key, str):
        return last.key
    if isinstance(last, jax.tree_util.GetAttrKey) and last.name != "time_limit":
        return last.name
    return None
