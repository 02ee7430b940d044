"""Joystick: Brax's ant follows random velocity commands under pushes, action latency,
observation noise and randomized friction and masses, with a curriculum.

One `mjzoo.task` of catalog items, its combinators innermost first (docs/catalog.md's
nesting order), the reward terms and terminations around them:

  the ant (`locomotion.at_pose`, 0.05 s control steps), reset with joint noise and a random
  heading; action latency U{0, 1} steps; the action history (for the action rate); a
  velocity command [vx, vy, yaw rate] ~ U(+-1 m/s, +-1 m/s, +-1 rad/s), stand still with
  probability 0.1, redrawn every 5-10 s and appended to the observation; observation
  noise; randomized friction (x U(0.5, 1.5)) and link masses
  (x U(0.8, 1.2)) per episode; velocity pushes of up to `push` m/s every 5-10 s; the
  divergence guard and the time limit.

Observation (29,): projected gravity (3), base height (1), base linear and angular
velocity in the base frame (3 + 3), hinge positions and velocities (8 + 8), the next
command (3), plus N(0, noise^2) noise.
Action (8,) in [-1, 1]: PD joint targets, Brax's pose + 0.5 rad x action (kp 200 N m/rad,
kd 15 N m s/rad). With torque actions PPO learned only to stand still (curves in
benchmarks/results/locomotion/ant_joystick_torque/); with targets it tracks commands.
Reward terms (weights): linear velocity tracking exp(-|v_xy - c_xy|^2 / 0.25) (1.0),
progress along the command min(v_xy . c_xy / |c_xy|, |c_xy|) (2.0; under the exp kernel
alone aimless steps earn less than standing still),
yaw-rate tracking exp(-(w_z - c_yaw)^2 / 0.25) (0.5), vertical velocity^2 (-0.5),
roll/pitch rate^2 (-0.05), action rate^2 (-0.01), effort (-0.02).
Terminated when the torso tilts over 1.2 rad or drops below 0.2 m; 500 steps (25 s).

`joystick(level=...)` is the task at a fixed difficulty: pushes and noise scale with the
level in [0, 1]. `joystick_curriculum()` trains through the levels: each environment's
level rises by 0.1 after an episode that lasted 80% of its steps and falls by 0.05
otherwise (`curriculum.by_episode_length`).
"""

from __future__ import annotations

import functools
from typing import Any
from typing import Callable

from jax.tree_util import Partial

import mjzoo
from mjzoo.builder import named
from mjzoo.catalog import actuators
from mjzoo.catalog import commands
from mjzoo.catalog import curriculum
from mjzoo.catalog import events
from mjzoo.catalog import observations
from mjzoo.catalog import randomizers
from mjzoo.catalog import resets
from mjzoo.catalog import rewards
from mjzoo.catalog import terminations
from mjzoo.catalog import trackers
from mjzoo.combinators import with_auto_reset
from mjzoo.envs import base
from mjzoo.envs.locomotion import MJX_OPTIONS
from mjzoo.envs.locomotion import actuated_pose
from mjzoo.envs.locomotion import at_pose
from mjzoo.envs.locomotion import reset_pose
from mjzoo.perturbations import with_domain_randomization
from mjzoo.perturbations import with_observation_noise
from mjzoo.types import Task

__all__ = ["joystick", "joystick_curriculum", "JOYSTICK", "PPO"]

# PPO hyperparameters (`mjzoo train ppo ant_joystick`; the benchmark trains the
# curriculum), after MuJoCo Playground's for its quadruped joysticks.
PPO = dict(
    num_envs=4096,
    unroll_length=40,
    num_minibatches=32,
    num_epochs=4,
    learning_rate=3e-4,
    entropy_coef=1e-2,
    discount=0.97,
    clip_epsilon=0.3,
    max_grad_norm=1.0,
    policy_hidden_sizes=(128,) * 4,
    value_hidden_sizes=(256,) * 5,
    activation="swish",
    total_steps=100_000_000,
)


