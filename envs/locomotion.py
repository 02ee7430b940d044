"""Running and standing tasks on Brax's bundled models: `mjzoo.task` of catalog items.

Each task is one `mjzoo.task` call (`gym_task`) whose pieces are catalog items built
from the loaded model, their numbers made the task's named parameters by
`mjzoo.builder.named`, so `task.with_params(min_height=0.9)` reaches them:

    physics = base.brax_asset("hopper.xml", ctrl_dt=0.008)
    m = physics.mj_model
    task = mjzoo.task(
        physics,
        observe=observations.concat(...),
        start=at_pose,                                            # Brax's pose: qpos0
        resets=(named(resets.joint_position_noise(m, 5e-3), "reset_noise"), ...),
        terminate={"too_low": named(terminations.base_too_low(m, 0.7, body="torso"), "min_height")},
        rewards={"forward": (rewards.forward_velocity(m, "torso"), 1.0), "alive": (alive, 1.0)},
        costs={"effort": (Partial(rewards.effort), 1e-3)},
        time_limit=1000,
        params={"qpos0": reset_pose(m)},
    )

Actions are the motors' controls (MuJoCo clamps them to ``ctrlrange``; PPO maps its
[-1, 1] actions onto that range), held over the physics substeps of a control step. The models are loaded at run time from
the installed brax package; physics defaults follow Brax's MJX settings (Newton solver,
few iterations, no Euler damping), each overridable like any physics option.

| task | model | control step | observation | terminated when | reward terms (weight) |
|---|---|---|---|---|---|
| hopper | hopper.xml | 0.008 s | joints but rootx, velocities (11) | torso z < 0.7 m or tilt > 0.2 rad | forward 1, alive 1, effort -1e-3 |
| walker | walker2d.xml | 0.008 s | (17) | torso z < 0.8 m or tilt > 1 rad | forward 1, alive 1, effort -1e-3 |
| cheetah | half_cheetah.xml | 0.05 s | (17) | never | forward 1, effort -0.1 |
| ant | ant.xml | 0.05 s | base z, quat, joints, base velocities, joint vel (27) | torso z < 0.2 m or > 1 m | forward 1, alive 1, effort -0.5 |
| humanoid_walk | humanoid.xml | 0.015 s | the same (45) | torso z < 1 m | forward (capped at 1.5 m/s) 1.25, alive 5, effort -0.1 |
| humanoid_run | humanoid.xml | 0.015 s | (45) | torso z < 1 m | forward 1.25, alive 5, effort -0.1 |
| humanoid_standup | humanoidstandup.xml | 0.015 s | (45) | never | torso height 1, effort -1e-3 |

"forward" is the world-x velocity of the robot's centre of mass (m/s,
`rewards.forward_velocity`), "alive" 1 per step not terminated, "effort" the sum of
squared actions. Episodes are 1000 control steps; resets add uniform noise to every
hinge joint's position and velocity.
"""

from __future__ import annotations

from typing import Any
from typing import Callable
from typing import Mapping

import jax
import mujoco
import numpy as np
from mujoco import mjx

import mjzoo
from mjzoo import names
from mjzoo import physics as physics_lib
from mjzoo.builder import alive
from mjzoo.builder import named
from mjzoo.catalog import observations
from mjzoo.catalog import resets
from mjzoo.catalog import rewards
from mjzoo.catalog import terminations
from mjzoo.envs import base
from mjzoo.types import Task

__all__ = [
    "hopper",
    "walker",
    "cheetah",
    "ant",
    "humanoid_walk",
    "humanoid_run",
    "humanoid_standup",
    "HOPPER",
    "WALKER",
    "CHEETAH",
    "ANT",
    "HUMANOID_WALK",
    "HUMANOID_RUN",
    "HUMANOID_STANDUP",
]

Array = jax.Array
Term = tuple[Callable, float]
Partial = jax.tree_util.Partial
# Brax's MJX settings for its free-floating models (fast, few solver iterations).
MJX_OPTIONS = dict(solver="newton", iterations=1, ls_iterations=4, disable_euler_damping=True)
_PLANAR = dict(solver="newton", iterations=4, ls_iterations=4, disable_euler_damping=True)


# --- the model at its pose -------------------------------------------------------------


def at_pose(p: dict, model: mjx.Model, data: mjx.Data, key: Array) -> mjx.Data:
    """Start: at rest in the pose `qpos0` [nq] (`reset_pose`)."""
    return data.replace(qpos=p["qpos0"])


