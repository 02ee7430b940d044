"""Reset items: randomize the physics state an episode starts from.

A reset item is ``(model: mjx.Model, data: mjx.Data, key) -> mjx.Data``; it edits the
`qpos` / `qvel` the task's own reset chose. An item that draws something the episode
must remember (a goal, a target) returns ``(data, {name: value})``: the entries are
merged into `state.info`. `with_resets(task, *items, observe=...)`
applies items in order after that reset, then recomputes what derives from the state
(body poses, sensors) with `mjx.forward`, then the observation with `observe`.

    task = resets.with_resets(
        task,
        resets.joint_positions(task.mj_model, fraction=0.3),
        resets.base_heading(task.mj_model),
        resets.base_velocity(task.mj_model, linear=(0.2, 0.2, 0.0)),
        observe=my_observation,  # (model, state) -> obs, the task's own
    )

Why `observe` is an argument: the task computed its observation inside its reset, from
the state before the items ran, and a `Task` exposes no separate observation function
(re-running its step would advance time). Pass the function the task observes with (an
observation item, or `observations.concat(...)` of several); `with_resets` checks at
construction that it gives the task's observation shape.

Where it sits: directly around the task that computes the observation, below
combinators that derive state from the reset (observation noise or history, trackers,
commands), and below `with_auto_reset` so that every episode is randomized. Cost: an
auto-reset computes a fresh reset at every step (and keeps it where an episode ended),
so the `mjx.forward` runs every step too, about one physics step's worth of work.

Reference-state initialization (`reference_state`) starts episodes at frames of a
`mjzoo.motion.Reference`: the whole qpos and qvel of a recorded frame.

Items use the free joint of the base `body` (None: the model's first free joint, see
`mjzoo.names`) or hinge and slide joints (`joints=None`: all of them). The free joint's `qvel` is MuJoCo's: linear
velocity in the world frame, angular velocity in the body frame.
"""

from __future__ import annotations

from typing import Callable
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import checks
from mjzoo import motion
from mjzoo import names
from mjzoo import physics
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "with_resets",
    "joint_positions",
    "joint_position_noise",
    "joint_velocities",
    "base_heading",
    "base_height",
    "base_tilt",
    "base_velocity",
    "reference_state",
]

Array = jax.Array
ResetItem = Callable[[mjx.Model, mjx.Data, Array], mjx.Data]
RESETS_STREAM = 0x4E5  # fold_in tag: the inner reset keeps its own key


# --- the combinator -----------------------------------------------------------------


def with_resets(task: Task, *items: ResetItem, observe: Callable[[mjx.Model, State], object]) -> Task:
    """Applies reset `items` in order after `task`'s reset, then `mjx.forward`, then
    ``state.obs = observe(model, state)``.

    Each item gets its own key, derived from the reset key. Keeps in `info` what the
    items return next to their data (``(data, {name: value})``), after the entries
    of the task's reset. Raises ValueError when no item is given, an item does not
    return an `mjx.Data` (or one with a dict), or `observe` gives another shape than
    the task's observation.
    """
    if not items:
        raise ValueError("with_resets: give at least one reset item")
    for i, fn in enumerate((*items, observe)):
        what = "observe" if i == len(items) else f"item {i}"
        if not callable(fn):
            raise TypeError(f"with_resets: {what} must be callable, got {type(fn).__name__}")
        checks.retrace_hazard("with_resets", what, fn)
    items = tuple(fn if isinstance(fn, jax.tree_util.Partial) else jax.tree_util.Partial(fn) for fn in items)
    if not isinstance(observe, jax.tree_util.Partial):
        observe = jax.tree_util.Partial(observe)
    _check(task, items, observe)
    return task.replace(start=Partial(_reset, task.start, items, observe))


