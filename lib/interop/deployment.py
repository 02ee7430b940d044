"""The deployment contract of an exported policy: what a robot (or plain C MuJoCo) must
feed it and do with its output, as JSON-ready data.

    terms = deployment.observation_terms(task)        # how the task observes, in the vocabulary below
    obs = deployment.frame(terms, mj_model, mj_data, previous_action)   # the same, from C MuJoCo

An exported policy is only usable if its observation can be rebuilt outside JAX. So the
contract describes each observation term by a *source* from a small vocabulary, every
one computable from `mujoco.MjModel` / `mujoco.MjData` with numpy (MjData's fields after
`mj_step` or `mj_forward`, the state MJX's step leaves them in):

  source                        params              value
  qpos / qvel                   index, joints       d.qpos[index] / d.qvel[index]
  cos_qpos / sin_qpos           index, joints       cos / sin of d.qpos[index] (a hinge angle)
  body_position                 bodies, components  d.xpos[body][components], body by body
  body_orientation              bodies              d.xquat[body] (wxyz), body by body
  site_position                 sites               d.site_xpos[site], site by site
  body_linear_velocity_local    body                R^T (v + w x (xpos[b] - subtree_com[root(b)])),
                                                    (w, v) = d.cvel[b], R = d.xmat[b]: the body
                                                    origin's velocity in its own frame
  body_angular_velocity_local   body                R^T d.cvel[b, :3] (a gyro)
  projected_gravity             body, gravity       R^T g / |g| ((0, 0, -1) upright)
  point_velocity_world          kind, names         per body (site): the point's world linear
                                                    velocity as above, then its body's w
  sensordata                    sensors, index      d.sensordata[index] (the named sensors)
  actuator_force                -                   d.actuator_force
  gait_clock                    frequency, offsets  cos then sin of each foot's phase 2 pi frequency
                                                    d.time + offset (a stepping clock; d.time is
                                                    0 at an episode's start)
  previous_action               -                   the previous task action (`action.to_task`
                                                    of the policy's last output); zeros at reset
  command                       record, meaning     the operator's command (a joystick's
                                                    [vx, vy, yaw rate]), given to `frame`

An observation is ``history`` frames, newest first, each the terms concatenated in order;
at an episode's start every frame is the first one. Of a dict observation (an asymmetric
actor-critic's, `observations.with_privileged_observation`) the contract describes the
policy's entry, ``observation["key"]``: a robot computes that one alone. A term the vocabulary cannot express
(contacts, a height scan, a user's own function) makes the contract fail, naming it and saying what to do:
`mjzoo.interop.export.end_to_end` exports any task's policy with its observation inside (no contract), and
`register_observation` teaches the vocabulary a function of one's own.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjzoo import names
from mjzoo.catalog.observations import ObservationHistoryState
from mjzoo.layers import find
from mjzoo.learning import to_controls
from mjzoo.running import reset
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "FORMAT",
    "SOURCES",
    "ContractError",
    "register_observation",
    "observation_terms",
    "frame",
    "frame_size",
    "action_mapping",
    "model_section",
    "stacked",
    "Check",
    "check_observation",
    "without_observation_noise",
]

Array = jax.Array
FORMAT = "mjzoo.policy/1"
SOURCES = (
    "qpos",
    "qvel",
    "cos_qpos",
    "sin_qpos",
    "body_position",
    "body_orientation",
    "site_position",
    "body_linear_velocity_local",
    "body_angular_velocity_local",
    "projected_gravity",
    "point_velocity_world",
    "sensordata",
    "actuator_force",
    "gait_clock",
    "previous_action",
    "command",
)
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
Describer = Callable[..., list[dict[str, Any]]]  # (mj_model, *bound params) -> terms
_OBSERVATIONS: dict[str, Describer] = {}  # "module:qualname" of an observation item -> describer
_STEPS: dict[str, Describer] = {}  # "module:qualname" of a task step that observes in fixed code -> describer


class ContractError(ValueError):
    """The task observes or acts in a way the contract's vocabulary cannot describe."""