def bare(physics: physics_lib.Physics, observe: Callable, actuator: Callable | None = None) -> Task:
    """The model alone: starts at rest in its pose (`reset_pose`, the parameter
    ``qpos0``), steps driven by `actuator` (a catalog actuator, e.g. `actuators.pd`;
    default: the action is the controls), observed by the item `observe`; no reward
    term, no termination, no time limit."""
    # Items of the catalog's form, (model, state) and (model, data, action, key): Partials.
    observe, actuator = (fn if fn is None or isinstance(fn, Partial) else Partial(fn) for fn in (observe, actuator))
    return mjzoo.task(
        physics,
        observe=observe,
        start=at_pose,
        actuator=actuator,
        params={"qpos0": reset_pose(physics.mj_model)},
        check=False,  # a part: the combinators wrapped around it may keep what `observe` reads
    )


def reset_pose(mj_model: mujoco.MjModel) -> np.ndarray:
    """[nq] the model's custom numeric ``init_qpos`` where it has one (Brax's convention:
    the ant's ankles, whose ranges exclude 0), else its ``qpos0``."""
    for i in range(mj_model.nnumeric):
        if mj_model.numeric(i).name == "init_qpos" and mj_model.numeric(i).data.shape == (mj_model.nq,):
            return np.asarray(mj_model.numeric(i).data)
    return np.asarray(mj_model.qpos0)


def actuated_pose(mj_model: mujoco.MjModel) -> np.ndarray:
    """[nu] the reset pose (`reset_pose`) of the joint each actuator drives: the default
    targets of PD actuators (`actuators.pd`), whose order is the actuators', not the joints'."""
    return reset_pose(mj_model)[mj_model.jnt_qposadr[mj_model.actuator_trnid[:, 0]]]


def free_base_observation(mj_model) -> Callable:
    """Base height, orientation (quat), hinge positions, base linear and angular velocity
    (base frame), hinge velocities: [1 + 4 + J + 3 + 3 + J]. No x, y: where the robot
    is should not change what it does."""
    return observations.concat(
        observations.base_height(mj_model),
        observations.base_orientation(mj_model),
        observations.joint_positions,
        observations.base_linear_velocity(mj_model),
        observations.base_angular_velocity(mj_model),
        observations.joint_velocities,
    )


def _planar_observation(mj_model) -> Callable:
    """Every joint position but the horizontal rootx, and every velocity."""
    hinges = [n for n in names.all_names(mj_model, "joint") if n != "rootx"]
    return observations.concat(observations.joint_positions_of(mj_model, hinges), observations.joint_velocities)


# --- the gym-style task -------------------------------------------------------------


def gym_task(
    physics: physics_lib.Physics,
    observe: Callable,
    *,
    progress: Mapping[str, Term],
    fallen: Mapping[str, Callable] | None,
    alive_weight: float,
    effort_weight: float,
    reset_noise: float,
    episode_steps: int,
) -> Task:
    """The model started at its pose (``qpos0``) with joint noise U(+-reset_noise)
    (rad, rad/s), ended by the `fallen` terminations, paid the `progress` reward terms
    and alive (if `fallen`), charged effort, truncated after `episode_steps`."""
    m = physics.mj_model
    noise = (
        named(resets.joint_position_noise(m, reset_noise), "reset_noise"),
        named(resets.joint_velocities(m, reset_noise), "reset_noise"),
    )
    terms = dict(progress)
    if fallen:
        terms["alive"] = (alive, alive_weight)
    return mjzoo.task(
        physics,
        observe=observe,
        start=at_pose,
        resets=noise,
        terminate=fallen or None,
        rewards=terms,
        costs={"effort": (Partial(rewards.effort), effort_weight)},
        time_limit=episode_steps,
        params={"qpos0": reset_pose(m)},
    )


def _upright_torso(
    m, min_height: float, max_tilt: float | None = None, max_height: float | None = None
) -> dict[str, Callable]:
    fallen = {"too_low": named(terminations.base_too_low(m, min_height, body="torso"), "min_height")}
    if max_height is not None:
        fallen["too_high"] = named(terminations.base_too_high(m, max_height, body="torso"), "max_height")
    if max_tilt is not None:
        fallen["tilted"] = named(terminations.not_upright(m, max_tilt, body="torso"), "max_tilt")
    return fallen


# --- planar runners -----------------------------------------------------------------


def _planar(
    asset: str,
    min_height: float | None,
    max_tilt: float | None,
    forward_weight: float,
    alive_weight: float,
    effort_weight: float,
    reset_noise: float,
    episode_steps: int,
    physics_options: dict[str, Any],
) -> Task:
    physics = base.brax_asset(asset, **physics_options)
    m = physics.mj_model
    return gym_task(
        physics,
        _planar_observation(m),
        progress={"forward": (rewards.forward_velocity(m, "torso"), forward_weight)},
        fallen=None if min_height is None else _upright_torso(m, min_height, max_tilt),
        alive_weight=alive_weight,
        effort_weight=effort_weight,
        reset_noise=reset_noise,
        episode_steps=episode_steps,
    )


