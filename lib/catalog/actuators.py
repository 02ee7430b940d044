"""Actuator models evaluated at every physics substep, and combinators on the action.

An actuator is ``(model, data, action, key) -> ctrl [nu]``: it turns the policy's
action into MuJoCo controls from the current joint state, once per physics substep, as
a motor driver running faster than the policy does. `step` runs the substeps; a task
whose step calls ``actuators.step(model, data, params.actuator, action, n_substeps,
key)`` instead of `mjzoo.physics.step` gets PD control, torque limits and actuator noise
in its physics. The actuators here drive ``<motor>`` actuators on hinge or slide joints
(ctrl is the actuator force; the joint gets ``gear * ctrl``), checked at construction;
torques and gains are in joint space (N m, or N for a slide joint).

The combinators (`with_action_latency`, `with_action_drop`, `with_action_filter`) change
the action the inner task receives; its reward still receives the action the policy
chose. Each keeps its state in its own record in ``state.layers`` (`ActionLatencyState`,
`ActionDropState`, `ActionFilterState`; read one with `mjzoo.find`), zeroed at reset, so it must
sit inside `with_auto_reset` (which resets it with every new episode). Clipping the
summed reward is `mjzoo.with_reward_clip`.
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import Callable
from typing import NamedTuple
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import batching
from mjzoo import checks
from mjzoo import names
from mjzoo import physics
from mjzoo import tree
from mjzoo.layers import layered
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "ActionLatencyState",
    "ActionDropState",
    "ActionFilterState",
    "Actuator",
    "Motors",
    "PDParams",
    "torque",
    "pd",
    "position_velocity",
    "position_targets",
    "step",
    "with_action_latency",
    "with_action_drop",
    "with_action_filter",
]

Array = jax.Array
Actuator = Callable[[mjx.Model, mjx.Data, Array, Array], Array]
Numbers = float | Sequence[float]
SUBSTEP_STREAM, LATENCY_STREAM, DROP_STREAM = 0xAC7, 0x1A7, 0xD50  # fold_in tags


# --- the motors ---------------------------------------------------------------------


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Motors:
    """Where each actuator's joint lives and how hard it may push; all [nu].

    qpos, dof: int32 indices of the joint's position and velocity; gear: joint torque
    per unit of ctrl; limit: joint torque bound, N m (N for slides), > 0.
    """

    qpos: Array
    dof: Array
    gear: Array
    limit: Array

    def ctrl(self, torque: Array) -> Array:
        """Joint torques [nu], clipped to +-limit, as the controls that produce them."""
        return jnp.clip(torque, -self.limit, self.limit) / self.gear


def _motors(mj_model: mujoco.MjModel, torque_limit: Numbers | None, who: str) -> Motors:
    labels = names.all_names(mj_model, "actuator")
    if mj_model.nu == 0:
        raise ValueError(f"{who}: the model has no actuators")
    joints = mj_model.actuator_trnid[:, 0]
    for i, name in enumerate(labels):
        joint_ok = mj_model.actuator_trntype[i] == mujoco.mjtTrn.mjTRN_JOINT and int(mj_model.jnt_type[joints[i]]) in (
            int(mujoco.mjtJoint.mjJNT_HINGE),
            int(mujoco.mjtJoint.mjJNT_SLIDE),
        )
        motor = (
            mj_model.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_NONE
            and mj_model.actuator_gaintype[i] == mujoco.mjtGain.mjGAIN_FIXED
            and mj_model.actuator_gainprm[i, 0] == 1.0
            and mj_model.actuator_biastype[i] == mujoco.mjtBias.mjBIAS_NONE
        )
        if not (joint_ok and motor and mj_model.actuator_gear[i, 0] != 0):
            raise ValueError(
                f"{who}: actuator {name!r} must be a <motor> with a nonzero gear on a hinge or slide "
                f"joint (ctrl = force); the model's actuators: {labels}"
            )
    gear = mj_model.actuator_gear[:, 0].astype(np.float64)
    if torque_limit is None:
        limit = np.full(mj_model.nu, np.inf)
        for limited, bounds in (
            (mj_model.actuator_ctrllimited, mj_model.actuator_ctrlrange),
            (mj_model.actuator_forcelimited, mj_model.actuator_forcerange),
        ):
            symmetric = np.minimum(-bounds[:, 0], bounds[:, 1]) * np.abs(gear)
            limit = np.where(limited.astype(bool), np.minimum(limit, symmetric), limit)
        if not np.isfinite(limit).all():
            unlimited = [n for n, lim in zip(labels, limit) if not np.isfinite(lim)]
            raise ValueError(f"{who}: actuators {unlimited} have no ctrlrange or forcerange; pass torque_limit")
    else:
        limit = np.asarray(checks.numbers(who, "torque_limit", torque_limit, mj_model.nu))
    if not (limit > 0).all():
        raise ValueError(f"{who}: torque limits {limit.tolist()} must be > 0 (a symmetric range around 0)")
    return Motors(
        qpos=jnp.asarray(mj_model.jnt_qposadr[joints], jnp.int32),
        dof=jnp.asarray(mj_model.jnt_dofadr[joints], jnp.int32),
        gear=jnp.asarray(gear, jnp.float32),
        limit=jnp.asarray(limit, jnp.float32),
    )


# --- torque -------------------------------------------------------------------------


def torque(mj_model: mujoco.MjModel, torque_limit: Numbers | None = None) -> Actuator:
    """Torque control: ``torque = clip(action, -1, 1) * torque_limit`` ([nu], N m).

    `torque_limit` (float or [nu], > 0; joint torque) defaults to the largest symmetric
    range inside the model's ctrlrange and forcerange, times the gear. MuJoCo still clamps
    ctrl to the model's ctrlrange. Uses no key.
    """
    return Partial(_torque, _motors(mj_model, torque_limit, "torque"))


def _torque(motors: Motors, model, data, action, key) -> Array:
    return motors.ctrl(jnp.clip(action, -1.0, 1.0) * motors.limit)


# --- position servos ------------------------------------------------------------------


def position_targets(
    mj_model: mujoco.MjModel, action_scale: Numbers = 0.5, default_pose: Numbers | None = None
) -> Actuator:
    """For a model's own ``<position>`` actuators (MuJoCo's PD servos, with the robot's
    gains kp, kv and force limits from its MJCF, as MuJoCo Playground's robots have them):
    ``ctrl = default_pose + action_scale * clip(action, -1, 1)`` [nu], rad, clipped to each
    actuator's ctrlrange. `default_pose` defaults to the model's first keyframe's ctrl
    (its standing pose), else zeros. Gains and strength are randomized on the model
    (`randomizers.scale_position_gains`). Uses no key."""
    who = "position_targets"
    servo = (mj_model.actuator_gaintype == mujoco.mjtGain.mjGAIN_FIXED) & (
        mj_model.actuator_biastype == mujoco.mjtBias.mjBIAS_AFFINE
    )
    if mj_model.nu == 0 or not servo.all():
        bad = [names.all_names(mj_model, "actuator")[i] for i in np.flatnonzero(~servo)]
        raise ValueError(f"{who}: every actuator must be a <position> servo (fixed gain, affine bias); not: {bad}")
    if default_pose is None:
        default_pose = mj_model.key_ctrl[0] if mj_model.nkey else np.zeros(mj_model.nu)
    pose = np.broadcast_to(np.asarray(default_pose, np.float32), (mj_model.nu,))
    scale = np.broadcast_to(np.asarray(action_scale, np.float32), (mj_model.nu,))
    if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(scale)) and np.all(scale > 0)):
        raise ValueError(f"{who}: default_pose must be finite and action_scale finite and > 0")
    low, high = np.where(mj_model.actuator_ctrllimited[:, None] > 0, mj_model.actuator_ctrlrange, [-np.inf, np.inf]).T
    return Partial(_position_targets, *(jnp.asarray(a, jnp.float32) for a in (pose, scale, low, high)))


def _position_targets(pose, scale, low, high, model, data, action, key) -> Array:
    return jnp.clip(pose + scale * jnp.clip(action, -1.0, 1.0), low, high)


# --- PD control ---------------------------------------------------------------------


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PDParams:
    """Parameters of `pd` and `position_velocity`, all float32 [nu] but the noise scales."""

    motors: Motors
    kp: Array  # N m / rad (N / m for slides)
    kd: Array  # N m s / rad (N s / m)
    default_pose: Array  # rad (m), the position target at zero action
    position_scale: Array  # rad (m) per unit of action
    velocity_scale: Array  # rad/s (m/s) per unit of action
    gain_noise: Array  # []: kp and kd are multiplied by U(1 - gain_noise, 1 + gain_noise)
    torque_noise: Array  # []: N m standard deviation of the added torque


def pd(
    mj_model: mujoco.MjModel,
    kp: Numbers,
    kd: Numbers,
    *,
    action_scale: Numbers = 1.0,
    default_pose: Numbers | None = None,
    torque_limit: Numbers | None = None,
    gain_noise: float = 0.0,
    torque_noise: float = 0.0,
) -> Actuator:
    """PD position control as on "MIT-style" motor drivers, per actuator ([nu]):

        target = default_pose + action_scale * clip(action, -1, 1)            rad
        torque = kp' * (target - q) - kd' * qdot + torque_noise * N(0, 1)     N m
        ctrl   = clip(torque, -torque_limit, torque_limit) / gear

    with ``kp' = kp * U(1 - gain_noise, 1 + gain_noise)`` and kd' likewise, drawn anew at
    every substep (gain_noise in [0, 1)). `kp`, `kd`, `action_scale` are floats or [nu];
    `default_pose` defaults to the joints' ``qpos0``; `torque_limit` as in `torque`. The
    model's actuators must be motors, so that MuJoCo adds no gains of its own.
    """
    return Partial(
        _pd, _pd_params(mj_model, "pd", kp, kd, action_scale, 0.0, default_pose, torque_limit, gain_noise, torque_noise)
    )


def position_velocity(
    mj_model: mujoco.MjModel,
    kp: Numbers,
    kd: Numbers,
    *,
    position_scale: Numbers = 1.0,
    velocity_scale: Numbers = 1.0,
    default_pose: Numbers | None = None,
    torque_limit: Numbers | None = None,
    gain_noise: float = 0.0,
    torque_noise: float = 0.0,
) -> Actuator:
    """PD control towards a position and a velocity target: the action is [2 nu], the
    position part first, then the velocity part, each clipped to [-1, 1]:

        target_q    = default_pose + position_scale * action[:nu]      rad
        target_qdot = velocity_scale * action[nu:]                     rad/s
        torque      = kp' * (target_q - q) + kd' * (target_qdot - qdot) + noise

    The rest as in `pd`. A task using it takes actions of 2 nu numbers: build it with
    ``task.replace(action_dim=2 * nu)`` so that `Task.action_size`, which algorithms and
    random policies size actions by, says so.
    """
    return Partial(
        _position_velocity,
        _pd_params(
            mj_model,
            "position_velocity",
            kp,
            kd,
            position_scale,
            velocity_scale,
            default_pose,
            torque_limit,
            gain_noise,
            torque_noise,
        ),
    )


def _pd_params(
    mj_model, who, kp, kd, position_scale, velocity_scale, default_pose, torque_limit, gain_noise, torque_noise
) -> PDParams:
    motors = _motors(mj_model, torque_limit, who)
    if default_pose is None:
        default_pose = mj_model.qpos0[np.asarray(motors.qpos)]
    if not 0.0 <= gain_noise < 1.0:
        raise ValueError(f"{who}: gain_noise={gain_noise!r} must be in [0, 1) so that gains stay positive")
    torque_noise = checks.number(who, "torque_noise", torque_noise, 0.0)

    def per(value, name: str, minimum: float = 0.0) -> Array:
        return checks.numbers(who, name, value, mj_model.nu, minimum)

    return PDParams(
        motors=motors,
        kp=per(kp, "kp"),
        kd=per(kd, "kd"),
        default_pose=per(default_pose, "default_pose", -np.inf),
        position_scale=per(position_scale, "position_scale"),
        velocity_scale=per(velocity_scale, "velocity_scale"),
        gain_noise=jnp.float32(gain_noise),
        torque_noise=torque_noise,
    )


def _pd_ctrl(p: PDParams, data: mjx.Data, target_q: Array, target_qdot: Array, key: Array) -> Array:
    kp_key, kd_key, torque_key = jax.random.split(key, 3)
    q, qdot = data.qpos[p.motors.qpos], data.qvel[p.motors.dof]
    kp, kd = _jitter(p.kp, p.gain_noise, kp_key), _jitter(p.kd, p.gain_noise, kd_key)
    force = kp * (target_q - q) + kd * (target_qdot - qdot)
    return p.motors.ctrl(force + p.torque_noise * jax.random.normal(torque_key, force.shape))


def _jitter(gain: Array, spread: Array, key: Array) -> Array:
    """`gain` times U(1 - spread, 1 + spread), per element."""
    return gain * jax.random.uniform(key, gain.shape, minval=1.0 - spread, maxval=1.0 + spread)


def _pd(p: PDParams, model, data, action, key) -> Array:
    target = p.default_pose + p.position_scale * jnp.clip(action, -1.0, 1.0)
    return _pd_ctrl(p, data, target, jnp.zeros_like(target), key)


def _position_velocity(p: PDParams, model, data, action, key) -> Array:
    nu = p.kp.shape[0]
    if action.shape != (2 * nu,):
        raise ValueError(f"position_velocity: the action must have shape ({2 * nu},), got {action.shape}")
    action = jnp.clip(action, -1.0, 1.0)
    return _pd_ctrl(p, data, p.default_pose + p.position_scale * action[:nu], p.velocity_scale * action[nu:], key)


# --- stepping -----------------------------------------------------------------------


def step(model: mjx.Model, data: mjx.Data, actuator: Actuator, action: Array, n_substeps: int, key: Array) -> mjx.Data:
    """Advances `n_substeps` (static int) physics steps, setting ``ctrl = actuator(model,
    data, action, key_i)`` from the current state before each one.

    `action` is held over the substeps; key_i = fold_in(fold_in(key, tag), i), so the
    task may pass its own step key. Returns the data after the last substep.
    """
    key = jax.random.fold_in(key, SUBSTEP_STREAM)

    def substep(i, data: mjx.Data) -> mjx.Data:
        ctrl = actuator(model, data, action, jax.random.fold_in(key, i))
        return physics.substep(model, data.replace(ctrl=jnp.asarray(ctrl, data.ctrl.dtype)))

    return jax.lax.fori_loop(0, n_substeps, substep, batching.clear_overflow(data))


# --- combinators on the action ------------------------------------------------------


class ActionLatencyState(NamedTuple):
    """`with_action_latency`'s record: ``delay``, int32 [], this episode's delay in
    control steps; ``buffer``, [max_latency + 1, nu] the latest actions, most recent first."""

    delay: Array
    buffer: Array
    inner: Any = ()


class ActionDropState(NamedTuple):
    """`with_action_drop`'s record: ``previous``, [nu] the last action passed on."""

    previous: Array
    inner: Any = ()