_INSTEAD = (
    "export the policy with the task's own observation inside instead, which needs no contract: "
    "mjzoo.interop.export.end_to_end (`mjzoo export RUN --format jax`); or build the observation from "
    "catalog terms (mjzoo.catalog.observations); or describe it with "
    "mjzoo.interop.deployment.register_observation"
)


def function_key(fn: Callable) -> str:
    """``module:qualname`` of a function: how the vocabulary's registries name it."""
    return f"{getattr(fn, '__module__', '?')}:{getattr(fn, '__qualname__', type(fn).__name__)}"


def register_observation(fn: Callable | str, describe: Describer, *, step: bool = False) -> None:
    """Teaches the vocabulary a function of one's own.

    Args:
      fn: an observation item ``(model, state) -> [k]`` as bound in a task (the function
        a `jax.tree_util.Partial` wraps), or its ``"module:qualname"``; with ``step=True``
        a task's step function that computes the observation in its own code.
      describe: ``(mj_model, *the Partial's bound params) -> [term, ...]``, each term a dict
        ``{"name", "size", "source", ...}`` in the vocabulary (`SOURCES`).
    """
    (_STEPS if step else _OBSERVATIONS)[fn if isinstance(fn, str) else function_key(fn)] = describe


# --- the terms --------------------------------------------------------------------------------------------------


def _name(m: mujoco.MjModel, kind: str, i: int) -> str:
    return names.all_names(m, kind, [int(i)])[0]


def _joints_of(m: mujoco.MjModel, index: np.ndarray, velocity: bool) -> list[str]:
    """The joint owning each qpos (qvel) entry."""
    owner = m.dof_jntid if velocity else np.searchsorted(m.jnt_qposadr, np.arange(m.nq), side="right") - 1
    return [_name(m, "joint", owner[i]) for i in np.asarray(index).ravel()]


def _indexed(source: str, name: str, m: mujoco.MjModel, index) -> dict[str, Any]:
    index = np.asarray(index, np.int64).ravel()
    velocity = source == "qvel"
    return dict(
        name=name, size=int(index.size), source=source, index=index.tolist(), joints=_joints_of(m, index, velocity)
    )


def _not_free(m: mujoco.MjModel, velocity: bool) -> np.ndarray:
    return names.joint_addresses(m, np.flatnonzero(m.jnt_type != _FREE), velocity)


def _gathered(m, field, index) -> list[dict[str, Any]]:
    field, ids = field.value, np.atleast_1d(np.asarray(index))
    if field in ("qpos", "qvel"):
        return [_indexed(field, f"{field}({', '.join(dict.fromkeys(_joints_of(m, ids, field == 'qvel')))})", m, ids)]
    if field == "sensordata":
        found = [
            _name(m, "sensor", s)
            for s in range(m.nsensor)
            if np.isin(m.sensor_adr[s] + np.arange(m.sensor_dim[s]), ids).any()
        ]
        return [
            dict(
                name=f"sensors({', '.join(found)})",
                size=int(ids.size),
                source="sensordata",
                sensors=found,
                index=ids.tolist(),
            )
        ]
    kinds = {
        "xpos": ("body", "body_position"),
        "xquat": ("body", "body_orientation"),
        "site_xpos": ("site", "site_position"),
    }
    if field not in kinds:
        raise ContractError(f"the observation reads data.{field}, which the contract's vocabulary does not cover")
    kind, source = kinds[field]
    labels = [_name(m, kind, i) for i in ids]
    term = dict(
        name=f"{source}({', '.join(labels)})",
        size=int(ids.size * (4 if field == "xquat" else 3)),
        source=source,
        **{"bodies" if kind == "body" else "sites": labels},
    )
    return [{**term, "components": [0, 1, 2]} if field == "xpos" else term]


def _height(m, body) -> list[dict[str, Any]]:
    label = _name(m, "body", body)
    return [dict(name=f"base_height({label})", size=1, source="body_position", bodies=[label], components=[2])]


