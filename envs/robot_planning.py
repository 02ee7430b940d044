"""Whole-body MPC tasks on real robots: the Unitree G1 stands up from lying on its back,
and the Unitree Go1 trots at a commanded speed. Their rewards are dense and smooth, made
for sampling planners (`PLANNING`: ``mjzoo plan mppi g1_standup``); PPO trains on them
as on any task.

    task = robot_planning.g1_standup()
    task = robot_planning.go1_trot(speed=0.6)

`g1_standup` runs on Menagerie's MJX G1 (``unitree_g1/scene_mjx.xml``: contact pairs of
the pelvis, head, hips, thighs, shins, arms and hands with the floor, which a robot
getting up needs; Playground's joystick scenes collide with the feet alone). It starts
on its back in the standing keyframe's joint pose (noise U(+-0.1 rad), a random
heading), 0.3 m above the floor. Its servos are driven to ``stand + 1.5 * action``
(rad; the G1's kp, kv and force limits, clipped to their ranges). Reward terms
(weights): the torso's upright cosine (2.0); costs: the pelvis's height below the
standing height, squared (20.0), joint deviation from the standing pose (0.1), action
rate (0.01). No termination: lying is where it starts. 5 s episodes. Solved when the
pelvis stays within 0.1 m of standing height over the last second.

`go1_trot` runs on Playground's Go1 scene (feet-only collisions). It starts in the home
keyframe (joint noise U(+-0.05 rad)) with a constant command [speed, 0, 0]. Servos go to
``home + 0.5 * action``. Reward terms (weights): velocity tracking
exp(-|v_xy - c_xy|^2 / 0.25) (1.0), yaw-rate tracking (0.5); costs: a trot's foot
heights (each diagonal pair swings 0.08 m high in turn, 0.5 s a cycle; squared error,
m^2) (50.0), tilt sin^2 (5.0), base height from home's (10.0), vertical velocity^2
(1.0), action rate (0.01). Terminated when tilted over 1 rad or the base drops below
0.12 m; 10 s episodes. Solved when the mean forward speed over the last 2 s is within
0.15 m/s of the command and it never fell.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial

import mjzoo
from mjzoo import names
from mjzoo import physics as physics_lib
from mjzoo.builder import named
from mjzoo.catalog import actuators
from mjzoo.catalog import commands
from mjzoo.catalog import observations
from mjzoo.catalog import resets
from mjzoo.catalog import rewards
from mjzoo.catalog import terminations
from mjzoo.catalog import trackers
from mjzoo.envs import base
from mjzoo.envs import robot_joystick
from mjzoo.envs.locomotion import at_pose
from mjzoo.layers import find
from mjzoo.robots import models
from mjzoo.robots import scenes
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["g1_standup", "go1_trot", "trot_foot_heights", "G1_STANDUP", "GO1_TROT"]

Array = jax.Array

# --- G1 standup ---------------------------------------------------------------------------


@functools.lru_cache(maxsize=4)
def _g1_full_contact(options: tuple[tuple[str, Any], ...]) -> tuple[physics_lib.Physics, np.ndarray]:
    """(Menagerie's MJX G1 scene at a 0.02 s control step, the standing qpos [nq] from
    Playground's G1 keyframe: Menagerie's MJX model has none)."""
    path = models.menagerie("unitree_g1") / "scene_mjx.xml"
    physics = physics_lib.load(path, **{"ctrl_dt": 0.02, **dict(options)})
    stand = scenes.spec("g1").compile()  # its keyframe alone: no MJX model built
    if stand.nq != physics.mj_model.nq or stand.nu != physics.mj_model.nu:
        raise ValueError(f"g1_standup: {path} and Playground's G1 scene differ in their joints or actuators")
    return physics, np.asarray(stand.key_qpos[0], np.float32)


def on_its_back(mj_model: mujoco.MjModel, height: float = 0.3) -> resets.ResetItem:
    """Reset item: the base turned pitch -90 degrees about its own y axis (lying on its
    back, facing up) at `height` m; the joints and heading are left to other items."""
    qpos_idx = jnp.asarray(names.free_joint_addresses(mj_model, None, "on_its_back")[0])
    half = -math.pi / 4  # half of -90 degrees
    quat = jnp.asarray([math.cos(half), 0.0, math.sin(half), 0.0], jnp.float32)
    return Partial(_on_its_back, qpos_idx, quat, jnp.float32(height))


def _on_its_back(qpos_idx, quat, height, model, data, key):
    qpos = data.qpos.at[qpos_idx[2]].set(height).at[qpos_idx[3:]].set(quat)
    return data.replace(qpos=qpos)


def g1_standup(*, episode_steps: int = 250, action_scale: float = 1.5, **physics_options: Any) -> Task:
    """The Unitree G1 getting up from its back (module docstring); physics options
    override the scene's."""
    physics, stand = _g1_full_contact(tuple(sorted(physics_options.items())))
    m = physics.mj_model
    joints = stand[7:]
    return mjzoo.task(
        physics,
        observe=observations.concat(
            observations.base_angular_velocity(m),
            observations.projected_gravity(m),
            observations.base_height(m),
            observations.joint_positions,
            observations.joint_velocities,
        ),
        start=at_pose,
        resets=(
            named(resets.joint_position_noise(m, 0.1), "reset_noise"),
            on_its_back(m),
            resets.base_heading(m),
        ),
        actuator=actuators.position_targets(m, action_scale, default_pose=joints),
        combinators=(functools.partial(trackers.with_action_history, length=2, observe=True),),
        rewards={
            "upright": (Partial(_torso_upright, jnp.int32(names.index(m, "body", "torso_link", "g1_standup"))), 2.0)
        },
        costs={
            "height": (rewards.base_height(m, float(stand[2])), 20.0),
            "posture": (rewards.joint_deviation(m, pose=joints), 0.1),
            "action_rate": (Partial(rewards.action_rate), 0.01),
        },
        time_limit=episode_steps,
        params={"qpos0": jnp.asarray(stand)},
    )


