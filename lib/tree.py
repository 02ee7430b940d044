"""Small pytree utilities shared by the running helpers and the combinators."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp

__all__ = ["Static", "where", "all_finite", "fill_missing", "zeros_like_shape"]

PyTree = Any


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Static:
    """A hashable value carried as static pytree metadata, not as a leaf.

    For the few structural numbers a task needs at trace time (loop counts such as
    physics substeps or action repeats): equal values share one jit cache entry.
    """

    value: Any = dataclasses.field(metadata=dict(static=True))


def where(cond: jax.Array, on_true: PyTree, on_false: PyTree) -> PyTree:
    """Leafwise `jnp.where` with a scalar condition over two same-structure pytrees."""
    return jax.tree.map(lambda a, b: jnp.where(cond, a, b), on_true, on_false)


def all_finite(tree: PyTree) -> jax.Array:
    """Scalar bool: every inexact leaf of `tree` is finite (integer leaves count as finite)."""
    checks = [
        jnp.all(jnp.isfinite(leaf))
        for leaf in jax.tree.leaves(tree)
        if jnp.issubdtype(jnp.asarray(leaf).dtype, jnp.inexact)
    ]
    return jnp.all(jnp.stack(checks)) if checks else jnp.array(True)


def zeros_like_shape(shape: PyTree) -> PyTree:
    """Zeros shaped like every leaf of `shape` (`jax.ShapeDtypeStruct`s or arrays)."""
    return jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shape)


def fill_missing(actual: dict, template: dict) -> dict:
    """`actual` with every key of `template` it lacks added as zeros, recursively.

    `template` holds arrays or `jax.ShapeDtypeStruct`s (from `jax.eval_shape`). Keys only in
    `actual` are kept; nested dicts present in both are merged the same way.
    """
    merged = dict(actual)
    for key, shape in template.items():
        if key not in merged:
            merged[key] = zeros_like_shape(shape)
        elif isinstance(shape, dict) and isinstance(merged[key], dict):
            merged[key] = fill_missing(merged[key], shape)
    return merged
