"""Brax's humanoid taught to walk by a motion prior (AMP): tasks, their reference, a style measure.

The reference is a walk recorded from a teacher, the deterministic PPO policy that
solved `humanoid_walk` (return 6793, 1.9 m/s): ``assets/humanoid_walk_ppo.npz``, 601
frames (9 s) at its control step, 0.015 s, cut from step 200 of one episode (past the
start from rest). The tasks pay no forward velocity: what makes the humanoid walk, and
walk like the teacher, is AMP's style reward.

    task = humanoid_amp.humanoid_amp_walk()
    reference = humanoid_amp.reference(task)          # the walk, at the task's control step
    config, hyperparams = amp.configure(**humanoid_amp.AMP)
    state, _ = amp.train(config, task, reference, hyperparams, jax.random.key(0))
    qpos = ...                                        # [T, nq] of a deterministic episode
    humanoid_amp.style_error(reference, qpos)         # rad; < STYLE_THRESHOLD: the teacher's style
    humanoid_amp.forward_speed(qpos, reference.dt)    # m/s; the teacher walks at 1.9

| task | reward terms (weight) | observation | notes |
|---|---|---|---|
| humanoid_amp_walk | alive 1, effort -0.01 | `humanoid_walk`'s (45) | AMP: task_weight 0.1, style 1 |
| humanoid_amp_joystick | + forward speed tracking 1, yaw-rate tracking 0.5 | + command (3) | AMP: task 0.5, style 0.5 |

Both are `humanoid_walk`'s model and physics (humanoid.xml, Brax's MJX settings, 5 x
3 ms per control step), its observation, fall (torso below 1 m), divergence guard and
1000-step time limit. Episodes start at a reference frame (its qpos and qvel) with
probability `reference_probability` (reference-state initialization), else from the
default pose with joint noise. The joystick's command [vx, 0, yaw rate] ~ U(speed) x
{0} x U(yaw_rate), redrawn every 5-10 s, is tracked with exp kernels
(`rewards.linear_velocity_tracking`, `rewards.angular_velocity_tracking`) in the
torso's frame.

Style. `style_error` is the mean joint-angle error (rad) of the 17 hinges to the
nearest reference window of `STYLE_WINDOW` = 10 frames (0.15 s)
(`motion.measures.nearest_window_error`): the student need not replay the clip in step,
only move, window by window, as some stretch of it does. Measured on whole 1000-step
episodes (15 s, start-up included):

  the teacher's 7 other episodes            0.056 - 0.059  (0.031 - 0.035 past step 200)
  the teacher's first 3 s (start from rest) 0.155 - 0.170
  no torques (collapses in 42 steps)        0.41
  uniform random actions (fall in 19-30)    0.46 - 0.57
  standing still in the reset pose          0.50

`STYLE_THRESHOLD` = 0.15 rad sits between: 2.5 times the teacher's own spread, under
half of anything that is not a walk; even the teacher's start-up does not pass. The
style alone does not tell a walk from marching in place: a student walks in the
teacher's style (`walks_like_teacher`) when its episode does not fall, its style error
is below the threshold and it moves forward at `MIN_SPEED` = 1 m/s or more.

With `AMP` on an H100 (benchmarks/amp.py, style measured past step 200) the student
walked in the teacher's style after 16.4M steps (211 s with compiling) and ended at
0.03 rad and 1.9 m/s, the teacher's own 0.033 rad and 1.95 m/s.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from jax.tree_util import Partial

import mjzoo
from mjzoo import checks
from mjzoo import motion
from mjzoo import physics as physics_lib
from mjzoo.builder import alive
from mjzoo.builder import named
from mjzoo.catalog import commands
from mjzoo.catalog import resets
from mjzoo.catalog import rewards
from mjzoo.catalog import terminations
from mjzoo.envs import base
from mjzoo.envs.locomotion import MJX_OPTIONS
from mjzoo.envs.locomotion import PPO
from mjzoo.envs.locomotion import at_pose
from mjzoo.envs.locomotion import free_base_observation
from mjzoo.envs.locomotion import reset_pose
from mjzoo.types import Task

__all__ = ["humanoid_amp_joystick", "humanoid_amp_walk", "WALK", "JOYSTICK", "walk_reference"]

REFERENCE_PATH = Path(__file__).parent / "assets" / "humanoid_walk_ppo.npz"
STYLE_WINDOW = 10  # frames (0.15 s): about a third of a step
STYLE_THRESHOLD = 0.15  # rad (module docstring)
MIN_SPEED = 1.0  # m/s: a walk, not marching in place
KEY_BODIES = ("left_foot", "right_foot", "left_lower_arm", "right_lower_arm")

# AMP hyperparameters (`mjzoo train amp humanoid_amp_walk`, benchmarks/amp.py): PPO's for
# the humanoid (Brax's; 2048 envs, unrolls of 160) with the reward at its own scale (the
# style reward is in [0, 1] per step) and a discriminator small enough that learning it
# costs little beside the physics (2 x 256, one epoch over each update's windows: 3.7% over
# PPO's time per step on an H100). The joystick's are the walk's with the task reward
# weighted as much as the style; they have not been trained on a GPU yet.
DISCRIMINATOR = dict(
    num_frames=2,
    disc_hidden_sizes=(256, 256),
    disc_epochs=1,
    disc_minibatches=8,
    disc_learning_rate=1e-4,
    gradient_penalty_weight=5.0,
    replay_size=200_000,
)
_AMP = dict(PPO["humanoid_walk"], reward_scaling=1.0, total_steps=40_000_000, key_bodies=KEY_BODIES, **DISCRIMINATOR)
AMP = dict(_AMP, task_weight=0.1, style_weight=1.0)  # alive keeps it up while the style reward is ~0
JOYSTICK_AMP = dict(_AMP, task_weight=0.5, style_weight=0.5, total_steps=100_000_000)


# --- the reference and the style measure ---------------------------------------------


def walk_reference(mj_model: mujoco.MjModel, dt: float) -> motion.Reference:
    """The teacher's walk (`REFERENCE_PATH`), checked against Brax's humanoid `mj_model`
    and resampled to a frame every `dt` s; one clip, not looped (it is not a cycle)."""
    return motion.reference(motion.load(REFERENCE_PATH, mj_model, name="walk"), mj_model, dt, loop=False)


def reference(task: Task, *, ctrl_dt: float = 0.015, **_: Any) -> motion.Reference:
    """The walk AMP imitates on `task` (`humanoid_amp_walk(ctrl_dt=ctrl_dt, ...)` or the
    joystick; the other overrides do not change it): `walk_reference` at `ctrl_dt`.
    The envs' record (`mjzoo.envs.reference`) calls it with the task's overrides."""
    return walk_reference(task.mj_model, ctrl_dt)


def hinge_columns(mj_model: mujoco.MjModel) -> np.ndarray:
    """int [J] the qpos columns of the model's hinge joints (the humanoid: 17, 7..23)."""
    hinge = mj_model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE
    return np.asarray(mj_model.jnt_qposadr[hinge], np.int64)


