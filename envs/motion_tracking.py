"""Whole-body motion tracking: a robot plays reference clips body by body (BeyondMimic's
recipe), one policy for several clips; `g1_track` on the Unitree G1 and its committed
clips (``envs/assets/motions/g1/*.npz``, retargeted from DeepMimic's by
``scripts/retarget_g1.py``).

    task = motion_tracking.g1_track()                        # every committed clip
    task = motion_tracking.g1_track(clips=("walk",))         # one
    task = motion_tracking.motion_tracking(physics, clips, motion_tracking.Tracked(bodies, anchor))  # any robot

One `mjzoo.task` of catalog items (`mjzoo.catalog.tracking`, `start_sampling`), innermost
first: the robot put on the reference at a start drawn from the adaptive table
(reference-state initialization; its clock is ``data.time``); its own ``<position>``
servos driven to ``pose + action_scale * action``; the last action kept (action rate,
and observed); the episode truncated when the clip ends (success) and terminated when
the anchor's height or tilt, or an end effector's height, leaves the reference's;
auto-reset; then the adaptive sampler, which moves the starts toward where episodes fail
and reports MPJPE and per-clip success (`start_sampling`, `start_sampling.summary`).

Observation (flat): the pelvis's angular velocity (3), projected gravity (3) and linear
velocity (3), joint positions and velocities (2 x J), the motion command (clip one-hot,
phase, the next frame's joint positions and velocities, the reference anchor's position
and orientation in the robot anchor's frame: C + 1 + 2 J + 9), the last action (nu).
Reward terms (weights, BeyondMimic's; sigmas as `tracking`'s defaults): anchor position
(0.5) and orientation (0.5), body positions (1.0), orientations (1.0), linear (1.0) and
angular (1.0) velocities relative to the anchor, joint positions (0.5); costs: action
rate (0.1), joint limits past 90% (10.0).

`PLANNING` tracks the same clips by sampling MPC on that reward: ``mjzoo view g1_track
--planner mppi --trace imu_in_pelvis left_foot right_foot left_palm right_palm`` draws
the plan as the paths of the pelvis, feet and hands.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any
from typing import Sequence

import numpy as np
from jax.tree_util import Partial

import mjzoo
from mjzoo import motion
from mjzoo import physics as physics_lib
from mjzoo.catalog import actuators
from mjzoo.catalog import observations
from mjzoo.catalog import rewards
from mjzoo.catalog import start_sampling
from mjzoo.catalog import trackers
from mjzoo.catalog import tracking
from mjzoo.combinators import with_auto_reset
from mjzoo.envs import base
from mjzoo.robots import scenes
from mjzoo.types import Task

__all__ = ["Tracked", "motion_tracking", "g1_track", "g1_clips", "G1", "G1_CLIPS", "G1_TRACK", "PPO", "PLANNING"]

MOTIONS = base.ASSETS / "motions" / "g1"
G1_CLIPS = tuple(sorted(p.stem for p in MOTIONS.glob("*.npz")))  # the committed clips


@dataclasses.dataclass(frozen=True)
class Tracked:
    """What tracking needs to know of a robot besides its model."""

    bodies: tuple[str, ...]  # the tracked bodies
    anchor: str  # one of them: the reference is moved onto it
    end_effectors: tuple[str, ...] = ()  # some of them: terminated 0.25 m off their reference height


# BeyondMimic's G1 bodies: pelvis, legs, torso (the anchor), arms; its end effectors the feet and hands.
G1 = Tracked(
    bodies=(
        "pelvis",
        "left_hip_roll_link",
        "left_knee_link",
        "left_ankle_roll_link",
        "right_hip_roll_link",
        "right_knee_link",
        "right_ankle_roll_link",
        "torso_link",
        "left_shoulder_roll_link",
        "left_elbow_link",
        "left_wrist_yaw_link",
        "right_shoulder_roll_link",
        "right_elbow_link",
        "right_wrist_yaw_link",
    ),
    anchor="torso_link",
    end_effectors=("left_ankle_roll_link", "right_ankle_roll_link", "left_wrist_yaw_link", "right_wrist_yaw_link"),
)
# PPO after BeyondMimic's (4096 envs, 24-step rollouts, 4 minibatches x 5 epochs, 512-256-128 ELU networks,
# learning rate 1e-3 with the KL-adaptive schedule at 0.01, entropy 5e-3, discount 0.99, lambda 0.95).
PPO = dict(
    num_envs=4096,
    unroll_length=24,
    num_minibatches=4,
    num_epochs=5,
    learning_rate=1e-3,
    target_kl=0.01,
    entropy_coef=5e-3,
    discount=0.99,
    gae_lambda=0.95,
    clip_epsilon=0.2,
    max_grad_norm=1.0,
    policy_hidden_sizes=(512, 256, 128),
    value_hidden_sizes=(512, 256, 128),
    activation="elu",
    total_steps=200_000_000,
)


@functools.lru_cache(maxsize=4)
def _g1(options: tuple[tuple[str, Any], ...]) -> physics_lib.Physics:
    return scenes.load("g1", **{"ctrl_dt": 0.02, **dict(options)})


def g1_clips(names: Sequence[str] = G1_CLIPS) -> list[motion.Clip]:
    """The committed G1 clips `names`, checked against the G1's model; ValueError
    listing them for an unknown name."""
    if isinstance(names, str) or not names or any(n not in G1_CLIPS for n in names):
        raise ValueError(f"g1_clips: clips={names!r} must be a non-empty list of {list(G1_CLIPS)}")
    model = _g1(()).mj_model
    return [motion.load(MOTIONS / f"{n}.npz", model) for n in names]


def motion_tracking(
    physics: physics_lib.Physics,
    clips: Sequence[motion.Clip],
    robot: Tracked,
    *,
    action_scale: float = 0.5,
    episode_steps: int = 500,
    bin_seconds: float = 0.25,
    adaptive_uniform: float = 0.1,
) -> Task:
    """Tracking of `clips` (of `physics`'s model, each played once) by a robot with
    ``<position>`` servos whose bodies `robot` names: the module docstring's task,
    auto-resetting, with the adaptive sampler outside; `episode_steps` caps an episode (a long clip's), `bin_seconds` and
    `adaptive_uniform` are the sampler's bin width and floor."""
    m = physics.mj_model
    ctrl_dt = float(m.opt.timestep) * physics.n_substeps
    ref = tracking.motion(motion.reference(clips, m, dt=ctrl_dt, loop=False), m, robot.bodies, robot.anchor)
    ends = {}
    if robot.end_effectors:
        ends["end_effector_height"] = tracking.body_height_deviation(ref, m, robot.end_effectors, 0.25)
    task = mjzoo.task(
        physics,
        observe=observations.concat(
            observations.base_angular_velocity(m),
            observations.projected_gravity(m),
            observations.base_linear_velocity(m),
            observations.joint_positions,
            observations.joint_velocities,
            tracking.motion_command(ref),
        ),
        resets=(start_sampling.reference_start(ref, bin_seconds),),
        actuator=actuators.position_targets(m, action_scale),
        combinators=(
            functools.partial(trackers.with_action_history, length=2, observe=True),
            functools.partial(tracking.with_clip_end, motion=ref),
        ),
        rewards={
            "anchor_position": (tracking.anchor_position_tracking(ref), 0.5),
            "anchor_orientation": (tracking.anchor_orientation_tracking(ref), 0.5),
            "body_position": (tracking.body_position_tracking(ref), 1.0),
            "body_orientation": (tracking.body_orientation_tracking(ref), 1.0),
            "body_linear_velocity": (tracking.body_linear_velocity_tracking(ref), 1.0),
            "body_angular_velocity": (tracking.body_angular_velocity_tracking(ref), 1.0),
            "joint_position": (tracking.joint_position_tracking(ref), 0.5),
        },
        costs={
            "action_rate": (Partial(rewards.action_rate), 0.1),
            "joint_limits": (rewards.joint_limits(m, 0.9), 10.0),
        },
        terminate={
            "anchor_height": tracking.anchor_height_deviation(ref, 0.25),
            "anchor_orientation": tracking.anchor_orientation_deviation(ref, 0.8),
            **ends,
        },
        time_limit=episode_steps,
    )
    return start_sampling.with_adaptive_starts(with_auto_reset(task), ref, bin_seconds, uniform=adaptive_uniform)


def g1_track(
    *,
    clips: Sequence[str] | str | None = None,
    action_scale: float = 0.5,
    episode_steps: int = 500,
    bin_seconds: float = 0.25,
    adaptive_uniform: float = 0.1,
    **physics_options: Any,
) -> Task:
    """The Unitree G1 tracking its committed clips `clips` (names, or one string of them
    separated by commas; default: all of `G1_CLIPS`) at a 0.02 s control step
    (`motion_tracking`); physics options override the scene's."""
    clips = G1_CLIPS if clips is None else tuple(clips.split(",")) if isinstance(clips, str) else tuple(clips)
    physics = _g1(tuple(sorted(physics_options.items())))
    settings = dict(action_scale=action_scale, episode_steps=episode_steps, bin_seconds=bin_seconds)
    return motion_tracking(physics, g1_clips(clips), G1, adaptive_uniform=adaptive_uniform, **settings)


def _tracked_well(states) -> tuple[bool, float]:
    """Solved when no step terminated (anchor or end effectors off the reference) and the
    bodies' mean position error (MPJPE) stayed within 50 mm; the score is that mean (mm)."""
    mpjpe = float(np.mean(states.metrics["tracking/mpjpe_mm"]))
    return (not bool(np.any(states.terminated))) and mpjpe <= 50.0, mpjpe


# Tracking MPC (`mjzoo plan mppi g1_track`, `mjzoo view g1_track --planner mppi`): the
# planners maximize the task's own tracking reward over 0.5 s, 4 knots, replanning every
# control step; a rollout that terminates counts no reward after it.
_SAMPLING = dict(num_samples=1024, horizon_steps=25, num_knots=4)
PLANNING = base.PlanningSetup(
    seconds=4.0,
    replan_every=1,
    plan_overrides={},
    success=_tracked_well,
    configs={
        "predictive_sampling": _SAMPLING,
        "mppi": _SAMPLING,
        "cem": dict(_SAMPLING, num_elites=64),
        "dial": dict(_SAMPLING, iterations=2),
        "cma_es": dict(_SAMPLING, num_elites=64),
    },
)

G1_TRACK = base.EnvSpec(
    make=g1_track,
    description="Unitree G1 tracking its motion clips (clips=walk,run: some)",
    ppo=PPO,
    planning=PLANNING,
)
