"""Motion features for adversarial motion priors (AMP): one function for the simulated
robot and for the reference motion.

An AMP discriminator tells windows of the policy's motion from windows of a reference
clip. If the two were featurized by different code (a simulator path and a clip path),
the discriminator could learn the difference between the two codes instead of the
difference between the motions. Here ONE function computes the features of one frame
from an `mjx.Data`; a reference frame is a template Data with the frame's qpos and qvel.

Per frame, for a floating base (the body of the model's first free joint, or
`root_body`) and a heading frame (the base's yaw, about world z):

    root_height                [1]   m
    root_tangent, root_normal  [3+3] the base's x and z axes with the heading removed
    root_linear_velocity       [3]   m/s in the heading frame (qvel holds it in the world)
    root_angular_velocity      [3]   rad/s in the heading frame (qvel: in the base frame)
    qpos/<joint>               [1 or 6] every hinge/slide angle; a ball joint's rotation
                                     as its x and z axes (continuous, unlike a quaternion)
    qvel/<joint>               [1 or 3] their velocities, per second
    key_body/<body>            [3]   each key body's origin relative to the base, in the
                                     heading frame

A fixed-base model has only the joints and the key bodies' world positions. Free joints
other than the base (props) are left out. The base's heading is the yaw of its x axis:
name a base whose x axis is not vertical.

    features = motion_features(task.mj_model, key_bodies=("left_foot", "right_foot"))
    f = features(task.model, state.data)                                 # [F]
    ref = frames_features(features, task.model, state.data, qpos, qvel)  # [k, F]
    amp_task = with_feature_window(task, features, num_frames=2)  # obs["motion"]: [2, F]
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import NamedTuple
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from mjzoo import names
from mjzoo import tree
from mjzoo.combinators import resets_itself
from mjzoo.layers import find
from mjzoo.layers import layered
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "FeatureWindowState",
    "Layout",
    "feature_layout",
    "feature_size",
    "frames_features",
    "motion_features",
    "with_feature_window",
]

Array = jax.Array
Partial = jax.tree_util.Partial
_FREE, _BALL = int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL)


@dataclasses.dataclass(frozen=True)
class Layout:
    """What a feature vector holds (static and hashable: carried as pytree metadata).

    Attributes:
      entries: ``(name, size)`` of each slice, in order.
      floating: whether the features start with the 13 of a floating base.
      model_sizes: (nq, nv, nbody) of the model the indices were resolved on.
    """

    entries: tuple[tuple[str, int], ...]
    floating: bool
    model_sizes: tuple[int, int, int]

    @property
    def size(self) -> int:
        return sum(size for _, size in self.entries)

    def slices(self) -> dict[str, slice]:
        """``{name: slice}`` into a feature vector, in order."""
        out, start = {}, 0
        for name, size in self.entries:
            out[name], start = slice(start, start + size), start + size
        return out


def motion_features(mj_model: mujoco.MjModel, key_bodies: Sequence[str] = (), root_body: str | None = None) -> Partial:
    """The motion features of one frame, as ``features(model, data) -> [F]`` float32.

    Args:
      mj_model: the host model (``task.mj_model``); names are resolved on it once.
      key_bodies: bodies whose positions relative to the base are features (feet, hands).
      root_body: the floating base, a body with a free joint; None: the body of the
        first free joint, or a fixed base if the model has none.

    Returns:
      A `jax.tree_util.Partial` over int32 index leaves (pass it through jit freely).
      `feature_size(features)` is F; `feature_layout(features)` names each slice.

    Raises:
      TypeError: `mj_model` is not a `mujoco.MjModel`.
      ValueError: a key body or `root_body` the model lacks (the message lists its
        bodies), or a `root_body` without a free joint.
    """
    who = "motion_features"
    if not isinstance(mj_model, mujoco.MjModel):
        raise TypeError(f"{who}: mj_model must be a mujoco.MjModel (task.mj_model), got {type(mj_model).__name__}")
    if isinstance(key_bodies, str):
        key_bodies = (key_bodies,)
    floating = root_body is not None or bool((mj_model.jnt_type == _FREE).any())
    root_qpos, root_qvel = names.free_joint_addresses(mj_model, root_body, who) if floating else ([], [])
    joints = [j for j in range(mj_model.njnt) if int(mj_model.jnt_type[j]) != _FREE]
    balls = [j for j in joints if int(mj_model.jnt_type[j]) == _BALL]
    scalars = [j for j in joints if int(mj_model.jnt_type[j]) != _BALL]
    bodies = names.ids(mj_model, "body", list(key_bodies), who, world=False) if len(key_bodies) else []
    leaves = [
        root_qpos,
        root_qvel,
        names.joint_addresses(mj_model, scalars, False),
        names.joint_addresses(mj_model, scalars, True),
        names.joint_addresses(mj_model, balls, False).reshape(-1, 4),
        names.joint_addresses(mj_model, balls, True).reshape(-1, 3),
        bodies,
    ]
    layout = Layout(
        _entries(mj_model, floating, scalars, balls, bodies),
        floating,
        (int(mj_model.nq), int(mj_model.nv), int(mj_model.nbody)),
    )
    return Partial(_features, tree.StaticValue(layout), *(jnp.asarray(x, jnp.int32) for x in leaves))


def _entries(mj_model, floating: bool, scalars, balls, bodies) -> tuple[tuple[str, int], ...]:
    """The layout's (name, size) pairs, in the order `_features` concatenates them."""

    def joint(ids):
        return names.all_names(mj_model, "joint", ids)

    root = (
        [
            ("root_height", 1),
            ("root_tangent", 3),
            ("root_normal", 3),
            ("root_linear_velocity", 3),
            ("root_angular_velocity", 3),
        ]
        if floating
        else []
    )
    return tuple(
        root
        + [(f"qpos/{n}", 1) for n in joint(scalars)]
        + [(f"qpos/{n}", 6) for n in joint(balls)]
        + [(f"qvel/{n}", 1) for n in joint(scalars)]
        + [(f"qvel/{n}", 3) for n in joint(balls)]
        + [(f"key_body/{n}", 3) for n in names.all_names(mj_model, "body", bodies)]
    )


