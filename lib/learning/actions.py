"""From a policy's actions to a task's controls.

Policies act in [-1, 1] (a tanh-squashed Gaussian, `distributions`), whatever the
actuators' units; `to_controls` maps that box onto each actuator's ctrlrange, so one
network head serves a 1 N motor and a 100 Nm one alike.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo.types import Task

__all__ = ["to_controls"]

Array = jax.Array


def to_controls(task: Task, action: Array) -> Array:
    """Maps actions in [-1, 1] onto `task`'s controls, affinely per actuator.

      ctrl = low + (action + 1) / 2 * (high - low)     where the actuator is ctrllimited
      ctrl = action                                    where it is not

    A task whose action is not one control per actuator (``task.action_dim`` set, e.g.
    PD position and velocity targets of `mjzoo.catalog.actuators`) maps its [-1, 1]
    actions itself: they are returned unchanged.

    Args:
      task: the task (its model's ``actuator_ctrlrange`` is a leaf: edits apply).
      action: [..., action_size] in [-1, 1].

    Returns:
      [..., action_size] controls.
    """
    if jnp.shape(action)[-1:] != (task.action_size,):
        raise ValueError(
            f"to_controls: the action has shape {jnp.shape(action)}; the task takes [..., {task.action_size}]"
        )
    if task.action_dim is not None:
        return action
    limited = np.asarray(task.mj_model.actuator_ctrllimited, bool)  # static: the model's structure
    low, high = task.model.actuator_ctrlrange[:, 0], task.model.actuator_ctrlrange[:, 1]
    return jnp.where(limited, low + (action + 1.0) * 0.5 * (high - low), action)
