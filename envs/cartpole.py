"""Cart-pole: a cart on a limited rail (+-1.8 m, up to 10 N) carries a 1 m pole.

Two tasks share the model and the reward:
  cartpole_balance  starts near upright; terminates when the pole leans past
                    `fall_angle` (0.5 rad), so the return counts balanced steps.
  cartpole_swingup  starts hanging down; must swing up and balance; never terminates.

Observation (5,): cart position (m), cos and sin of the pole angle from upright, cart
velocity (m/s), pole angular velocity (rad/s).
Action (1,): force in [-1, 1] x 10 N.
Reward terms per step (each a weight times a value in [0, 1]):
  upright   +1.0  * (1 + cos angle) / 2
  centered  +0.1  * tolerance(cart position, margin=2 m)
  velocity  -0.1  * (1 - tolerance(pole angular velocity, margin=5 rad/s))
  effort    -0.01 * action^2
Truncated after `episode_steps` (500 steps of 0.02 s = 10 s).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

import mjzoo
from mjzoo.catalog.rewards import tolerance
from mjzoo.catalog.shaping import wrap_angle
from mjzoo.envs import base
from mjzoo.envs.base import ASSETS
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["balance", "swingup", "BALANCE", "SWINGUP"]

Array = jax.Array

# PPO hyperparameters that solve each task (`mjzoo train ppo cartpole_balance`).
BALANCE_PPO = dict(
    num_envs=256,
    unroll_length=32,
    num_minibatches=8,
    num_epochs=4,
    learning_rate=1e-3,
    entropy_coef=1e-3,
    discount=0.99,
    total_steps=1_000_000,
)
SWINGUP_PPO = dict(
    num_envs=256,
    unroll_length=32,
    num_minibatches=8,
    num_epochs=4,
    learning_rate=1e-3,
    entropy_coef=1e-3,
    discount=0.99,
    total_steps=3_000_000,
)


def _upright_at_end(states) -> tuple[bool, float]:
    """Balanced when |pole angle from upright| < 0.2 rad over the last second."""
    return base.held_near(states, lambda s: np.asarray(wrap_angle(s.data.qpos[..., 1])), 0.2)


# Sampling planners (`mjzoo plan mppi cartpole_swingup`): plan at the simulation's own
# 0.02 s step over 1.2 s (a coarser planning step left the pole wobbling +-0.3 rad), and
# replan every 2 steps (25 Hz).
_SAMPLING = dict(num_samples=64, horizon_steps=60, num_knots=5)
SWINGUP_PLANNING = base.PlanningSetup(
    seconds=8.0,
    replan_every=2,
    plan_overrides={},
    success=_upright_at_end,
    configs={
        "predictive_sampling": _SAMPLING,
        "mppi": dict(_SAMPLING, temperature=0.05),
        "cem": dict(_SAMPLING, num_elites=8, sigma_min=0.1),
        "dial": dict(_SAMPLING, iterations=2, temperature=1.0, beta_horizon=4.0),
        "cma_es": dict(_SAMPLING, num_elites=8),
        "ilqr": dict(horizon_steps=_SAMPLING["horizon_steps"], iterations=3),
    },
)


def observe(data: mjx.Data) -> Array:
    """[5] cart position, cos and sin of the pole angle, cart and pole velocities."""
    qpos, qvel = data.qpos, data.qvel
    return jnp.stack([qpos[0], jnp.cos(qpos[1]), jnp.sin(qpos[1]), qvel[0], qvel[1]])


def observation(p: dict, model: mjx.Model, state: State) -> Array:
    """The task's observation, `observe` of the state's physics."""
    return observe(state.data)


def start(p: dict, model: mjx.Model, data: mjx.Data, key: Array) -> mjx.Data:
    """The pole at `init_angle` (rad; 0 upright), the cart centred, every coordinate
    and velocity within U(+-init_noise)."""
    qpos_key, qvel_key = jax.random.split(key)
    qpos = jnp.array([0.0, 1.0]) * p["init_angle"] + jax.random.uniform(
        qpos_key, (2,), minval=-p["init_noise"], maxval=p["init_noise"]
    )
    qvel = jax.random.uniform(qvel_key, (2,), minval=-p["init_noise"], maxval=p["init_noise"])
    return data.replace(qpos=qpos.astype(data.qpos.dtype), qvel=qvel.astype(data.qvel.dtype))


def upright(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: (1 + cos angle) / 2."""
    return (1.0 + jnp.cos(next_state.data.qpos[1])) / 2.0


