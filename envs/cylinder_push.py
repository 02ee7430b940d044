"""Cylinder push: a planar pusher must shove a sliding cylinder onto a goal.

Pusher (sphere, r = 5 cm, 2 motors of up to 5 N) and cylinder (r = 10 cm, 0.5 kg) slide
on slide joints whose damping stands in for floor friction; only they collide.

Observation (12,): pusher position and velocity, cylinder position and velocity, goal
minus cylinder, cylinder minus pusher (m, m/s; xy each).
Action (2,): pusher forces in [-1, 1] x 5 N along x and y.
Reward terms per step (each a weight times a value in [0, 1]):
  goal      +1.0  * tolerance(cylinder-goal distance, margin=1.5 m, linear)
  approach  +0.3  * tolerance(distance from the pusher to the point behind the cylinder,
                    opposite the goal, margin=1.5 m, linear)
  effort    -0.01 * mean(action^2)
No termination; truncated after `episode_steps` (500 steps of 0.02 s = 10 s).
Keeps ``info["goal"]`` (2,), also shown by the model's mocap marker.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo.catalog.rewards import tolerance
from mjzoo.combinators import with_reward
from mjzoo.envs import base
from mjzoo.envs.base import ASSETS
from mjzoo.planning.closed_loop import Hooks
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["push", "PUSH", "PPO", "PLANNING"]

Array = jax.Array
CONTACT_DISTANCE = 0.15  # pusher radius + cylinder radius

# PPO hyperparameters for this task (`mjzoo train ppo cylinder_push`).
PPO = dict(
    num_envs=256,
    unroll_length=32,
    num_minibatches=8,
    num_epochs=4,
    learning_rate=1e-3,
    entropy_coef=1e-3,
    discount=0.99,
    total_steps=5_000_000,
)


def _behind(data: mjx.Data, goal: Array) -> Array:
    """[2] where the pusher must be to push the cylinder straight at the goal."""
    _, cylinder = positions(data)
    to_goal = goal - cylinder
    return cylinder - CONTACT_DISTANCE * to_goal / jnp.maximum(jnp.linalg.norm(to_goal), 1e-6)


def _approach_distance(model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    pusher, _ = positions(next_state.data)
    return jnp.linalg.norm(_behind(next_state.data, next_state.info["goal"]) - pusher)


def phase_view(in_position: Array, approach_weight: Array, plan_task: Task, start: State) -> Task:
    """Pre-rollout hook, a two-phase task: until the pusher is within `in_position` (m)
    of the point behind the cylinder, the planner's view also charges
    `approach_weight` x that distance per step; once there, it plans the push alone."""
    pusher, _ = positions(start.data)
    far = jnp.linalg.norm(_behind(start.data, start.info["goal"]) - pusher) > in_position
    return with_reward(plan_task, "approach_phase", _approach_distance, -jnp.where(far, approach_weight, 0.0))


def _on_goal(states) -> tuple[bool, float]:
    """Solved when the cylinder ends within 5 cm of the goal."""
    distance = np.linalg.norm(states.data.qpos[-1, 2:4] - states.info["goal"][-1])
    return bool(distance < 0.05), float(distance)


# Sampling planners (`mjzoo plan mppi cylinder_push`): plan with 0.05 s control steps
# (1.5 s horizon), replan every 2 simulation steps (25 Hz). The planner's view drops the
# shaped approach term and plans in two phases instead (a pre-rollout hook).
_SAMPLING = dict(num_samples=32, horizon_steps=30, num_knots=4)
PLANNING = base.PlanningSetup(
    seconds=8.0,
    replan_every=2,
    plan_overrides=dict(ctrl_dt=0.05, approach_weight=0.0),
    success=_on_goal,
    hooks=Hooks(pre_rollout=Partial(phase_view, np.float32(0.05), np.float32(1.0))),
    configs={
        "predictive_sampling": _SAMPLING,
        "mppi": dict(_SAMPLING, temperature=0.05),
        "cem": dict(_SAMPLING, num_elites=4, sigma_min=0.2),
        "dial": dict(_SAMPLING, iterations=2, temperature=1.0, beta_horizon=4.0),
        "cma_es": dict(_SAMPLING, num_elites=4),
        "ilqr": dict(horizon_steps=_SAMPLING["horizon_steps"], iterations=3),
    },
)


def positions(data: mjx.Data) -> tuple[Array, Array]:
    """(pusher xy, cylinder xy)."""
    return data.qpos[0:2], data.qpos[2:4]


def observe(p: dict, model: mjx.Model, state: State) -> Array:
    """[12] pusher position and velocity, cylinder position and velocity, goal minus
    cylinder, cylinder minus pusher."""
    data, goal = state.data, state.info["goal"]
    pusher, cylinder = positions(data)
    return jnp.concatenate([pusher, data.qvel[0:2], cylinder, data.qvel[2:4], goal - cylinder, cylinder - pusher])


def start(p: dict, model: mjx.Model, data: mjx.Data, key: Array) -> tuple[mjx.Data, dict[str, Array]]:
    """Cylinder and goal uniform in [-spawn_range, spawn_range]^2, the pusher in 1.6
    times that, moved clear of the cylinder; keeps ``info["goal"]``."""
    pusher_key, cylinder_key, goal_key = jax.random.split(key, 3)
    r = p["spawn_range"]
    cylinder = jax.random.uniform(cylinder_key, (2,), minval=-r, maxval=r)
    goal = jax.random.uniform(goal_key, (2,), minval=-r, maxval=r)
    pusher = jax.random.uniform(pusher_key, (2,), minval=-1.6 * r, maxval=1.6 * r)
    # Never start overlapping: move the pusher out along the line from the cylinder.
    offset = pusher - cylinder
    gap = jnp.linalg.norm(offset)
    direction = jnp.where(gap > 1e-6, offset / jnp.maximum(gap, 1e-6), jnp.array([1.0, 0.0]))
    pusher = jnp.where(gap < 2 * CONTACT_DISTANCE, cylinder + 2 * CONTACT_DISTANCE * direction, pusher)
    data = data.replace(qpos=jnp.concatenate([pusher, cylinder]), mocap_pos=data.mocap_pos.at[0, :2].set(goal))
    return data, {"goal": goal}


def _linear(p: dict, distance: Array) -> Array:
    return tolerance(distance, margin=p["margin"], sigmoid="linear", value_at_margin=0.0)


def on_goal(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: 1 with the cylinder on the goal, 0 at `margin` m."""
    _, cylinder = positions(next_state.data)
    return _linear(p, jnp.linalg.norm(next_state.info["goal"] - cylinder))


