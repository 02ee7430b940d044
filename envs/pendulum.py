"""Pendulum swing-up: a torque-limited pendulum (2.5 N m against 4.9 N m of gravity at
horizontal) must pump energy, swing up and balance upright.

Observation (3,): cos and sin of the angle from upright, angular velocity (rad/s).
Action (1,): torque in [-1, 1] x 2.5 N m.
Reward terms per step (each a weight times a value in [0, 1]):
  upright   +1.0  * (1 + cos angle) / 2 * (1 + tolerance(angular velocity, margin=5 rad/s)) / 2
  velocity  -0.5  * (1 - tolerance(angular velocity, bounds=+-10 rad/s, margin=20 rad/s, linear))
  effort    -0.01 * action^2
The upright term pays in full only when upright and slow (dm_control's small_velocity
factor), so balancing earns about 1 per step against about 0.25 for spinning through the
top. The velocity term is 0 up to 10 rad/s (a swing-up passes the bottom at about 9) and
reaches its full weight at 30 rad/s: the joint is lightly damped, so a pendulum pushed
one way keeps spinning up (towards 50 rad/s) unless that costs something.
No termination; truncated after `episode_steps` (500 steps of 0.02 s = 10 s).
Starts hanging down (angle pi) with a small random offset.
Solved: a deterministic PPO policy swings up in about 2 s and holds, mean return >= 380.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

import mjzoo
from mjzoo.catalog.rewards import tolerance
from mjzoo.catalog.shaping import wrap_angle
from mjzoo.combinators import with_reward
from mjzoo.envs import base
from mjzoo.envs.base import ASSETS
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["swingup", "SWINGUP", "PPO", "SAC", "FAST_TD3", "PLANNING"]

Array = jax.Array

# PPO hyperparameters that solve this task (`mjzoo train ppo pendulum_swingup`): a
# deterministic eval return >= 380 (swung up and held) by 0.4-2.4M steps over 8 seeds
# when calibrated. Re-measured under XLA's default optimization level: seeds 1-4 by
# 0.4-1.6M steps, but seed 0 ends at 229 (the suite's level 0 changes its numerics and
# it passes there): not every seed solves it.
PPO = dict(
    num_envs=256,
    unroll_length=32,
    num_minibatches=8,
    num_epochs=4,
    learning_rate=1e-3,
    entropy_coef=1e-2,
    discount=0.97,
    total_steps=3_000_000,
)


# The replay learners, at a CPU's scale: SAC's config swung up and held (deterministic
# returns 423 and 326, seeds 0 and 1) after 32k steps when calibrated.
_REPLAY = dict(
    num_envs=16,
    learning_starts=1024,
    gradient_steps=4,
    policy_hidden_sizes=(64, 64),
    critic_hidden_sizes=(64, 64),
    learning_rate=1e-3,
    discount=0.97,
    total_steps=50_000,
)
SAC = dict(_REPLAY, batch_size=128, initial_alpha=0.1)
FAST_TD3 = dict(_REPLAY, batch_size=256, num_atoms=51, v_min=-10.0, v_max=40.0, weight_decay=0.0)


def _angle_squared(model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    angle = next_state.data.qpos[0]
    return jnp.square(wrap_angle(angle))


def precise_upright(task: Task) -> Task:
    """The planners' view: also charges angle^2 per step. The task's own upright term is
    flat at the top ((1 + cos a) / 2 loses 1.5% at 0.25 rad), too flat for a few dozen
    samples to tell holding still from wobbling."""
    return with_reward(task, "precise_upright", _angle_squared, -1.0)


def _upright_at_end(states) -> tuple[bool, float]:
    """Solved when |angle from upright| < 0.2 rad over the last second."""
    return base.held_near(states, lambda s: np.asarray(wrap_angle(s.data.qpos[..., 0])), 0.2)


# Sampling planners (`mjzoo plan mppi pendulum_swingup`): plan at the simulation's own
# 0.02 s step over 1.2 s (with 0.05 s planning steps the pendulum wobbled +-0.3 rad at
# the top), replan every 2 simulation steps (25 Hz).
_SAMPLING = dict(num_samples=64, horizon_steps=60, num_knots=4, noise_scale=0.2)
PLANNING = base.PlanningSetup(
    seconds=6.0,
    replan_every=2,
    plan_overrides={},
    success=_upright_at_end,
    configs={
        "predictive_sampling": _SAMPLING,
        "mppi": dict(_SAMPLING, temperature=0.1),
        "cem": dict(_SAMPLING, num_elites=8, sigma_min=0.1),
        "dial": dict(_SAMPLING, iterations=2, temperature=1.0, beta_horizon=4.0),
        "cma_es": dict(_SAMPLING, num_elites=8),
        "ilqr": dict(horizon_steps=_SAMPLING["horizon_steps"], iterations=3),
    },
    plan_view=precise_upright,
)


def observe(data: mjx.Data) -> Array:
    """[3] cos and sin of the angle from upright, angular velocity (rad/s)."""
    angle = data.qpos[0]
    return jnp.stack([jnp.cos(angle), jnp.sin(angle), data.qvel[0]])


def observation(p: dict, model: mjx.Model, state: State) -> Array:
    """The task's observation, `observe` of the state's physics."""
    return observe(state.data)


def hanging(p: dict, model: mjx.Model, data: mjx.Data, key: Array) -> mjx.Data:
    """Start: hanging down (angle pi) and still, each within U(+-init_noise) rad, rad/s."""
    noise = jax.random.uniform(key, (2,), minval=-p["init_noise"], maxval=p["init_noise"])
    return data.replace(qpos=data.qpos.at[0].set(jnp.pi + noise[0]), qvel=data.qvel.at[0].set(noise[1]))


def upright(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: (1 + cos angle) / 2, halved unless slow (dm_control's small_velocity)."""
    angle, speed = next_state.data.qpos[0], next_state.data.qvel[0]
    small_velocity = (1.0 + tolerance(speed, margin=p["small_velocity_margin"])) / 2.0
    return (1.0 + jnp.cos(angle)) / 2.0 * small_velocity