def _reset(reset_fn, items, observe, model: mjx.Model, key: Array) -> State:
    state = reset_fn(model, key)
    data, info = state.data, dict(state.info)
    for item, item_key in zip(items, jax.random.split(jax.random.fold_in(key, RESETS_STREAM), len(items))):
        data, written = _data_and_info(item(model, data, item_key))
        info.update(written)
    state = state.replace(data=physics.forward(model, data), info=info)
    return state.replace(obs=observe(model, state))


def _data_and_info(out) -> tuple[mjx.Data, dict]:
    """An item's result as (data, info entries): it returns data or (data, {name: value})."""
    return (out[0], out[1]) if isinstance(out, tuple) else (out, {})


def _check(task: Task, items, observe) -> None:
    key = jax.random.key(0)
    state = jax.eval_shape(task.start, task.model, key)
    for i, item in enumerate(items):
        out = jax.eval_shape(item, task.model, state.data, key)
        data, info = out if isinstance(out, tuple) and len(out) == 2 else (out, {})
        if jax.tree.structure(data) != jax.tree.structure(state.data) or not isinstance(info, dict):
            raise ValueError(
                f"with_resets: item {i} must return an mjx.Data or (mjx.Data, dict of info entries), "
                f"got {type(out).__name__}"
            )
        state = state.replace(info={**state.info, **info})
    seen = _shapes(jax.eval_shape(lambda s: observe(task.model, s), state))
    if seen != _shapes(state.obs):
        raise ValueError(
            f"with_resets: observe gives {seen}, but the task observes {_shapes(state.obs)}; "
            "pass the function the task computes its observation with"
        )


def _shapes(tree):
    return jax.tree.map(lambda x: (x.shape, str(x.dtype)), tree)


def _free_joint(mj_model: mujoco.MjModel, body: str | None, who: str) -> tuple[Array, Array]:
    return tuple(jnp.asarray(i) for i in names.free_joint_addresses(mj_model, body, who))


# --- quaternions (w, x, y, z), MuJoCo's convention ----------------------------------


def _quat_mul(a: Array, b: Array) -> Array:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return jnp.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def _axis_quat(axis: int, angle: Array) -> Array:
    """Rotation by `angle` rad about the x (0), y (1) or z (2) axis."""
    return jnp.zeros(4).at[0].set(jnp.cos(angle / 2)).at[axis + 1].set(jnp.sin(angle / 2))


# --- joint items --------------------------------------------------------------------


def joint_positions(mj_model: mujoco.MjModel, fraction: float = 0.5, joints: Sequence[str] | None = None) -> ResetItem:
    """Each joint's position uniform in a `fraction` of its range around the reset pose.

    For a joint at q (rad or m, as the task's reset left it) with range [lo, hi]:
    qpos ~ U(q - fraction (q - lo), q + fraction (hi - q)); fraction 1 spans the whole
    range, 0 keeps q. Ranges are read from the model at each reset (so randomized
    ranges apply). `joints`: hinge or slide joint names with a range; None: every such
    joint. `fraction` in [0, 1].
    """
    who = "resets.joint_positions"
    ids = names.joints(mj_model, joints, who, limited=True)
    fraction = checks.number(who, "fraction", fraction, 0.0, 1.0)
    return Partial(_joint_positions, jnp.asarray(ids), jnp.asarray(mj_model.jnt_qposadr[ids]), fraction)


def _joint_positions(ids, qpos_idx, fraction, model, data, key):
    q, lo, hi = data.qpos[qpos_idx], model.jnt_range[ids, 0], model.jnt_range[ids, 1]
    low, high = q - fraction * (q - lo), q + fraction * (hi - q)
    return data.replace(qpos=data.qpos.at[qpos_idx].set(jax.random.uniform(key, q.shape, minval=low, maxval=high)))


