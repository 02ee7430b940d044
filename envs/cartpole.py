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

import dataclasses

import jax
import jax.numpy as jnp
from mujoco import mjx

from mjzoo.catalog.rewards import tolerance
from mjzoo.envs import base
from mjzoo.types import State, Task

__all__ = ["Params", "balance", "swingup"]

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
    return base.held_near(states, lambda s: base.wrap(s.data.qpos[..., 1]), 0.2)


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
    },
)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Params:
    upright_weight: Array
    centered_weight: Array
    velocity_weight: Array
    effort_weight: Array
    centered_margin: Array
    velocity_margin: Array
    init_angle: Array  # pole angle at reset, rad (0 upright, pi hanging)
    init_noise: Array  # uniform half-width of the reset noise on every coordinate
    fall_angle: Array  # |angle| beyond which the episode terminates (inf: never)
    data0: mjx.Data  # the reset template, `Physics.data0`
    n_substeps: int = dataclasses.field(metadata=dict(static=True))


def observe(data: mjx.Data) -> Array:
    cart, angle = data.qpos[0], data.qpos[1]
    return jnp.stack([cart, jnp.cos(angle), jnp.sin(angle), data.qvel[0], data.qvel[1]])


def reset(p: Params, model: mjx.Model, key: Array) -> State:
    qpos_key, qvel_key = jax.random.split(key)
    data = p.data0
    qpos = jnp.array([0.0, 1.0]) * p.init_angle + jax.random.uniform(
        qpos_key, (2,), minval=-p.init_noise, maxval=p.init_noise
    )
    qvel = jax.random.uniform(qvel_key, (2,), minval=-p.init_noise, maxval=p.init_noise)
    data = data.replace(qpos=qpos.astype(data.qpos.dtype), qvel=qvel.astype(data.qvel.dtype))
    return State.create(data, observe(data))


def step(p: Params, model: mjx.Model, state: State, action: Array, key: Array) -> State:
    data = base.advance(model, state, action, p.n_substeps)
    return state.replace(data=data, obs=observe(data))


def reward(p: Params, model: mjx.Model, state: State, action: Array, next_state: State) -> dict[str, Array]:
    data = next_state.data
    return {
        "upright": p.upright_weight * (1.0 + jnp.cos(data.qpos[1])) / 2.0,
        "centered": p.centered_weight * tolerance(data.qpos[0], margin=p.centered_margin),
        "velocity": -p.velocity_weight * (1.0 - tolerance(data.qvel[1], margin=p.velocity_margin)),
        "effort": -p.effort_weight * jnp.mean(jnp.square(jnp.clip(action, -1.0, 1.0))),
    }


def terminate(p: Params, model: mjx.Model, state: State) -> tuple[Array, Array]:
    leaning = jnp.abs(jnp.arctan2(jnp.sin(state.data.qpos[1]), jnp.cos(state.data.qpos[1])))
    return leaning > p.fall_angle, jnp.zeros((), bool)


def _make(
    *,
    episode_steps,
    upright_weight,
    centered_weight,
    velocity_weight,
    effort_weight,
    centered_margin,
    velocity_margin,
    init_angle,
    init_noise,
    fall_angle,
    ctrl_dt,
    **physics_options,
) -> Task:
    physics = base.load("cartpole.xml", ctrl_dt=ctrl_dt, **physics_options)
    params = Params(
        **base.floats(
            upright_weight=upright_weight,
            centered_weight=centered_weight,
            velocity_weight=velocity_weight,
            effort_weight=effort_weight,
            centered_margin=centered_margin,
            velocity_margin=velocity_margin,
            init_angle=init_angle,
            init_noise=init_noise,
            fall_angle=fall_angle,
        ),
        data0=physics.data0,
        n_substeps=physics.n_substeps,
    )
    return base.build(physics, params, reset, step, reward, terminate, episode_steps=episode_steps)


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
        init_angle=jnp.pi,
        fall_angle=jnp.inf,
        **physics_options,
    )
