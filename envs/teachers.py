"""A sampling planner as a motion teacher: AMP learns the cart-pole swing-up from MPPI.

A planner solves a task online, at a cost per control step (here 64 rollouts of 1.2 s
every two steps). Its closed-loop runs are motion clips like any motion capture: a
policy trained by adversarial motion priors (`mjzoo.algorithms.amp`) on them should
move like the planner and then act at the price of one network evaluation.

    task = teachers.cartpole_amp_swingup()          # cartpole_swingup (+ optional clip starts)
    reference = teachers.reference(task)            # the planner's clip at the control step
    config, hyperparams = amp.configure(**teachers.AMP)
    state, _ = amp.train(config, task, reference, hyperparams, jax.random.key(0))
    err = teachers.style_error(task, reference, qpos)  # qpos [T, 2] of a run, from hanging

The clip ``envs/assets/cartpole_swingup_mppi.npz`` (401 frames at 50 fps, 8 s) is
episode 3 of MPPI's closed loop on ``cartpole_swingup`` with the env's own planning
configuration (64 samples, 60-step horizon, 5 knots, temperature 0.05, replanning every
2 steps), made by

    mjzoo collect mppi --task cartpole_swingup --out /tmp/cp --episodes 4   # seed 0
    cp /tmp/cp/motions/episode_003.npz envs/assets/cartpole_swingup_mppi.npz

It starts hanging (hinge 3.15 rad), swings back to 1.2 rad with the cart at the rail's
end, then up through increasing angle (upright first at 2.4 s, hinge 2 pi), and
balances within 0.21 rad over its last 4 s (the best of the 4 episodes: the others
leaned up to 0.22-0.50 rad while balancing; one swung up the other way, to 0 rad).

Reference-state initialization: episodes start hanging, as the task's own, because
the policy must learn the swing-up from the bottom; with `reference_init` > 0 that
fraction starts at a frame of the clip instead (mostly the balancing phase, which fills
5 of its 8 s), so the discriminator's reward for being upright is seen early.

What AMP learned here (2M steps, 2 CPU cores; 8 runs of 10 s from hanging): on style
alone (`AMP`, with or without RSI, 2 or 10 frames per window, a sharper discriminator)
the policy settles into small swings at the bottom (hinge 2.8-3.4 rad), the clip's
first pump, and drops the pole from RSI's upright starts; with half task reward
(``task_weight=0.5``) it swings up and balances (return 406, MPPI's 349) but spins
twice first. `style_error` both ways: MPPI's other episodes 0.08-0.27 (1.2 for the
mirrored one), AMP style-only 0.78, AMP half task 0.92, PPO 2.3, random 0.86.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import mujoco
import numpy as np

from mjzoo import motion
from mjzoo.catalog import resets
from mjzoo.envs import base
from mjzoo.envs import cartpole
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["CARTPOLE_CLIP", "cartpole_amp_swingup", "cartpole_clip"]

CARTPOLE_CLIP: Path = base.ASSETS / "cartpole_swingup_mppi.npz"
STYLE_WINDOW = 25  # frames (0.5 s) per compared window: about one pump of the swing-up

# AMP on style alone (`mjzoo train amp mjzoo.envs.teachers:cartpole_amp_swingup`), 4-12 min on 2 shared CPU
# cores; it does not swing up yet (module docstring).
AMP = dict(
    num_envs=128,
    unroll_length=32,
    num_minibatches=8,
    num_epochs=4,
    learning_rate=1e-3,
    entropy_coef=1e-3,
    discount=0.99,
    total_steps=2_000_000,
    task_weight=0.0,
    style_weight=1.0,
    num_frames=2,
    disc_hidden_sizes=(256, 256),
    disc_learning_rate=1e-4,
    gradient_penalty_weight=5.0,
    disc_minibatches=8,
)


def cartpole_clip(mj_model: mujoco.MjModel) -> motion.Clip:
    """The planner's swing-up (module docstring), checked against the cart-pole `mj_model`."""
    return motion.load(CARTPOLE_CLIP, mj_model, name="cartpole_swingup_mppi")


