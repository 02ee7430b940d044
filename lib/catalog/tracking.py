"""Whole-body motion tracking: a robot follows reference clips, body by body.

    clips = motion.reference([walk, run], mj_model, dt=ctrl_dt, loop=False)
    ref = tracking.motion(clips, mj_model, bodies=("pelvis", "left_knee_link", ...), anchor="torso_link")
    task = mjzoo.task(
        physics,
        observe=observations.concat(..., tracking.motion_command(ref)),
        resets=(start_sampling.reference_start(ref),),          # reference-state initialization
        rewards={"body_position": (tracking.body_position_tracking(ref), 1.0), ...},
        terminate={"anchor_height": tracking.anchor_height_deviation(ref), ...},
        combinators=(functools.partial(tracking.with_clip_end, motion=ref),),
    )

A `Motion` holds the clips (`mjzoo.motion.Reference`, one frame per control step) and,
computed once on the host with C MuJoCo, the world poses and velocities of B tracked
bodies in every frame; one of them is the anchor (BeyondMimic's: the G1's torso).

The clock: an episode starts at frame f of clip c (`start_sampling.reference_start`)
with ``data.time = f * dt`` and ``info["reference_clip"] = c``; the reference frame of any
later state is ``round(data.time / dt)`` (float32 time drifts by far less than half a
frame over an episode). Every item here is thus a pure function of the state.

Anchoring (BeyondMimic's practice): the reference bodies are compared where they would
be if the reference's anchor stood at the robot's anchor, turned by the yaw between the
two (its height kept): drift of the whole robot costs only the anchor terms. The tracking
rewards are exp(-error / sigma^2), error the mean over bodies (joints) of the squared
distance (m^2), rotation angle (rad^2) or velocity difference ((m/s)^2, (rad/s)^2, the
reference's turned by that yaw). Body poses are read from ``xpos`` / ``xquat`` and
velocities from ``cvel``, as the last physics step left them.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import checks
from mjzoo import motion as motion_lib
from mjzoo import names
from mjzoo import tree
from mjzoo.catalog.contacts import point_velocity
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "Motion",
    "motion",
    "clock",
    "quat_multiply",
    "quat_rotate",
    "quat_angle",
    "yaw_only",
    "anchored",
    "mpjpe",
    "motion_command",
    "anchor_position_tracking",
    "anchor_orientation_tracking",
    "body_position_tracking",
    "body_orientation_tracking",
    "body_linear_velocity_tracking",
    "body_angular_velocity_tracking",
    "joint_position_tracking",
    "anchor_height_deviation",
    "anchor_orientation_deviation",
    "body_height_deviation",
    "with_clip_end",
]

Array = jax.Array


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Motion:
    """Reference clips with their tracked bodies' world states, M frames in all.

    Attributes:
      clips: the `mjzoo.motion.Reference` (qpos [M, nq], qvel [M, nv], C clips).
      body_pos: float32 [M, B, 3] world positions of the tracked bodies' origins, m.
      body_quat: float32 [M, B, 4] their world orientations (w, x, y, z).
      body_linvel: float32 [M, B, 3] world linear velocities of their origins, m/s.
      body_angvel: float32 [M, B, 3] world angular velocities, rad/s.
      bodies: int32 [B] the tracked bodies' ids in the model.
      anchor: int32 [] the anchor's index in `bodies`.
      joint_qpos: int32 [J] qpos addresses of the tracked hinge and slide joints.
      joint_qvel: int32 [J] their qvel addresses.
    """

    clips: motion_lib.Reference
    body_pos: Array
    body_quat: Array
    body_linvel: Array
    body_angvel: Array
    bodies: Array
    anchor: Array
    joint_qpos: Array
    joint_qvel: Array

    @property
    def num_clips(self) -> int:
        return self.clips.num_clips


def motion(
    clips: motion_lib.Reference, mj_model: mujoco.MjModel, bodies: names.Names, anchor: str, joints=None
) -> Motion:
    """The `Motion` of `clips` (built for `mj_model`, one frame per control step) with the
    named `bodies` tracked, `anchor` one of them; `joints` (hinge or slide joints, None:
    all) for `joint_position_tracking` and `motion_command`. Host code: one forward
    kinematics per frame."""
    who = "tracking.motion"
    if not isinstance(clips, motion_lib.Reference):
        raise TypeError(f"{who}: clips must be a motion.Reference (motion.reference(...)), got {type(clips).__name__}")
    if clips.qpos.shape[1] != mj_model.nq or clips.qvel.shape[1] != mj_model.nv:
        raise ValueError(
            f"{who}: the clips have nq={clips.qpos.shape[1]}, nv={clips.qvel.shape[1]} "
            f"but the model nq={mj_model.nq}, nv={mj_model.nv}"
        )
    if int(np.min(clips.length)) < 2:
        raise ValueError(f"{who}: every clip needs at least 2 frames at the control step; lengths {clips.length}")
    ids = np.asarray(names.ids(mj_model, "body", bodies, who, world=False))
    tracked = [mj_model.body(int(i)).name for i in ids]
    if anchor not in tracked:
        raise ValueError(f"{who}: anchor={anchor!r} must be one of the tracked bodies {tracked}")
    joint_ids = names.joints(mj_model, joints, who)
    data = mujoco.MjData(mj_model)
    frames = []
    for qpos, qvel in zip(np.asarray(clips.qpos, np.float64), np.asarray(clips.qvel, np.float64)):
        data.qpos, data.qvel = qpos, qvel
        mujoco.mj_kinematics(mj_model, data)
        mujoco.mj_comPos(mj_model, data)
        mujoco.mj_comVel(mj_model, data)
        velocity = np.zeros((len(ids), 6))
        for k, body in enumerate(ids):  # (angular, linear) at the body's origin, world frame
            mujoco.mj_objectVelocity(mj_model, data, mujoco.mjtObj.mjOBJ_XBODY, int(body), velocity[k], 0)
        frames.append((data.xpos[ids].copy(), data.xquat[ids].copy(), velocity[:, 3:], velocity[:, :3]))
    pos, quat, linvel, angvel = (jnp.asarray(np.stack(x), jnp.float32) for x in zip(*frames))
    return Motion(
        clips=clips,
        body_pos=pos,
        body_quat=quat,
        body_linvel=linvel,
        body_angvel=angvel,
        bodies=jnp.asarray(ids, jnp.int32),
        anchor=jnp.int32(tracked.index(anchor)),
        joint_qpos=jnp.asarray(mj_model.jnt_qposadr[joint_ids], jnp.int32),
        joint_qvel=jnp.asarray(mj_model.jnt_dofadr[joint_ids], jnp.int32),
    )


def clock(ref: Motion, state: State) -> tuple[Array, Array, Array]:
    """(clip int32 [], frame int32 [] in the clip, index int32 [] into the frames) of the
    reference at `state`: ``info["reference_clip"]`` and ``round(data.time / dt)``, the
    frame held at the clip's last past its end."""
    clip = state.info["reference_clip"]
    frame = jnp.round(state.data.time / ref.clips.dt).astype(jnp.int32)
    frame = jnp.clip(frame, 0, ref.clips.length[clip] - 1)
    return clip, frame, ref.clips.start[clip] + frame