def joystick(
    *,
    level: float = 1.0,
    episode_steps: int = 500,
    push: float = 0.5,
    noise: float = 0.05,
    max_action_latency: int = 1,
    tracking_weight: float = 1.0,
    tracking_sigma: float = 0.25,
    progress_weight: float = 2.0,
    yaw_tracking_weight: float = 0.5,
    vertical_weight: float = 0.5,
    roll_pitch_weight: float = 0.05,
    action_rate_weight: float = 0.01,
    effort_weight: float = 0.02,
    ctrl_dt: float = 0.05,
    kp: float = 200.0,
    kd: float = 15.0,
    action_scale: float = 0.5,
    actuator: Callable | None = None,
    **physics_options: Any,
) -> Task:
    """The joystick task at curriculum `level` in [0, 1] (pushes of up to level * push
    m/s, observation noise of level * noise). Actions are PD joint targets
    (`actuators.pd`: Brax's pose + `action_scale` x action rad, gains `kp` N m/rad and
    `kd` N m s/rad, torques up to the motors' 150 N m); `actuator` replaces that with
    any catalog actuator built on the ant's model."""
    physics = base.brax_asset("ant.xml", **{**MJX_OPTIONS, "ctrl_dt": ctrl_dt, **physics_options})
    m = physics.mj_model
    actuator = actuator or actuators.pd(m, kp, kd, action_scale=action_scale, default_pose=actuated_pose(m))
    observe = observations.concat(
        observations.projected_gravity(m),
        observations.base_height(m),
        observations.base_linear_velocity(m),
        observations.base_angular_velocity(m),
        observations.joint_positions,
        observations.joint_velocities,
    )
    jitter = (
        named(resets.joint_position_noise(m, 0.1), "reset_noise"),
        named(resets.joint_velocities(m, 0.1), "reset_noise"),
    )
    physics_draw = randomizers.combine(randomizers.scale_friction(m, 0.5, 1.5), randomizers.scale_masses(m, 0.8, 1.2))
    # Innermost first (docs/catalog.md's order); the terms below see the states they make.
    layers = (
        functools.partial(actuators.with_action_latency, max_latency=max_action_latency),
        functools.partial(trackers.with_action_history, length=2),
        functools.partial(
            commands.with_velocity_command,
            vx=(-1.0, 1.0),
            vy=(-1.0, 1.0),
            yaw_rate=(-1.0, 1.0),
            resample_interval=(5.0, 10.0),
            stand_probability=0.1,
        ),
        functools.partial(with_observation_noise, scale=level * noise),
        functools.partial(with_domain_randomization, randomize=physics_draw),
        functools.partial(events.with_velocity_pushes, interval=(5.0, 10.0), linear=(level * push, level * push, 0.0)),
    )
    return mjzoo.task(
        physics,
        observe=observe,
        start=at_pose,
        resets=(*jitter, resets.base_heading(m)),
        actuator=actuator,
        combinators=layers,
        rewards={
            "tracking": (named(rewards.linear_velocity_tracking(m, tracking_sigma), "tracking_sigma"), tracking_weight),
            "progress": (rewards.command_progress(m), progress_weight),
            "yaw_tracking": (
                named(rewards.angular_velocity_tracking(m, tracking_sigma), "tracking_sigma"),
                yaw_tracking_weight,
            ),
        },
        costs={
            "vertical": (rewards.vertical_velocity(m), vertical_weight),
            "roll_pitch": (rewards.roll_pitch_velocity(m), roll_pitch_weight),
            "action_rate": (Partial(rewards.action_rate), action_rate_weight),
            "effort": (Partial(rewards.effort), effort_weight),
        },
        terminate={
            "tilted": named(terminations.not_upright(m, 1.2), "max_tilt"),
            "too_low": named(terminations.base_too_low(m, 0.2), "min_height"),
        },
        time_limit=episode_steps,
        params={"qpos0": reset_pose(m)},
    )


def joystick_curriculum(rule: curriculum.Rule | None = None, **overrides: Any) -> Task:
    """`joystick` with each environment's level moved by `rule` (default: by its episode
    lengths, from 0); auto-resets inside, so the level survives episode ends."""
    steps = overrides.get("episode_steps", 500)
    rule = rule or curriculum.by_episode_length(steps, fraction=0.8, up=0.1, down=0.05)

    def at(level: float) -> Task:
        return with_auto_reset(joystick(level=level, **overrides))

    return curriculum.with_curriculum(at, rule)


JOYSTICK = base.EnvSpec(
    make=joystick, description="Brax's ant following velocity commands under pushes and noise", ppo=PPO
)
