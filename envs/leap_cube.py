"""Dexterous manipulation: the LEAP hand turns a cube in its palm to goal orientations,
one after another (the flagship task of the sampling-MPC peers Judo and Hydrax). Its
reward is dense and smooth, made for sampling planners (`PLANNING`: ``mjzoo plan mppi
leap_cube_rotate``); PPO trains on it as on any task.

    task = leap_cube.leap_cube_rotate()
    mjzoo.find(state, leap_cube.CubeGoalState).reached  # goals reached this episode

It runs on Playground's LEAP hand cube scene (``scene_mjx_cube.xml``: the right hand
palm up, a 7 cm cube, the scene's 0.01 s Euler step) at a 0.05 s control step (20 Hz,
a rate the real hand's servos take). It starts in the scene's home keyframe (hand joint
noise U(+-0.05 rad)), with a goal orientation drawn uniformly over all rotations. The
hand's servos are driven to ``home + action`` (rad, clipped to their ranges). When the
cube comes within `goal_tolerance` (0.4 rad, Judo's) of its goal, a new goal is drawn
and the count of goals reached rises (`with_cube_goal`; the goal is mirrored to the
scene's mocap cube for the viewer, and appended to the observation).

Reward terms (weights): goals reached (10 each); costs: the cube's orientation error to
its goal, squared (1.0, rad^2), its distance from the palm's grasp site, squared (1000.0,
m^2; Judo weighs the two in this ratio), dropped (100.0 a step while it lies below
`drop_height`), hand joint velocities squared (1e-4), action rate (0.01). Terminated
when the cube drops below -0.05 m (4 cm under the palm, Playground's); 30 s episodes.
Solved when it reaches 10 goals in a row without a drop. The planners' model never
reaches a goal (tolerance 0): a goal redrawn at random inside the horizon would teach
them to stop short of reaching one.
"""

from __future__ import annotations

import functools
import math
from typing import Any
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial

import mjzoo
from mjzoo import checks
from mjzoo import names
from mjzoo import physics as physics_lib
from mjzoo.builder import named
from mjzoo.catalog import actuators
from mjzoo.catalog import observations
from mjzoo.catalog import resets
from mjzoo.catalog import rewards
from mjzoo.catalog import trackers
from mjzoo.catalog import tracking
from mjzoo.envs import base
from mjzoo.envs.locomotion import at_pose
from mjzoo.layers import find
from mjzoo.layers import layered
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.robots import scenes
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "leap_cube_rotate",
    "with_cube_goal",
    "orientation_cost",
    "hold_cost",
    "cube_dropped",
    "random_orientation",
    "goals_in_a_row",
    "CubeGoalState",
    "LEAP_CUBE_ROTATE",
]

Array = jax.Array
SCENE = "scene_mjx_cube.xml"
GOAL_STREAM = 0x60A1  # fold_in tag: the inner task keeps its own key
GOALS_TO_SOLVE = 10


@functools.lru_cache(maxsize=4)
def _scene(options: tuple[tuple[str, Any], ...]) -> physics_lib.Physics:
    """Playground's LEAP hand cube scene at a 0.05 s control step."""
    return scenes.load("leap_hand", scene=SCENE, **{"ctrl_dt": 0.05, **dict(options)})


# --- orientations -------------------------------------------------------------------------


def random_orientation(key: Array) -> Array:
    """[4] a unit quaternion (wxyz) uniform over all rotations (Shoemake's method)."""
    u, v, w = jax.random.uniform(key, (3,))
    a, b = jnp.sqrt(1.0 - u), jnp.sqrt(u)
    return jnp.stack(
        [
            a * jnp.sin(2 * jnp.pi * v),
            a * jnp.cos(2 * jnp.pi * v),
            b * jnp.sin(2 * jnp.pi * w),
            b * jnp.cos(2 * jnp.pi * w),
        ]
    )


# --- the goal -------------------------------------------------------------------------------


class CubeGoalState(NamedTuple):
    """`with_cube_goal`'s record: ``goal`` float32 [4] the cube's goal orientation (unit
    quaternion wxyz, world frame), ``reached`` int32 [] goals reached this episode."""

    goal: Array
    reached: Array
    inner: Any = ()


