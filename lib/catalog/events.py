"""Events during an episode, `Task -> Task`: pushes that kick the robot at random times.

    task = events.with_velocity_pushes(task, interval=(5.0, 10.0), linear=(0.5, 0.5, 0.0))
    task = events.with_force_pushes(task, "torso", interval=(3.0, 6.0), force=(80, 80, 0), duration=0.2)

Timing: each combinator keeps a countdown in seconds of physics time in its record,
drawn U(interval) at reset and after every push, and decreased by the physics time each
step advances (`data.time`), so it needs no control period and stays right under action
repeat. A push is due at the first step that starts within half a physics step of the
countdown's end. Push sizes are drawn per axis, uniform in [-max, max].

Where they sit: inside `with_auto_reset`, so every episode starts a fresh countdown;
outside `with_resets` or anything that recomputes the state at reset. The pushes are
applied before the inner step, so the physics integrates them and the observation of the
step sees their effect.
"""

from __future__ import annotations

from typing import Any
from typing import NamedTuple
from typing import Sequence

import jax
import jax.numpy as jnp
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import checks
from mjzoo import names
from mjzoo.layers import layered
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "with_velocity_pushes",
    "with_force_pushes",
    "elapsed",
    "due",
    "countdown_interval",
    "VelocityPushState",
    "ForcePushState",
]

Array = jax.Array
PUSH_STREAM = 0x9B5  # fold_in tag: the inner task keeps its own key


class VelocityPushState(NamedTuple):
    """`with_velocity_pushes`' record: ``countdown``, s to the next push."""

    countdown: Array
    inner: Any = ()


class ForcePushState(NamedTuple):
    """`with_force_pushes`' record: ``countdown`` s to the next push, ``remaining`` s of
    the current push left, ``force`` [3] N."""

    countdown: Array
    remaining: Array
    force: Array
    inner: Any = ()


def elapsed(state: State, next_state: State) -> Array:
    """Physics time a step advanced, s (float32 scalar); 0 if the time went backwards
    (a new episode began inside the step)."""
    return jnp.maximum(next_state.data.time - state.data.time, 0.0)


def due(model: mjx.Model, countdown: Array) -> Array:
    """Bool scalar: a `countdown` (s) has run out, within half a physics step (so float
    rounding of the elapsed times never delays an event by a whole step)."""
    return countdown <= 0.5 * model.opt.timestep


def countdown_interval(who: str, name: str, interval) -> Array:
    """A checked (low, high) time range, s, with 0 < low <= high: float32 [2]."""
    return checks.interval(who, name, interval, 0.0, open_low=True)


def _draw(key: Array, interval: Array) -> Array:
    return jax.random.uniform(key, (), minval=interval[0], maxval=interval[1])


# --- velocity pushes ----------------------------------------------------------------


def with_velocity_pushes(
    task: Task,
    interval: Sequence[float] = (5.0, 10.0),
    linear: Sequence[float] = (0.5, 0.5, 0.0),
    angular: Sequence[float] = (0.0, 0.0, 0.0),
    body: str | None = None,
) -> Task:
    """Kicks the base every U(interval) seconds by adding a random velocity to its free
    joint: dv_i ~ U(-linear_i, linear_i) m/s (world frame), dw_i ~ U(-angular_i,
    angular_i) rad/s (body frame).

    `body`: the base, whose free joint is kicked (None: the model's first free joint).
    `interval`: (low, high) s with 0 < low. Keeps a `VelocityPushState`. Metrics: ``velocity_push/applied`` (1 at a
    push), ``velocity_push/linear`` (|dv| m/s), ``velocity_push/angular`` (|dw| rad/s),
    0 between pushes.
    """
    who = "events.with_velocity_pushes"
    _, qvel_idx = names.free_joint_addresses(task.mj_model, body, who)
    interval = countdown_interval(who, "interval", interval)
    limits = jnp.concatenate([checks.numbers(who, "linear", linear, 3), checks.numbers(who, "angular", angular, 3)])
    start = Partial(_velocity_reset, task.start, interval)
    step = Partial(_velocity_step, task.step, jnp.asarray(qvel_idx), interval, limits)
    return layered(task, VelocityPushState, start, step)


def _velocity_reset(reset_fn, interval, model, key) -> State:
    state = reset_fn(model, key)
    return wrap(state, VelocityPushState(countdown=_draw(jax.random.fold_in(key, PUSH_STREAM), interval)))