def hopper(
    *,
    episode_steps: int = 1000,
    forward_weight: float = 1.0,
    alive_weight: float = 1.0,
    effort_weight: float = 1e-3,
    min_height: float = 0.7,
    max_tilt: float = 0.2,
    reset_noise: float = 5e-3,
    ctrl_dt: float = 0.008,
    **physics_options,
) -> Task:
    """One-legged hopper running along +x (Brax's hopper.xml)."""
    options = {**_PLANAR, "ctrl_dt": ctrl_dt, **physics_options}
    return _planar(
        "hopper.xml",
        min_height,
        max_tilt,
        forward_weight,
        alive_weight,
        effort_weight,
        reset_noise,
        episode_steps,
        options,
    )


def walker(
    *,
    episode_steps: int = 1000,
    forward_weight: float = 1.0,
    alive_weight: float = 1.0,
    effort_weight: float = 1e-3,
    min_height: float = 0.8,
    max_tilt: float = 1.0,
    reset_noise: float = 5e-3,
    ctrl_dt: float = 0.008,
    **physics_options,
) -> Task:
    """Planar biped walker running along +x (Brax's walker2d.xml)."""
    options = {**_PLANAR, "ctrl_dt": ctrl_dt, **physics_options}
    return _planar(
        "walker2d.xml",
        min_height,
        max_tilt,
        forward_weight,
        alive_weight,
        effort_weight,
        reset_noise,
        episode_steps,
        options,
    )


def cheetah(
    *,
    episode_steps: int = 1000,
    forward_weight: float = 1.0,
    effort_weight: float = 0.1,
    reset_noise: float = 0.1,
    ctrl_dt: float = 0.05,
    **physics_options,
) -> Task:
    """Planar half-cheetah running along +x (Brax's half_cheetah.xml); never terminates."""
    options = {**_PLANAR, "ctrl_dt": ctrl_dt, **physics_options}
    return _planar(
        "half_cheetah.xml", None, None, forward_weight, 0.0, effort_weight, reset_noise, episode_steps, options
    )


# --- free-floating runners ----------------------------------------------------------


def ant(
    *,
    episode_steps: int = 1000,
    forward_weight: float = 1.0,
    alive_weight: float = 1.0,
    effort_weight: float = 0.5,
    min_height: float = 0.2,
    max_height: float | None = 1.0,
    reset_noise: float = 0.1,
    ctrl_dt: float = 0.05,
    **physics_options,
) -> Task:
    """Four-legged ant running along +x (Brax's ant.xml). Its torso must stay between
    `min_height` and `max_height` (m): without the ceiling PPO learns to bounce metres
    high off the soft contacts instead of running."""
    options = {**MJX_OPTIONS, "ctrl_dt": ctrl_dt, **physics_options}
    return _free_runner(
        "ant.xml",
        None,
        episode_steps,
        forward_weight,
        alive_weight,
        effort_weight,
        min_height,
        max_height,
        reset_noise,
        options,
    )


def _free_runner(
    asset: str,
    max_speed: float | None,
    episode_steps: int,
    forward_weight: float,
    alive_weight: float,
    effort_weight: float,
    min_height: float,
    max_height: float | None,
    reset_noise: float,
    options: dict[str, Any],
) -> Task:
    physics = base.brax_asset(asset, **options)
    m = physics.mj_model
    forward = rewards.forward_velocity(m, max_speed=max_speed)
    if max_speed is not None:
        forward = named(forward, "max_speed")
    return gym_task(
        physics,
        free_base_observation(m),
        progress={"forward": (forward, forward_weight)},
        fallen=_upright_torso(m, min_height, max_height=max_height),
        alive_weight=alive_weight,
        effort_weight=effort_weight,
        reset_noise=reset_noise,
        episode_steps=episode_steps,
    )


def humanoid_walk(
    *,
    episode_steps: int = 1000,
    forward_weight: float = 1.25,
    max_speed: float = 1.5,
    alive_weight: float = 5.0,
    effort_weight: float = 0.1,
    min_height: float = 1.0,
    reset_noise: float = 0.01,
    ctrl_dt: float = 0.015,
    **physics_options,
) -> Task:
    """Humanoid walking along +x (Brax's humanoid.xml); speed beyond `max_speed` (m/s)
    earns nothing more."""
    options = {**MJX_OPTIONS, "ctrl_dt": ctrl_dt, **physics_options}
    return _free_runner(
        "humanoid.xml",
        max_speed,
        episode_steps,
        forward_weight,
        alive_weight,
        effort_weight,
        min_height,
        None,
        reset_noise,
        options,
    )