# --- quaternions (w, x, y, z), batched over leading axes ------------------------------


def quat_multiply(a: Array, b: Array) -> Array:
    """[..., 4] the rotation b then a (Hamilton product a b)."""
    aw, av, bw, bv = a[..., :1], a[..., 1:], b[..., :1], b[..., 1:]
    w = aw * bw - jnp.sum(av * bv, axis=-1, keepdims=True)
    return jnp.concatenate([w, aw * bv + bw * av + jnp.cross(av, bv)], axis=-1)


def quat_rotate(q: Array, v: Array) -> Array:
    """[..., 3] vectors `v` [..., 3] rotated by unit quaternions `q` [..., 4]."""
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * jnp.cross(u, v)
    return v + w * t + jnp.cross(u, t)


def _conjugate(q: Array) -> Array:
    return q * jnp.array([1.0, -1.0, -1.0, -1.0], q.dtype)


def quat_angle(a: Array, b: Array) -> Array:
    """[...] the angle (rad, in [0, pi]) of the rotation between unit quaternions a and
    b [..., 4]: 2 atan2(|v|, |w|) of conj(a) b; its gradient is finite where a = b."""
    d = quat_multiply(_conjugate(a), b)
    sin_sq = jnp.sum(jnp.square(d[..., 1:]), axis=-1)
    sin = jnp.sqrt(jnp.where(sin_sq > 0, sin_sq, 1.0)) * (sin_sq > 0)  # |v|, without sqrt's NaN slope at 0
    return 2.0 * jnp.arctan2(sin, jnp.abs(d[..., 0]))


