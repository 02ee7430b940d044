"""Running mean and variance of observations, and normalization by them.

The statistics are a pytree (`RunningStats`) threaded through training like any other
state; the functions are pure. Batches are merged with the exact parallel formula of
Chan, Golub and LeVeque (1979): the statistics after updating with the halves of a
batch, one after the other, equal those after updating with the whole batch (up to
float rounding), so the result does not depend on how collection is chunked.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp

__all__ = ["RunningStats", "VAR_EPS", "init_stats", "update_stats", "normalize"]

Array = jax.Array
PyTree = Any

VAR_EPS = 1e-8  # keeps the division finite for features that never vary


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class RunningStats:
    """Mean and population variance of every observation element seen so far.

    Attributes:
      mean: pytree shaped like one observation, float32.
      var: pytree shaped like one observation, float32; population variance (ddof 0),
        as `numpy.var`.
      count: float32 scalar, the number of observations merged in. Float32 counts are
        exact up to 2**24 and keep the merge weights accurate to ~1e-7 beyond.
    """

    mean: PyTree
    var: PyTree
    count: Array

    def replace(self, **changes: Any) -> "RunningStats":
        return dataclasses.replace(self, **changes)


def init_stats(example_obs: PyTree) -> RunningStats:
    """Statistics of no data: mean 0, var 1, count 0.

    With count 0 the first `update_stats` replaces mean and var by the batch's own
    moments exactly (no epsilon count is needed), and `normalize` before any update is
    the identity up to clipping.

    Args:
      example_obs: one observation (pytree of arrays); only shapes are read.
    """
    mean = jax.tree.map(lambda x: jnp.zeros(jnp.shape(x), jnp.float32), example_obs)
    var = jax.tree.map(lambda x: jnp.ones(jnp.shape(x), jnp.float32), example_obs)
    return RunningStats(mean=mean, var=var, count=jnp.zeros((), jnp.float32))


def update_stats(stats: RunningStats, batch: PyTree, num_batch_dims: int) -> RunningStats:
    """Merges a batch of observations into the running statistics.

    With n_a = stats.count, n_b the batch size, n = n_a + n_b and delta = mean_b - mean_a:

      mean = mean_a + delta * n_b / n
      var  = (n_a * var_a + n_b * var_b + delta^2 * n_a * n_b / n) / n

    where mean_b, var_b are the batch's own (two-pass) mean and population variance.

    Args:
      stats: the statistics so far.
      batch: observation pytree whose leaves are [*batch_dims, *obs_shape] with
        `num_batch_dims` leading batch dims (e.g. [T, B, ...] with num_batch_dims=2).
      num_batch_dims: static int >= 0.

    Returns:
      The updated `RunningStats`.
    """
    if isinstance(num_batch_dims, bool) or not isinstance(num_batch_dims, int) or num_batch_dims < 0:
        raise ValueError(f"update_stats: num_batch_dims={num_batch_dims!r} must be an integer >= 0")
    batch_shape = _check_leading_shape("update_stats", stats.mean, batch, num_batch_dims)
    batch_count = math.prod(batch_shape)
    if batch_count == 0:
        raise ValueError(f"update_stats: the batch is empty (batch dims {batch_shape})")

    axes = tuple(range(num_batch_dims))
    n_a = stats.count
    n_b = jnp.float32(batch_count)
    n = n_a + n_b
    weight_b = n_b / n  # in (0, 1]; 1 on the first update, which drops the init values

    def merge(mean_a: Array, var_a: Array, x: Array) -> tuple[Array, Array]:
        x = jnp.asarray(x, jnp.float32)
        mean_b = jnp.mean(x, axis=axes)
        var_b = jnp.var(x, axis=axes)
        delta = mean_b - mean_a
        mean = mean_a + delta * weight_b
        # Divided through by n: n_a/n * var_a + n_b/n * var_b + delta^2 * (n_a/n) * (n_b/n).
        var = (1.0 - weight_b) * var_a + weight_b * var_b + jnp.square(delta) * (1.0 - weight_b) * weight_b
        return mean, var

    treedef = jax.tree.structure(stats.mean)
    merged = [
        merge(m, v, x)
        for m, v, x in zip(jax.tree.leaves(stats.mean), jax.tree.leaves(stats.var), jax.tree.leaves(batch))
    ]
    return RunningStats(
        mean=jax.tree.unflatten(treedef, [m for m, _ in merged]),
        var=jax.tree.unflatten(treedef, [v for _, v in merged]),
        count=n,
    )


def normalize(stats: RunningStats, obs: PyTree, clip: float | Array = 5.0) -> PyTree:
    """(obs - mean) / sqrt(var + 1e-8), clipped to [-clip, clip], leaf by leaf.

    Args:
      stats: the statistics to normalize with.
      obs: observation pytree; leaves may carry any leading batch dims,
        [..., *obs_shape].
      clip: scalar > 0.

    Returns:
      float32 pytree shaped like `obs`.
    """
    treedef = jax.tree.structure(stats.mean)
    obs_leaves = _flatten_like("normalize", treedef, obs)
    for path_and_mean, x in zip(jax.tree_util.tree_flatten_with_path(stats.mean)[0], obs_leaves):
        path, mean = path_and_mean
        shape, obs_shape = jnp.shape(x), jnp.shape(mean)
        if len(shape) < len(obs_shape) or shape[len(shape) - len(obs_shape) :] != obs_shape:
            raise ValueError(
                f"normalize: observation leaf {jax.tree_util.keystr(path)!r} has shape {shape}, "
                f"which does not end in the statistics' shape {obs_shape}"
            )

    def one(mean: Array, var: Array, x: Array) -> Array:
        z = (jnp.asarray(x, jnp.float32) - mean) / jnp.sqrt(var + VAR_EPS)
        return jnp.clip(z, -clip, clip)

    return jax.tree.map(one, stats.mean, stats.var, obs)


def _flatten_like(name: str, treedef: Any, obs: PyTree) -> list:
    if jax.tree.structure(obs) != treedef:
        raise ValueError(
            f"{name}: the observation's structure {jax.tree.structure(obs)} differs from the "
            f"statistics' structure {treedef}"
        )
    return jax.tree.leaves(obs)


def _check_leading_shape(name: str, mean: PyTree, batch: PyTree, num_batch_dims: int) -> tuple[int, ...]:
    """The batch dims shared by every leaf; raises naming the first leaf that disagrees."""
    leaves = _flatten_like(name, jax.tree.structure(mean), batch)
    batch_shape = None
    for (path, m), x in zip(jax.tree_util.tree_flatten_with_path(mean)[0], leaves):
        shape = jnp.shape(x)
        if shape[num_batch_dims:] != jnp.shape(m) or len(shape) != num_batch_dims + jnp.ndim(m):
            raise ValueError(
                f"{name}: leaf {jax.tree_util.keystr(path)!r} has shape {shape}; expected "
                f"{num_batch_dims} batch dims followed by the observation shape {jnp.shape(m)}"
            )
        if batch_shape is not None and shape[:num_batch_dims] != batch_shape:
            raise ValueError(
                f"{name}: leaf {jax.tree_util.keystr(path)!r} has batch dims {shape[:num_batch_dims]}, "
                f"others have {batch_shape}"
            )
        batch_shape = shape[:num_batch_dims]
    return batch_shape if batch_shape is not None else ()