def joint_position_noise(mj_model: mujoco.MjModel, scale, joints: Sequence[str] | None = None) -> ResetItem:
    """Adds U(-scale, scale) (rad or m) to each joint's reset position, clipped to its
    range if it has one. `scale`: a number >= 0 or one per joint. `joints`: hinge or
    slide joint names; None: all of them."""
    who = "resets.joint_position_noise"
    ids = names.joints(mj_model, joints, who)
    scale = checks.numbers(who, "scale", scale, len(ids))
    limited = jnp.asarray(mj_model.jnt_limited[ids], bool)
    return Partial(_joint_position_noise, jnp.asarray(ids), jnp.asarray(mj_model.jnt_qposadr[ids]), limited, scale)


def _joint_position_noise(ids, qpos_idx, limited, scale, model, data, key):
    q = data.qpos[qpos_idx] + jax.random.uniform(key, scale.shape, minval=-scale, maxval=scale)
    clipped = jnp.clip(q, model.jnt_range[ids, 0], model.jnt_range[ids, 1])
    return data.replace(qpos=data.qpos.at[qpos_idx].set(jnp.where(limited, clipped, q)))


def joint_velocities(mj_model: mujoco.MjModel, scale, joints: Sequence[str] | None = None) -> ResetItem:
    """Adds U(-scale, scale) (rad/s or m/s) to each joint's reset velocity. `scale`: a
    number >= 0 or one per joint. `joints`: hinge or slide joint names; None: all."""
    who = "resets.joint_velocities"
    ids = names.joints(mj_model, joints, who)
    return Partial(
        _joint_velocities, jnp.asarray(mj_model.jnt_dofadr[ids]), checks.numbers(who, "scale", scale, len(ids))
    )


def _joint_velocities(dof_idx, scale, model, data, key):
    noise = jax.random.uniform(key, scale.shape, minval=-scale, maxval=scale)
    return data.replace(qvel=data.qvel.at[dof_idx].add(noise))


# --- base (free joint) items --------------------------------------------------------


def base_heading(mj_model: mujoco.MjModel, yaw=(-np.pi, np.pi), body: str | None = None) -> ResetItem:
    """Turns the base about the vertical through it by U(yaw) rad: its orientation and
    its (world-frame) linear velocity rotate; position and body-frame angular velocity
    stay. Commutes with `base_tilt`."""
    who = "resets.base_heading"
    return Partial(_base_heading, *_free_joint(mj_model, body, who), checks.interval(who, "yaw", yaw))


def _base_heading(qpos_idx, qvel_idx, yaw, model, data, key):
    angle = jax.random.uniform(key, (), minval=yaw[0], maxval=yaw[1])
    quat = _quat_mul(_axis_quat(2, angle), data.qpos[qpos_idx[3:]])
    vx, vy = data.qvel[qvel_idx[0]], data.qvel[qvel_idx[1]]
    c, s = jnp.cos(angle), jnp.sin(angle)
    qvel = data.qvel.at[qvel_idx[:2]].set(jnp.stack([c * vx - s * vy, s * vx + c * vy]))
    return data.replace(qpos=data.qpos.at[qpos_idx[3:]].set(quat), qvel=qvel)


def base_height(mj_model: mujoco.MjModel, height, body: str | None = None) -> ResetItem:
    """Sets the base's world z position to U(height) m; `height` = (low, high)."""
    who = "resets.base_height"
    qpos_idx, _ = _free_joint(mj_model, body, who)
    return Partial(_base_height, qpos_idx[2], checks.interval(who, "height", height))


def _base_height(z_idx, height, model, data, key):
    z = jax.random.uniform(key, (), minval=height[0], maxval=height[1])
    return data.replace(qpos=data.qpos.at[z_idx].set(z))


def base_tilt(mj_model: mujoco.MjModel, roll: float = 0.1, pitch: float = 0.1, body: str | None = None) -> ResetItem:
    """Tilts the base by pitch ~ U(-pitch, pitch) about its own y axis, then roll ~
    U(-roll, roll) about its own x axis (rad): quat <- quat * q_y(pitch) * q_x(roll), the
    Z-Y-X Euler order, so the heading is kept. Velocities are left as they are."""
    who = "resets.base_tilt"
    qpos_idx, _ = _free_joint(mj_model, body, who)
    return Partial(_base_tilt, qpos_idx, checks.numbers(who, "(roll, pitch)", (roll, pitch), 2))