def _in_base(m, quantity, body) -> list[dict[str, Any]]:
    label, q = _name(m, "body", body), quantity.value
    if q == "gravity":
        g = np.asarray(m.opt.gravity, float)
        return [
            dict(name=f"projected_gravity({label})", size=3, source="projected_gravity", body=label, gravity=g.tolist())
        ]
    return [dict(name=f"base_{q}_velocity({label})", size=3, source=f"body_{q}_velocity_local", body=label)]


def _point_velocities(m, field, points, bodies) -> list[dict[str, Any]]:
    kind = "body" if field.value == "xpos" else "site"
    labels = [_name(m, kind, i) for i in np.atleast_1d(np.asarray(points))]
    return [
        dict(
            name=f"{kind}_velocities({', '.join(labels)})",
            size=6 * len(labels),
            source="point_velocity_world",
            kind=kind,
            names=labels,
        )
    ]


def _concat(m, fns) -> list[dict[str, Any]]:
    return [term for fn in fns for term in describe_item(m, fn)]


def _cartpole(m, params) -> list[dict[str, Any]]:
    """`mjzoo.envs.cartpole.observe`: [cart position, cos, sin of the pole angle, both velocities]."""
    return [
        _indexed("qpos", "cart_position", m, [0]),
        _indexed("cos_qpos", "pole_angle_cos", m, [1]),
        _indexed("sin_qpos", "pole_angle_sin", m, [1]),
        _indexed("qvel", "cart_velocity", m, [0]),
        _indexed("qvel", "pole_angular_velocity", m, [1]),
    ]


def _gait_clock(m, frequency, offsets) -> list[dict[str, Any]]:
    """`catalog.gait.clock`: its frequency and the feet's phase offsets."""
    f, phases = float(frequency), [float(o) for o in np.asarray(offsets)]
    return [dict(name=f"gait_clock({f:g} Hz)", size=2 * len(phases), source="gait_clock", frequency=f, offsets=phases)]


_CATALOG = "mjzoo.catalog.observations"
_OBSERVATIONS.update(
    {
        f"{_CATALOG}:_gathered": _gathered,
        f"{_CATALOG}:_height": _height,
        f"{_CATALOG}:_in_base": _in_base,
        f"{_CATALOG}:_point_velocities": _point_velocities,
        f"{_CATALOG}:_concat": _concat,
        f"{_CATALOG}:joint_positions": lambda m: [_indexed("qpos", "joint_positions", m, _not_free(m, False))],
        f"{_CATALOG}:joint_velocities": lambda m: [_indexed("qvel", "joint_velocities", m, _not_free(m, True))],
        f"{_CATALOG}:actuator_forces": lambda m: [
            dict(name="actuator_forces", size=int(m.nu), source="actuator_force")
        ],
        f"{_CATALOG}:last_action": lambda m: [dict(name="last_action", size=-1, source="previous_action")],
    }
)
_OBSERVATIONS["mjzoo.catalog.gait:_clock"] = _gait_clock
_OBSERVATIONS["mjzoo.envs.cartpole:observation"] = lambda m: _cartpole(m, None)


# Steps of combinators that append to, or split, the observation of the task they wrap.
_COMMANDS = {
    "VelocityCommandState": "[vx m/s, vy m/s, yaw rate rad/s]: forward, left, counter-clockwise, in the base's heading frame",
    "JointCommandState": "joint position targets, rad (m), in the command's joint order",
}


def _command_step(m, step_fn, c) -> list[dict[str, Any]] | None:
    """`commands.with_*_command`: the inner terms, then the command when observed."""
    inner = _find(m, step_fn)
    if inner is None or not c.observe:
        return inner
    record = c.record.__name__
    size = int(c.low.shape[0])
    return [*inner, dict(name=c.name, size=size, source="command", record=record, meaning=_COMMANDS.get(record, ""))]


def _action_history_step(m, step_fn, observed) -> list[dict[str, Any]] | None:
    """`trackers.with_action_history(observe=True)`: the inner terms, then the last action."""
    inner = _find(m, step_fn)
    if inner is None or not observed.value:
        return inner
    return [*inner, dict(name="last_action", size=-1, source="previous_action")]


