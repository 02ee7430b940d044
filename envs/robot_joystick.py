"""Joysticks for real robots: the Unitree G1 and Go1, the Booster T1 and the Berkeley
Humanoid follow velocity commands on flat ground or on a terrain grid.

Each is one `mjzoo.task` of catalog items on the robot's MJX scene from MuJoCo
Playground (feet-only collisions; `mjzoo.robots.scenes`), its models from
`mjzoo.robots` (``pip install 'mjzoo[robots]'`` puts them on disk). Innermost first:

  the robot in its standing keyframe, joint noise U(±0.1 rad) and a random heading (on a
  terrain: over the platform of a tile the curriculum picks); its own ``<position>``
  servos driven to ``pose + action_scale * action`` (`actuators.position_targets`: the
  robot's kp, kv and force limits) with a latency of U{0, 1} control steps; the last two
  actions (action rate); the feet (air time, slip, clearance); a velocity command
  [vx, vy, yaw rate] redrawn every 5-10 s, standing still with probability 0.1;
  observation noise; physics drawn every episode (friction x U(0.4, 1.25), link masses x
  U(0.9, 1.1), COM shifts of U(±2 cm), servo strength x U(0.8, 1.2), joint damping x
  U(0.8, 1.2), armature x U(1, 1.05)); velocity pushes of up to `push` m/s every 5-10 s;
  the divergence guard and a 20 s time limit.

Observation, a dict (PPO's ``policy_obs_key="state"``, ``value_obs_key="privileged_state"``;
`observations.with_privileged_observation`):
  state             gyro (3), projected gravity (3), joint positions and velocities
                    (each with N(0, noise^2) noise), the last action (nu), the command
                    (3): what a robot has, and all an exported policy reads
  privileged_state  the same, then without noise the base's linear velocity (3) and
                    height (1), the feet's contacts, and on a terrain the height scan
                    (11 x 7 points, 0.1 m apart) under the base: the critic's view
Reward terms (weights, named parameters): velocity tracking exp(-|v_xy - c_xy|^2 / 0.25)
(1.0) and yaw-rate tracking (0.5); feet air time past 0.1 s while commanded to move
(0.5 quadruped, 1.0 humanoids), alive (1 a step not terminated: 2.0 humanoids, 0
quadruped); costs: vertical velocity^2 (2.0), roll/pitch rate^2
(0.05), tilt sin^2 (5.0), base height from the keyframe's (10), action rate (0.01),
torque^2 (2e-4 quadruped, 0 humanoids), joint limits past 95% (1.0), foot slip (0.1), standing still at zero
command (0.5). Terminated when tilted over 1 rad or the base drops below `min_height`.
With `gait_frequency` (Hz) the robot also observes a stepping clock (`catalog.gait`: cos
and sin of each foot's phase; a biped's feet half a cycle apart, the Go1's diagonal pairs
together) and is paid 1.0 for lifting its feet along the clock's 0.15 m curve while it
moves or is commanded to (`feet_phase`; Playground's G1 runs its clock at 1.25-1.5 Hz).

Terrains: "flat" (the scene's plane), "rough" (rough, slopes up and down: 6 rows of
difficulty), "stairs" (stairs up and down). On a terrain each environment starts on a
tile of its curriculum row, a row harder after it walked 2 m in an episode, a row easier
after a fall (`mjzoo.robots.terrain.by_walked_distance`).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax.numpy as jnp
from jax.tree_util import Partial

import mjzoo
from mjzoo import motion
from mjzoo import physics as physics_lib
from mjzoo.builder import alive
from mjzoo.builder import named
from mjzoo.catalog import actuators
from mjzoo.catalog import commands
from mjzoo.catalog import curriculum
from mjzoo.catalog import events
from mjzoo.catalog import gait
from mjzoo.catalog import observations
from mjzoo.catalog import randomizers
from mjzoo.catalog import resets
from mjzoo.catalog import rewards
from mjzoo.catalog import terminations
from mjzoo.catalog import trackers
from mjzoo.combinators import with_auto_reset
from mjzoo.envs import base
from mjzoo.envs.locomotion import at_pose
from mjzoo.perturbations import with_domain_randomization
from mjzoo.perturbations import with_observation_noise
from mjzoo.robots import scenes
from mjzoo.robots import terrain as terrain_lib
from mjzoo.types import Task

__all__ = [
    "Robot",
    "ROBOTS",
    "TERRAINS",
    "robot_joystick",
    "G1",
    "T1",
    "GO1",
    "BERKELEY_HUMANOID",
    "PPO",
    "HUMANOID_PPO",
]


@dataclasses.dataclass(frozen=True)
class Robot:
    """What a joystick needs to know of one robot's scene."""

    name: str  # Menagerie's folder (`mjzoo.robots.menagerie`)
    feet: tuple[str, ...]  # foot geoms
    min_height: float  # m: terminated below
    action_scale: float  # rad per unit of action
    air_time_weight: float
    # Per step survived, and the torque cost's weight. A humanoid held at its pose by its
    # servos falls within ~1 s, and under PPO's first exploration noise (actions
    # tanh(N(0, 0.69^2))) its costs outweighed its rewards (G1: -2.15 a step alive, of
    # which torque^2 -1.32): falling early was what the return paid for. Humanoids pay 2
    # a step up and no torque cost (Playground's G1 and T1 have none): +0.15 a step (T1
    # +1.03, Berkeley Humanoid +0.92) under that noise.
    alive_weight: float = 0.0
    torque_weight: float = 2e-4
    # The yaw-rate tracking reward's weight (the speed's is 1). The G1 at 0.5 learnt to
    # follow the speed but hardly to turn (|w - cmd| 0.34 rad/s after 78.6M steps on one
    # seed); at 1.0 it tracked both by then (0.19; benchmarks/results/robots).
    yaw_tracking_weight: float = 0.5


