"""Value-target normalization: the value function learns returns in units of their
running spread, and PopArt keeps its predictions when those units change.

Returns grow and shrink by orders of magnitude over a run (and differ between tasks),
which makes a fixed value-loss weight and learning rate wrong for most of it. The
critic instead predicts normalized targets (R - mu) / sigma, with mu and sigma the
running mean and standard deviation of the targets seen (`RunningStats` of scalars);
its output is denormalized wherever a value is used (GAE's bootstrap, the targets).

When the statistics move from (mu, sigma) to (mu', sigma'), the normalized
predictions of an unchanged network would jump. PopArt ("Preserving Outputs Precisely,
while Adaptively Rescaling Targets", van Hasselt et al., 2016) rescales the output
layer so that the unnormalized outputs stay exactly what they were:

    sigma' (W' h + b') + mu' = sigma (W h + b) + mu   for every h
    <=>  W' = W sigma / sigma',   b' = (sigma b + mu - mu') / sigma'

    stats = init_value_stats()
    new_stats = update_value_stats(stats, returns)                 # returns [T, N]
    value_params = [*value_params[:-1], popart_rescale(value_params[-1], stats, new_stats)]
    targets = normalize_values(new_stats, returns)                 # for the value loss
    values = denormalize_values(new_stats, value_net.apply(value_params, obs)[..., 0])
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjzoo.learning.normalization import VAR_EPS
from mjzoo.learning.normalization import RunningStats
from mjzoo.learning.normalization import init_stats
from mjzoo.learning.normalization import update_stats

__all__ = ["denormalize_values", "init_value_stats", "normalize_values", "popart_rescale", "update_value_stats"]

Array = jax.Array


def init_value_stats() -> RunningStats:
    """Statistics of no value targets: scalar mean 0, var 1, count 0.

    normalize_values and denormalize_values are then the identity (up to the 1e-8 in
    the standard deviation), and the first `update_value_stats` takes the first batch's
    own moments exactly.
    """
    return init_stats(jnp.zeros((), jnp.float32))


def update_value_stats(stats: RunningStats, targets: Array) -> RunningStats:
    """Merges a batch of value targets, every element one sample, into the statistics
    (Chan et al.'s exact merge, `mjzoo.learning.update_stats`).

    Args:
      stats: scalar statistics (from `init_value_stats`).
      targets: [...] value targets (e.g. GAE returns [T, N]), at least one element.

    Returns:
      The updated scalar `RunningStats`.
    """
    if jnp.shape(stats.mean) != ():
        raise ValueError(f"update_value_stats: the statistics must be scalar, got mean shape {jnp.shape(stats.mean)}")
    targets = jnp.asarray(targets, jnp.float32)
    return update_stats(stats, targets, num_batch_dims=targets.ndim)


def _std(stats: RunningStats) -> Array:
    # The same epsilon as observation normalization: finite for constant targets.
    return jnp.sqrt(stats.var + VAR_EPS)


def normalize_values(stats: RunningStats, values: Array) -> Array:
    """(values - mu) / sigma with sigma = sqrt(var + 1e-8); no clipping, since value
    targets far from the mean are exactly the ones to learn.

    Args:
      stats: scalar statistics.
      values: [...] returns or values in the task's units.

    Returns:
      float32 [...], same shape.
    """
    return (jnp.asarray(values, jnp.float32) - stats.mean) / _std(stats)


def denormalize_values(stats: RunningStats, normalized: Array) -> Array:
    """normalized * sigma + mu, sigma = sqrt(var + 1e-8): the inverse of
    `normalize_values`.

    Args:
      stats: scalar statistics.
      normalized: [...] values in normalized units (the critic's outputs).

    Returns:
      float32 [...], same shape, in the task's units.
    """
    return jnp.asarray(normalized, jnp.float32) * _std(stats) + stats.mean


def popart_rescale(output_layer: dict[str, Array], old: RunningStats, new: RunningStats) -> dict[str, Array]:
    """PopArt: the value head's output layer rescaled so that its denormalized outputs
    are unchanged when the statistics move from `old` (mu, sigma) to `new`
    (mu', sigma'):

      W' = W * sigma / sigma'
      b' = (sigma * b + mu - mu') / sigma'

    with sigma = sqrt(var + 1e-8), as in `normalize_values`. Only the last Dense layer
    changes, so denormalize(new, f'(x)) = denormalize(old, f(x)) for every input x, up
    to float rounding.

    Args:
      output_layer: the last layer of an `mlp`'s params (`params[-1]`),
        {"kernel": [H, K], "bias": [K]} (K = 1 for a value head; each of K outputs is
        rescaled alike).
      old: scalar statistics the layer was trained against.
      new: scalar statistics it will be trained against.

    Returns:
      {"kernel": [H, K], "bias": [K]}, the same dtypes. Other keys of `output_layer`
      are kept as they are.
    """
    missing = {"kernel", "bias"} - set(output_layer)
    if missing:
        raise ValueError(
            f"popart_rescale: output_layer must hold 'kernel' and 'bias' (an mlp's params[-1]); "
            f"it lacks {sorted(missing)} (has {sorted(output_layer)})"
        )
    sigma, sigma_new = _std(old), _std(new)
    kernel, bias = output_layer["kernel"], output_layer["bias"]
    new_kernel = kernel * (sigma / sigma_new)
    new_bias = (sigma * bias + old.mean - new.mean) / sigma_new
    return {**output_layer, "kernel": new_kernel.astype(kernel.dtype), "bias": new_bias.astype(bias.dtype)}