_STEPS.update(
    {
        "mjzoo.catalog.commands:_command_step": _command_step,
        "mjzoo.catalog.trackers:_history_step": _action_history_step,
        # the policy's view is the inner observation: the privileged part is the critic's
        "mjzoo.catalog.observations:_privileged_step": lambda m, step_fn, *_: _find(m, step_fn),
    }
)


def describe_item(m: mujoco.MjModel, fn: Any) -> list[dict[str, Any]]:
    """The terms of one observation item (a Partial over a catalog function, or a registered one)."""
    func, args = (fn.func, fn.args) if isinstance(fn, jax.tree_util.Partial) else (fn, ())
    describe = _OBSERVATIONS.get(function_key(func))
    if describe is None:
        raise ContractError(
            f"cannot describe the observation term {function_key(func)}: the contract's vocabulary "
            f"covers {', '.join(SOURCES)} (the catalog's joint, base, body, site, sensor, "
            f"actuator-force and last-action items); {_INSTEAD}"
        )
    return describe(m, *args)


def _find(m: mujoco.MjModel, node: Any, depth: int = 0) -> list[dict[str, Any]] | None:
    """The observation of a task's step chain: the outermost step that sets it."""
    if depth > 64:
        return None
    if isinstance(node, Task):
        return _find(m, node.step, depth + 1)
    if isinstance(node, jax.tree_util.Partial):
        key = function_key(node.func)
        if key in _STEPS:
            return _STEPS[key](m, *node.args)
        if key == "mjzoo.combinators:_observed_step":  # with_observation: a function of the observation
            raise ContractError(
                f"the task's observation passes through mjzoo.with_observation("
                f"{function_key(node.args[1].func)}), which the contract's vocabulary cannot describe; {_INSTEAD}"
            )
        for arg in node.args:
            if dataclasses.is_dataclass(arg) and not isinstance(arg, type) and hasattr(arg, "observe"):
                return describe_item(m, arg.observe)
        for arg in node.args:
            if isinstance(arg, (jax.tree_util.Partial, Task)):
                found = _find(m, arg, depth + 1)
                if found is not None:
                    return found
    return None


def observation_terms(task: Task) -> list[dict[str, Any]]:
    """One frame of `task`'s observation as terms of the vocabulary (module docstring).

    Raises:
      ContractError: naming the term, or the step, the vocabulary cannot describe.
    """
    m = task.mj_model
    terms = _find(m, task.step)
    if terms is None:
        raise ContractError(
            f"cannot find how the task observes: its step ({function_key(task.step.func)}) is not a "
            "known task step, and none of the steps it wraps holds a catalog observation (`observe`); "
            f"{_INSTEAD}(..., step=True)"
        )
    size = task.action_size
    return [{**t, "size": size} if t["source"] == "previous_action" else t for t in terms]


def frame_size(terms: list[dict[str, Any]]) -> int:
    return int(sum(t["size"] for t in terms))


# --- evaluating the terms on C MuJoCo ---------------------------------------------------------------------------


def _id(m: mujoco.MjModel, kind: str, name: str) -> int:
    obj = {"body": mujoco.mjtObj.mjOBJ_BODY, "site": mujoco.mjtObj.mjOBJ_SITE, "sensor": mujoco.mjtObj.mjOBJ_SENSOR}
    i = mujoco.mj_name2id(m, obj[kind], name)
    if i < 0:
        raise ContractError(f"the model has no {kind} named {name!r}, which the observation reads")
    return i