def feature_layout(features: Partial) -> dict[str, slice]:
    """``{name: slice}`` of each part of `features`' output (for diagnostics, plots)."""
    return _layout("feature_layout", features).slices()


def feature_size(features: Partial) -> int:
    """F, the length of one frame's features."""
    return _layout("feature_size", features).size


def _layout(who: str, features) -> Layout:
    if not (isinstance(features, Partial) and features.func is _features):
        raise TypeError(f"{who}: features must come from motion_features(...), got {type(features).__name__}")
    return features.args[0].value


# --- the features of one frame -----------------------------------------------------


def _features(
    layout: tree.StaticValue,
    root_qpos,
    root_qvel,
    scalar_qpos,
    scalar_qvel,
    ball_qpos,
    ball_qvel,
    key_bodies,
    model: mjx.Model,
    data: mjx.Data,
) -> Array:
    qpos, qvel = data.qpos.astype(jnp.float32), data.qvel.astype(jnp.float32)
    parts, to_heading, origin = [], jnp.eye(3), jnp.zeros(3)
    if layout.value.floating:
        origin = qpos[root_qpos[:3]]
        rotation = _rotation(qpos[root_qpos[3:]])
        to_heading = _yaw(jnp.arctan2(rotation[1, 0], rotation[0, 0])).T  # world -> heading frame
        local = to_heading @ rotation
        angular = rotation @ qvel[root_qvel[3:]]  # MuJoCo keeps it in the base frame
        parts += [origin[2:], local[:, 0], local[:, 2], to_heading @ qvel[root_qvel[:3]], to_heading @ angular]
    axes = jax.vmap(_rotation)(qpos[ball_qpos])[:, :, ::2]  # [B, 3, 2]: the x and z axes
    parts += [qpos[scalar_qpos], jnp.swapaxes(axes, 1, 2).ravel(), qvel[scalar_qvel], qvel[ball_qvel].ravel()]
    if key_bodies.shape[0]:
        # After mjx.step, data.xpos belongs to the qpos before the step's integration
        # (MuJoCo computes positions first, then integrates), and a reference frame's
        # Data holds the template's xpos: recompute the bodies from this qpos.
        xpos = mjx.kinematics(model, data).xpos[key_bodies].astype(jnp.float32)
        parts.append(((xpos - origin) @ to_heading.T).ravel())
    return jnp.concatenate(parts)


def _rotation(quat: Array) -> Array:
    """The rotation matrix [3, 3] of a wxyz quaternion (normalized here: qpos drifts)."""
    w, x, y, z = quat / jnp.linalg.norm(quat)
    return jnp.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _yaw(angle: Array) -> Array:
    """The rotation [3, 3] by `angle` about world z."""
    c, s = jnp.cos(angle), jnp.sin(angle)
    return jnp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# --- reference frames ---------------------------------------------------------------