def humanoid_run(
    *,
    episode_steps: int = 1000,
    forward_weight: float = 1.25,
    alive_weight: float = 5.0,
    effort_weight: float = 0.1,
    min_height: float = 1.0,
    reset_noise: float = 0.01,
    ctrl_dt: float = 0.015,
    **physics_options,
) -> Task:
    """Humanoid running along +x as fast as it can (Brax's humanoid.xml)."""
    options = {**MJX_OPTIONS, "ctrl_dt": ctrl_dt, **physics_options}
    return _free_runner(
        "humanoid.xml",
        None,
        episode_steps,
        forward_weight,
        alive_weight,
        effort_weight,
        min_height,
        None,
        reset_noise,
        options,
    )


def humanoid_standup(
    *,
    episode_steps: int = 1000,
    height_weight: float = 1.0,
    effort_weight: float = 1e-3,
    reset_noise: float = 0.01,
    ctrl_dt: float = 0.015,
    **physics_options,
) -> Task:
    """Humanoid getting up from lying on its back (Brax's humanoidstandup.xml): reward
    the torso's height (m) per step; never terminates."""
    physics = base.brax_asset("humanoidstandup.xml", **{**MJX_OPTIONS, "ctrl_dt": ctrl_dt, **physics_options})
    m = physics.mj_model
    return gym_task(
        physics,
        free_base_observation(m),
        progress={"height": (rewards.body_height(m, "torso"), height_weight)},
        fallen=None,
        alive_weight=0.0,
        effort_weight=effort_weight,
        reset_noise=reset_noise,
        episode_steps=episode_steps,
    )


# PPO hyperparameters (`mjzoo train ppo <task>`, benchmarks/locomotion.py), after Brax's
# published ones for these models (Brax collects batch x minibatches sequences of `unroll`
# steps per update; here each env collects that many steps in one unroll).
_BRAX = dict(
    num_minibatches=32,
    learning_rate=3e-4,
    discount=0.97,
    clip_epsilon=0.3,
    max_grad_norm=None,
    policy_hidden_sizes=(32,) * 4,
    value_hidden_sizes=(256,) * 5,
    activation="swish",
)
_HUMANOID = dict(
    _BRAX, num_envs=2048, unroll_length=160, num_epochs=8, entropy_coef=1e-3, reward_scaling=0.1, total_steps=50_000_000
)
PPO = {
    "hopper": dict(_BRAX, num_envs=2048, unroll_length=160, num_epochs=8, entropy_coef=1e-3, total_steps=20_000_000),
    "walker": dict(_BRAX, num_envs=2048, unroll_length=160, num_epochs=8, entropy_coef=1e-3, total_steps=20_000_000),
    "cheetah": dict(
        _BRAX, num_envs=2048, unroll_length=160, num_epochs=8, entropy_coef=1e-3, discount=0.95, total_steps=50_000_000
    ),
    "ant": dict(
        _BRAX,
        num_envs=4096,
        unroll_length=80,
        num_epochs=4,
        entropy_coef=1e-2,
        reward_scaling=10.0,
        total_steps=50_000_000,
    ),
    "humanoid_walk": _HUMANOID,
    "humanoid_run": _HUMANOID,
    "humanoid_standup": dict(
        _HUMANOID, unroll_length=240, learning_rate=6e-4, entropy_coef=1e-2, total_steps=100_000_000
    ),
}


HOPPER = base.EnvSpec(make=hopper, description="Brax's one-legged hopper running along +x", ppo=PPO["hopper"])
WALKER = base.EnvSpec(make=walker, description="Brax's planar biped walker running along +x", ppo=PPO["walker"])
CHEETAH = base.EnvSpec(make=cheetah, description="Brax's planar half-cheetah running along +x", ppo=PPO["cheetah"])
ANT = base.EnvSpec(make=ant, description="Brax's four-legged ant running along +x", ppo=PPO["ant"])
HUMANOID_WALK = base.EnvSpec(
    make=humanoid_walk, description="Brax's humanoid walking along +x (up to 1.5 m/s)", ppo=PPO["humanoid_walk"]
)
HUMANOID_RUN = base.EnvSpec(make=humanoid_run, description="Brax's humanoid running along +x", ppo=PPO["humanoid_run"])
HUMANOID_STANDUP = base.EnvSpec(
    make=humanoid_standup, description="Brax's humanoid getting up from its back", ppo=PPO["humanoid_standup"]
)
