"""Pendulum swing-up: a torque-limited pendulum (1 N m against 4.9 N m of gravity at
horizontal) must pump energy, swing up and balance upright.

Observation (3,): cos and sin of the angle from upright, angular velocity (rad/s).
Action (1,): torque in [-1, 1] N m.
Reward terms per step (each a weight times a value in [0, 1]):
  upright   +1.0  * (1 + cos angle) / 2
  velocity  -0.1  * (1 - tolerance(angular velocity, margin=5 rad/s))
  effort    -0.01 * action^2
No termination; truncated after `episode_steps` (500 steps of 0.02 s = 10 s).
Starts hanging down (angle pi) with a small random offset.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from mujoco import mjx

from mjzoo.envs import base
from mjzoo.rewards import tolerance
from mjzoo.types import State, Task

__all__ = ["Params", "swingup"]

Array = jax.Array

# PPO hyperparameters that solve this task (`mjzoo train ppo pendulum_swingup`).
PPO = dict(num_envs=256, unroll_length=32, num_minibatches=8, num_epochs=4, learning_rate=1e-3,
           entropy_coef=1e-3, discount=0.97, total_steps=1_500_000)  # fmt: skip


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Params:
    upright_weight: Array
    velocity_weight: Array
    effort_weight: Array
    velocity_margin: Array
    velocity_bound: Array
    slow_margin: Array
    init_noise: Array  # rad and rad/s, uniform half-width around hanging still
    n_substeps: int = dataclasses.field(metadata=dict(static=True))


def observe(data: mjx.Data) -> Array:
    angle = data.qpos[0]
    return jnp.stack([jnp.cos(angle), jnp.sin(angle), data.qvel[0]])


def reset(p: Params, model: mjx.Model, key: Array) -> State:
    noise = jax.random.uniform(key, (2,), minval=-p.init_noise, maxval=p.init_noise)
    data = mjx.make_data(model)
    data = data.replace(qpos=data.qpos.at[0].set(jnp.pi + noise[0]), qvel=data.qvel.at[0].set(noise[1]))
    return State.create(data, observe(data))


def step(p: Params, model: mjx.Model, state: State, action: Array, key: Array) -> State:
    data = base.advance(model, state, action, p.n_substeps)
    return state.replace(data=data, obs=observe(data))


def reward(p: Params, model: mjx.Model, state: State, action: Array, next_state: State) -> dict[str, Array]:
    data = next_state.data
    return {
        "upright": p.upright_weight * tolerance(jnp.arctan2(jnp.sin(data.qpos[0]), jnp.cos(data.qpos[0])), margin=jnp.pi, sigmoid="linear", value_at_margin=0.0)
        * (1.0 + tolerance(data.qvel[0], margin=p.slow_margin)) / 2.0,
        "velocity": -p.velocity_weight * (1.0 - tolerance(data.qvel[0], lower=-p.velocity_bound, upper=p.velocity_bound,
                                                          margin=p.velocity_margin, sigmoid="linear", value_at_margin=0.0)),
        "effort": -p.effort_weight * jnp.mean(jnp.square(jnp.clip(action, -1.0, 1.0))),
    }


def swingup(
    *,
    episode_steps: int = 500,
    upright_weight: float = 1.0,
    velocity_weight: float = 0.5,
    effort_weight: float = 0.01,
    velocity_margin: float = 20.0,
    velocity_bound: float = 10.0,
    slow_margin: float = 5.0,
    init_noise: float = 0.1,
    ctrl_dt: float = 0.02,
    **physics_options,
) -> Task:
    """The pendulum swing-up task; keyword arguments override weights and physics."""
    physics = base.load("pendulum.xml", ctrl_dt=ctrl_dt, **physics_options)
    params = Params(
        **base.floats(
            upright_weight=upright_weight, velocity_weight=velocity_weight, effort_weight=effort_weight,
            velocity_margin=velocity_margin, velocity_bound=velocity_bound, slow_margin=slow_margin, init_noise=init_noise,
        ),
        n_substeps=physics.n_substeps,
    )  # fmt: skip
    return base.build(physics, params, reset, step, reward, base.never_terminate, episode_steps=episode_steps)