def _point_velocity(m, d, body: int, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World linear velocity of a point fixed to `body`, and the body's angular velocity."""
    w, v = d.cvel[body, :3], d.cvel[body, 3:]
    return v + np.cross(w, point - d.subtree_com[m.body_rootid[body]]), w


def _term(m: mujoco.MjModel, d: mujoco.MjData, t: dict[str, Any], previous: np.ndarray, command) -> np.ndarray:
    s = t["source"]
    if s in ("qpos", "qvel", "cos_qpos", "sin_qpos"):
        x = (d.qvel if s == "qvel" else d.qpos)[t["index"]]
        return np.cos(x) if s == "cos_qpos" else np.sin(x) if s == "sin_qpos" else x
    if s == "body_position":
        return np.concatenate([d.xpos[_id(m, "body", b)][t["components"]] for b in t["bodies"]])
    if s == "body_orientation":
        return np.concatenate([d.xquat[_id(m, "body", b)] for b in t["bodies"]])
    if s == "site_position":
        return np.concatenate([d.site_xpos[_id(m, "site", x)] for x in t["sites"]])
    if s in ("body_linear_velocity_local", "body_angular_velocity_local", "projected_gravity"):
        b = _id(m, "body", t["body"])
        if s == "projected_gravity":
            g = np.asarray(t["gravity"], float)
            vector = g / np.linalg.norm(g) if np.linalg.norm(g) > 0 else np.array([0.0, 0.0, -1.0])
        else:
            linear, angular = _point_velocity(m, d, b, d.xpos[b])
            vector = linear if s == "body_linear_velocity_local" else angular
        return d.xmat[b].reshape(3, 3).T @ vector
    if s == "point_velocity_world":
        parts = []
        for label in t["names"]:
            i = _id(m, t["kind"], label)
            body, point = (i, d.xpos[i]) if t["kind"] == "body" else (m.site_bodyid[i], d.site_xpos[i])
            parts.extend(_point_velocity(m, d, body, point))
        return np.concatenate(parts)
    if s == "sensordata":
        return d.sensordata[t["index"]]
    if s == "actuator_force":
        return d.actuator_force
    if s == "gait_clock":
        phase = 2 * np.pi * t["frequency"] * d.time + np.asarray(t["offsets"], float)
        return np.concatenate([np.cos(phase), np.sin(phase)])
    if s == "previous_action":
        return previous
    if s == "command":
        if command is None:
            raise ContractError(f"the observation holds a command ({t['name']}: {t.get('meaning')}); pass command=")
        return np.asarray(command, float)
    raise ContractError(f"unknown observation source {s!r} in term {t.get('name')!r}; known: {', '.join(SOURCES)}")


def frame(
    terms: list[dict[str, Any]],
    m: mujoco.MjModel,
    d: mujoco.MjData,
    previous_action: np.ndarray,
    command: np.ndarray | None = None,
) -> np.ndarray:
    """One observation frame [frame_size] float32 from C MuJoCo's state, term by term.

    Args:
      terms: the contract's ``observation["terms"]``.
      m, d: the model and its data after `mj_step` (or `mj_forward` at a reset).
      previous_action: [action size] the last task action (zeros at an episode's start).
      command: the operator's command, for a ``command`` term (its ``meaning`` says what).
    """
    parts = [np.ravel(_term(m, d, t, np.asarray(previous_action, float), command)) for t in terms]
    for t, p in zip(terms, parts):
        if p.size != t["size"]:
            raise ContractError(
                f"observation term {t['name']!r} has {p.size} values on this model; the contract says {t['size']}"
            )
    return np.concatenate(parts).astype(np.float32) if parts else np.zeros(0, np.float32)


# --- actions and the model --------------------------------------------------------------------------------------


_ACTUATORS = tuple(
    f"mjzoo.catalog.actuators:_{kind}" for kind in ("pd", "torque", "position_velocity", "position_targets")
)


def _actuator_partial(node: Any, depth: int = 0) -> jax.tree_util.Partial | None:
    """The catalog actuator (`mjzoo.catalog.actuators`) the task's step drives its motors with, if any."""
    if depth > 64:
        return None
    if isinstance(node, Task):
        return _actuator_partial(node.step, depth + 1)
    if isinstance(node, jax.tree_util.Partial):
        if function_key(node.func) in _ACTUATORS:
            return node
        for arg in node.args:
            inner = getattr(arg, "actuator", None) if dataclasses.is_dataclass(arg) else None
            found = _actuator_partial(inner if inner is not None else arg, depth + 1)
            if inner is not None and found is None:
                raise ContractError(
                    f"the task drives its motors with {function_key(getattr(inner, 'func', inner))}, "
                    "which the contract's vocabulary cannot describe (it knows the catalog's pd, "
                    "position_velocity, torque and position_targets actuators)"
                )
            if found is not None:
                return found
    return None


def _floats(x) -> list[float]:
    return np.asarray(x, float).ravel().tolist()


def action_mapping(task: Task) -> dict[str, Any]:
    """How the policy's output becomes the motors' ctrl: ``to_task`` (output in [-1, 1]
    to the task's action, as `mjzoo.learning.to_controls`), then ``to_ctrl`` (the task's
    action to ctrl, at every physics substep)."""
    m = task.mj_model
    low, high = m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1]
    if task.action_dim is None:
        to_task = dict(
            type="ctrlrange_affine",
            formula="limited: low + (a + 1) / 2 * (high - low); else a",
            low=_floats(low),
            high=_floats(high),
            limited=np.asarray(m.actuator_ctrllimited, bool).tolist(),
        )
    else:
        to_task = dict(type="identity")
    actuator = _actuator_partial(task.step)
    if actuator is None:
        to_ctrl = dict(type="direct", formula="ctrl = task action, held over the substeps (MuJoCo clamps to ctrlrange)")
    elif function_key(actuator.func).endswith(":_position_targets"):
        pose, scale = actuator.args[:2]
        to_ctrl = dict(
            type="position_targets",
            formula="ctrl = default_pose + action_scale * clip(a, -1, 1), per actuator (MuJoCo clamps it to "
            "ctrlrange); each <position> servo then applies kp (ctrl - q) - kv qdot within its forcerange",
            default_pose=_floats(pose),
            action_scale=_floats(scale),
            **_servos(m),
        )
    else:
        p = actuator.args[0]
        motors = p.motors if hasattr(p, "motors") else p
        kind = function_key(actuator.func).split(":_")[1]
        to_ctrl = dict(
            type=kind,
            qpos_index=np.asarray(motors.qpos).tolist(),
            dof_index=np.asarray(motors.dof).tolist(),
            gear=_floats(motors.gear),
            torque_limit=_floats(motors.limit),
        )
        if kind == "torque":
            to_ctrl["formula"] = "ctrl = clip(clip(a, -1, 1) * torque_limit, -torque_limit, torque_limit) / gear"
        else:
            to_ctrl.update(
                kp=_floats(p.kp),
                kd=_floats(p.kd),
                default_pose=_floats(p.default_pose),
                position_scale=_floats(p.position_scale),
                velocity_scale=_floats(p.velocity_scale),
                formula="every substep: a = clip(a, -1, 1); q* = default_pose + position_scale * a[:nu]; "
                "qd* = velocity_scale * a[nu:] (position_velocity) or 0 (pd); ctrl = "
                "clip(kp (q* - qpos[qpos_index]) + kd (qd* - qvel[dof_index]), -torque_limit, "
                "torque_limit) / gear",
                training_noise=dict(gain=float(p.gain_noise), torque=float(p.torque_noise)),
            )
    return dict(size=task.action_size, to_task=to_task, to_ctrl=to_ctrl)