def with_cube_goal(task: Task, mj_model: mujoco.MjModel, tolerance: float = 0.4, body: str = "cube") -> Task:
    """`task` with a goal orientation for `body`'s free joint, drawn uniformly at reset
    and again at the end of any step that leaves the body within `tolerance` rad of it
    (which counts one goal reached; 0: never reached, never redrawn). The goal is
    appended to the (1-D) observation, as a command is, and written to the model's first
    mocap body (a goal marker), if it has one. Metrics: ``goal/reached`` (1 at a step
    that reached one). Rewards read the goal an action was for from `state`."""
    tolerance = checks.number("with_cube_goal", "tolerance", tolerance, 0.0, math.pi)
    quat = names.free_joint_addresses(mj_model, body, "with_cube_goal")[0][3:]
    numbers = {"goal_tolerance": jnp.float32(tolerance)}  # a dict key names it: `with_params` reaches it
    step = Partial(_goal_step, task.step, jnp.asarray(quat), numbers)
    return layered(task, CubeGoalState, Partial(_goal_reset, task.start), step)


def _publish(state: State, inner_obs: Array, record: CubeGoalState) -> State:
    data = state.data
    if data.mocap_quat.shape[0]:  # the scene's goal marker
        data = data.replace(mocap_quat=data.mocap_quat.at[0].set(record.goal))
    obs = jnp.concatenate([inner_obs, record.goal.astype(inner_obs.dtype)])
    return wrap(state.replace(data=data, obs=obs), record)


def _goal_reset(reset_fn, model, key) -> State:
    state = reset_fn(model, key)
    goal = random_orientation(jax.random.fold_in(key, GOAL_STREAM))
    return _publish(state, state.obs, CubeGoalState(goal, jnp.int32(0)))


def _goal_step(step_fn, quat, numbers: dict, model, state: State, action, key) -> State:
    record, inner = peel(state, CubeGoalState)
    next_state = step_fn(model, inner.replace(obs=state.obs[:-4]), action, key)
    hit = tracking.quat_angle(next_state.data.qpos[quat], record.goal) < numbers["goal_tolerance"]
    goal = jnp.where(hit, random_orientation(jax.random.fold_in(key, GOAL_STREAM)), record.goal)
    next_state = next_state.replace(metrics={**next_state.metrics, "goal/reached": hit.astype(jnp.float32)})
    return _publish(next_state, next_state.obs, CubeGoalState(goal, record.reached + hit.astype(jnp.int32)))


# --- terms ----------------------------------------------------------------------------------


def _goals(p, model, state: State, action: Array, next_state: State) -> Array:
    """Reward: the goals this transition reached (0 or 1)."""
    return (find(next_state, CubeGoalState).reached - find(state, CubeGoalState).reached).astype(jnp.float32)


def orientation_cost(mj_model: mujoco.MjModel, body: str = "cube") -> Partial:
    """Cost: the orientation error (rad) of `body`'s free joint to the goal the action
    was for (`CubeGoalState` in `state`), squared: smooth, and steep far from the goal."""
    return Partial(_orientation, jnp.asarray(names.free_joint_addresses(mj_model, body, "orientation_cost")[0][3:]))


def _orientation(quat, model, state: State, action: Array, next_state: State) -> Array:
    return jnp.square(tracking.quat_angle(next_state.data.qpos[quat], find(state, CubeGoalState).goal))


def hold_cost(mj_model: mujoco.MjModel, position: Array, body: str = "cube") -> Partial:
    """Cost: the squared distance (m^2) of `body`'s free joint position from `position` [3] (m)."""
    xyz = names.free_joint_addresses(mj_model, body, "hold_cost")[0][:3]
    return Partial(_hold, jnp.asarray(xyz), jnp.asarray(position, jnp.float32))


def _hold(xyz, position, model, state: State, action: Array, next_state: State) -> Array:
    return jnp.sum(jnp.square(next_state.data.qpos[xyz] - position))


def cube_dropped(mj_model: mujoco.MjModel, height: float, body: str = "cube") -> Partial:
    """Termination: `body`'s free joint position is below `height` (m, world z)."""
    height = checks.number("cube_dropped", "height", height)
    return Partial(_below, jnp.int32(names.free_joint_addresses(mj_model, body, "cube_dropped")[0][2]), height)


def _below(z, height, model, state: State) -> Array:
    return state.data.qpos[z] < height


def _dropped(z, height, model, state: State, action: Array, next_state: State) -> Array:
    """Cost: 1 while the cube lies below the drop height, else 0."""
    return _below(z, height, model, next_state).astype(jnp.float32)


