"""Termination items and `with_terminations`, which ends episodes on them.

A termination item is ``(model: mjx.Model, state: State) -> Array[]`` bool, for ONE
environment: True when the state is terminal (no value bootstrap). Items with names or
numbers are built by constructors taking the host `mujoco.MjModel` (``task.mj_model``);
names are resolved once and every number is a float32 / int32 pytree leaf, so changing
a limit does not retrace:

    task = terminations.with_terminations(task, {
        "fallen": terminations.not_upright(task.mj_model, max_angle=1.0),
        "too_low": terminations.base_too_low(task.mj_model, min_height=0.2),
        "torso_contact": terminations.illegal_contact(task.mj_model, ["torso"], others="floor"),
    })

Body poses and contacts are read from ``state.data`` as the last `mjx.step` left them
(computed before integration: one physics substep behind qpos and qvel).
"""

from __future__ import annotations

import math
from typing import Callable
from typing import Mapping

import jax
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from mjzoo import checks
from mjzoo import names
from mjzoo import tree
from mjzoo.catalog import contacts
from mjzoo.combinators import TimeLimitState
from mjzoo.layers import find
from mjzoo.running import reset
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "not_upright",
    "base_too_low",
    "base_too_high",
    "illegal_contact",
    "bad_velocity",
    "far_from_origin",
    "episode_length",
    "with_terminations",
]

Array = jax.Array
Partial = jax.tree_util.Partial
Termination = Callable[[mjx.Model, State], Array]
Names = names.Names


def _base(mj_model: mujoco.MjModel, body: str | None, who: str) -> Array:
    return jnp.int32(names.base_body(mj_model, body, who))


# --- items ----------------------------------------------------------------------------


def not_upright(mj_model: mujoco.MjModel, max_angle: float, body: str | None = None) -> Partial:
    """True when the body's z axis tilts from the world's vertical by more than
    `max_angle` (rad, in (0, pi]): ``xmat[2, 2] = cos(tilt) < cos(max_angle)``. The body
    defaults to the first body with a free joint (the floating base)."""
    max_angle = checks.number("not_upright", "max_angle", max_angle, 0.0, math.pi, open_low=True)
    return Partial(_not_upright, _base(mj_model, body, "not_upright"), max_angle)


def _not_upright(body, max_angle, model, state) -> Array:
    return state.data.xmat[body, 2, 2] < jnp.cos(max_angle)


def base_too_low(mj_model: mujoco.MjModel, min_height: float, body: str | None = None) -> Partial:
    """True when the body's origin is below `min_height` (m, world z). The body defaults
    to the first body with a free joint."""
    min_height = checks.number("base_too_low", "min_height", min_height)
    return Partial(_base_too_low, _base(mj_model, body, "base_too_low"), min_height)


def _base_too_low(body, min_height, model, state) -> Array:
    return state.data.xpos[body, 2] < min_height


def base_too_high(mj_model: mujoco.MjModel, max_height: float, body: str | None = None) -> Partial:
    """True when the body's origin is above `max_height` (m, world z): a legged robot
    that leaves the ground by that much has found a contact exploit, not a gait. The
    body defaults to the first body with a free joint."""
    max_height = checks.number("base_too_high", "max_height", max_height)
    return Partial(_base_too_high, _base(mj_model, body, "base_too_high"), max_height)


def _base_too_high(body, max_height, model, state) -> Array:
    return state.data.xpos[body, 2] > max_height


def illegal_contact(mj_model: mujoco.MjModel, geoms: Names, others: Names | None = None) -> Partial:
    """True when any of the named geoms touches one of `others` (any geom if None), e.g.
    the torso or the knees with the floor. Touching: an active contact (distance below
    margin - gap)."""
    return Partial(_illegal_contact, *contacts.geom_sets(mj_model, geoms, others, "illegal_contact"))


def _illegal_contact(geoms, others, model, state) -> Array:
    return jnp.any(contacts.touching(state.data, geoms, others))


def bad_velocity(max_qvel: float) -> Partial:
    """True when any |qvel| entry exceeds `max_qvel` (rad/s or m/s, > 0) or qpos or qvel
    is not finite.

    For a task-specific limit counted in the metrics. `mjzoo.with_divergence_guard`
    stays the safety net: it also reverts the physics so NaN never reaches the batch.
    """
    return Partial(_bad_velocity, checks.number("bad_velocity", "max_qvel", max_qvel, 0.0, open_low=True))


def _bad_velocity(max_qvel, model, state) -> Array:
    data = state.data
    finite = jnp.all(jnp.isfinite(data.qpos)) & jnp.all(jnp.isfinite(data.qvel))
    return ~finite | jnp.any(jnp.abs(jnp.nan_to_num(data.qvel)) > max_qvel)