def _servos(m: mujoco.MjModel) -> dict[str, Any]:
    """The gains of a model's <position> servos, in actuator order: what a robot's motor
    drivers must be set to (kp N m/rad, kv N m s/rad, the force limits, the joint each drives)."""
    return dict(
        joints=[_name(m, "joint", j) for j in m.actuator_trnid[:, 0]],
        kp=_floats(m.actuator_gainprm[:, 0]),
        kv=_floats(0.0 - m.actuator_biasprm[:, 2]),
        force_limit=[
            float(hi) if lim else None for lim, hi in zip(m.actuator_forcelimited, m.actuator_forcerange[:, 1])
        ],
    )


def model_section(m: mujoco.MjModel) -> dict[str, Any]:
    """Names in MuJoCo's order, addresses, control ranges and the physics options."""
    kinds = {int(getattr(mujoco.mjtJoint, f"mjJNT_{k.upper()}")): k for k in ("free", "ball", "slide", "hinge")}
    joints = [
        dict(
            name=_name(m, "joint", j),
            type=kinds[int(m.jnt_type[j])],
            qpos_address=int(m.jnt_qposadr[j]),
            dof_address=int(m.jnt_dofadr[j]),
        )
        for j in range(m.njnt)
    ]
    actuators = [
        dict(
            name=_name(m, "actuator", i),
            joint=_name(m, "joint", m.actuator_trnid[i, 0])
            if m.actuator_trntype[i] == mujoco.mjtTrn.mjTRN_JOINT
            else None,
            ctrl_range=_floats(m.actuator_ctrlrange[i]) if m.actuator_ctrllimited[i] else None,
            gear=float(m.actuator_gear[i, 0]),
        )
        for i in range(m.nu)
    ]
    return dict(
        nq=int(m.nq),
        nv=int(m.nv),
        nu=int(m.nu),
        joints=joints,
        actuators=actuators,
        joint_names=[j["name"] for j in joints],
        actuator_names=[a["name"] for a in actuators],
        ctrl_range=np.asarray(m.actuator_ctrlrange, float).tolist(),
        ctrl_limited=np.asarray(m.actuator_ctrllimited, bool).tolist(),
    )