def _velocity_step(step_fn, qvel_idx, interval, limits, model, state, action, key) -> State:
    draw_key, kick_key = jax.random.split(jax.random.fold_in(key, PUSH_STREAM))
    own, inner = peel(state, VelocityPushState)
    countdown = own.countdown
    push = due(model, countdown)
    kick = jnp.where(push, jax.random.uniform(kick_key, (6,), minval=-limits, maxval=limits), 0.0)
    kicked = inner.replace(data=state.data.replace(qvel=state.data.qvel.at[qvel_idx].add(kick)))
    next_state = step_fn(model, kicked, action, key)
    countdown = jnp.where(push, _draw(draw_key, interval), countdown) - elapsed(state, next_state)
    metrics = {
        "velocity_push/applied": push.astype(jnp.float32),
        "velocity_push/linear": jnp.linalg.norm(kick[:3]),
        "velocity_push/angular": jnp.linalg.norm(kick[3:]),
    }
    return wrap(next_state, VelocityPushState(countdown=countdown)).replace(metrics={**next_state.metrics, **metrics})


# --- force pushes -------------------------------------------------------------------


def with_force_pushes(
    task: Task,
    body: str,
    interval: Sequence[float] = (5.0, 10.0),
    force: Sequence[float] = (50.0, 50.0, 0.0),
    duration: float = 0.2,
) -> Task:
    """Pushes `body` every U(interval) seconds with a random force held for `duration` s.

    The force F_i ~ U(-force_i, force_i) N (world frame, at the body's center of mass)
    is added to ``data.xfrc_applied[body, :3]`` for every step that starts while the
    push lasts (so `duration` is rounded to whole control steps), and taken off again
    after the step: other uses of `xfrc_applied` are kept. A push due while another
    lasts replaces it. It must sit inside `with_auto_reset`: outside it, a step that
    starts a new episode would have the force taken off the new episode's data. Keeps a
    `ForcePushState`. Metrics:
    ``force_push/started`` (1 at a push's first step), ``force_push/force`` (|F| N applied
    during the step, else 0).
    """
    who = "events.with_force_pushes"
    body_id = jnp.int32(names.index(task.mj_model, "body", body, who, world=False))
    interval = countdown_interval(who, "interval", interval)
    duration = checks.number(who, "duration", duration, 0.0, open_low=True)
    params = (body_id, interval, checks.numbers(who, "force", force, 3), duration)
    start = Partial(_force_reset, task.start, interval)
    return layered(task, ForcePushState, start, Partial(_force_step, task.step, *params))


def _force_reset(reset_fn, interval, model, key) -> State:
    state = reset_fn(model, key)
    pushes = ForcePushState(
        countdown=_draw(jax.random.fold_in(key, PUSH_STREAM), interval),
        remaining=jnp.zeros((), jnp.float32),
        force=jnp.zeros((3,), jnp.float32),
    )
    return wrap(state, pushes)


def _force_step(step_fn, body, interval, limits, duration, model, state, action, key) -> State:
    draw_key, force_key = jax.random.split(jax.random.fold_in(key, PUSH_STREAM))
    pushes, inner = peel(state, ForcePushState)
    start = due(model, pushes.countdown)
    force = jnp.where(start, jax.random.uniform(force_key, (3,), minval=-limits, maxval=limits), pushes.force)
    remaining = jnp.where(start, duration, pushes.remaining)
    applied = jnp.where(remaining > 0.5 * model.opt.timestep, force, 0.0)
    pushed = state.data.replace(xfrc_applied=state.data.xfrc_applied.at[body, :3].add(applied))
    next_state = step_fn(model, inner.replace(data=pushed), action, key)
    data = next_state.data.replace(xfrc_applied=next_state.data.xfrc_applied.at[body, :3].add(-applied))
    dt = elapsed(state, next_state)
    pushes = ForcePushState(
        countdown=jnp.where(start, _draw(draw_key, interval), pushes.countdown) - dt,
        remaining=jnp.maximum(remaining - dt, 0.0),
        force=force,
    )
    metrics = {"force_push/started": start.astype(jnp.float32), "force_push/force": jnp.linalg.norm(applied)}
    return wrap(next_state, pushes).replace(data=data, metrics={**next_state.metrics, **metrics})