class ActionFilterState(NamedTuple):
    """`with_action_filter`'s record: ``previous``, [nu] the last filtered action."""

    previous: Array
    inner: Any = ()


def _kept(state: State, record, **metrics: Array) -> State:
    return wrap(state, record).replace(metrics={**state.metrics, **metrics})


def with_action_latency(task: Task, max_latency: int) -> Task:
    """Delays every action by d control steps, d ~ U{0, ..., max_latency} drawn per episode.

    Until d actions have been given, the inner task receives zeros. Keeps an
    `ActionLatencyState` (the delay and the latest actions); logs
    ``metrics["action_latency/delay"]``. `max_latency` (static int >= 0) sets the
    buffer's shape: changing it retraces.
    """
    max_latency = checks.integer("with_action_latency", "max_latency", max_latency, 0)
    start = Partial(_latency_reset, task.start, tree.StaticValue(max_latency))
    return layered(task, ActionLatencyState, start, Partial(_latency_step, task.step))


def _latency_reset(reset_fn, max_latency: tree.StaticValue, model, key) -> State:
    state = reset_fn(model, key)
    delay = jax.random.randint(jax.random.fold_in(key, LATENCY_STREAM), (), 0, max_latency.value + 1)
    buffer = jnp.zeros((max_latency.value + 1, model.nu), jnp.float32)
    return _kept(state, ActionLatencyState(delay=delay.astype(jnp.int32), buffer=buffer))