def physics_section(m: mujoco.MjModel, control_dt: float) -> dict[str, Any]:
    """The control step, and the physics step and options C MuJoCo must run with."""
    dt = float(m.opt.timestep)
    return dict(
        control_dt=control_dt,
        physics_dt=dt,
        substeps=round(control_dt / dt),
        integrator=mujoco.mjtIntegrator(m.opt.integrator).name,
        solver=mujoco.mjtSolver(m.opt.solver).name,
        iterations=int(m.opt.iterations),
        ls_iterations=int(m.opt.ls_iterations),
        disable_flags=int(m.opt.disableflags),
    )


class Check(NamedTuple):
    """What `check_observation` measured."""

    max_error: float  # max |contract's observation - task's| over the checked states
    control_dt: float  # seconds per task step, measured
    history: int  # frames per observation


# --- the observation, checked on MJX's states ---------------------------------------------------------------------

_NOISE = (
    "mjzoo.perturbations:_noisy_reset",
    "mjzoo.perturbations:_noisy_obs_step",
    "mjzoo.catalog.observations:_bias_reset",
    "mjzoo.catalog.observations:_scaled_reset",
    "mjzoo.catalog.observations:_scaled_step",
)  # (each binds (inner function, scale, ...))


def without_observation_noise(task: Task) -> Task:
    """`task` with the scales of its observation-noise combinators (`with_observation_noise`,
    `with_observation_bias`, `with_multiplicative_observation_noise`) set to 0: the
    observation a deployment computes. Same pytree structure, so no recompile."""

    def clean(node: Any) -> Any:
        if isinstance(node, Task):  # a combinator that holds the task it wraps (domain randomization)
            return node.replace(start=clean(node.start), step=clean(node.step))
        if not isinstance(node, jax.tree_util.Partial):
            return node
        args = [clean(arg) for arg in node.args]
        if function_key(node.func) in _NOISE:
            args[1] = jnp.zeros_like(args[1])
        return jax.tree_util.Partial(node.func, *args, **node.keywords)

    return task.replace(start=clean(task.start), step=clean(task.step))


def stacked(frames: list[np.ndarray], length: int) -> np.ndarray:
    """The newest `length` frames, newest first, the oldest repeated before there are enough."""
    recent = frames[-length:][::-1]
    return np.concatenate(recent + [recent[-1]] * (length - len(recent)))


@functools.partial(jax.jit, static_argnums=2)  # module level: one compile per task structure
def _random_run(task: Task, key: Array, steps: int):
    """A reset and `steps` transitions under uniform random actions: (first state, (states, task actions))."""
    reset_key, run_key = jax.random.split(key)
    state = reset(task, reset_key)

    def body(state: State, key):
        act_key, step_key = jax.random.split(key)
        action = to_controls(task, jax.random.uniform(act_key, (task.action_size,), minval=-1.0, maxval=1.0))
        after = transition(task, state, action, step_key)
        return after, (after, action)

    return state, jax.lax.scan(body, state, jax.random.split(run_key, steps))[1]