def _torso_upright(torso, model, state: State, action: Array, next_state: State) -> Array:
    """Reward in [-1, 1]: cos of the angle between the torso's z axis and the world's
    (`rewards.upright` reads a floating base; the torso sits above the waist joints)."""
    return next_state.data.xmat[torso, 2, 2]


def _stood_up(states) -> tuple[bool, float]:
    """Solved when the pelvis stays within 0.1 m of the standing height over the last
    second; the score is the largest miss (m)."""
    stand_z = float(_g1_full_contact(())[1][2])
    return base.held_near(states, lambda s: np.asarray(s.data.qpos[..., 2]) - stand_z, 0.1)


# Sampling planners: 1024 samples over 0.5 s (25 control steps), replanning every step.
G1_PLANNING = base.sampling_setup(5.0, _stood_up, horizon_steps=25, num_knots=4, noise_scale=0.5)
G1_STANDUP = base.EnvSpec(
    make=g1_standup, description="Unitree G1 standing up from lying on its back (MPC-friendly)", planning=G1_PLANNING
)

# --- Go1 trot -----------------------------------------------------------------------------

GO1_FEET = ("FR", "FL", "RR", "RL")
TROT_PAIRS = jnp.asarray([0, 1, 1, 0])  # FR and RL swing together, then FL and RR


def trot_foot_heights(time: Array, period: float, clearance: float, ground: float) -> Array:
    """[4] target heights (m) of the feet FR, FL, RR, RL at `time` (s) in a trot of
    `period` s: in each half cycle one diagonal pair swings along ``ground + clearance *
    sin(pi * s)`` (s in [0, 1] through the half) while the other stands at `ground`."""
    phase = jnp.mod(time / period, 1.0)
    swinging = jnp.where(phase < 0.5, 0, 1)
    lift = clearance * jnp.sin(jnp.pi * jnp.mod(2.0 * phase, 1.0))
    return ground + jnp.where(TROT_PAIRS == swinging, lift, 0.0)


