"""The G1 walking and running on command in a human's style: AMP on the G1's joystick.

The reference is the G1's retargeted DeepMimic walk (0.89 m/s) and run (3.1 m/s)
(``assets/motions/g1``, `mjzoo.motion.retarget`), both loops, resampled to the joystick's
control step (0.02 s). The task is `robot_joystick("g1")` on flat ground with its servos,
randomized physics, pushes, noise and asymmetric observation, asked only forward speeds
and turns (the clips hold nothing else), and starting from a clip frame with probability
`reference_probability` (reference-state initialization). AMP's style reward makes it
move as the clips do while the joystick's rewards make it follow the command.

    task = mjzoo.envs.make("g1_amp_joystick")
    reference = mjzoo.envs.reference("g1_amp_joystick", task)
    config, hyperparams = amp.configure(**mjzoo.envs.hyperparameters("g1_amp_joystick", "amp"))
    ...                                               # mjzoo train amp g1_amp_joystick
    robot_amp.style_error(reference, qpos)            # rad, of a deterministic episode's [T, 36]

Style. `style_error` is `motion.nearest_window_error` of the 29 joint angles over windows
of `STYLE_WINDOW` frames (0.16 s): how far, window by window, the motion is from the
nearest stretch of either clip. Tracking is the joystick's (`mjzoo.interop.tracking`).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from mjzoo import motion
from mjzoo import physics as physics_lib
from mjzoo.envs import base
from mjzoo.envs import humanoid_amp
from mjzoo.envs import motion_tracking
from mjzoo.envs import robot_joystick as joystick
from mjzoo.types import Task

__all__ = ["g1_amp_joystick", "reference", "g1_reference", "style_error", "G1_AMP_JOYSTICK", "AMP"]

CLIPS = motion_tracking.MOTIONS  # the committed G1 clips (scripts/retarget_g1.py)
CLIP_NAMES = ("walk", "run")
STYLE_WINDOW = 8  # frames (0.16 s at the control step)
KEY_BODIES = ("left_ankle_roll_link", "right_ankle_roll_link", "left_wrist_yaw_link", "right_wrist_yaw_link")

# The joystick's PPO (Playground's, 8192 envs, asymmetric critic) with the humanoid's
# discriminator, seeing transitions of the joints, root velocities and the feet and
# hands (root-relative); the task's reward and the style count alike.
AMP = dict(joystick.PPO, key_bodies=KEY_BODIES, **humanoid_amp.DISCRIMINATOR, task_weight=0.5, style_weight=0.5)


def g1_reference(mj_model: mujoco.MjModel, dt: float, clips: str | tuple[str, ...] = CLIP_NAMES) -> motion.Reference:
    """The G1's retargeted `clips` (names in ``assets/motions/g1``), checked against
    `mj_model` (the G1's Playground scene) and resampled to a frame every `dt` s, looping,
    equally likely."""
    clips = (clips,) if isinstance(clips, str) else tuple(clips)  # one name, as the CLI's overrides give it
    known = list(motion_tracking.G1_CLIPS)
    unknown = [c for c in clips if c not in known]
    if unknown or not clips:
        raise ValueError(f"robot_amp.g1_reference: clips {list(clips)} unknown or empty; the G1's clips: {known}")
    loaded = [motion.load(CLIPS / f"{name}.npz", mj_model, name=name) for name in clips]
    return motion.reference(loaded, mj_model, dt, loop=True)


def reference(task: Task, *, clips: str | tuple[str, ...] = CLIP_NAMES, **overrides: Any) -> motion.Reference:
    """What AMP imitates on `task` (`g1_amp_joystick(**overrides)`): `g1_reference` at its
    control step. The envs' record (`mjzoo.envs.reference`) calls it with the task's
    overrides; the physics options among them set the step (nothing is compiled)."""
    physics = _physics(overrides)
    if task.mj_model.nq != physics.mj_model.nq:
        raise ValueError(
            f"robot_amp.reference: the task's model has nq={task.mj_model.nq}, the G1's {physics.mj_model.nq}"
        )
    return g1_reference(task.mj_model, physics.ctrl_dt, clips)


def _physics(options: dict[str, Any]):
    """The G1's flat scene with these physics options (the joystick's cached one)."""
    chosen = tuple(sorted((k, v) for k, v in options.items() if k in physics_lib.OPTIONS))
    return joystick._scene("g1", "flat", chosen)[0]


def g1_amp_joystick(
    *,
    clips: str | tuple[str, ...] = CLIP_NAMES,
    vx: tuple[float, float] = (0.0, 2.0),
    yaw_rate: tuple[float, float] = (-0.5, 0.5),
    reference_probability: float = 0.5,
    episode_steps: int = 1000,
    push: float = 0.5,
    noise: float = 0.02,
    max_action_latency: int = 1,
    **physics_options: Any,
) -> Task:
    """The G1's flat joystick (`robot_joystick("g1")`) commanded forward at U(`vx`) m/s
    and turning at U(`yaw_rate`) rad/s, no sideways speed, starting at a frame of the
    `clips` (`g1_reference`) with `reference_probability`."""
    physics = _physics(physics_options)
    return joystick.robot_joystick(
        "g1",
        vx=vx,
        vy=(0.0, 0.0),
        yaw_rate=yaw_rate,
        reference=g1_reference(physics.mj_model, physics.ctrl_dt, clips),
        reference_probability=reference_probability,
        episode_steps=episode_steps,
        push=push,
        noise=noise,
        max_action_latency=max_action_latency,
        **physics_options,
    )


def style_error(reference: motion.Reference, qpos, window: int = STYLE_WINDOW) -> float:
    """The mean joint-angle error (rad) of `qpos` [T >= `window`, nq] (an episode of the
    G1) to the nearest `window`-frame stretches of `reference`'s clips: columns 7.., the
    joints past the free root (`motion.nearest_window_error`)."""
    nq = np.shape(reference.qpos)[-1]
    if np.ndim(qpos) != 2 or np.shape(qpos)[1] != nq or np.shape(qpos)[0] < window:
        raise ValueError(f"robot_amp.style_error: qpos has shape {np.shape(qpos)}; expected [T >= {window}, {nq}]")
    return humanoid_amp.style_error(reference, qpos, window)  # the same measure: past any free root


G1_AMP_JOYSTICK = base.EnvSpec(
    make=g1_amp_joystick,
    description="Unitree G1 following velocity commands in the style of retargeted human walk and run (AMP)",
    ppo=joystick.PPO,
    amp=AMP,
    reference=reference,
)