ROBOTS = {
    "g1": Robot("unitree_g1", ("left_foot", "right_foot"), 0.4, 0.5, 1.0, 2.0, 0.0, yaw_tracking_weight=1.0),
    "t1": Robot("booster_t1", ("left_foot_1", "right_foot_1"), 0.35, 1.0, 1.0, 2.0, 0.0),
    "berkeley_humanoid": Robot("berkeley_humanoid", ("l_foot1", "r_foot1"), 0.25, 0.5, 1.0, 2.0, 0.0),
    "go1": Robot("unitree_go1", ("FR", "FL", "RR", "RL"), 0.12, 0.5, 0.5),
}
TERRAINS = {"flat": None, "rough": ("rough", "slope_up", "slope_down"), "stairs": ("stairs_up", "stairs_down")}
ROWS = 6
# PPO after Playground's for its joysticks (Brax PPO on 8192 envs, 4x128 policy, 5x256 critic).
PPO = dict(
    num_envs=8192,
    unroll_length=20,
    num_minibatches=32,
    num_epochs=4,
    learning_rate=3e-4,
    entropy_coef=1e-2,
    discount=0.97,
    clip_epsilon=0.2,
    max_grad_norm=1.0,
    policy_hidden_sizes=(512, 256, 128),
    value_hidden_sizes=(512, 256, 128),
    activation="swish",
    policy_obs_key="state",
    value_obs_key="privileged_state",
    total_steps=100_000_000,
)
HUMANOID_PPO = dict(PPO, entropy_coef=5e-3, lr_schedule="constant")  # Playground's for its G1, T1, Berkeley Humanoid


@functools.lru_cache(maxsize=16)
def _scene(robot: str, terrain: str, options: tuple[tuple[str, Any], ...]):
    """(physics, terrain grid or None): one compile per robot, terrain and options."""
    kinds = TERRAINS[terrain]
    grid = None if kinds is None else terrain_lib.grid(kinds, rows=ROWS, tile_size=8.0, resolution=0.1)
    return scenes.load(ROBOTS[robot].name, grid, **{"ctrl_dt": 0.02, **dict(options)}), grid