def trot_gait(mj_model: mujoco.MjModel, period: float = 0.5, clearance: float = 0.08) -> Partial:
    """Cost: sum over the Go1's feet (spheres) of (centre height - `trot_foot_heights`)^2
    (m^2), a standing foot's centre one radius above the floor."""
    ids = names.ids(mj_model, "geom", GO1_FEET, "trot_gait")
    ground = float(np.mean(mj_model.geom_size[ids, 0]))
    return Partial(_trot_gait, jnp.asarray(ids, jnp.int32), *(jnp.float32(x) for x in (period, clearance, ground)))


def _trot_gait(ids, period, clearance, ground, model, state: State, action: Array, next_state: State) -> Array:
    target = trot_foot_heights(next_state.data.time, period, clearance, ground)
    return jnp.sum(jnp.square(next_state.data.geom_xpos[ids, 2] - target))


def go1_trot(*, speed: float = 0.5, episode_steps: int = 500, **physics_options: Any) -> Task:
    """The Unitree Go1 trotting forward at `speed` m/s (module docstring); physics options
    override the scene's."""
    if not math.isfinite(speed):
        raise ValueError(f"go1_trot: speed must be finite, got {speed!r}")
    physics = robot_joystick._scene("go1", "flat", tuple(sorted(physics_options.items())))[0]  # the joystick's compile
    m = physics.mj_model
    command = functools.partial(commands.with_velocity_command, vx=(speed, speed), vy=(0.0, 0.0), yaw_rate=(0.0, 0.0))
    return mjzoo.task(
        physics,
        observe=observations.concat(
            observations.base_angular_velocity(m),
            observations.projected_gravity(m),
            observations.base_linear_velocity(m),
            observations.joint_positions,
            observations.joint_velocities,
        ),
        start=at_pose,
        resets=(named(resets.joint_position_noise(m, 0.05), "reset_noise"),),
        actuator=actuators.position_targets(m, 0.5),
        combinators=(functools.partial(trackers.with_action_history, length=2, observe=True), command),
        rewards={
            "tracking": (rewards.linear_velocity_tracking(m, 0.25), 1.0),
            "yaw_tracking": (rewards.angular_velocity_tracking(m, 0.25), 0.5),
        },
        costs={
            "gait": (trot_gait(m), 50.0),
            "tilt": (rewards.flat_orientation(m), 5.0),
            "height": (rewards.base_height(m, float(m.key_qpos[0][2])), 10.0),
            "vertical": (rewards.vertical_velocity(m), 1.0),
            "action_rate": (Partial(rewards.action_rate), 0.01),
        },
        terminate={
            "tilted": named(terminations.not_upright(m, 1.0), "max_tilt"),
            "too_low": named(terminations.base_too_low(m, 0.12), "min_height"),
        },
        time_limit=episode_steps,
        params={"qpos0": jnp.asarray(m.key_qpos[0], jnp.float32)},
    )


def _trots(states) -> tuple[bool, float]:
    """Solved when it never fell and its mean forward speed over the last 2 s is within
    0.15 m/s of the command; the score is that speed's miss (m/s)."""
    time = np.asarray(states.data.time)
    last = time >= time[-1] - 2.0 + 1e-6
    speed = float(np.mean(np.asarray(states.data.qvel[..., 0])[last]))
    miss = abs(speed - float(np.asarray(find(states, commands.VelocityCommandState).command)[-1, 0]))
    return (not bool(np.any(states.terminated))) and miss <= 0.15, miss


GO1_PLANNING = base.sampling_setup(6.0, _trots, horizon_steps=25, num_knots=5, noise_scale=0.5, dial_iterations=4)
GO1_TROT = base.EnvSpec(
    make=go1_trot, description="Unitree Go1 trotting at a commanded speed (MPC-friendly)", planning=GO1_PLANNING
)