def yaw_only(q: Array) -> Array:
    """[..., 4] the rotation about world z alone that turns x as `q` [..., 4] does, seen
    from above."""
    w, x, y, z = (q[..., i] for i in range(4))
    yaw = jnp.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    zero = jnp.zeros_like(yaw)
    return jnp.stack([jnp.cos(yaw / 2), zero, zero, jnp.sin(yaw / 2)], axis=-1)


def anchored(
    ref_pos: Array, ref_quat: Array, anchor: Array, robot_pos: Array, robot_quat: Array
) -> tuple[Array, Array, Array]:
    """The reference bodies moved onto the robot's anchor (BeyondMimic's relative frame).

    Args:
      ref_pos: [B, 3] reference body positions, world, m; ref_quat: [B, 4] orientations.
      anchor: int [] the anchor's index among the B bodies.
      robot_pos: [3] the robot's anchor position; robot_quat: [4] its orientation.

    Returns:
      (pos [B, 3], quat [B, 4], turn [4]): the reference turned about world z by `turn`,
      the yaw from the reference's anchor to the robot's, and shifted so that its anchor
      stands at the robot's anchor in x and y, at its own height.
    """
    turn = yaw_only(quat_multiply(robot_quat, _conjugate(ref_quat[anchor])))
    origin = robot_pos.at[2].set(ref_pos[anchor, 2])
    pos = origin + quat_rotate(turn, ref_pos - ref_pos[anchor])
    return pos, quat_multiply(turn, ref_quat), turn


def _robot(ref: Motion, model: mjx.Model, state: State) -> tuple[Array, Array, Array, Array]:
    """The tracked bodies' world positions [B, 3], orientations [B, 4], linear and
    angular velocities [B, 3] in `state`."""
    data = state.data
    pos = data.xpos[ref.bodies]
    linvel, angvel = point_velocity(model, data, ref.bodies, pos)
    return pos, data.xquat[ref.bodies], linvel, angvel


def _reference(ref: Motion, state: State) -> tuple[Array, Array, Array, Array]:
    index = clock(ref, state)[2]
    return ref.body_pos[index], ref.body_quat[index], ref.body_linvel[index], ref.body_angvel[index]


def mpjpe(ref: Motion, state: State) -> Array:
    """float32 []: mean per-body position error (mm) of `state` to the reference at its
    clock, both relative to their anchors (MPJPE; the anchor's own error is 0)."""
    pos, ref_pos = state.data.xpos[ref.bodies], _reference(ref, state)[0]
    error = (pos - pos[ref.anchor]) - (ref_pos - ref_pos[ref.anchor])
    return 1000.0 * jnp.mean(jnp.linalg.norm(error, axis=-1))


# --- the observation ------------------------------------------------------------------


def motion_command(ref: Motion) -> Partial:
    """Observation [C + 1 + 2 J + 9]: the clip one-hot [C]; the phase, frame / (length -
    1) in [0, 1]; the next frame's reference joint positions [J] (rad, m) and velocities
    [J]; the reference anchor's position [3] (m) and orientation (the first two columns
    of its rotation matrix, [6]) in the robot anchor's frame, at the next frame: where
    the action should take the robot."""
    return Partial(_motion_command, ref)


def _motion_command(ref: Motion, model, state: State) -> Array:
    clip, frame, _ = clock(ref, state)
    length = ref.clips.length[clip]
    target = ref.clips.start[clip] + jnp.minimum(frame + 1, length - 1)
    anchor = ref.bodies[ref.anchor]
    rot = state.data.xmat[anchor]  # columns: the robot anchor's axes
    ref_rot = _matrix(ref.body_quat[target, ref.anchor])
    position = rot.T @ (ref.body_pos[target, ref.anchor] - state.data.xpos[anchor])
    parts = [
        jax.nn.one_hot(clip, ref.num_clips),
        (frame / jnp.maximum(length - 1, 1))[None],
        ref.clips.qpos[target, ref.joint_qpos],
        ref.clips.qvel[target, ref.joint_qvel],
        position,
        (rot.T @ ref_rot)[:, :2].T.ravel(),
    ]
    return jnp.concatenate(parts).astype(jnp.float32)


def _matrix(q: Array) -> Array:
    """[3, 3] the rotation matrix of unit quaternion `q` [4]: its columns the rotated axes."""
    return jnp.stack([quat_rotate(q, e) for e in jnp.eye(3, dtype=q.dtype)], axis=1)


# --- rewards: exp(-error / sigma^2), in (0, 1] ----------------------------------------