def too_fast(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: 0 up to velocity_bound rad/s, 1 at velocity_bound + velocity_margin."""
    return 1.0 - tolerance(
        next_state.data.qvel[0],
        lower=-p["velocity_bound"],
        upper=p["velocity_bound"],
        margin=p["velocity_margin"],
        sigmoid="linear",
        value_at_margin=0.0,
    )


def effort(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: the mean squared action, clipped to [-1, 1]."""
    return jnp.mean(jnp.square(jnp.clip(action, -1.0, 1.0)))


def swingup(
    *,
    episode_steps: int = 500,
    upright_weight: float = 1.0,
    velocity_weight: float = 0.5,
    effort_weight: float = 0.01,
    small_velocity_margin: float = 5.0,
    velocity_bound: float = 10.0,
    velocity_margin: float = 20.0,
    init_noise: float = 0.1,
    ctrl_dt: float = 0.02,
    **physics_options,
) -> Task:
    """The pendulum swing-up task; keyword arguments override weights and physics."""
    return mjzoo.task(
        ASSETS / "pendulum.xml",
        observe=observation,
        start=hanging,
        rewards={"upright": (upright, upright_weight)},
        costs={"velocity": (too_fast, velocity_weight), "effort": (effort, effort_weight)},
        time_limit=episode_steps,
        params=dict(
            small_velocity_margin=small_velocity_margin,
            velocity_bound=velocity_bound,
            velocity_margin=velocity_margin,
            init_noise=init_noise,
        ),
        ctrl_dt=ctrl_dt,
        **physics_options,
    )


SWINGUP = base.EnvSpec(
    make=swingup,
    description="torque-limited pendulum: swing up and balance",
    ppo=PPO,
    sac=SAC,
    fast_td3=FAST_TD3,
    planning=PLANNING,
)
