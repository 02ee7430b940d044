"""Reward terms, and the bounded shape `tolerance` (from `mjzoo.catalog.shaping`).

Every item but `tolerance` and `terms` is a reward term ``(model, state, action,
next_state) -> float32 scalar``, UNWEIGHTED: the weight comes from
``mjzoo.with_reward(task, name, fn, weight)`` or `terms`. A term documented as a "Reward" grows with good behaviour (give it a
positive weight); a "Cost" is >= 0 and grows with bad behaviour (give it a negative
weight). Unless said otherwise a term reads the physics of `next_state` (after the
action), so add terms inside `with_auto_reset`; the command is
``mjzoo.find(state, commands.VelocityCommandState).command`` ([3]: forward m/s, lateral
m/s, yaw rad/s, in the base frame), the one in force when the action was chosen.

Constructors resolve names once, from the host `mujoco.MjModel` (``task.mj_model``), and
return ``Partial(fn, ...)``: indices and numbers are pytree leaves. Base terms read
the free joint of `body` (default: the model's first free joint, see `mjzoo.names`) from
``qpos`` / ``qvel``: the state after the step's integration.
"""

from __future__ import annotations

import math
from typing import Callable
from typing import Mapping
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjzoo import checks
from mjzoo import names
from mjzoo.catalog.commands import VelocityCommandState
from mjzoo.catalog.shaping import SIGMOIDS
from mjzoo.catalog.shaping import tolerance
from mjzoo.catalog.trackers import ActionHistoryState
from mjzoo.catalog.trackers import FeetState
from mjzoo.combinators import with_rewards
from mjzoo.layers import find
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "tolerance",
    "SIGMOIDS",
    "terms",
    "alive",
    "linear_velocity_tracking",
    "command_progress",
    "angular_velocity_tracking",
    "vertical_velocity",
    "roll_pitch_velocity",
    "base_height",
    "flat_orientation",
    "upright",
    "joint_deviation",
    "stand_still",
    "joint_limits",
    "symmetry",
    "action_rate",
    "action_acceleration",
    "action_jerk",
    "torque",
    "energy",
    "feet_air_time",
    "foot_slip",
    "foot_clearance",
    "forward_velocity",
    "body_height",
    "effort",
]

Array = jax.Array
Partial = jax.tree_util.Partial


# --- composing terms ----------------------------------------------------------------


def terms(task: Task, spec: Mapping[str, tuple[Callable, float]]) -> Task:
    """Adds each ``name: (fn, weight)`` of `spec` as `mjzoo.with_reward` would, in order.

    A name the task already has raises `with_reward`'s ValueError.
    """
    for name, entry in spec.items():
        if not (isinstance(entry, tuple) and len(entry) == 2):
            raise ValueError(f"terms: entry {name!r} must be a (fn, weight) pair, got {entry!r}")
    return with_rewards(task, spec)


def alive(task: Task) -> Partial:
    """Reward: 1 per transition, 0 on one that `task` terminates (truncation is not a
    failure). Evaluates `task.terminate` on `next_state`, so add it to `task` itself or
    to a task with the same terminations."""
    return Partial(_alive, task.terminate)


def _alive(terminate_fn, model, state, action, next_state) -> Array:
    terminated, _ = terminate_fn(model, next_state)
    return 1.0 - jnp.asarray(terminated, jnp.float32)


def _base(mj_model: mujoco.MjModel, body: str | None, who: str) -> Array:
    """int32 [2]: the qpos and qvel addresses of the free joint of `body` (see `names`)."""
    qpos, qvel = names.free_joint_addresses(mj_model, body, who)
    return jnp.array([qpos[0], qvel[0]], jnp.int32)


# --- floating base ------------------------------------------------------------------


def _rotate_inverse(quat: Array, v: Array) -> Array:
    """`v` ([3], world frame) in the frame of the unit quaternion `quat` ([4], w x y z)."""
    w, u = quat[0], -quat[1:]
    t = 2.0 * jnp.cross(u, v)
    return v + w * t + jnp.cross(u, t)