def _latency_step(step_fn, model, state, action, key) -> State:
    latency, inner = peel(state, ActionLatencyState)
    buffer = jnp.concatenate([jnp.asarray(action, jnp.float32)[None], latency.buffer[:-1]])
    next_state = step_fn(model, inner, buffer[latency.delay], key)
    delay = latency.delay.astype(jnp.float32)
    return _kept(next_state, latency._replace(buffer=buffer), **{"action_latency/delay": delay})


def with_action_drop(task: Task, probability: float) -> Task:
    """With `probability` (in [0, 1]) per step, the inner task receives the action it
    received at the previous step instead of the new one (a lost command packet).

    Keeps an `ActionDropState` (``previous``: [nu], the last action passed on; zeros at
    reset); logs ``metrics["action_drop/dropped"]`` (1.0 when this step's was dropped).
    """
    probability = checks.number("with_action_drop", "probability", probability, 0.0, 1.0)
    start = Partial(_previous_reset, task.start, tree.StaticValue(ActionDropState))
    return layered(task, ActionDropState, start, Partial(_drop_step, task.step, probability))


def _previous_reset(reset_fn, record: tree.StaticValue, model, key) -> State:
    state = reset_fn(model, key)
    return _kept(state, record.value(previous=jnp.zeros((model.nu,), jnp.float32)))