def behind(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: 1 with the pusher right behind the cylinder (opposite the goal), 0 at
    `margin` m from there."""
    pusher, _ = positions(next_state.data)
    return _linear(p, jnp.linalg.norm(_behind(next_state.data, next_state.info["goal"]) - pusher))


def effort(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: the mean squared action, clipped to [-1, 1]."""
    return jnp.mean(jnp.square(jnp.clip(action, -1.0, 1.0)))


def push(
    *,
    episode_steps: int = 500,
    goal_weight: float = 1.0,
    approach_weight: float = 0.3,
    effort_weight: float = 0.01,
    margin: float = 1.5,
    spawn_range: float = 0.5,
    ctrl_dt: float = 0.02,
    **physics_options,
) -> Task:
    """The cylinder-push task; keyword arguments override weights and physics."""
    return mjzoo.task(
        ASSETS / "cylinder_push.xml",
        observe=observe,
        start=start,
        rewards={"goal": (on_goal, goal_weight), "approach": (behind, approach_weight)},
        costs={"effort": (effort, effort_weight)},
        time_limit=episode_steps,
        params=dict(margin=margin, spawn_range=spawn_range),
        ctrl_dt=ctrl_dt,
        # Judo's scene keeps MuJoCo's own solver limits, and so does this one: the CPU
        # planners are measured against Judo's on the same physics (mjzoo.solver.SHIPPED
        # drifts the cylinder 1.9 cm over 2 s). Named, they are a choice, not an oversight.
        **{"iterations": 100, "ls_iterations": 50, **physics_options},
    )


PUSH = base.EnvSpec(
    make=push, description="planar pusher: shove a sliding cylinder onto a goal", ppo=PPO, planning=PLANNING
)