def _kernel(error: Array, sigma: Array) -> Array:
    return jnp.exp(-error / jnp.square(sigma))


def _sigma(who: str, sigma: float) -> Array:
    return checks.number(who, "sigma", sigma, 0.0, open_low=True)


def anchor_position_tracking(ref: Motion, sigma: float = 0.3) -> Partial:
    """Reward in (0, 1]: exp(-|p - p_ref|^2 / sigma^2), p the anchor's world position (m);
    sigma in m."""
    return Partial(_anchor_position, ref, _sigma("anchor_position_tracking", sigma))


def _anchor_position(ref, sigma, model, state, action, next_state) -> Array:
    pos = next_state.data.xpos[ref.bodies[ref.anchor]]
    return _kernel(jnp.sum(jnp.square(pos - _reference(ref, next_state)[0][ref.anchor])), sigma)


def anchor_orientation_tracking(ref: Motion, sigma: float = 0.4) -> Partial:
    """Reward in (0, 1]: exp(-angle^2 / sigma^2), angle (rad) between the anchor's world
    orientation and the reference's; sigma in rad."""
    return Partial(_anchor_orientation, ref, _sigma("anchor_orientation_tracking", sigma))


def _anchor_orientation(ref, sigma, model, state, action, next_state) -> Array:
    quat = next_state.data.xquat[ref.bodies[ref.anchor]]
    return _kernel(jnp.square(quat_angle(quat, _reference(ref, next_state)[1][ref.anchor])), sigma)


def body_position_tracking(ref: Motion, sigma: float = 0.3) -> Partial:
    """Reward in (0, 1]: exp(-mean_b |x_b - x_ref_b|^2 / sigma^2) over the tracked bodies,
    the reference anchored on the robot (`anchored`); sigma in m."""
    return Partial(_body_positions, ref, _sigma("body_position_tracking", sigma))


def body_orientation_tracking(ref: Motion, sigma: float = 0.4) -> Partial:
    """Reward in (0, 1]: exp(-mean_b angle_b^2 / sigma^2), angle_b (rad) between body b's
    orientation and the anchored reference's; sigma in rad."""
    return Partial(_body_orientations, ref, _sigma("body_orientation_tracking", sigma))


def body_linear_velocity_tracking(ref: Motion, sigma: float = 1.0) -> Partial:
    """Reward in (0, 1]: exp(-mean_b |v_b - R v_ref_b|^2 / sigma^2), world linear
    velocities of the bodies' origins (m/s), R the anchoring yaw; sigma in m/s."""
    return Partial(_body_velocities, ref, _sigma("body_linear_velocity_tracking", sigma), tree.StaticValue(2))


def body_angular_velocity_tracking(ref: Motion, sigma: float = 3.14) -> Partial:
    """Reward in (0, 1]: exp(-mean_b |w_b - R w_ref_b|^2 / sigma^2), world angular
    velocities (rad/s), R the anchoring yaw; sigma in rad/s."""
    return Partial(_body_velocities, ref, _sigma("body_angular_velocity_tracking", sigma), tree.StaticValue(3))


def _goal(ref: Motion, model, state: State) -> tuple[tuple[Array, ...], tuple[Array, ...]]:
    """(robot, goal): the tracked bodies' (pos, quat, linvel, angvel) in `state`, and the
    reference's at its clock, anchored on the robot (velocities turned by the yaw)."""
    robot = _robot(ref, model, state)
    ref_pos, ref_quat, ref_linvel, ref_angvel = _reference(ref, state)
    a = ref.anchor
    pos, quat, turn = anchored(ref_pos, ref_quat, a, robot[0][a], robot[1][a])
    return robot, (pos, quat, quat_rotate(turn, ref_linvel), quat_rotate(turn, ref_angvel))


def _mean_square(a: Array, b: Array) -> Array:
    """Mean over bodies of the squared distance between rows of a and b [B, 3]."""
    return jnp.mean(jnp.sum(jnp.square(a - b), axis=-1))


def _body_positions(ref, sigma, model, state, action, next_state) -> Array:
    robot, goal = _goal(ref, model, next_state)
    return _kernel(_mean_square(robot[0], goal[0]), sigma)


def _body_orientations(ref, sigma, model, state, action, next_state) -> Array:
    robot, goal = _goal(ref, model, next_state)
    return _kernel(jnp.mean(jnp.square(quat_angle(robot[1], goal[1]))), sigma)