def frames_features(features: Partial, model: mjx.Model, template: mjx.Data, qpos: Array, qvel: Array) -> Array:
    """The features of k reference frames: [k, F] float32.

    Each frame is ``template.replace(qpos=qpos[i], qvel=qvel[i])`` through `features`,
    vmapped: exactly the code the simulated states go through.

    Args:
      features: from `motion_features`.
      model: the MJX model.
      template: any Data of the model for ONE environment (a reset state's): only its
        structure and non-kinematic fields are used.
      qpos: [k, nq] generalized positions. qvel: [k, nv] velocities, per second.
    """
    nq, nv, _ = _layout("frames_features", features).model_sizes
    for arg, value, width in (("qpos", qpos, nq), ("qvel", qvel, nv)):
        if jnp.ndim(value) != 2 or jnp.shape(value)[1] != width:
            raise ValueError(
                f"frames_features: {arg} must have shape [k, {width}] for this model, got {list(jnp.shape(value))}"
            )
    if jnp.shape(qpos)[0] != jnp.shape(qvel)[0]:
        raise ValueError(f"frames_features: qpos and qvel have {jnp.shape(qpos)[0]} and {jnp.shape(qvel)[0]} frames")
    if jnp.shape(template.qpos) != (nq,):
        raise ValueError(
            f"frames_features: template must be one environment's Data (qpos [{nq}]), "
            f"got qpos {list(jnp.shape(template.qpos))}"
        )
    dtype = template.qpos.dtype

    def one(q: Array, v: Array) -> Array:
        return features(model, template.replace(qpos=q.astype(dtype), qvel=v.astype(dtype)))

    return jax.vmap(one)(jnp.asarray(qpos), jnp.asarray(qvel))


# --- the window combinator ------------------------------------------------------------


def with_feature_window(task: Task, features: Partial, num_frames: int) -> Task:
    """Observes ``{"policy": <the task's observation>, "motion": [num_frames, F]}``: the
    features of the last `num_frames` states, oldest first, newest last.

    At reset the window is the reset state's features repeated; each step drops the
    oldest frame and appends the new state's. Where the task restarts episodes inside
    its step (`with_auto_reset` inside this combinator), the window restarts with the
    new episode, so no window spans two episodes. Keeps the window in its record,
    `FeatureWindowState` (an outer observation noise does not reach it); the inner step
    receives the ``"policy"`` observation. Costs one `mjx.kinematics` per step with key bodies.

    Raises:
      ValueError: `num_frames` < 2 (a discriminator judges transitions: at least two
        frames), `features` resolved on another model, or the task already keeps a
        window. TypeError: `features` is not from `motion_features`.
    """
    layout = _layout("with_feature_window", features)
    if isinstance(num_frames, bool) or not isinstance(num_frames, int) or num_frames < 2:
        raise ValueError(
            f"with_feature_window: num_frames={num_frames!r} must be an integer >= 2: the "
            "discriminator judges transitions, which take two frames"
        )
    sizes = (int(task.mj_model.nq), int(task.mj_model.nv), int(task.mj_model.nbody))
    if sizes != layout.model_sizes:
        raise ValueError(
            f"with_feature_window: features were built for a model with (nq, nv, nbody) = "
            f"{layout.model_sizes}, the task's has {sizes}: build them from task.mj_model"
        )
    if find(jax.eval_shape(task.start, task.model, jax.random.key(0)), FeatureWindowState, None) is not None:
        raise ValueError("with_feature_window: the task already keeps a motion window; raise its num_frames")
    restarts = tree.StaticValue(resets_itself(task))
    return layered(
        task,
        FeatureWindowState,
        start=Partial(_window_start, task.start, features, tree.StaticValue(num_frames)),
        step=Partial(_window_step, task.step, features, restarts),
    )


class FeatureWindowState(NamedTuple):
    """`with_feature_window`'s record: the window [num_frames, F], oldest frame first."""

    window: Array
    inner: Any = ()


def _windowed(state: State, window: Array) -> State:
    return wrap(state.replace(obs={"policy": state.obs, "motion": window}), FeatureWindowState(window))


def _window_start(start_fn, features, num_frames: tree.StaticValue, model, key) -> State:
    state = start_fn(model, key)
    return _windowed(state, jnp.repeat(features(model, state.data)[None], num_frames.value, axis=0))


def _window_step(step_fn, features, restarts: tree.StaticValue, model, state: State, action, key) -> State:
    record, state = peel(state, FeatureWindowState)
    window = record.window
    next_state = step_fn(model, state.replace(obs=state.obs["policy"]), action, key)
    frame = features(model, next_state.data)
    shifted = jnp.concatenate([window[1:], frame[None]])
    if restarts.value:  # the inner auto-reset records whether the step ended an episode
        outcome = next_state.outcome
        ended = outcome.terminated | outcome.truncated
        shifted = jnp.where(ended, jnp.broadcast_to(frame, window.shape), shifted)
    return _windowed(next_state, shifted)
