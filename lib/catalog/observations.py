"""Observation items and observation combinators of the locomotion catalog.

An observation item is ``(model: mjx.Model, state: State) -> Array[k]`` float32, for ONE
environment. Items that need names are built by a constructor taking the host
`mujoco.MjModel` (``task.mj_model``); it resolves the names once (`mjzoo.names`; the
base `body` defaults to the first free joint's body) and returns ``Partial(fn,
indices...)``, so indices are int32 pytree leaves. `concat` joins items:

    obs_fn = observations.concat(
        observations.projected_gravity(task.mj_model),
        observations.base_angular_velocity(task.mj_model),
        observations.joint_positions, observations.joint_velocities,
        observations.last_action,
    )

The command a policy follows is not an item here: `commands.with_velocity_command` (and
the other command combinators) append it to the observation themselves (``observe=True``,
the one supported way), because they redraw it after the inner step has observed.

Kinematic quantities (xpos, xmat, cvel, sensordata, contacts, contact forces) are read
from ``state.data`` as the last `mjx.step` left them: MuJoCo computes them before it
integrates, so they describe the state one physics substep before qpos and qvel.

Combinators: history, per-episode bias, multiplicative noise (additive noise is
`mjzoo.with_observation_noise`), and the asymmetric actor-critic's privileged view.
"""

from __future__ import annotations

from typing import Any
from typing import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjzoo import checks
from mjzoo import names
from mjzoo import tree
from mjzoo.catalog import contacts
from mjzoo.catalog.contacts import point_velocity
from mjzoo.catalog.trackers import ActionHistoryState
from mjzoo.catalog.trackers import FeetState
from mjzoo.layers import find
from mjzoo.layers import layered
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.perturbations import add_noise
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "joint_positions",
    "joint_velocities",
    "joint_positions_of",
    "joint_velocities_of",
    "base_position",
    "base_height",
    "base_orientation",
    "base_linear_velocity",
    "base_angular_velocity",
    "projected_gravity",
    "body_positions",
    "body_velocities",
    "site_positions",
    "site_velocities",
    "point_velocity",
    "sensors",
    "actuator_forces",
    "geom_contacts",
    "foot_contacts",
    "foot_forces",
    "last_action",
    "concat",
    "with_observation_history",
    "with_observation_bias",
    "ObservationHistoryState",
    "ObservationBiasState",
    "with_multiplicative_observation_noise",
    "with_privileged_observation",
]

Array = jax.Array
Partial = jax.tree_util.Partial
Observation = Callable[[mjx.Model, State], Array]
Names = names.Names
BIAS_STREAM, SCALE_NOISE_STREAM = 0xB1A5, 0x5CA1E  # fold_in tags: the inner task keeps its key
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)


def _gather(field: str, index) -> Partial:
    """An item reading ``data.<field>[index]``, flattened; the index is an int32 leaf."""
    return Partial(_gathered, tree.StaticValue(field), jnp.asarray(index, jnp.int32))


def _gathered(field: tree.StaticValue, index, model, state) -> Array:
    return getattr(state.data, field.value)[index].ravel().astype(jnp.float32)


def _base(mj_model: mujoco.MjModel, body: str | None, who: str) -> Array:
    return jnp.int32(names.base_body(mj_model, body, who))


def _not_free(model) -> np.ndarray:
    return np.flatnonzero(model.jnt_type != _FREE)


# --- joints ---------------------------------------------------------------------------


def joint_positions(model: mjx.Model, state: State) -> Array:
    """qpos of every joint except free joints: the floating base is excluded (it is
    `base_position` and `base_orientation`). [nq - 7 * free joints]: rad for hinges, m
    for slides, a wxyz quaternion per ball joint."""
    return state.data.qpos[names.joint_addresses(model, _not_free(model), False)].astype(jnp.float32)


def joint_velocities(model: mjx.Model, state: State) -> Array:
    """qvel of every joint except free joints: [nv - 6 * free joints], rad/s or m/s."""
    return state.data.qvel[names.joint_addresses(model, _not_free(model), True)].astype(jnp.float32)


def joint_positions_of(mj_model: mujoco.MjModel, joints: Names) -> Partial:
    """qpos of the named joints, in the order given: 1 entry per hinge or slide, 4 per
    ball, 7 per free joint (a free joint named explicitly is included)."""
    return _gather("qpos", _entries(mj_model, joints, False, "joint_positions_of"))


def joint_velocities_of(mj_model: mujoco.MjModel, joints: Names) -> Partial:
    """qvel of the named joints, in the order given: 1 entry per hinge or slide, 3 per
    ball, 6 per free joint (world linear, then local angular velocity)."""
    return _gather("qvel", _entries(mj_model, joints, True, "joint_velocities_of"))