_READ = (
    "qpos",
    "qvel",
    "act",
    "xpos",
    "xquat",
    "xmat",
    "site_xpos",
    "cvel",
    "subtree_com",
    "sensordata",
    "actuator_force",
)  # (the arrays the vocabulary reads)


def _c_data(m: mujoco.MjModel, data: mjx.Data) -> mujoco.MjData:
    """A C MjData holding what the vocabulary reads of one MJX state (`mjx.get_data` also
    refactors the inertia, and warns on MJX's states)."""
    d = mujoco.MjData(m)
    d.time = float(data.time)
    for field in _READ:
        target = getattr(d, field)
        target[...] = np.asarray(getattr(data, field)).reshape(target.shape)
    return d


def _command(terms: list[dict[str, Any]], state: State) -> np.ndarray | None:
    """The command the task drew, read from its command combinator's record."""
    from mjzoo.catalog import commands  # the records are the command combinators'

    records = [t["record"] for t in terms if t["source"] == "command"]
    return None if not records else np.asarray(find(state, getattr(commands, records[0])).command, float)


def check_observation(
    task: Task, terms: list[dict[str, Any]], key: Array, steps: int = 8, obs_key: str | None = None
) -> Check:
    """Rebuilds `task`'s observation from `terms` on MJX states (a reset, then `steps`
    transitions under uniformly random actions) and compares it with the task's own,
    observation noise off (`without_observation_noise`); of a dict observation, the
    entry `obs_key` (the policy's). A command term takes the command the task drew.

    Raises:
      ContractError: the observation (its entry) is not one flat array, or the rebuilt one
        differs by more than 1e-4 (relative above 1); the message names the worst terms.
    """
    first, (states, actions) = _random_run(without_observation_noise(task), key, steps)

    def observed(state: State) -> Any:
        obs = state.obs
        return obs.get(obs_key) if isinstance(obs, dict) and obs_key is not None else obs

    if not isinstance(observed(first), jax.Array) or observed(first).ndim != 1:
        split = isinstance(first.obs, dict)
        which = f" entry {obs_key!r}" if split and obs_key is not None else ""
        hint = f"; its entries: {sorted(first.obs)} (give obs_key, PPO's policy_obs_key)" if split and not which else ""
        raise ContractError(
            f"the task's observation{which} is {jax.tree.structure(observed(first))}; "
            f"the contract describes one flat array{hint}"
        )
    size = frame_size(terms)
    history = getattr(find(first, ObservationHistoryState, None), "frames", None)
    length = 1 if history is None else int(history.shape[0])
    if observed(first).shape[0] != length * size:
        raise ContractError(
            f"the task observes {observed(first).shape[0]} numbers; the described terms make "
            f"{size} per frame x {length} frames: {[t['name'] for t in terms]}"
        )
    m, previous, frames = task.mj_model, np.zeros(task.action_size), []
    errors, expected = [], []
    for t in range(steps + 1):
        state = first if t == 0 else jax.tree.map(lambda x, t=t: x[t - 1], states)
        if t > 0:
            previous = np.asarray(actions[t - 1], float)
        frames.append(frame(terms, m, _c_data(m, state.data), previous, _command(terms, state)))
        want = np.asarray(observed(state), np.float64)
        errors.append(np.abs(stacked(frames, length) - want) / np.maximum(1.0, np.abs(want)))
        expected.append(want)
    worst = np.max(errors, axis=0)
    if not np.all(worst <= 1e-4) or not np.all(np.isfinite(worst)):
        per_term, start = [], 0
        for term in terms:
            per_term.append((float(np.max(worst[:size].reshape(-1)[start : start + term["size"]])), term["name"]))
            start += term["size"]
        bad = ", ".join(f"{n} (error {e:.3g})" for e, n in sorted(per_term, reverse=True) if e > 1e-4)
        raise ContractError(f"the described observation does not reproduce the task's: {bad or 'history'}")
    control_dt = float(states.data.time[0] - first.data.time)
    return Check(max_error=float(np.max(worst)), control_dt=control_dt, history=length)