def style_error(reference: motion.Reference, qpos, window: int = STYLE_WINDOW) -> float:
    """The mean joint-angle error (rad) of `qpos` to the nearest reference windows.

    Args:
      reference: a `motion.Reference` of Brax's humanoid (`reference(task)`); qpos
        columns 7.. are compared: the 17 hinges past the free root.
      qpos: [T, nq] a simulated episode's positions, T >= `window`.
      window: frames per window.

    Returns:
      `motion.nearest_window_error` of the hinge columns: the average over the episode's
      windows of the smallest mean |angle error| to a window of the reference's frames.
    """
    who = "humanoid_amp.style_error"
    if not isinstance(reference, motion.Reference):
        raise TypeError(
            f"{who}: reference must be a motion.Reference (humanoid_amp.reference(task)), "
            f"got {type(reference).__name__}"
        )
    ref = np.asarray(reference.qpos)
    qpos = np.asarray(qpos, np.float64)
    if qpos.ndim != 2 or qpos.shape[1] != ref.shape[1]:
        raise ValueError(f"{who}: qpos has shape {qpos.shape}; expected [T, nq={ref.shape[1]}]")
    return motion.nearest_window_error(ref, qpos, np.arange(7, ref.shape[1]), window)


def forward_speed(qpos, dt: float) -> float:
    """The root's mean forward (world +x) speed (m/s) over `qpos` [T, nq] (T >= 2), a
    frame every `dt` s (the control step; its reference's ``reference.dt``)."""
    qpos = np.asarray(qpos, np.float64)
    if qpos.ndim != 2 or qpos.shape[0] < 2:
        raise ValueError(f"humanoid_amp.forward_speed: qpos has shape {qpos.shape}; expected [T >= 2, nq]")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"humanoid_amp.forward_speed: dt={dt!r} must be a number of seconds > 0")
    return float((qpos[-1, 0] - qpos[0, 0]) / ((qpos.shape[0] - 1) * dt))


def walks_like_teacher(error: float, speed: float, fell: bool) -> bool:
    """Whether an episode with this `style_error` (rad) and `forward_speed` (m/s), which
    fell or not, walks in the teacher's style: no fall, error < `STYLE_THRESHOLD` and
    speed >= `MIN_SPEED`."""
    return (not fell) and error < STYLE_THRESHOLD and speed >= MIN_SPEED


# --- the tasks --------------------------------------------------------------------------