def _base_state(next_state: State, base: Array) -> tuple[Array, Array, Array, Array]:
    """(position [3] m world, linear velocity [3] m/s, angular velocity [3] rad/s,
    gravity direction [3] unit) of the base; all but the position in the base frame."""
    data = next_state.data
    position = jax.lax.dynamic_slice(data.qpos, (base[0],), (3,))
    quat = jax.lax.dynamic_slice(data.qpos, (base[0] + 3,), (4,))
    quat = quat / jnp.linalg.norm(quat)
    velocity = jax.lax.dynamic_slice(data.qvel, (base[1],), (6,))  # linear: world; angular: local
    gravity = _rotate_inverse(quat, jnp.array([0.0, 0.0, -1.0]))
    return position, _rotate_inverse(quat, velocity[:3]), velocity[3:], gravity


def linear_velocity_tracking(mj_model: mujoco.MjModel, sigma: float = 0.25, body: str | None = None) -> Partial:
    """Reward in (0, 1]: exp(-|v_xy - command[:2]|^2 / sigma), v the base linear
    velocity in the base frame (m/s); sigma in (m/s)^2. Reads the velocity command of `state`."""
    who = "linear_velocity_tracking"
    return Partial(_linear_tracking, _base(mj_model, body, who), _sigma(who, sigma))


def _sigma(who: str, sigma: float) -> Array:
    return checks.number(who, "sigma", sigma, 0.0, open_low=True)


def _linear_tracking(base, sigma, model, state, action, next_state) -> Array:
    velocity = _base_state(next_state, base)[1]
    return jnp.exp(-jnp.sum(jnp.square(velocity[:2] - _command(state)[:2])) / sigma)


