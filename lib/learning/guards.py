"""The non-finite update guard: a gradient step that produced a NaN or an infinity is
dropped, and the run goes on from the parameters before it.

One bad minibatch (an exploding physics state, a log-probability of an action at the
edge of the squashed Gaussian) otherwise writes NaN into the parameters and the
optimizer's moments, and every later step inherits it. Checking the step's loss,
gradients and results, and keeping the old ones where any is non-finite, costs one
reduction per leaf and no Python control flow, so it runs inside `lax.scan` and under
`vmap` (each member of a batch of runs skips its own bad steps):

    def sgd_step(carry, minibatch):
        params, opt_state = carry
        (loss, metrics), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, minibatch)
        updates, new_opt_state = optimizer.update(grads, opt_state, params)
        params, opt_state, skipped = skip_non_finite_update(
            optax.apply_updates(params, updates), new_opt_state, params, opt_state, grads, loss
        )
        return (params, opt_state), {**metrics, "skipped_steps": skipped}

`learn` averages metrics over steps, so "skipped_steps" reads as the fraction skipped.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from mjzoo import tree

__all__ = ["skip_non_finite_update"]

Array = jax.Array
PyTree = Any


def skip_non_finite_update(
    new_params: PyTree,
    new_opt_state: PyTree,
    old_params: PyTree,
    old_opt_state: PyTree,
    grads: PyTree,
    loss: Array,
) -> tuple[PyTree, PyTree, Array]:
    """The step's new params and optimizer state if it is finite, else the old ones:

      finite  = every inexact leaf of (loss, grads, new_params, new_opt_state) is finite
      result  = (new_params, new_opt_state) if finite else (old_params, old_opt_state)
      skipped = 1 - finite

    The results are checked too, not only the gradients: finite gradients can still
    overflow the optimizer's moments or the parameters. Integer leaves (optax's step
    counts) count as finite; a skipped step does not advance them either.

    Args:
      new_params, new_opt_state: after the step.
      old_params, old_opt_state: before it; the same structures and shapes.
      grads: the step's gradients (any pytree).
      loss: the step's loss, scalar (or any array).

    Returns:
      (params, opt_state, skipped), skipped an int32 scalar, 1 where the step was
      dropped and 0 where it was kept.
    """
    for name, old, new in (("params", old_params, new_params), ("opt_state", old_opt_state, new_opt_state)):
        if jax.tree.structure(old) != jax.tree.structure(new):
            raise ValueError(
                f"skip_non_finite_update: old and new {name} differ in structure: "
                f"{jax.tree.structure(old)} vs {jax.tree.structure(new)}"
            )
    finite = tree.all_finite((loss, grads, new_params, new_opt_state))
    params, opt_state = tree.where(finite, (new_params, new_opt_state), (old_params, old_opt_state))
    return params, opt_state, jnp.logical_not(finite).astype(jnp.int32)