def _humanoid(
    physics: physics_lib.Physics,
    reference: motion.Reference,
    *,
    reference_probability: float,
    reset_noise: float,
    min_height: float,
    episode_steps: int,
    alive_weight: float,
    effort_weight: float,
    rewards_: dict[str, tuple[Any, float]] | None = None,
    combinators: Sequence[Any] = (),
) -> Task:
    """The humanoid started at its pose with joint noise, or (with
    `reference_probability`) at a reference frame, fallen below `min_height` (m), paid
    alive and the `rewards_` terms, charged effort."""
    m = physics.mj_model
    noise = (
        named(resets.joint_position_noise(m, reset_noise), "reset_noise"),
        named(resets.joint_velocities(m, reset_noise), "reset_noise"),
    )
    start = resets.reference_state(reference, reference_probability)
    task = mjzoo.task(
        physics,
        observe=free_base_observation(m),
        start=at_pose,
        resets=(*noise, start),
        combinators=combinators,
        terminate={"too_low": named(terminations.base_too_low(m, min_height, body="torso"), "min_height")},
        rewards={**(rewards_ or {}), "alive": (alive, alive_weight)},
        costs={"effort": (Partial(rewards.effort), effort_weight)},
        time_limit=episode_steps,
        params={"qpos0": reset_pose(m)},
    )
    return task


def _physics(ctrl_dt: float, physics_options: dict[str, Any]) -> physics_lib.Physics:
    return base.brax_asset("humanoid.xml", **{**MJX_OPTIONS, "ctrl_dt": ctrl_dt, **physics_options})


def humanoid_amp_walk(
    *,
    episode_steps: int = 1000,
    alive_weight: float = 1.0,
    effort_weight: float = 0.01,
    min_height: float = 1.0,
    reset_noise: float = 0.01,
    reference_probability: float = 0.7,
    ctrl_dt: float = 0.015,
    **physics_options: Any,
) -> Task:
    """Brax's humanoid free to walk, for AMP (module docstring): reward "alive"
    (`alive_weight` per step not fallen) and effort (-`effort_weight` x sum of squared
    actions), no forward velocity (AMP's reference: `reference`); starts at
    a reference frame with `reference_probability`, else the default pose with
    U(+-`reset_noise`) joint noise; falls when the torso is below `min_height` (m)."""
    physics = _physics(ctrl_dt, physics_options)
    reference = walk_reference(physics.mj_model, physics.ctrl_dt)
    return _humanoid(
        physics,
        reference,
        reference_probability=reference_probability,
        reset_noise=reset_noise,
        min_height=min_height,
        episode_steps=episode_steps,
        alive_weight=alive_weight,
        effort_weight=effort_weight,
    )


def humanoid_amp_joystick(
    *,
    episode_steps: int = 1000,
    speed: Sequence[float] = (0.5, 2.5),
    yaw_rate: Sequence[float] = (-0.5, 0.5),
    resample_interval: Sequence[float] = (5.0, 10.0),
    tracking_weight: float = 1.0,
    yaw_tracking_weight: float = 0.5,
    tracking_sigma: float = 0.25,
    alive_weight: float = 1.0,
    effort_weight: float = 0.01,
    min_height: float = 1.0,
    reset_noise: float = 0.01,
    reference_probability: float = 0.7,
    ctrl_dt: float = 0.015,
    **physics_options: Any,
) -> Task:
    """`humanoid_amp_walk` asked to follow a velocity command in the teacher's style:
    the command (`commands.VelocityCommandState`) = [vx ~ U(`speed`) m/s, 0, yaw rate ~ U(`yaw_rate`) rad/s] in the
    torso's heading frame, redrawn every U(`resample_interval`) s and appended to the
    observation (48); rewards exp(-|v_xy - c_xy|^2 / sigma) (`tracking_weight`) and
    exp(-(w_z - c_yaw)^2 / sigma) (`yaw_tracking_weight`), sigma = `tracking_sigma`,
    besides alive and effort."""
    checks.interval("humanoid_amp_joystick", "speed", speed)  # named as given (the command calls it vx)
    physics = _physics(ctrl_dt, physics_options)
    m = physics.mj_model
    reference = walk_reference(m, physics.ctrl_dt)
    command = functools.partial(
        commands.with_velocity_command, vx=speed, vy=(0.0, 0.0), yaw_rate=yaw_rate, resample_interval=resample_interval
    )
    tracking = {
        "tracking": (named(rewards.linear_velocity_tracking(m, tracking_sigma), "tracking_sigma"), tracking_weight),
        "yaw_tracking": (
            named(rewards.angular_velocity_tracking(m, tracking_sigma), "tracking_sigma"),
            yaw_tracking_weight,
        ),
    }
    return _humanoid(
        physics,
        reference,
        reference_probability=reference_probability,
        reset_noise=reset_noise,
        min_height=min_height,
        episode_steps=episode_steps,
        alive_weight=alive_weight,
        effort_weight=effort_weight,
        rewards_=tracking,
        combinators=(command,),
    )


WALK = base.EnvSpec(
    make=humanoid_amp_walk,
    description="Brax's humanoid walking in a teacher's style (AMP)",
    amp=AMP,
    reference=reference,
)
JOYSTICK = base.EnvSpec(
    make=humanoid_amp_joystick,
    description="Brax's humanoid following velocity commands in a teacher's style (AMP)",
    amp=JOYSTICK_AMP,
    reference=reference,
)