def _body_velocities(ref, sigma, which, model, state, action, next_state) -> Array:
    robot, goal = _goal(ref, model, next_state)
    return _kernel(_mean_square(robot[which.value], goal[which.value]), sigma)


def joint_position_tracking(ref: Motion, sigma: float = 0.5) -> Partial:
    """Reward in (0, 1]: exp(-mean_j (q_j - q_ref_j)^2 / sigma^2) over the tracked joints
    (rad or m); sigma in their units."""
    return Partial(_joint_positions, ref, _sigma("joint_position_tracking", sigma))


def _joint_positions(ref, sigma, model, state, action, next_state) -> Array:
    index = clock(ref, next_state)[2]
    error = next_state.data.qpos[ref.joint_qpos] - ref.clips.qpos[index, ref.joint_qpos]
    return _kernel(jnp.mean(jnp.square(error)), sigma)


# --- terminations -----------------------------------------------------------------------


def anchor_height_deviation(ref: Motion, max_error: float = 0.25) -> Partial:
    """Termination: the anchor's height differs from the reference's by more than
    `max_error` (m; the task's parameter ``max_height_error``)."""
    max_error = checks.number("anchor_height_deviation", "max_error", max_error, 0.0, open_low=True)
    return Partial(_anchor_height, ref, max_height_error=max_error)  # a keyword: a named leaf


def _anchor_height(ref, model, state, max_height_error) -> Array:
    z = state.data.xpos[ref.bodies[ref.anchor], 2]
    return jnp.abs(z - _reference(ref, state)[0][ref.anchor, 2]) > max_height_error


def anchor_orientation_deviation(ref: Motion, max_error: float = 0.8) -> Partial:
    """Termination: the z component of gravity's direction in the anchor's frame differs
    from the reference's by more than `max_error` (in [0, 2]; BeyondMimic's 0.8: a
    tilt difference of about 37 degrees from upright; the parameter ``max_tilt_error``)."""
    max_error = checks.number("anchor_orientation_deviation", "max_error", max_error, 0.0, 2.0, open_low=True)
    return Partial(_anchor_orientation_deviation, ref, max_tilt_error=max_error)


def _anchor_orientation_deviation(ref, model, state, max_tilt_error) -> Array:
    up = state.data.xmat[ref.bodies[ref.anchor], 2, 2]  # -gravity_z in the anchor frame
    ref_up = _matrix(_reference(ref, state)[1][ref.anchor])[2, 2]
    return jnp.abs(up - ref_up) > max_tilt_error


def body_height_deviation(
    ref: Motion, mj_model: mujoco.MjModel, bodies: Sequence[str], max_error: float = 0.25
) -> Partial:
    """Termination: any of the named tracked `bodies` (e.g. the feet and hands) is more
    than `max_error` (m, the parameter ``max_body_height_error``) above or below its
    reference height."""
    who = "body_height_deviation"
    tracked = [mj_model.body(int(i)).name for i in np.asarray(ref.bodies)]
    missing = [b for b in bodies if b not in tracked]
    if missing or not bodies:
        raise ValueError(f"{who}: bodies {list(bodies)} must be some of the tracked bodies {tracked}")
    rows = jnp.asarray([tracked.index(b) for b in bodies], jnp.int32)
    max_error = checks.number(who, "max_error", max_error, 0.0, open_low=True)
    return Partial(_body_height, ref, rows, max_body_height_error=max_error)


def _body_height(ref, rows, model, state, max_body_height_error) -> Array:
    z = state.data.xpos[ref.bodies[rows], 2]
    return jnp.any(jnp.abs(z - _reference(ref, state)[0][rows, 2]) > max_body_height_error)


# --- the clip's end -------------------------------------------------------------------


def with_clip_end(task: Task, motion: Motion) -> Task:
    """Truncates the episode when the reference reaches its clip's last frame: the clip
    is done, which is success, not failure (``terminated`` stays the task's). Keeps no
    record."""
    if not isinstance(motion, Motion):
        raise TypeError(f"with_clip_end: motion must be a tracking.Motion, got {type(motion).__name__}")
    return task.replace(terminate=Partial(_clip_end, task.terminate, motion))


def _clip_end(terminate_fn, ref: Motion, model, state: State) -> tuple[Array, Array]:
    terminated, truncated = terminate_fn(model, state)
    clip, frame, _ = clock(ref, state)
    done = frame >= ref.clips.length[clip] - 1
    terminated = jnp.asarray(terminated, bool)
    return terminated, (jnp.asarray(truncated, bool) | done) & ~terminated