def _hand_velocity(dofs, model, state: State, action: Array, next_state: State) -> Array:
    """Cost: the hand's joint velocities squared, (rad/s)^2 summed."""
    return jnp.sum(jnp.square(next_state.data.qvel[dofs]))


def _cube_pose(qpos_idx, qvel_idx, model, state: State) -> Array:
    """Observation: the cube's position (m), orientation (wxyz) and velocities [13]."""
    return jnp.concatenate([state.data.qpos[qpos_idx], state.data.qvel[qvel_idx]]).astype(jnp.float32)


def leap_cube_rotate(
    *,
    goal_tolerance: float = 0.4,
    drop_height: float = -0.05,
    action_scale: float = 1.0,
    episode_steps: int = 600,
    **physics_options: Any,
) -> Task:
    """The LEAP hand turning a cube to goal orientations (module docstring); physics
    options override the scene's."""
    physics = _scene(tuple(sorted(physics_options.items())))
    m = physics.mj_model
    home = np.asarray(m.key_qpos[0], np.float32)
    cube, cube_dofs = (jnp.asarray(a) for a in names.free_joint_addresses(m, "cube", "leap_cube_rotate"))
    dofs = jnp.asarray(names.joint_addresses(m, names.joints(m, None, "leap_cube_rotate"), True))
    grasp = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, grasp, 0)
    mujoco.mj_kinematics(m, grasp)  # the palm is fixed: its grasp site is where the cube is held
    hold = np.asarray(grasp.site("grasp_site").xpos, np.float32)
    dropped = cube_dropped(m, drop_height)
    return mjzoo.task(
        physics,
        observe=observations.concat(
            observations.joint_positions, observations.joint_velocities, Partial(_cube_pose, cube, cube_dofs)
        ),
        start=at_pose,
        resets=(named(resets.joint_position_noise(m, 0.05), "reset_noise"),),
        actuator=actuators.position_targets(m, action_scale),
        combinators=(
            functools.partial(trackers.with_action_history, length=2, observe=True),
            functools.partial(with_cube_goal, mj_model=m, tolerance=goal_tolerance),
        ),
        rewards={"goals": (_goals, 10.0)},
        costs={
            "orientation": (orientation_cost(m), 1.0),
            "position": (named(hold_cost(m, hold), "hold_position"), 1000.0),
            "dropped": (named(Partial(_dropped, *dropped.args), "drop_height"), 100.0),
            "hand_velocity": (Partial(_hand_velocity, dofs), 1e-4),
            "action_rate": (Partial(rewards.action_rate), 0.01),
        },
        terminate={"dropped": named(dropped, "drop_height")},
        time_limit=episode_steps,
        params={"qpos0": jnp.asarray(home)},
    )


def goals_in_a_row(states, goals: int = GOALS_TO_SOLVE) -> tuple[bool, float]:
    """Solved when `goals` goals are reached before the cube first drops (a drop ends
    the run of goals); the score is the goals reached by then. `states` [T]: the run's
    stacked states (numpy leaves)."""
    reached = np.asarray(find(states, CubeGoalState).reached)
    dropped = np.flatnonzero(np.asarray(states.terminated))
    in_a_row = int(reached[dropped[0]] if dropped.size else reached[-1])
    return in_a_row >= goals, float(in_a_row)


# Judo's shipped LEAP settings: 32 samples over 1 s (20 control steps, 4 knots), noise
# 0.2 rad widening 5x along the horizon, replanning every step (20 Hz), on a CPU's native
# rollouts (a GPU's MJX step of this scene costs 2.4 ms at 1024 samples: 4 replans a
# second over 1 s). Their model never reaches a goal (module docstring). A run lasts 120 s:
# a goal takes 4-12 s on 2 CPU cores, so 40 s runs rarely had time for 10 of them.
PLANNING = base.sampling_setup(
    120.0,
    functools.partial(goals_in_a_row, goals=GOALS_TO_SOLVE),
    num_samples=32,
    horizon_steps=20,
    num_knots=4,
    noise_scale=0.2,
    noise_ramp=4.0,
    plan_overrides={"goal_tolerance": 0.0},
)
LEAP_CUBE_ROTATE = base.EnvSpec(
    make=leap_cube_rotate,
    description="LEAP hand turning a cube to goal orientations, one after another (MPC-friendly)",
    planning=PLANNING,
)