def _entries(mj_model: mujoco.MjModel, joints: Names, velocity: bool, who: str) -> np.ndarray:
    return names.joint_addresses(mj_model, names.ids(mj_model, "joint", joints, who), velocity)


# --- the base body (default: the first body with a free joint) ------------------------


def base_position(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """World position of the base body's origin: [3] m."""
    return _gather("xpos", _base(mj_model, body, "base_position"))


def base_height(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """World height of the base body's origin: [1] m (its x, y left out: a running
    policy should not depend on where it is)."""
    return Partial(_height, _base(mj_model, body, "base_height"))


def _height(body, model, state) -> Array:
    return state.data.xpos[body, 2:].astype(jnp.float32)


def base_orientation(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """World orientation of the base body: [4] unit quaternion, wxyz."""
    return _gather("xquat", _base(mj_model, body, "base_orientation"))


def base_linear_velocity(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """Linear velocity of the base body's origin in the base frame: [3] m/s."""
    return Partial(_in_base, tree.StaticValue("linear"), _base(mj_model, body, "base_linear_velocity"))


def base_angular_velocity(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """Angular velocity of the base body in the base frame: [3] rad/s (a gyro)."""
    return Partial(_in_base, tree.StaticValue("angular"), _base(mj_model, body, "base_angular_velocity"))


def projected_gravity(mj_model: mujoco.MjModel, body: str | None = None) -> Partial:
    """The gravity direction (unit vector of ``model.opt.gravity``; -z when gravity is
    off) in the base frame: [3], (0, 0, -1) when upright."""
    return Partial(_in_base, tree.StaticValue("gravity"), _base(mj_model, body, "projected_gravity"))


def _in_base(quantity: tree.StaticValue, body, model, state) -> Array:
    """A world vector in the base frame, R^T v (xmat's columns are the base's axes)."""
    data = state.data
    if quantity.value == "linear":
        vector = point_velocity(model, data, body[None], data.xpos[body][None])[0][0]
    elif quantity.value == "angular":
        vector = data.cvel[body, :3]
    else:
        norm = jnp.linalg.norm(model.opt.gravity)
        vector = jnp.where(norm > 0, model.opt.gravity / jnp.maximum(norm, 1e-30), jnp.array([0.0, 0.0, -1.0]))
    return (data.xmat[body].T @ vector).astype(jnp.float32)


# --- bodies, sites, sensors, actuators -------------------------------------------------


def body_positions(mj_model: mujoco.MjModel, bodies: Names) -> Partial:
    """World positions of the named bodies' origins: [3 B] m, (x, y, z) per body."""
    return _gather("xpos", names.ids(mj_model, "body", bodies, "body_positions"))


def body_velocities(mj_model: mujoco.MjModel, bodies: Names) -> Partial:
    """World-frame velocities of the named bodies' origins: [6 B], per body linear
    (m/s) then angular (rad/s)."""
    ids = jnp.asarray(names.ids(mj_model, "body", bodies, "body_velocities"))
    return Partial(_point_velocities, tree.StaticValue("xpos"), ids, ids)


def site_positions(mj_model: mujoco.MjModel, sites: Names) -> Partial:
    """World positions of the named sites: [3 S] m."""
    return _gather("site_xpos", names.ids(mj_model, "site", sites, "site_positions"))


def site_velocities(mj_model: mujoco.MjModel, sites: Names) -> Partial:
    """World-frame velocities of the named sites: [6 S], per site the linear velocity of
    the site point (m/s) then the angular velocity of its body (rad/s)."""
    ids = names.ids(mj_model, "site", sites, "site_velocities")
    bodies = jnp.asarray(mj_model.site_bodyid[ids], jnp.int32)
    return Partial(_point_velocities, tree.StaticValue("site_xpos"), jnp.asarray(ids), bodies)


def _point_velocities(field: tree.StaticValue, points, bodies, model, state) -> Array:
    linear, angular = point_velocity(model, state.data, bodies, getattr(state.data, field.value)[points])
    return jnp.concatenate([linear, angular], axis=1).ravel().astype(jnp.float32)


def sensors(mj_model: mujoco.MjModel, sensor_names: Names) -> Partial:
    """Readings of the named sensors concatenated in the order given: [sum of their
    dims], in each sensor's units (slices ``sensor_adr : sensor_adr + sensor_dim`` of
    ``data.sensordata``)."""
    ids = names.ids(mj_model, "sensor", sensor_names, "sensors")
    adr, dim = mj_model.sensor_adr, mj_model.sensor_dim
    return _gather("sensordata", np.concatenate([adr[i] + np.arange(dim[i]) for i in ids]))


def actuator_forces(model: mjx.Model, state: State) -> Array:
    """Scalar force of each actuator, ``data.actuator_force``: [nu], N or N m before the
    transmission's gear."""
    return state.data.actuator_force.astype(jnp.float32)


# --- contacts (see `mjzoo.catalog.contacts`) -------------------------------------------------


def geom_contacts(mj_model: mujoco.MjModel, geoms: Names, others: Names | None = None) -> Partial:
    """1.0 where each named geom touches one of `others` (any geom if None), else 0.0:
    [G] float32. Touching: an active contact (distance < margin - gap)."""
    return Partial(_geom_contacts, *contacts.geom_sets(mj_model, geoms, others, "geom_contacts"))


def foot_forces(mj_model: mujoco.MjModel, feet: Names, floor: Names | None = None) -> Partial:
    """Normal contact force on each named foot geom from `floor` (a geom name or names;
    any geom if None): [F] N, summed over the foot's contacts, 0 in the air.

    Decoded from the constraint solver's forces (``efc_force``) of the last physics
    step, as ``mj_contactForce`` does, for pyramidal and elliptic cones.
    """
    return Partial(_foot_forces, *contacts.geom_sets(mj_model, feet, floor, "foot_forces"))


def foot_contacts(model: mjx.Model, state: State) -> Array:
    """The feet's contacts (`trackers.FeetState`, kept by `trackers.with_feet`) as
    1.0 / 0.0: [F] float32."""
    return find(state, FeetState).contact.astype(jnp.float32)


def _geom_contacts(geoms, others, model, state) -> Array:
    return contacts.touching(state.data, geoms, others).astype(jnp.float32)


def _foot_forces(feet, others, model, state) -> Array:
    return contacts.forces(model, state.data, feet, others)


# --- what the trackers keep, and joining items -----------------------------------------


def last_action(model: mjx.Model, state: State) -> Array:
    """The previous action, row 0 of `trackers.ActionHistoryState` (kept by
    `trackers.with_action_history`): [nu] float32."""
    return find(state, ActionHistoryState).actions[0].astype(jnp.float32)


def concat(*fns: Observation) -> Partial:
    """One item joining the outputs of `fns`, each flattened, in order: [sum of k]."""
    if not fns:
        raise ValueError("concat: give at least one observation item")
    for i, fn in enumerate(fns):
        if not callable(fn):
            raise TypeError(f"concat: item {i} must be callable, got {type(fn).__name__}")
    return Partial(_concat, tuple(fn if isinstance(fn, Partial) else Partial(fn) for fn in fns))


def _concat(fns, model, state) -> Array:
    return jnp.concatenate([jnp.ravel(jnp.asarray(fn(model, state), jnp.float32)) for fn in fns])


# --- combinators -----------------------------------------------------------------------


def with_observation_history(task: Task, length: int) -> Task:
    """Observes the last `length` observations, newest first, joined along the first
    axis: a leaf of shape [k] becomes [length * k], obs[:k] the newest (a scalar leaf
    becomes [length]). At reset the history is filled with the first observation.

    Keeps an `ObservationHistoryState`, each leaf stacked to [length, ...]; the inner
    step still receives its own newest observation. Sits inside `with_auto_reset` (each
    episode starts a new history); noise combinators inside it perturb each frame once.
    Applied twice, the outer one keeps a history of the inner one's stacked observations.
    """
    length = checks.integer("with_observation_history", "length", length)
    start = Partial(_history_reset, task.start, tree.StaticValue(length))
    return layered(task, ObservationHistoryState, start, Partial(_history_step, task.step))


class ObservationHistoryState(NamedTuple):
    """`with_observation_history`'s record: ``frames``, the observation pytree with
    each leaf stacked to [length, ...], newest first."""

    frames: Any
    inner: Any = ()


class ObservationBiasState(NamedTuple):
    """`with_observation_bias`'s record: ``bias``, shaped like the observation."""

    bias: Any
    inner: Any = ()


def _with_history(state: State, history) -> State:
    flat = jax.tree.map(lambda h: h.reshape((-1,) + h.shape[2:]), history)
    return wrap(state.replace(obs=flat), ObservationHistoryState(frames=history))


def _history_reset(reset_fn, length: tree.StaticValue, model, key) -> State:
    state = reset_fn(model, key)
    return _with_history(state, jax.tree.map(lambda o: jnp.repeat(jnp.asarray(o)[None], length.value, 0), state.obs))


def _history_step(step_fn, model, state, action, key) -> State:
    own, inner = peel(state, ObservationHistoryState)
    history = own.frames
    next_state = step_fn(model, inner.replace(obs=jax.tree.map(lambda h: h[0], history)), action, key)
    shifted = jax.tree.map(lambda h, o: jnp.concatenate([o[None], h[:-1]]), history, next_state.obs)
    return _with_history(next_state, shifted)


def _gaussian(obs, scale: Array, key: Array):
    """N(0, scale^2) draws shaped like each floating leaf of `obs`; integer zeros elsewhere."""
    return add_noise(jax.tree.map(jnp.zeros_like, obs), scale, key)


def with_observation_bias(task: Task, scale: float) -> Task:
    """Adds a bias that is constant over an episode, drawn at reset from N(0, scale^2)
    for every entry of every floating observation leaf (a miscalibrated sensor).

    Keeps an `ObservationBiasState`, shaped like the observation. Inside
    `with_auto_reset`, every episode draws a new bias.
    """
    scale = checks.number("with_observation_bias", "scale", scale, 0.0)
    return layered(task, ObservationBiasState, Partial(_bias_reset, task.start, scale), Partial(_bias_step, task.step))


def _biased(state: State, bias) -> State:
    return wrap(state.replace(obs=jax.tree.map(jnp.add, state.obs, bias)), ObservationBiasState(bias=bias))


def _bias_reset(reset_fn, scale, model, key) -> State:
    state = reset_fn(model, key)
    return _biased(state, _gaussian(state.obs, scale, jax.random.fold_in(key, BIAS_STREAM)))


def _bias_step(step_fn, model, state, action, key) -> State:
    own, inner = peel(state, ObservationBiasState)
    return _biased(step_fn(model, inner, action, key), own.bias)


def with_multiplicative_observation_noise(task: Task, scale: float) -> Task:
    """Observes ``obs * (1 + e)``, e ~ N(0, scale^2) drawn for every entry of every
    floating leaf after reset and after every step: noise proportional to the signal.
    Keeps no record."""
    scale = checks.number("with_multiplicative_observation_noise", "scale", scale, 0.0)
    return task.replace(start=Partial(_scaled_reset, task.start, scale), step=Partial(_scaled_step, task.step, scale))


def _scaled(state: State, scale: Array, key: Array) -> State:
    noise = _gaussian(state.obs, scale, jax.random.fold_in(key, SCALE_NOISE_STREAM))
    return state.replace(obs=jax.tree.map(lambda o, e: o * (1 + e), state.obs, noise))


def _scaled_reset(reset_fn, scale, model, key) -> State:
    return _scaled(reset_fn(model, key), scale, key)


def _scaled_step(step_fn, scale, model, state, action, key) -> State:
    return _scaled(step_fn(model, state, action, key), scale, key)


def with_privileged_observation(
    task: Task, observe: Observation, keys: tuple[str, str] = ("state", "privileged_state")
) -> Task:
    """An asymmetric actor-critic's two views: the observation becomes
    ``{keys[0]: obs, keys[1]: concat(obs, observe(model, state))}``.

    The policy's view is the task's own observation (noise, history, command and all);
    the critic's adds `observe`'s privileged numbers [k], read after every reset and
    step without noise: what a simulator knows and a robot does not (base velocity,
    contacts, the terrain under the robot). PPO reads them with
    ``policy_obs_key=keys[0], value_obs_key=keys[1]``; an exported policy reads
    ``keys[0]`` alone. The inner step receives its own observation. Keeps no record.
    """
    who = "with_privileged_observation"
    if not callable(observe):
        raise TypeError(f"{who}: observe must be an observation item, got {type(observe).__name__}")
    if len(keys) != 2 or not all(isinstance(k, str) and k for k in keys) or keys[0] == keys[1]:
        raise ValueError(f"{who}: keys={keys!r} must be two different names (the policy's, the critic's)")
    obs = jax.eval_shape(task.start, task.model, jax.random.key(0)).obs
    if not (isinstance(obs, jax.ShapeDtypeStruct) and obs.ndim == 1):
        raise ValueError(f"{who}: the task must observe a 1-D array; it observes {jax.tree.map(jnp.shape, obs)}")
    observe = observe if isinstance(observe, Partial) else Partial(observe)
    keys = tree.StaticValue(tuple(keys))
    return task.replace(
        start=Partial(_privileged_reset, task.start, observe, keys),
        step=Partial(_privileged_step, task.step, observe, keys),
    )


def _views(state: State, observe: Partial, keys: tree.StaticValue, model) -> State:
    privileged = jnp.ravel(jnp.asarray(observe(model, state), jnp.float32))
    own = state.obs
    return state.replace(obs={keys.value[0]: own, keys.value[1]: jnp.concatenate([own, privileged.astype(own.dtype)])})


def _privileged_reset(reset_fn, observe, keys, model, key) -> State:
    return _views(reset_fn(model, key), observe, keys, model)


def _privileged_step(step_fn, observe, keys, model, state, action, key) -> State:
    inner = step_fn(model, state.replace(obs=state.obs[keys.value[0]]), action, key)
    return _views(inner, observe, keys, model)
