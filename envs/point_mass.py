"""Point mass: drive a 0.3 kg mass in a 1 m square to a target drawn at every reset.

Observation (6,): position (m), velocity (m/s), target minus position (m).
Action (2,): forces in [-1, 1] N along x and y.
Reward terms per step (each a weight times a value in [0, 1]):
  reach   +1.0  * tolerance(distance to target, upper=target_radius, margin=0.5 m)
  effort  -0.01 * mean(action^2)
No termination; truncated after `episode_steps` (250 steps of 0.02 s = 5 s).
Keeps ``info["goal"]`` (2,), the target, also shown by the model's mocap marker, and
``info["plan_cost"]``, what a planner's last rollouts predicted (0 outside planning).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo.catalog.rewards import tolerance
from mjzoo.envs import base
from mjzoo.envs.base import ASSETS
from mjzoo.planning.closed_loop import Hooks
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["reach", "REACH", "PPO", "PLANNING"]

Array = jax.Array
MASS_BODY = 2  # the mass in point_mass.xml (0: world, 1: the mocap target)

# PPO hyperparameters that solve this task (`mjzoo train ppo point_mass`).
PPO = dict(
    num_envs=256,
    unroll_length=32,
    num_minibatches=8,
    num_epochs=4,
    learning_rate=1e-3,
    entropy_coef=1e-3,
    discount=0.97,
    total_steps=2_000_000,
)


def new_goal_when_reached(radius: Array, spawn_range: Array, sim_task: Task, state: State, key: Array) -> State:
    """Post-simulation-step hook: once the mass is within `radius` (m) of its goal, a new
    goal is drawn uniformly in [-spawn_range, spawn_range]^2 (info, mocap marker and
    observation follow). The planner sees it through the state it plans from."""
    reached = jnp.linalg.norm(state.info["goal"] - state.data.qpos) < radius
    goal = jnp.where(
        reached, jax.random.uniform(key, (2,), minval=-spawn_range, maxval=spawn_range), state.info["goal"]
    )
    data = state.data.replace(mocap_pos=state.data.mocap_pos.at[0, :2].set(goal))
    return state.replace(data=data, obs=_observation(data, goal), info={**state.info, "goal": goal})


def gusts(force: Array, sim_task: Task, state: State, key: Array) -> State:
    """Pre-simulation-step hook: a gust of wind on the mass, N(0, `force`) newtons along
    x and y, drawn anew before every simulation step. The planner does not model it."""
    wind = force * jax.random.normal(key, (2,))
    xfrc = state.data.xfrc_applied.at[MASS_BODY, :2].set(wind.astype(state.data.xfrc_applied.dtype))
    return state.replace(data=state.data.replace(xfrc_applied=xfrc))


def plan_cost(state: State, planner_state) -> State:
    """Post-rollout hook: what the last batch of rollouts found, kept in the simulation's
    ``info["plan_cost"]``: the cost the planner predicts for its chosen plan (about
    -horizon x reach weight once the mass holds the goal), for logs and the viewer."""
    return state.replace(info={**state.info, "plan_cost": jnp.asarray(planner_state.cost, jnp.float32)})


def warm_start(plan_task: Task, state: State, num_knots: int) -> Array:
    """A first plan for the planners: full force straight at the goal (instead of zero)."""
    to_goal = state.info["goal"] - state.data.qpos
    direction = to_goal / jnp.maximum(jnp.max(jnp.abs(to_goal)), 1e-6)
    return jnp.broadcast_to(direction, (num_knots, 2)).astype(jnp.float32)


def goals_reached(states) -> int:
    """How many times the goal moved during a run (each move: one goal reached)."""
    goals = np.asarray(states.info["goal"])
    return int(np.sum(np.any(goals[1:] != goals[:-1], axis=-1)))


def _reaches_goals(states) -> tuple[bool, float]:
    """Solved when the mass reaches at least 3 successive goals."""
    reached = goals_reached(states)
    return reached >= 3, float(reached)


# Sampling planners (`mjzoo plan mppi point_mass`): continuous reaching, a new goal once
# one is reached (a post-simulation-step hook), in gusts of wind the planner does not
# model (a pre-simulation-step hook), its predicted cost kept (a post-rollout hook);
# 0.05 s planning steps over 1 s.
_SAMPLING = dict(num_samples=32, horizon_steps=20, num_knots=3)
PLANNING = base.PlanningSetup(
    seconds=6.0,
    replan_every=2,
    plan_overrides=dict(ctrl_dt=0.05),
    success=_reaches_goals,
    hooks=Hooks(
        warm_start=warm_start,
        post_sim_step=Partial(new_goal_when_reached, np.float32(0.05), np.float32(0.3)),
        pre_sim_step=Partial(gusts, np.float32(0.05)),
        post_rollout=plan_cost,
    ),
    configs={
        "predictive_sampling": _SAMPLING,
        "mppi": dict(_SAMPLING, temperature=0.05),
        "cem": dict(_SAMPLING, num_elites=4, sigma_min=0.2),
        "dial": dict(_SAMPLING, iterations=2, temperature=1.0, beta_horizon=4.0),
        "cma_es": dict(_SAMPLING, num_elites=4),
        "ilqr": dict(horizon_steps=_SAMPLING["horizon_steps"], iterations=3),
    },
)


def observe(p: dict, model: mjx.Model, state: State) -> Array:
    """[6] position (m), velocity (m/s), target minus position (m)."""
    return _observation(state.data, state.info["goal"])


def _observation(data: mjx.Data, goal: Array) -> Array:
    return jnp.concatenate([data.qpos, data.qvel, goal - data.qpos])


def start(p: dict, model: mjx.Model, data: mjx.Data, key: Array) -> tuple[mjx.Data, dict[str, Array]]:
    """The mass and its target uniform in [-spawn_range, spawn_range]^2 (the target also
    on the mocap marker); keeps ``info["goal"]`` and ``info["plan_cost"]`` (0)."""
    start_key, goal_key = jax.random.split(key)
    position = jax.random.uniform(start_key, (2,), minval=-p["spawn_range"], maxval=p["spawn_range"])
    goal = jax.random.uniform(goal_key, (2,), minval=-p["spawn_range"], maxval=p["spawn_range"])
    data = data.replace(qpos=position, mocap_pos=data.mocap_pos.at[0, :2].set(goal))
    return data, {"goal": goal, "plan_cost": jnp.zeros((), jnp.float32)}


def reached(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: 1 within `target_radius` m of the target, 0.1 at `reach_margin` beyond."""
    distance = jnp.linalg.norm(next_state.info["goal"] - next_state.data.qpos)
    return tolerance(distance, upper=p["target_radius"], margin=p["reach_margin"])


def effort(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: the mean squared action, clipped to [-1, 1]."""
    return jnp.mean(jnp.square(jnp.clip(action, -1.0, 1.0)))


def reach(
    *,
    episode_steps: int = 250,
    reach_weight: float = 1.0,
    effort_weight: float = 0.01,
    target_radius: float = 0.03,
    reach_margin: float = 0.5,
    spawn_range: float = 0.4,
    ctrl_dt: float = 0.02,
    **physics_options,
) -> Task:
    """The point-mass reaching task; keyword arguments override weights and physics."""
    return mjzoo.task(
        ASSETS / "point_mass.xml",
        observe=observe,
        start=start,
        rewards={"reach": (reached, reach_weight)},
        costs={"effort": (effort, effort_weight)},
        time_limit=episode_steps,
        params=dict(target_radius=target_radius, reach_margin=reach_margin, spawn_range=spawn_range),
        ctrl_dt=ctrl_dt,
        **physics_options,
    )


REACH = base.EnvSpec(
    make=reach, description="point mass: reach a target drawn at every reset", ppo=PPO, planning=PLANNING
)
