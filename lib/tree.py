"""Small pytree utilities shared by the running helpers and the combinators."""

from __future__ import annotations

import dataclasses
import math
from typing import Any
from typing import Mapping

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["StaticValue", "where", "all_finite", "named", "with_named"]

PyTree = Any


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class StaticValue:
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


def strongly_typed(tree: PyTree) -> PyTree:
    """`tree` with each Python number and weakly typed array (a Python number's type, as
    ``data.replace(time=0.0)`` leaves it) made a strongly typed array of its dtype; other
    leaves as they are. A jitted loop fed its own output compiles once only if its first
    input's types match its outputs', weak types included; a step computes such a leaf
    from strongly typed ones (``time + timestep``) and returns it strong."""

    def strong(x: Any) -> Any:
        if isinstance(x, (int, float, complex)) or (isinstance(x, jax.Array) and jax.typeof(x).weak_type):
            return jax.lax.convert_element_type(x, jnp.result_type(x))
        return x

    return jax.tree.map(strong, tree)


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


def named(tree: PyTree, skip: tuple[type, ...] = (), unnamed: tuple[str, ...] = ()) -> dict[str, Any]:
    """The leaves of `tree` that have a name, ``{name: leaf}``, in flattening order; where a
    name has several leaves, the first one's. A leaf's name is the last step of its path
    when that is a string dict key or an attribute not in `unnamed`; nodes of a `skip`
    type are neither searched nor named."""
    found: dict[str, Any] = {}
    for path, leaf in jax.tree_util.tree_flatten_with_path(tree, is_leaf=lambda n: isinstance(n, skip))[0]:
        name = _leaf_name(path, unnamed)
        if name is not None and not isinstance(leaf, skip):
            found.setdefault(name, leaf)
    return found


def with_named(
    tree: PyTree, values: Mapping[str, Any], who: str, skip: tuple[type, ...] = (), unnamed: tuple[str, ...] = ()
) -> PyTree:
    """`tree` with every leaf named like a key of `values` (see `named`) replaced by that
    value, cast to the leaf's shape and dtype: the structure, and so any jit cache entry,
    is kept. Raises KeyError for a name `tree` lacks (listing those it has) and
    ValueError for a value of another shape, both prefixed by `who`."""
    known = named(tree, skip, unnamed)
    unknown = sorted(set(values) - set(known))
    if unknown:
        raise KeyError(
            f"{who}: the task has no parameter named {', '.join(map(repr, unknown))}; "
            f"its named parameters: {', '.join(known) or 'none'}"
        )

    def replace(path, leaf):
        name = _leaf_name(path, unnamed)
        if name not in values or isinstance(leaf, skip):
            return leaf
        shape, dtype = np.shape(leaf), getattr(leaf, "dtype", None) or np.asarray(leaf).dtype
        new = values[name]  # np.shape, not np.asarray: a traced value works too (inside jit)
        if np.shape(new) != shape:
            raise ValueError(
                f"{who}: {name}={values[name]!r} has shape {np.shape(new)}, but the task's "
                f"{name} has shape {shape} ({jax.tree_util.keystr(path)})"
            )
        return jnp.asarray(new, dtype)

    return jax.tree_util.tree_map_with_path(replace, tree, is_leaf=lambda n: isinstance(n, skip))


def _leaf_name(path: tuple, unnamed: tuple[str, ...]) -> str | None:
    last = path[-1] if path else None
    if isinstance(last, jax.tree_util.DictKey) and isinstance(last.key, str):
        return last.key
    if isinstance(last, jax.tree_util.GetAttrKey) and last.name not in unnamed:
        return last.name
    return None


@dataclasses.dataclass(frozen=True)
class Packing:
    """A pytree's leaves laid out in one flat array per dtype, and back.

    A jitted call pays per argument and per result (~1 and ~7 us each on a small CPU):
    a simulation state of ~100 leaves costs more to pass in and out than a cart-pole
    step costs to compute. Loops that call small jits carry `pack`'s few arrays instead
    and unpack inside the jit, where it costs nothing. Typed PRNG keys travel as their
    key data.

        packing = Packing.of(state)
        step = jax.jit(lambda packed, key: packing.pack(advance(packing.unpack(packed), key)))
    """

    treedef: Any
    shapes: tuple[tuple[int, ...], ...]  # each leaf's shape, key data's trailing axes included
    dtypes: tuple[Any, ...]  # each leaf's storage dtype (typed keys: their key data's)
    keys: tuple[Any, ...]  # each typed key leaf's PRNG implementation, else None

    @classmethod
    def of(cls, tree: PyTree) -> Packing:
        leaves, treedef = jax.tree.flatten(tree)
        keys = tuple(jax.random.key_impl(x) if _is_key(x) else None for x in leaves)
        data = [jax.random.key_data(x) if k else x for x, k in zip(leaves, keys)]
        return cls(treedef, tuple(jnp.shape(x) for x in data), tuple(jnp.result_type(x) for x in data), keys)

    @property
    def groups(self) -> tuple[Any, ...]:
        """The packed arrays' dtypes, in order."""
        return tuple(dict.fromkeys(self.dtypes))

    def pack(self, tree: PyTree) -> tuple[jax.Array, ...]:
        """One flat array per dtype of `groups`, each leaf cast to its recorded dtype."""
        leaves, treedef = jax.tree.flatten(tree)
        if treedef != self.treedef:
            raise ValueError(f"Packing.pack: the tree's structure changed: {treedef} (was {self.treedef})")
        parts: dict[Any, list] = {g: [] for g in self.groups}
        for leaf, key, shape, dtype in zip(leaves, self.keys, self.shapes, self.dtypes):
            leaf = jax.random.key_data(leaf) if key is not None else jnp.asarray(leaf)
            if leaf.shape != shape:
                raise ValueError(f"Packing.pack: a leaf's shape changed: {leaf.shape} (was {shape})")
            parts[dtype].append(jnp.ravel(leaf).astype(dtype))
        return tuple(jnp.concatenate(parts[g]) for g in self.groups)

    def unpack(self, packed: tuple[jax.Array, ...]) -> PyTree:
        """The tree `pack` made `packed` from (leading batch axes kept, as after stacking)."""
        arrays = dict(zip(self.groups, packed))
        batch = packed[0].shape[:-1]
        offsets, leaves = dict.fromkeys(self.groups, 0), []
        for key, shape, dtype in zip(self.keys, self.shapes, self.dtypes):
            start, size = offsets[dtype], math.prod(shape)
            offsets[dtype] += size
            leaf = arrays[dtype][..., start : start + size].reshape(*batch, *shape)
            leaves.append(jax.random.wrap_key_data(leaf, impl=key) if key is not None else leaf)
        return jax.tree.unflatten(self.treedef, leaves)


def _is_key(x: Any) -> bool:
    return isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jax.dtypes.prng_key)
