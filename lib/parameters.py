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

import jax

from mjzoo import tree
from mjzoo.types import FUNCTIONS
from mjzoo.types import PHYSICS
from mjzoo.types import UNNAMED
from mjzoo.types import Task

__all__ = ["params", "with_params"]

Array = jax.Array


def params(task: Task) -> dict[str, Array]:
    """The task's named numbers: ``{name: value}``, in the order first found (where a name
    has several leaves, as when a task binds its parameters into all four functions, the
    first one's value)."""
    return tree.named({f: getattr(task, f) for f in FUNCTIONS}, skip=PHYSICS, unnamed=UNNAMED)


def with_params(task: Task, **values) -> Task:
    """`task` with every leaf named like a keyword replaced by that value.

    Each value takes the shape of the leaves it replaces (a number for a [] leaf) and is
    cast to their dtype. Raises KeyError for a name the task lacks (listing the names
    it has) and ValueError for a value of another shape. The same as
    ``task.with_params(**values)``.
    """
    return task.with_params(**values)