def far_from_origin(mj_model: mujoco.MjModel, radius: float, body: str | None = None) -> Partial:
    """True when the body's origin is more than `radius` (m, > 0) from the world origin
    in the horizontal plane (x, y). The body defaults to the first body with a free
    joint."""
    radius = checks.number("far_from_origin", "radius", radius, 0.0, open_low=True)
    return Partial(_far_from_origin, _base(mj_model, body, "far_from_origin"), radius)


def _far_from_origin(body, radius, model, state) -> Array:
    return jnp.linalg.norm(state.data.xpos[body, :2]) > radius


def episode_length(max_steps: int) -> Partial:
    """True once the episode has taken `max_steps` steps, counted by the nearest
    `mjzoo.with_time_limit` inside it (its `TimeLimitState`; every env from
    a shipped env, built by `mjzoo.task(..., time_limit=N)`, has one; wrap `with_terminations` outside it).

    `with_time_limit` truncates: the episode is cut short and the value is bootstrapped,
    right when time is not part of the task (the usual case in locomotion). This item
    terminates: the episode really ends there and nothing comes after it, right for a
    task with a fixed horizon whose observation carries the time.
    """
    return Partial(_episode_length, jnp.int32(checks.integer("episode_length", "max_steps", max_steps)))


def _episode_length(max_steps, model, state) -> Array:
    return find(state, TimeLimitState).steps >= max_steps


# --- the combinator -------------------------------------------------------------------


def with_terminations(task: Task, items: Mapping[str, Termination]) -> Task:
    """Terminates the episode when the task's own terminate or any item says so.

    ``terminated = inner terminated | any(item(model, next_state))``; truncated only if
    not terminated. Each item's flag on the state a step returns is recorded in
    ``metrics["termination/<name>"]`` as float32 1.0 / 0.0 (0 at reset); averaged over a
    batch, it is the fraction of episodes ending for that reason. Keeps no record.

    Items see the state this combinator's step returns: wrap it outside the combinators
    whose records they read (`with_time_limit` for `episode_length`) and inside
    `with_auto_reset` and `with_action_repeat` (so that every inner step is checked).
    """
    if not isinstance(items, Mapping) or not items:
        raise ValueError(f"with_terminations: items must be a non-empty dict {{name: fn}}, got {items!r}")
    for name, fn in items.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"with_terminations: every name must be a non-empty string, got {name!r}")
        if not callable(fn):
            raise TypeError(f"with_terminations: item {name!r} must be callable, got {type(fn).__name__}")
    names = tree.StaticValue(tuple(items))
    fns = tuple(fn if isinstance(fn, Partial) else Partial(fn) for fn in items.values())
    _check_items(task, names.value, fns)
    return task.replace(
        start=Partial(_terminations_reset, task.start, names),
        step=Partial(_terminations_step, task.step, names, fns),
        terminate=Partial(_terminations_terminate, task.terminate, fns),
    )


def _check_items(task: Task, names: tuple[str, ...], fns: tuple) -> None:
    """Fails at construction if an item cannot run on the task's states, returns no
    scalar, or its metric name is taken. Abstract evaluation only: no compile."""
    state = jax.eval_shape(lambda key: reset(task, key), jax.random.key(0))
    for name, fn in zip(names, fns):
        if f"termination/{name}" in state.metrics:
            raise ValueError(f"with_terminations: the task already records metrics['termination/{name}']")
        try:
            out = jax.eval_shape(fn, task.model, state)
        except KeyError as e:
            raise ValueError(
                f"with_terminations: item {name!r} reads info[{e.args[0]!r}], which the task does not keep; "
                f"info keys: {sorted(state.info)}"
            ) from None
        except LookupError as e:  # a combinator's record the task does not keep, from mjzoo.find
            raise ValueError(f"with_terminations: item {name!r}: {e}") from None
        if not hasattr(out, "shape") or out.shape != ():
            raise ValueError(f"with_terminations: item {name!r} must return a scalar, got {out}")


def _flags(fns, model, state: State) -> list[Array]:
    return [jnp.asarray(fn(model, state), bool) for fn in fns]


def _terminations_reset(reset_fn, names: tree.StaticValue, model, key) -> State:
    state = reset_fn(model, key)
    zeros = {f"termination/{name}": jnp.zeros((), jnp.float32) for name in names.value}
    return state.replace(metrics={**state.metrics, **zeros})


def _terminations_step(step_fn, names: tree.StaticValue, fns, model, state, action, key) -> State:
    next_state = step_fn(model, state, action, key)
    flags = _flags(fns, model, next_state)
    recorded = {f"termination/{name}": flag.astype(jnp.float32) for name, flag in zip(names.value, flags)}
    return next_state.replace(metrics={**next_state.metrics, **recorded})


def _terminations_terminate(terminate_fn, fns, model, state) -> tuple[Array, Array]:
    terminated, truncated = terminate_fn(model, state)
    terminated = jnp.asarray(terminated, bool) | jnp.any(jnp.stack(_flags(fns, model, state)))
    return terminated, jnp.asarray(truncated, bool) & ~terminated