def command_progress(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """Reward (m/s): the base's horizontal velocity along the commanded one, capped at
    the commanded speed: min(v_xy . c_xy / |c_xy|, |c_xy|), base frame; 0 for a zero
    command. Unlike the exp kernel of `linear_velocity_tracking`, aimless motion earns
    nothing on average and every step toward the command pays, so policies that start
    by standing still still find the gait. Reads the velocity command of `state`."""
    return Partial(_command_progress, _base(mj_model, body, "command_progress"))


def _command_progress(base, model, state, action, next_state) -> Array:
    velocity, command = _base_state(next_state, base)[1][:2], _command(state)[:2]
    speed = jnp.sqrt(jnp.sum(jnp.square(command)))
    return jnp.minimum(jnp.dot(velocity, command) / jnp.maximum(speed, 1e-6), speed)


def angular_velocity_tracking(mj_model: mujoco.MjModel, sigma: float = 0.25, body: str | None = None) -> Partial:
    """Reward in (0, 1]: exp(-(w_z - command[2])^2 / sigma), w_z the base yaw rate in the
    base frame (rad/s); sigma in (rad/s)^2. Reads the velocity command of `state`."""
    who = "angular_velocity_tracking"
    return Partial(_angular_tracking, _base(mj_model, body, who), _sigma(who, sigma))


def _angular_tracking(base, sigma, model, state, action, next_state) -> Array:
    yaw_rate = _base_state(next_state, base)[2][2]
    return jnp.exp(-jnp.square(yaw_rate - _command(state)[2]) / sigma)


def vertical_velocity(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """Cost: v_z^2, the base's linear velocity along its own z axis, (m/s)^2."""
    return Partial(_vertical_velocity, _base(mj_model, body, "vertical_velocity"))


def _vertical_velocity(base, model, state, action, next_state) -> Array:
    return jnp.square(_base_state(next_state, base)[1][2])


def roll_pitch_velocity(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """Cost: w_x^2 + w_y^2, the base's roll and pitch rates in its own frame, (rad/s)^2."""
    return Partial(_roll_pitch_velocity, _base(mj_model, body, "roll_pitch_velocity"))


def _roll_pitch_velocity(base, model, state, action, next_state) -> Array:
    return jnp.sum(jnp.square(_base_state(next_state, base)[2][:2]))


def base_height(mj_model: mujoco.MjModel, lower: float, upper: float | None = None, body: str | None = None) -> Partial:
    """Cost: squared distance (m^2) of the base's world height z outside [lower, upper]
    (m): (z - target)^2 for a target (``upper=None``), 0 anywhere inside a range."""
    upper = lower if upper is None else upper
    if not (math.isfinite(lower) and math.isfinite(upper) and lower <= upper):
        raise ValueError(f"base_height: need finite lower <= upper, got lower={lower!r}, upper={upper!r}")
    return Partial(_base_height, _base(mj_model, body, "base_height"), jnp.float32(lower), jnp.float32(upper))


def _base_height(base, lower, upper, model, state, action, next_state) -> Array:
    z = _base_state(next_state, base)[0][2]
    return jnp.square(jnp.maximum(lower - z, 0.0) + jnp.maximum(z - upper, 0.0))


def flat_orientation(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """Cost: g_x^2 + g_y^2 of the unit gravity direction in the base frame: sin^2 of the
    base's tilt from upright, 0 when level."""
    return Partial(_flat_orientation, _base(mj_model, body, "flat_orientation"))


def _flat_orientation(base, model, state, action, next_state) -> Array:
    return jnp.sum(jnp.square(_base_state(next_state, base)[3][:2]))


def upright(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """Reward in [-1, 1]: cos of the angle between the base's z axis and the world's."""
    return Partial(_upright, _base(mj_model, body, "upright"))


def _upright(base, model, state, action, next_state) -> Array:
    return -_base_state(next_state, base)[3][2]


# --- joints -------------------------------------------------------------------------


def joint_deviation(
    mj_model: mujoco.MjModel, joints: Sequence[str] | None = None, pose: Sequence[float] | None = None
) -> Partial:
    """Cost: sum over `joints` (default: every hinge and slide joint) of (q - pose)^2, in
    rad^2 or m^2; `pose` lists one position per joint (default: the model's qpos0)."""
    who = "joint_deviation"
    ids = names.joints(mj_model, joints, who)
    adr = mj_model.jnt_qposadr[ids]
    pose = mj_model.qpos0[adr] if pose is None else np.asarray(pose, np.float32)
    if pose.shape != (len(ids),):
        raise ValueError(f"{who}: pose must have one value per joint ({len(ids)}), got shape {pose.shape}")
    return Partial(_joint_deviation, jnp.asarray(adr, jnp.int32), jnp.asarray(pose, jnp.float32))


def _joint_deviation(adr, pose, model, state, action, next_state) -> Array:
    return jnp.sum(jnp.square(next_state.data.qpos[adr] - pose))


def stand_still(mj_model: mujoco.MjModel, pose: Sequence[float] | None = None, max_command: float = 0.1) -> Partial:
    """Cost: `joint_deviation` from `pose` (default: the model's first keyframe, else
    qpos0) of every hinge and slide joint, counted only while the velocity command of
    `state` is below `max_command` in norm (m/s and rad/s together): stand still when told to."""
    if not (math.isfinite(max_command) and max_command >= 0):
        raise ValueError(f"stand_still: max_command={max_command!r} must be finite and >= 0")
    ids = names.joints(mj_model, None, "stand_still")
    adr = mj_model.jnt_qposadr[ids]
    full = mj_model.key_qpos[0] if (pose is None and mj_model.nkey) else mj_model.qpos0
    pose = full[adr] if pose is None else np.asarray(pose, np.float32)
    return Partial(_stand_still, jnp.asarray(adr, jnp.int32), jnp.asarray(pose, jnp.float32), jnp.float32(max_command))


def _stand_still(adr, pose, max_command, model, state, action, next_state) -> Array:
    still = jnp.linalg.norm(_command(state)) < max_command
    return jnp.where(still, _joint_deviation(adr, pose, model, state, action, next_state), 0.0)


def joint_limits(mj_model: mujoco.MjModel, soft: float = 0.9, joints: Sequence[str] | None = None) -> Partial:
    """Cost: sum over `joints` (hinge or slide joints with a range; default: every such
    joint) of how far q lies outside the soft range, the middle `soft` fraction (in
    (0, 1]) of its range: rad or m, linear in the excess (legged gym)."""
    who = "joint_limits"
    soft = float(checks.number(who, "soft", soft, 0.0, 1.0, open_low=True))
    ids = names.joints(mj_model, joints, who, limited=True)
    low, high = mj_model.jnt_range[ids].T
    middle, half = (low + high) / 2, soft * (high - low) / 2
    soft_range = jnp.asarray(np.stack([middle - half, middle + half]), jnp.float32)
    return Partial(_joint_limits, jnp.asarray(mj_model.jnt_qposadr[ids], jnp.int32), soft_range)


def _joint_limits(adr, soft_range, model, state, action, next_state) -> Array:
    q = next_state.data.qpos[adr]
    return jnp.sum(jnp.maximum(soft_range[0] - q, 0.0) + jnp.maximum(q - soft_range[1], 0.0))


def symmetry(
    mj_model: mujoco.MjModel, pairs: Sequence[tuple[str, str]], signs: Sequence[float] | None = None
) -> Partial:
    """Cost: sum over joint pairs (a, b) of (q_a - sign * q_b)^2, rad^2 or m^2. `signs`
    (each +1 or -1, default +1) say how a joint mirrors its twin: -1 for joints whose axes
    mirror (e.g. hip roll), +1 for those that move alike (e.g. knee pitch)."""
    who = "symmetry"
    if not pairs or any(not (isinstance(p, (tuple, list)) and len(p) == 2) for p in pairs):
        raise ValueError(f"{who}: pairs must be a non-empty list of (joint, joint) names, got {pairs!r}")
    ids = np.array([names.joints(mj_model, list(pair), who) for pair in pairs])
    signs = np.ones(len(pairs)) if signs is None else np.asarray(signs, np.float32)
    if signs.shape != (len(pairs),) or not np.all(np.abs(signs) == 1):
        raise ValueError(f"{who}: signs must be one +1 or -1 per pair ({len(pairs)}), got {signs.tolist()}")
    return Partial(_symmetry, jnp.asarray(mj_model.jnt_qposadr[ids], jnp.int32), jnp.asarray(signs, jnp.float32))


def _symmetry(adr, signs, model, state, action, next_state) -> Array:
    q = next_state.data.qpos[adr]  # [P, 2]
    return jnp.sum(jnp.square(q[:, 0] - signs * q[:, 1]))


# --- progress (the gym-style running and standing objectives) ------------------------


def forward_velocity(mj_model: mujoco.MjModel, body: str | None = None, max_speed: float | None = None) -> Partial:
    """Reward: the world-x velocity (m/s) of the centre of mass of `body`'s subtree
    (default: the first free joint's body; a planar model's torso gives the whole
    robot), over the control step: (com'_x - com_x) / elapsed time; capped at
    `max_speed` (m/s, > 0) if given, so that moving faster earns nothing more."""
    who = "forward_velocity"
    cap = np.inf if max_speed is None else checks.number(who, "max_speed", max_speed, 0.0, open_low=True)
    return Partial(_forward_velocity, jnp.int32(names.base_body(mj_model, body, who)), jnp.float32(cap))


def _forward_velocity(body, cap, model, state, action, next_state) -> Array:
    elapsed = jnp.maximum(next_state.data.time - state.data.time, 1e-6)
    velocity = (next_state.data.subtree_com[body, 0] - state.data.subtree_com[body, 0]) / elapsed
    return jnp.minimum(velocity, cap)


def body_height(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """Reward: the world height z (m) of `body`'s origin (default: the first free
    joint's body), from ``xpos``."""
    return Partial(_body_height, jnp.int32(names.base_body(mj_model, body, "body_height")))


def _body_height(body, model, state, action, next_state) -> Array:
    return next_state.data.xpos[body, 2]


def effort(model, state: State, action: Array, next_state: State) -> Array:
    """Cost: sum of squared actions [nu], in the units the task takes them (e.g. motor
    controls): the gym tasks' control cost."""
    return jnp.sum(jnp.square(action))


# --- actions and effort -------------------------------------------------------------


def _difference(next_state: State, order: int, who: str) -> Array:
    """The `order`-th backward difference of the actions `trackers.with_action_history` keeps."""
    try:
        history = find(next_state, ActionHistoryState).actions
    except LookupError:
        history = None
    if history is None or history.shape[0] < order + 1:
        have = "none" if history is None else f"length {history.shape[0]}"
        raise ValueError(
            f"{who} needs an action history of length >= {order + 1} (has {have}): "
            f"wrap the task with trackers.with_action_history(task, length={order + 1})"
        )
    coefficients = [(-1) ** k * math.comb(order, k) for k in range(order + 1)]
    return sum(c * history[k] for k, c in enumerate(coefficients))


def action_rate(model, state: State, action: Array, next_state: State) -> Array:
    """Cost: |a_t - a_{t-1}|^2 over the [nu] actions recorded by
    `trackers.with_action_history` (h[0] is this transition's action; 0 before reset)."""
    return jnp.sum(jnp.square(_difference(next_state, 1, "action_rate")))


def action_acceleration(model, state: State, action: Array, next_state: State) -> Array:
    """Cost: |a_t - 2 a_{t-1} + a_{t-2}|^2, from the recorded action history (length >= 3)."""
    return jnp.sum(jnp.square(_difference(next_state, 2, "action_acceleration")))


def action_jerk(model, state: State, action: Array, next_state: State) -> Array:
    """Cost: |a_t - 3 a_{t-1} + 3 a_{t-2} - a_{t-3}|^2, from the recorded action history
    (length >= 4)."""
    return jnp.sum(jnp.square(_difference(next_state, 3, "action_jerk")))


def torque(model, state: State, action: Array, next_state: State) -> Array:
    """Cost: sum of squared actuator forces (``data.actuator_force`` [nu], in the
    actuators' units: N m for a gear-1 motor on a hinge)."""
    return jnp.sum(jnp.square(next_state.data.actuator_force))


def energy(model, state: State, action: Array, next_state: State) -> Array:
    """Cost: sum over dofs of |actuator generalized force * joint velocity| (W), from
    ``data.qfrc_actuator`` and ``qvel`` [nv]: mechanical power, gears included."""
    return jnp.sum(jnp.abs(next_state.data.qfrc_actuator * next_state.data.qvel))


# --- feet (a FeetState, kept by trackers.with_feet) ---------------------------------


def _feet(next_state: State, who: str) -> FeetState:
    try:
        return find(next_state, FeetState)
    except LookupError:
        raise ValueError(f"{who} needs the feet's state: wrap the task with trackers.with_feet(task, ...)") from None


def _command(state: State) -> Array:
    """The velocity command [3] in force in `state`."""
    try:
        return find(state, VelocityCommandState).command
    except LookupError:
        raise ValueError(
            "this reward term reads the velocity command: wrap the task with commands.with_velocity_command "
            "(or with_heading_command) inside the term"
        ) from None


def feet_air_time(threshold: float = 0.5, min_command: float | None = None) -> Partial:
    """Reward (legged gym): sum over feet touching down in this transition of
    (last air time - threshold), s: positive for steps longer than `threshold`. With
    `min_command` (m/s) it is 0 unless |command[:2]| > min_command (from
    the velocity command of `state`), so standing still is not punished."""
    if not math.isfinite(threshold):
        raise ValueError(f"feet_air_time: threshold={threshold!r} must be finite")
    if min_command is None:
        return Partial(_feet_air_time, jnp.float32(threshold))
    if not min_command >= 0:
        raise ValueError(f"feet_air_time: min_command={min_command!r} must be >= 0")
    return Partial(_gated_feet_air_time, jnp.float32(threshold), jnp.float32(min_command))


def _feet_air_time(threshold, model, state, action, next_state) -> Array:
    feet = _feet(next_state, "feet_air_time")
    return jnp.sum((feet.last_air_time - threshold) * feet.first_contact)


def _gated_feet_air_time(threshold, min_command, model, state, action, next_state) -> Array:
    moving = jnp.linalg.norm(_command(state)[:2]) > min_command
    return jnp.where(moving, _feet_air_time(threshold, model, state, action, next_state), 0.0)


def foot_slip(model, state: State, action: Array, next_state: State) -> Array:
    """Cost: sum over feet in contact of the foot's squared horizontal speed, (m/s)^2."""
    feet = _feet(next_state, "foot_slip")
    return jnp.sum(feet.contact * jnp.sum(jnp.square(feet.velocity[:, :2]), axis=-1))


def foot_clearance(target: float) -> Partial:
    """Cost: sum over feet off the ground of (z - target)^2 * |v_xy|, z the foot geom's
    world height (m), v its velocity (m/s): swinging feet should pass at `target`
    (the geom centre's height, e.g. radius + lift)."""
    if not math.isfinite(target):
        raise ValueError(f"foot_clearance: target={target!r} must be finite")
    return Partial(_foot_clearance, jnp.float32(target))


def _foot_clearance(target, model, state, action, next_state) -> Array:
    feet = _feet(next_state, "foot_clearance")
    speed = jnp.linalg.norm(feet.velocity[:, :2], axis=-1)
    return jnp.sum(~feet.contact * jnp.square(feet.position[:, 2] - target) * speed)