def cartpole_amp_swingup(
    *,
    reference_init: float = 0.0,
    episode_steps: int = 500,
    upright_weight: float = 1.0,
    centered_weight: float = 0.1,
    velocity_weight: float = 0.1,
    effort_weight: float = 0.01,
    ctrl_dt: float = 0.02,
    **physics_options,
) -> Task:
    """`cartpole.swingup(...)` (its reward weights, episode length and physics options)
    for AMP with the planner's clip as its reference (`reference`); a fraction
    `reference_init` in [0, 1] of the episodes starts at a clip frame
    (`resets.reference_state`), the others hanging."""
    task = cartpole.swingup(
        episode_steps=episode_steps,
        upright_weight=upright_weight,
        centered_weight=centered_weight,
        velocity_weight=velocity_weight,
        effort_weight=effort_weight,
        ctrl_dt=ctrl_dt,
        **physics_options,
    )
    if reference_init:
        ref = reference(task, ctrl_dt=ctrl_dt)
        task = resets.with_resets(task, resets.reference_state(ref, reference_init), observe=_observe)
    return task


def reference(task: Task, *, ctrl_dt: float = 0.02, **_: Any) -> motion.Reference:
    """The planner's clip (`cartpole_clip`) on `task`'s model, resampled to one frame per
    control step `ctrl_dt` (the task's, `cartpole_amp_swingup(ctrl_dt=...)`), not
    looping: what AMP imitates. The envs' record (`mjzoo.envs.reference`) calls it with
    the task's overrides; the others do not change it."""
    return motion.reference(cartpole_clip(task.mj_model), task.mj_model, dt=ctrl_dt, loop=False)


def _observe(model, state: State) -> jax.Array:
    return cartpole.observe(state.data)


def style_error(
    task: Task, reference: motion.Reference, qpos, window: int = STYLE_WINDOW, both_ways: bool = True
) -> float:
    """How far a run moves from the task's reference, in m and rad averaged over the
    slider and hinge: `motion.nearest_window_error` of the run's windows to their
    nearest reference windows and, with `both_ways`, averaged with that of the
    reference's windows to their nearest windows of the run.

    One way alone scores a pole that hangs still as well as the clip's first second
    (0.16); both ways, the clip's swing and balance must also appear in the run.

    Args:
      task: the cart-pole task the run is of (`cartpole_amp_swingup`): its model.
      reference: the motion to compare with (`reference(task)`).
      qpos: [T, 2] the run's cart position and hinge angle, T >= `window`; the angle
        as simulated (continuous, not wrapped): a pole that spins over the top is
        2 pi away from one that swung up once, as it should be.
      window: frames per compared window.
      both_ways: also measure the reference against the run.
    """
    if not isinstance(reference, motion.Reference):
        raise TypeError(
            "teachers.style_error: reference must be a motion.Reference (teachers.reference(task)), "
            f"got {type(reference).__name__}"
        )
    qpos, ref = np.asarray(qpos), np.asarray(reference.qpos)
    if qpos.ndim != 2 or qpos.shape[1] != task.mj_model.nq:
        raise ValueError(f"teachers.style_error: qpos has shape {qpos.shape}; expected [T, {task.mj_model.nq}]")
    columns = np.arange(task.mj_model.nq)
    run_to_reference = motion.nearest_window_error(ref, qpos, columns, window)
    if not both_ways:
        return run_to_reference
    return 0.5 * (run_to_reference + motion.nearest_window_error(qpos, ref, columns, window))


CARTPOLE_AMP_SWINGUP = base.EnvSpec(
    make=cartpole_amp_swingup,
    description="cart-pole swing-up learned from MPPI's runs (AMP)",
    amp=AMP,
    reference=reference,
)