def robot_joystick(
    robot: str = "go1",
    *,
    terrain: str = "flat",
    level: float = 0.0,
    episode_steps: int = 1000,
    push: float = 0.5,
    noise: float = 0.02,
    max_action_latency: int = 1,
    vx: tuple[float, float] = (-1.0, 1.0),
    vy: tuple[float, float] = (-0.5, 0.5),
    yaw_rate: tuple[float, float] = (-1.0, 1.0),
    reference: motion.Reference | None = None,
    reference_probability: float = 0.5,
    gait_frequency: float | None = None,
    **physics_options: Any,
) -> Task:
    """`robot`'s joystick (one of `ROBOTS`) on `terrain` (one of `TERRAINS`); on a
    terrain, starting on row ``round(level * 5)`` (a curriculum moves `level`). The
    command [`vx`, `vy`, `yaw_rate`] is drawn from those ranges (m/s, rad/s). With a
    `reference` (motion of this robot's model, at its control step), an episode starts at
    one of its frames with `reference_probability` (reference-state initialization)."""
    if robot not in ROBOTS:
        raise ValueError(f"robot_joystick: robot={robot!r} is unknown; the robots: {sorted(ROBOTS)}")
    if terrain not in TERRAINS:
        raise ValueError(f"robot_joystick: terrain={terrain!r} is unknown; the terrains: {sorted(TERRAINS)}")
    if reference is not None and TERRAINS[terrain] is not None:
        raise ValueError(
            f"robot_joystick: a reference starts episodes where its clip's root was: flat terrain only, not {terrain!r}"
        )
    spec = ROBOTS[robot]
    physics, grid = _scene(robot, terrain, tuple(sorted(physics_options.items())))
    m = physics.mj_model
    clock, stepping = (), {}
    if gait_frequency is not None:
        offsets = gait.BIPED if len(spec.feet) == 2 else gait.TROT
        clock = (gait.clock(gait_frequency, offsets),)
        stepping = {"feet_phase": (gait.feet_phase(m, spec.feet, gait_frequency, offsets), 1.0)}
    sensed = observations.concat(  # what the robot's IMU and encoders give (and its gait clock)
        observations.base_angular_velocity(m),
        observations.projected_gravity(m),
        observations.joint_positions,
        observations.joint_velocities,
        *clock,
    )
    privileged = (
        observations.base_linear_velocity(m),
        observations.base_height(m),
        observations.geom_contacts(m, spec.feet, "floor"),
    )
    if grid is not None:
        privileged += (terrain_lib.height_scan(m),)
    start = (terrain_lib.start_on_tile(m, grid, level=level),) if grid is not None else ()
    if reference is not None:  # after the noise and heading: a reference frame replaces the state
        start += (resets.reference_state(reference, reference_probability),)
    physics_draw = randomizers.combine(
        randomizers.scale_friction(m, 0.4, 1.25),
        randomizers.scale_masses(m, 0.9, 1.1),
        randomizers.shift_com(m, 0.02),
        randomizers.scale_position_gains(m, 0.8, 1.2),
        randomizers.scale_damping(m, 0.8, 1.2),
        randomizers.scale_armature(m, 1.0, 1.05),
    )
    layers = (
        functools.partial(actuators.with_action_latency, max_latency=max_action_latency),
        functools.partial(with_observation_noise, scale=noise),  # on the sensors alone
        functools.partial(trackers.with_action_history, length=2, observe=True),
        functools.partial(trackers.with_feet, feet=spec.feet, floor="floor"),
        functools.partial(
            commands.with_velocity_command,
            vx=vx,
            vy=vy,
            yaw_rate=yaw_rate,
            resample_interval=(5.0, 10.0),
            stand_probability=0.1,
        ),
        functools.partial(with_domain_randomization, randomize=physics_draw),
        functools.partial(events.with_velocity_pushes, interval=(5.0, 10.0), linear=(push, push, 0.0)),
        functools.partial(observations.with_privileged_observation, observe=observations.concat(*privileged)),
    )
    return mjzoo.task(
        physics,
        observe=sensed,
        start=at_pose,
        resets=(
            named(resets.joint_position_noise(m, 0.1), "reset_noise"),
            resets.base_heading(m),
            *start,
        ),
        actuator=actuators.position_targets(m, spec.action_scale),
        combinators=layers,
        rewards={
            "tracking": (rewards.linear_velocity_tracking(m, 0.25), 1.0),
            "yaw_tracking": (rewards.angular_velocity_tracking(m, 0.25), spec.yaw_tracking_weight),
            "air_time": (rewards.feet_air_time(0.1, min_command=0.1), spec.air_time_weight),
            "alive": (alive, spec.alive_weight),
            **stepping,
        },
        costs={
            "vertical": (rewards.vertical_velocity(m), 2.0),
            "roll_pitch": (rewards.roll_pitch_velocity(m), 0.05),
            "tilt": (rewards.flat_orientation(m), 5.0),
            "height": (rewards.base_height(m, float(m.key_qpos[0][2])), 10.0),
            "action_rate": (Partial(rewards.action_rate), 0.01),
            "torque": (Partial(rewards.torque), spec.torque_weight),
            "joint_limits": (rewards.joint_limits(m, 0.95), 1.0),
            "foot_slip": (Partial(rewards.foot_slip), 0.1),
            "stand_still": (rewards.stand_still(m), 0.5),
        },
        terminate={
            "tilted": named(terminations.not_upright(m, 1.0), "max_tilt"),
            "too_low": named(terminations.base_too_low(m, spec.min_height), "min_height"),
        },
        time_limit=episode_steps,
        params={"qpos0": jnp.asarray(m.key_qpos[0], jnp.float32)},
    )