def _base_tilt(qpos_idx, limits, model, data, key):
    roll, pitch = jax.random.uniform(key, (2,), minval=-limits, maxval=limits)
    quat = _quat_mul(_quat_mul(data.qpos[qpos_idx[3:]], _axis_quat(1, pitch)), _axis_quat(0, roll))
    return data.replace(qpos=data.qpos.at[qpos_idx[3:]].set(quat))


def base_velocity(
    mj_model: mujoco.MjModel, linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, 0.0), body: str | None = None
) -> ResetItem:
    """Adds U(-linear_i, linear_i) m/s to each axis of the base's world-frame linear
    velocity and U(-angular_i, angular_i) rad/s to its body-frame angular velocity;
    `linear`, `angular`: 3 numbers >= 0 each."""
    who = "resets.base_velocity"
    _, qvel_idx = _free_joint(mj_model, body, who)
    limits = jnp.concatenate([checks.numbers(who, "linear", linear, 3), checks.numbers(who, "angular", angular, 3)])
    return Partial(_base_velocity, qvel_idx, limits)


def _base_velocity(qvel_idx, limits, model, data, key):
    kick = jax.random.uniform(key, (6,), minval=-limits, maxval=limits)
    return data.replace(qvel=data.qvel.at[qvel_idx].add(kick))


# --- reference-state initialization --------------------------------------------------


def reference_state(reference: motion.Reference, probability: float = 1.0) -> ResetItem:
    """With `probability`, the episode starts at a frame of `reference` drawn by
    `motion.sample_frame` (clip by weight, frame uniform in the clip): its qpos and
    qvel replace the whole state. Otherwise the task's own reset state is kept.

    Writes ``info["reference_clip"]`` and ``info["reference_frame"]`` (int32 []): the
    clip and frame started from, -1 and -1 when the task's own reset was kept (a
    tracker can follow the reference from there). A looping clip sampled mid-way
    keeps its root position as recorded. The reference and `probability` in [0, 1]
    are leaves: other clips or probabilities of the same shapes do not recompile; the
    probability is the task's parameter ``reference_probability`` (`mjzoo.params`).
    """
    who = "resets.reference_state"
    if not isinstance(reference, motion.Reference):
        raise TypeError(
            f"{who}: reference must be a motion.Reference (motion.reference(...)), got {type(reference).__name__}"
        )
    probability = checks.number(who, "probability", probability, 0.0, 1.0)
    return Partial(_reference_state, reference, reference_probability=probability)  # a keyword: a named leaf


def _reference_state(reference, model, data, key, reference_probability):
    if reference.qpos.shape[1:] != data.qpos.shape or reference.qvel.shape[1:] != data.qvel.shape:
        raise ValueError(
            f"resets.reference_state: the reference has nq={reference.qpos.shape[1]}, "
            f"nv={reference.qvel.shape[1]} but the task's model nq={data.qpos.shape[0]}, "
            f"nv={data.qvel.shape[0]}"
        )
    use_key, frame_key = jax.random.split(key)
    clip, t = motion.sample_frame(reference, frame_key)
    index = motion.frame_index(reference, clip, t)
    use = jax.random.uniform(use_key) < reference_probability
    qpos = jnp.where(use, reference.qpos[index].astype(data.qpos.dtype), data.qpos)
    qvel = jnp.where(use, reference.qvel[index].astype(data.qvel.dtype), data.qvel)
    info = {"reference_clip": jnp.where(use, clip, -1), "reference_frame": jnp.where(use, t, -1)}
    return data.replace(qpos=qpos, qvel=qvel), info
