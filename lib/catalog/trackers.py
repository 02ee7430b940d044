"""Shared per-episode trackers, `Task -> Task`: records in `state.layers` that several
catalog items read (found with `mjzoo.find`) (observations of the last actions or foot contacts, the action-rate
and feet rewards), kept once per task instead of recomputed by each reader.

Both trackers keep per-episode state, so they sit INSIDE `mjzoo.with_auto_reset` (wrap
the task with them first): the reset that starts a new episode then clears them. Items
that read them must be added at the same level of any `with_action_repeat`.
"""

from __future__ import annotations

from typing import Any
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import checks
from mjzoo import names
from mjzoo import tree
from mjzoo.catalog import contacts
from mjzoo.catalog.contacts import point_velocity
from mjzoo.layers import layered
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["with_action_history", "with_feet", "ActionHistoryState", "FeetState"]

Array = jax.Array


class ActionHistoryState(NamedTuple):
    """`with_action_history`'s record: ``actions``, [length, nu] float32, row 0 the
    action of the transition that produced the state, row k the one k transitions
    earlier; zeros at reset."""

    actions: Array
    inner: Any = ()


class FeetState(NamedTuple):
    """`with_feet`'s record, over the F watched foot geoms (see `with_feet`)."""

    contact: Array  # [F] bool
    position: Array  # [F, 3] m
    velocity: Array  # [F, 3] m/s
    air_time: Array  # [F] float32 s
    first_contact: Array  # [F] bool
    last_air_time: Array  # [F] float32 s
    inner: Any = ()


# --- action history -----------------------------------------------------------------


def with_action_history(task: Task, length: int = 3, observe: bool = False) -> Task:
    """Keeps the last `length` actions in an `ActionHistoryState`: [length, nu]
    float32, row 0 the action of the transition that produced the state, row k the one
    k transitions earlier; zeros at reset.

    Records the action its step receives: wrap it outside action filters and noise to
    record the policy's action, inside them to record what the actuators got. With
    ``observe=True`` row 0, the last action, is appended to the (1-D) observation, as
    the command combinators append their command: the one way a policy sees its last
    action (an observation item cannot, as it runs inside this combinator).
    """
    length = checks.integer("with_action_history", "length", length)
    shape = tree.StaticValue((length, task.action_size))
    if observe:
        obs = jax.eval_shape(task.start, task.model, jax.random.key(0)).obs
        if not (isinstance(obs, jax.ShapeDtypeStruct) and obs.ndim == 1):
            raise ValueError(
                "with_action_history: observe=True appends the last action to a 1-D array observation, "
                f"but the task observes {jax.tree.map(lambda x: x.shape, obs)}"
            )
    observed = tree.StaticValue(bool(observe))
    start = Partial(_history_reset, task.start, shape, observed)
    return layered(task, ActionHistoryState, start, Partial(_history_step, task.step, observed))


def _kept_actions(state: State, actions: Array, observed: tree.StaticValue) -> State:
    if observed.value:
        state = state.replace(obs=jnp.concatenate([state.obs, actions[0].astype(state.obs.dtype)]))
    return wrap(state, ActionHistoryState(actions=actions))


def _history_reset(reset_fn, shape: tree.StaticValue, observed: tree.StaticValue, model: mjx.Model, key) -> State:
    return _kept_actions(reset_fn(model, key), jnp.zeros(shape.value, jnp.float32), observed)


def _history_step(step_fn, observed: tree.StaticValue, model: mjx.Model, state: State, action: Array, key) -> State:
    own, inner = peel(state, ActionHistoryState)
    if observed.value:
        inner = inner.replace(obs=inner.obs[: -own.actions.shape[1]])
    next_state = step_fn(model, inner, action, key)
    history = jnp.concatenate([jnp.asarray(action, jnp.float32)[None], own.actions[:-1]])
    return _kept_actions(next_state, history, observed)


# --- feet ---------------------------------------------------------------------------


def with_feet(task: Task, feet: names.Names, floor: names.Names) -> Task:
    """Keeps a `FeetState`, over the F geoms named in `feet` (in that order):

      contact       [F] bool     the foot touches a `floor` geom (one name or several):
                                 an active contact (`mjzoo.catalog.contacts.touching`)
      air_time      [F] float32  s since the foot last left the floor (or since reset);
                                 0 while in contact
      first_contact [F] bool     the foot touched down in this transition
      last_air_time [F] float32  s in the air before the last touch-down (0 until one)
      position      [F, 3]       world position of each foot geom's centre, m
      velocity      [F, 3]       world linear velocity of that point, m/s

    updated after every step from the new physics (contacts, positions and velocities as
    of the last physics substep). The time a transition adds to `air_time` is the
    simulated time it advanced (``data.time``): the control period, whatever the
    substeps, action repeats or randomized timestep. At reset it reads the contacts of
    the reset's data, so the task's reset must leave its data forwarded
    (`mjx.forward`, as `resets.with_resets` does: apply with_feet after it).
    """
    geoms, floor = contacts.geom_sets(task.mj_model, feet, floor, "with_feet")
    bodies = jnp.asarray(task.mj_model.geom_bodyid[np.asarray(geoms)], jnp.int32)
    indices = (geoms, bodies, floor)  # a tuple: indices are not parameters (mjzoo.params names dict keys)
    return layered(task, FeetState, Partial(_feet_reset, task.start, indices), Partial(_feet_step, task.step, indices))


def _feet_now(indices: tuple, model: mjx.Model, data: mjx.Data) -> dict[str, Array]:
    """Contact, position and velocity of each foot in `data`."""
    geoms, bodies, floor = indices
    position = data.geom_xpos[geoms]
    velocity, _ = point_velocity(model, data, bodies, position)
    contact = contacts.touching(data, geoms, floor)
    return {"contact": contact, "position": position, "velocity": velocity}


def _feet_reset(reset_fn, indices: tuple, model: mjx.Model, key: Array) -> State:
    state = reset_fn(model, key)
    now = _feet_now(indices, model, state.data)
    zeros = jnp.zeros(now["contact"].shape, jnp.float32)
    feet = FeetState(**now, air_time=zeros, first_contact=jnp.zeros_like(now["contact"]), last_air_time=zeros)
    return wrap(state, feet)


def _feet_step(step_fn, indices: tuple, model: mjx.Model, state: State, action: Array, key: Array) -> State:
    before, inner = peel(state, FeetState)
    next_state = step_fn(model, inner, action, key)
    now = _feet_now(indices, model, next_state.data)
    air_time = before.air_time + (next_state.data.time - state.data.time).astype(jnp.float32)
    first_contact = now["contact"] & ~before.contact
    feet = FeetState(
        **now,
        air_time=jnp.where(now["contact"], 0.0, air_time),
        first_contact=first_contact,
        last_air_time=jnp.where(first_contact, air_time, before.last_air_time),
    )
    return wrap(next_state, feet)