def robot_curriculum(robot: str = "go1", terrain: str = "rough", **overrides: Any) -> Task:
    """`robot_joystick` on a terrain with each environment's row moved by the terrain
    curriculum (from the easiest); auto-resets inside, so the row survives episode ends."""
    if TERRAINS.get(terrain) is None:
        raise ValueError(
            f"robot_curriculum: terrain={terrain!r} must be one of {sorted(k for k, v in TERRAINS.items() if v)}"
        )

    def at(level: float) -> Task:
        return with_auto_reset(robot_joystick(robot, terrain=terrain, level=level, **overrides))

    options = tuple(sorted((k, v) for k, v in overrides.items() if k in physics_lib.OPTIONS))
    m = _scene(robot, terrain, options)[0].mj_model
    return curriculum.with_curriculum(at, terrain_lib.by_walked_distance(m, 2.0, rows=ROWS))


def _spec(robot: str, description: str) -> base.EnvSpec:
    def make(
        *,
        terrain: str = "flat",
        episode_steps: int = 1000,
        push: float = 0.5,
        noise: float = 0.02,
        max_action_latency: int = 1,
        gait_frequency: float | None = None,
        **physics_options: Any,
    ) -> Task:
        options = dict(episode_steps=episode_steps, push=push, noise=noise, max_action_latency=max_action_latency)
        options["gait_frequency"] = gait_frequency
        if TERRAINS.get(terrain) is not None:
            return robot_curriculum(robot, terrain, **options, **physics_options)
        return robot_joystick(robot, terrain=terrain, **options, **physics_options)

    make.__name__ = f"{robot}_joystick"
    make.__doc__ = f"{description}: `robot_joystick({robot!r})`, on a terrain with its curriculum."
    return base.EnvSpec(make=make, description=description, ppo=PPO if robot == "go1" else HUMANOID_PPO)


G1 = _spec("g1", "Unitree G1 humanoid following velocity commands (terrain='flat' | 'rough')")
T1 = _spec("t1", "Booster T1 humanoid following velocity commands (terrain='flat' | 'rough')")
BERKELEY_HUMANOID = _spec(
    "berkeley_humanoid", "Berkeley Humanoid following velocity commands (terrain='flat' | 'rough')"
)
GO1 = _spec("go1", "Unitree Go1 quadruped following velocity commands (terrain='flat' | 'rough' | 'stairs')")