def _drop_step(step_fn, probability, model, state, action, key) -> State:
    own, inner = peel(state, ActionDropState)
    dropped = jax.random.uniform(jax.random.fold_in(key, DROP_STREAM)) < probability
    applied = jnp.where(dropped, own.previous, jnp.asarray(action, jnp.float32))
    next_state = step_fn(model, inner, applied, key)
    return _kept(next_state, ActionDropState(previous=applied), **{"action_drop/dropped": dropped.astype(jnp.float32)})


def with_action_filter(task: Task, alpha: float) -> Task:
    """First-order low-pass filter on the action: the inner task receives
    ``a_t = alpha * action_t + (1 - alpha) * a_{t-1}``, with a_{-1} = 0 (alpha in (0, 1]).

    Keeps an `ActionFilterState` (``previous``: [nu], a_{t-1}).
    """
    alpha = checks.number("with_action_filter", "alpha", alpha, 0.0, 1.0, open_low=True)  # 1: no filtering
    start = Partial(_previous_reset, task.start, tree.StaticValue(ActionFilterState))
    return layered(task, ActionFilterState, start, Partial(_filter_step, task.step, alpha))


def _filter_step(step_fn, alpha, model, state, action, key) -> State:
    own, inner = peel(state, ActionFilterState)
    applied = alpha * jnp.asarray(action, jnp.float32) + (1.0 - alpha) * own.previous
    return _kept(step_fn(model, inner, applied, key), ActionFilterState(previous=applied))
