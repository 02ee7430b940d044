"""Commands, `Task -> Task`: targets the policy is asked to follow, redrawn at random times.

    task = commands.with_velocity_command(task, vx=(-1, 1), vy=(-0.5, 0.5), yaw_rate=(-1, 1))
    mjzoo.find(state, commands.VelocityCommandState).command  # float32 [3]: vx, vy (m/s, base frame), yaw rate (rad/s)

Each combinator draws a target at reset and again every U(resample_interval) seconds of
physics time (a countdown, as in `events`), and keeps it, with the command it publishes,
in its record, which rewards and observations find by type (`mjzoo.find`):
  `VelocityCommandState`  ``command`` [3]   `with_velocity_command`, `with_heading_command`
  `JointCommandState`     ``command`` [J]   `with_joint_position_command`
Each record also holds ``countdown`` (s to the next draw) and ``target``. Metrics:
``<name>/resampled`` (1 at a step that drew a new target).

Timing: the command is redrawn at the END of a step, after the inner step. So the
command an action was chosen for is the one in the state it was chosen from; at a
resampling step `next_state` already holds the next command. Tracking rewards should
read the command from `state`.

Observation: ``observe=True`` (the default) is THE way a policy sees its command: the
combinator appends the command to the observation (a 1-D array) after every reset and
step, so the observation always carries the command the next action is for. The
catalog has no observation item for it because the inner task observes before the
command is redrawn (and before it exists, at reset). The inner task's step still
receives its own observation (the command stripped off). With ``observe=False`` the
command is only in the record (for rewards, or an observation pytree the user builds
outside this combinator).

Where they sit: inside `with_auto_reset` (a new command each episode), outside
`with_resets`, and below observation noise or history (those then see the command too).
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import NamedTuple
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial

from mjzoo import checks
from mjzoo import names
from mjzoo import tree
from mjzoo.catalog.events import countdown_interval
from mjzoo.catalog.events import due
from mjzoo.catalog.events import elapsed
from mjzoo.catalog.shaping import wrap_angle
from mjzoo.layers import layered
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "with_velocity_command",
    "with_heading_command",
    "with_joint_position_command",
    "VelocityCommandState",
    "JointCommandState",
]

Array = jax.Array
COMMAND_STREAM = 0xC0D  # fold_in tag: the inner task keeps its own key


class VelocityCommandState(NamedTuple):
    """The record of `with_velocity_command` and `with_heading_command`: ``command``
    float32 [3] = [vx, vy, yaw rate] (m/s, m/s, rad/s, base heading frame), the
    ``target`` [3] it is made from, ``countdown`` s to the next draw."""

    countdown: Array
    target: Array
    command: Array
    inner: Any = ()


class JointCommandState(NamedTuple):
    """`with_joint_position_command`'s record: ``command`` = ``target`` [J] joint
    positions (rad or m), ``countdown`` s to the next draw."""

    countdown: Array
    target: Array
    command: Array
    inner: Any = ()


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class _Command:
    """What one command combinator needs: its record type, how to draw a target and how
    to turn the target into the published command."""

    interval: Array  # [2] s between redraws
    low: Array  # [k] the target is uniform in [low, high] per component
    high: Array
    zero_probability: Array  # each zeroable component is 0 with this probability
    stand_probability: Array  # all zeroable components are 0 with this probability
    zeroable: Array  # [k] bool
    publish: jax.tree_util.Partial  # (model, data, target [k]) -> command
    name: str = dataclasses.field(metadata=dict(static=True))  # the metrics' prefix
    record: type = dataclasses.field(metadata=dict(static=True))  # VelocityCommandState or JointCommandState
    observe: bool = dataclasses.field(metadata=dict(static=True))


def _with_command(task: Task, command: _Command) -> Task:
    if command.observe:
        obs = jax.eval_shape(task.start, task.model, jax.random.key(0)).obs
        if not (isinstance(obs, jax.ShapeDtypeStruct) and obs.ndim == 1):
            raise ValueError(
                f"commands: observe=True appends the command to a 1-D array observation, but the task "
                f"observes {jax.tree.map(lambda x: x.shape, obs)}; pass observe=False and read "
                f"mjzoo.find(state, {command.record.__name__}).command"
            )
    start = Partial(_command_reset, task.start, command)
    return layered(task, command.record, start, Partial(_command_step, task.step, command))


def _draw(c: _Command, key: Array) -> dict[str, Array]:
    """A new target and the time to the next redraw."""
    value_key, zero_key, stand_key, time_key = jax.random.split(jax.random.fold_in(key, COMMAND_STREAM), 4)
    value = jax.random.uniform(value_key, c.low.shape, minval=c.low, maxval=c.high)
    zero = jax.random.uniform(zero_key, c.low.shape) < c.zero_probability
    zero |= jax.random.uniform(stand_key, ()) < c.stand_probability
    countdown = jax.random.uniform(time_key, (), minval=c.interval[0], maxval=c.interval[1])
    return {"countdown": countdown, "target": jnp.where(zero & c.zeroable, 0.0, value)}


def _publish(c: _Command, model, state: State, own: dict, inner_obs, metrics: dict) -> State:
    command = c.publish(model, state.data, own["target"])
    obs = jnp.concatenate([inner_obs, command.astype(inner_obs.dtype)]) if c.observe else inner_obs
    record = c.record(countdown=own["countdown"], target=own["target"], command=command)
    return wrap(state, record).replace(obs=obs, metrics={**state.metrics, **metrics})


def _command_reset(reset_fn, c: _Command, model, key) -> State:
    state = reset_fn(model, key)
    return _publish(c, model, state, _draw(c, key), state.obs, {})


def _command_step(step_fn, c: _Command, model, state, action, key) -> State:
    inner_obs = state.obs[: -c.low.shape[0]] if c.observe else state.obs
    record, inner = peel(state, c.record)
    next_state = step_fn(model, inner.replace(obs=inner_obs), action, key)
    countdown = record.countdown - elapsed(state, next_state)
    resample = due(model, countdown)
    own = tree.where(resample, _draw(c, key), {"countdown": countdown, "target": record.target})
    return _publish(c, model, next_state, own, next_state.obs, {f"{c.name}/resampled": resample.astype(jnp.float32)})


def _identity(model, data, target):
    return target


def _probabilities(who: str, **values: float) -> dict[str, Array]:
    return {name: checks.number(who, name, value, 0.0, 1.0) for name, value in values.items()}


# --- velocity -----------------------------------------------------------------------


def with_velocity_command(
    task: Task,
    vx: Sequence[float] = (-1.0, 1.0),
    vy: Sequence[float] = (-0.5, 0.5),
    yaw_rate: Sequence[float] = (-1.0, 1.0),
    resample_interval: Sequence[float] = (5.0, 10.0),
    zero_probability: float = 0.0,
    stand_probability: float = 0.0,
    observe: bool = True,
) -> Task:
    """A velocity command `VelocityCommandState` ``.command`` = [vx, vy, yaw rate] (m/s, m/s, rad/s;
    forward, left, counter-clockwise, in the base's heading frame).

    Each component ~ U(range), then independently set to 0 with `zero_probability`;
    all three are 0 (stand still) with `stand_probability`. Redrawn every
    U(resample_interval) s.
    """
    who = "commands.with_velocity_command"
    ranges = [checks.interval(who, n, r) for n, r in (("vx", vx), ("vy", vy), ("yaw_rate", yaw_rate))]
    command = _Command(
        interval=countdown_interval(who, "resample_interval", resample_interval),
        low=jnp.stack([r[0] for r in ranges]),
        high=jnp.stack([r[1] for r in ranges]),
        **_probabilities(who, zero_probability=zero_probability, stand_probability=stand_probability),
        zeroable=jnp.ones(3, bool),
        publish=Partial(_identity),
        name="velocity_command",
        record=VelocityCommandState,
        observe=bool(observe),
    )
    return _with_command(task, command)


# --- heading ------------------------------------------------------------------------


def with_heading_command(
    task: Task,
    vx: Sequence[float] = (-1.0, 1.0),
    vy: Sequence[float] = (-0.5, 0.5),
    heading: Sequence[float] = (-np.pi, np.pi),
    gain: float = 0.5,
    max_yaw_rate: float = 1.0,
    resample_interval: Sequence[float] = (5.0, 10.0),
    zero_probability: float = 0.0,
    stand_probability: float = 0.0,
    body: str | None = None,
    observe: bool = True,
) -> Task:
    """A velocity command whose yaw rate steers the base to a target heading:
    `VelocityCommandState` ``.command`` = [vx, vy, clip(gain * wrap(target - yaw), +-max_yaw_rate)],
    yaw = the heading of the base `body`'s x axis (rad, from its free joint; None: the
    model's first free joint), recomputed after every step; gain in 1/s.

    vx, vy and the target heading (rad, world frame) are redrawn every
    U(resample_interval) s; `zero_probability` and `stand_probability` apply to vx, vy
    only. Its record's ``target`` is [vx, vy, heading].
    """
    who = "commands.with_heading_command"
    ranges = [checks.interval(who, n, r) for n, r in (("vx", vx), ("vy", vy), ("heading", heading))]
    gain, max_yaw_rate = checks.number(who, "gain", gain, 0.0), checks.number(who, "max_yaw_rate", max_yaw_rate, 0.0)
    qpos_idx, _ = names.free_joint_addresses(task.mj_model, body, who)
    command = _Command(
        interval=countdown_interval(who, "resample_interval", resample_interval),
        low=jnp.stack([r[0] for r in ranges]),
        high=jnp.stack([r[1] for r in ranges]),
        **_probabilities(who, zero_probability=zero_probability, stand_probability=stand_probability),
        zeroable=jnp.array([True, True, False]),
        publish=Partial(_steer, jnp.asarray(qpos_idx[3:]), gain, max_yaw_rate),
        name="heading_command",
        record=VelocityCommandState,
        observe=bool(observe),
    )
    return _with_command(task, command)


def _steer(quat_idx, gain, max_yaw_rate, model, data, target) -> Array:
    w, x, y, z = data.qpos[quat_idx]
    yaw = jnp.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))  # heading of the body's x axis
    error = wrap_angle(target[2] - yaw)
    return jnp.stack([target[0], target[1], jnp.clip(gain * error, -max_yaw_rate, max_yaw_rate)])


# --- joint positions ----------------------------------------------------------------


def with_joint_position_command(
    task: Task,
    joints: Sequence[str],
    ranges: Sequence[Sequence[float]] | None = None,
    resample_interval: Sequence[float] = (5.0, 10.0),
    observe: bool = True,
) -> Task:
    """Target positions `JointCommandState` ``.command`` [J] (rad or m) for hinge / slide
    `joints`, each ~ U(range), redrawn every U(resample_interval) s.

    `ranges`: one (low, high) per joint; None: each joint's own range (the joints must
    have one).
    """
    who = "commands.with_joint_position_command"
    ids = names.joints(task.mj_model, joints, who, limited=ranges is None)
    if ranges is None:
        ranges = task.mj_model.jnt_range[ids]
    elif len(ranges) != len(ids):
        raise ValueError(f"{who}: give one (low, high) range per joint: {len(ids)} joints, {len(ranges)} ranges")
    joint_names = names.all_names(task.mj_model, "joint", ids)
    ranges = jnp.stack([checks.interval(who, f"range of {name!r}", r) for name, r in zip(joint_names, ranges)])
    command = _Command(
        interval=countdown_interval(who, "resample_interval", resample_interval),
        low=ranges[:, 0],
        high=ranges[:, 1],
        zero_probability=jnp.float32(0.0),
        stand_probability=jnp.float32(0.0),
        zeroable=jnp.zeros(len(ids), bool),
        publish=Partial(_identity),
        name="joint_position_command",
        record=JointCommandState,
        observe=bool(observe),
    )
    return _with_command(task, command)