def centered(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: 1 at the rail's centre, 0.1 at `centered_margin` m."""
    return tolerance(next_state.data.qpos[0], margin=p["centered_margin"])


def swinging(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: 0 with the pole still, 0.9 at `velocity_margin` rad/s."""
    return 1.0 - tolerance(next_state.data.qvel[1], margin=p["velocity_margin"])


def effort(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: the mean squared action, clipped to [-1, 1]."""
    return jnp.mean(jnp.square(jnp.clip(action, -1.0, 1.0)))


def fallen(p: dict, model: mjx.Model, state: State) -> Array:
    """Whether the pole leans more than `fall_angle` rad from upright."""
    leaning = jnp.abs(wrap_angle(state.data.qpos[1]))
    return leaning > p["fall_angle"]


def _make(
    *,
    episode_steps: int,
    upright_weight: float,
    centered_weight: float,
    velocity_weight: float,
    effort_weight: float,
    centered_margin: float,
    velocity_margin: float,
    init_angle: float,
    init_noise: float,
    fall_angle: float | None,
    ctrl_dt: float,
    **physics_options,
) -> Task:
    params = dict(
        centered_margin=centered_margin, velocity_margin=velocity_margin, init_angle=init_angle, init_noise=init_noise
    )
    if fall_angle is not None:
        params["fall_angle"] = fall_angle
    return mjzoo.task(
        ASSETS / "cartpole.xml",
        observe=observation,
        start=start,
        rewards={"upright": (upright, upright_weight), "centered": (centered, centered_weight)},
        costs={"velocity": (swinging, velocity_weight), "effort": (effort, effort_weight)},
        terminate=None if fall_angle is None else fallen,
        time_limit=episode_steps,
        params=params,
        ctrl_dt=ctrl_dt,
        **physics_options,
    )


def balance(
    *,
    episode_steps: int = 500,
    upright_weight: float = 1.0,
    centered_weight: float = 0.1,
    velocity_weight: float = 0.1,
    effort_weight: float = 0.01,
    centered_margin: float = 2.0,
    velocity_margin: float = 5.0,
    init_noise: float = 0.1,
    fall_angle: float = 0.5,
    ctrl_dt: float = 0.02,
    **physics_options,
) -> Task:
    """Balance from near upright; terminates when the pole falls past `fall_angle`."""
    return _make(**{k: v for k, v in locals().items() if k != "physics_options"}, init_angle=0.0, **physics_options)


def swingup(
    *,
    episode_steps: int = 500,
    upright_weight: float = 1.0,
    centered_weight: float = 0.1,
    velocity_weight: float = 0.1,
    effort_weight: float = 0.01,
    centered_margin: float = 2.0,
    velocity_margin: float = 5.0,
    init_noise: float = 0.05,
    ctrl_dt: float = 0.02,
    **physics_options,
) -> Task:
    """Swing up from hanging down and balance; never terminates."""
    return _make(
        **{k: v for k, v in locals().items() if k != "physics_options"},
        init_angle=float(np.pi),
        fall_angle=None,
        **physics_options,
    )


BALANCE = base.EnvSpec(make=balance, description="cart-pole: keep the pole up from near upright", ppo=BALANCE_PPO)
SWINGUP = base.EnvSpec(
    make=swingup,
    description="cart-pole: swing the pole up from hanging and balance",
    ppo=SWINGUP_PPO,
    planning=SWINGUP_PLANNING,
)
