"""Learned pieces a planner calls at run time, as pytrees, and the placement that lets a
host loop call a jitted planner with them without compiling it again.

A terminal value is a ``(model, state) -> value`` function (a critic: the value to go of
the rollout's final state) given as a `jax.tree_util.Partial`: its bound arrays, the
critic's weights, are pytree leaves, so a jitted `plan` takes new weights as new
arguments of the same shapes and never recompiles.

`jax.jit` compiles a function again when an argument that was *uncommitted* (fresh from
an eager op) comes back *committed* (an output of a jit whose inputs were): a host loop
that feeds `plan` its own planner state traces twice unless the first state is already
committed. `committed` places a tree where its arrays already are, committing them.
"""

from __future__ import annotations

from typing import Callable
from typing import TypeVar

import jax
import jax.numpy as jnp

from mjzoo.types import State

__all__ = ["TerminalValue", "as_terminal_value", "committed"]

Array = jax.Array
TerminalValue = Callable[[object, State], Array]  # (model, state) -> value to go, float32 scalar
Tree = TypeVar("Tree")


def committed(tree: Tree) -> Tree:
    """`tree` with each leaf an array committed to the device it is on (uncommitted
    arrays, numpy arrays and numbers: the default device). Traced trees are returned as
    they are: inside a jit placement is the compiler's."""
    leaves = jax.tree.leaves(tree)
    if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
        return tree

    def commit(leaf) -> Array:
        leaf = jnp.asarray(leaf)
        return leaf if leaf.committed else jax.device_put(leaf, leaf.device)

    return jax.tree.map(commit, tree)


def as_terminal_value(fn: TerminalValue | None) -> jax.tree_util.Partial | None:
    """`fn` as a terminal value a jitted planner takes as an argument: a plain function
    wrapped in a `jax.tree_util.Partial`, a Partial kept with its bound arrays committed
    (`committed`); None stays None (no terminal value).

    Raises:
      TypeError: `fn` is neither None nor callable.
    """
    if fn is None:
        return None
    if not callable(fn):
        raise TypeError(f"terminal_value must be a callable (model, state) -> value, got {type(fn).__name__}")
    return committed(fn if isinstance(fn, jax.tree_util.Partial) else jax.tree_util.Partial(fn))
