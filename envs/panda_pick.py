"""A Franka Panda picks up a cube and holds it at a target in the air. Its rewards are
dense and smooth, made for sampling planners (`PLANNING`: ``mjzoo plan mppi
panda_pick``); PPO trains on it as on any task.

    task = panda_pick.panda_pick()
    task = panda_pick.panda_pick(action_scale=0.5, ctrl_dt=0.02)

The scene is Playground's ``mjx_single_cube.xml`` on Menagerie's MJX Panda (as its
``PandaPickCube`` loads it): a 4 x 4 x 6 cm cube of 0.1 kg on the floor, collisions of the
finger pads and the hand's capsule alone, contact sensors of the pads and the capsule
against the floor, a mocap marker that shows the target. The arm starts in the scene's
"home" keyframe, the gripper open 0.35 m above the floor pointing down; the cube at rest
uniform in x in [0.5, 0.7] m, y in [-0.1, 0.1] m; the target uniform in the same square,
0.15-0.3 m above the floor (``info["target"]`` [3], m, the cube centre's). The Panda's
servos are driven to ``home + action_scale * action`` (rad, the arm's seven joints) and
its fingers to ``0.04 + 0.04 * action`` (m: open at 0, closed at -1), clipped to their
ranges. Reward terms (weights): the gripper's distance to the cube 1 - tanh(5 d) (1.0);
the cube's to the target 1 - tanh(5 d) (4.0); lifted: the cube's rise above its resting
height over 5 cm, in [0, 1] (2.0); costs: a finger pad or the hand touching the floor
(0.25), action rate (0.01). Terminated when the cube leaves the workspace (|x|, |y| or z
beyond 1 m, or below the floor); 5 s episodes. Solved when the cube stays within 5 cm of
the target over the last second.
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo import names
from mjzoo import physics as physics_lib
from mjzoo.builder import named
from mjzoo.catalog import actuators
from mjzoo.catalog import rewards
from mjzoo.catalog import trackers
from mjzoo.envs import base
from mjzoo.robots import models
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["panda_pick", "sample_goal", "PANDA_PICK", "PLANNING", "SCENE"]

Array = jax.Array
SCENE = "mjx_single_cube.xml"
FLOOR_SENSORS = ("left_finger_pad_floor_found", "right_finger_pad_floor_found", "hand_capsule_floor_found")
GRIPPER_OPEN = 0.04  # m, each finger's travel (ctrlrange [0, 0.04])


@functools.lru_cache(maxsize=4)
def _scene(options: tuple[tuple[str, Any], ...]) -> physics_lib.Physics:
    """Playground's Panda-and-cube scene at a 0.02 s control step (Playground's)."""
    files = models.assets("panda")
    # The scene includes Menagerie's through a path into Playground's own tree, which exists
    # in EnvPool's wheel alone: includes resolve by file name (`assets` lists Playground's
    # XML files before Menagerie's, so Menagerie's `mjx_scene.xml` is the one included).
    spec = mujoco.MjSpec.from_string(
        (models.playground_xmls("panda") / SCENE).read_text(),
        include={name: data for name, data in files.items() if name.endswith(".xml")},
        assets=files,
    )
    return physics_lib.of_spec(spec, label=f"franka_emika_panda:{SCENE}", **{"ctrl_dt": 0.02, **dict(options)})


def sample_goal(p: dict, model: mjx.Model, data: mjx.Data, key: Array) -> tuple[mjx.Data, dict[str, Array]]:
    """Reset item: the cube at rest, its xy uniform in [cube_low, cube_high] (m), and the
    target [3] uniform in [target_low, target_high], shown by the mocap marker; keeps
    ``info["target"]``."""
    cube_key, target_key = jax.random.split(key)
    xy = jax.random.uniform(cube_key, (2,), minval=p["cube_low"], maxval=p["cube_high"])
    target = jax.random.uniform(target_key, (3,), minval=p["target_low"], maxval=p["target_high"])
    qpos = p["qpos0"].at[-7:-5].set(xy)  # the cube's free joint is the scene's last
    return data.replace(qpos=qpos, mocap_pos=data.mocap_pos.at[0].set(target)), {"target": target}


def observe(gripper, cube, model: mjx.Model, state: State) -> Array:
    """[40]: qpos [16] and qvel [15] (arm, fingers, cube), the gripper's position, the
    cube's from the gripper, the target's from the cube (m); the task appends the last
    action [8]."""
    data = state.data
    at, box = data.site_xpos[gripper], data.xpos[cube]
    return jnp.concatenate([data.qpos, data.qvel, at, box - at, state.info["target"] - box])


def reach(gripper, cube, model, state: State, action: Array, next_state: State) -> Array:
    """In (0, 1]: 1 - tanh(5 |cube - gripper|) (m), 1 with the gripper at the cube's centre."""
    data = next_state.data
    return 1.0 - jnp.tanh(5.0 * jnp.linalg.norm(data.xpos[cube] - data.site_xpos[gripper]))


def place(cube, model, state: State, action: Array, next_state: State) -> Array:
    """In (0, 1]: 1 - tanh(5 |target - cube|) (m), 1 with the cube at the target."""
    return 1.0 - jnp.tanh(5.0 * jnp.linalg.norm(next_state.info["target"] - next_state.data.xpos[cube]))


def lifted(cube, rest_height, lift_height, model, state: State, action: Array, next_state: State) -> Array:
    """In [0, 1]: the cube's rise above `rest_height` over `lift_height` (m)."""
    return jnp.clip((next_state.data.xpos[cube, 2] - rest_height) / lift_height, 0.0, 1.0)


def floor_contact(sensors, model, state: State, action: Array, next_state: State) -> Array:
    """1 while a finger pad or the hand's capsule touches the floor (the scene's contact
    sensors at `sensors`, sensordata addresses), else 0."""
    return jnp.any(next_state.data.sensordata[sensors] > 0).astype(jnp.float32)


def out_of_workspace(cube, workspace, model, state: State) -> Array:
    """The cube beyond `workspace` m of the robot's base in x, y or z, or below the floor."""
    at = state.data.xpos[cube]
    return jnp.any(jnp.abs(at) > workspace) | (at[2] < 0.0)


def panda_pick(*, episode_steps: int = 250, action_scale: float = 1.0, **physics_options: Any) -> Task:
    """The Panda lifting a cube to a target (module docstring); physics options override
    the scene's."""
    physics = _scene(tuple(sorted(physics_options.items())))
    m = physics.mj_model
    home = m.key("home")
    if m.nq != 16 or m.jnt_type[-1] != mujoco.mjtJoint.mjJNT_FREE:
        raise ValueError(f"panda_pick: {SCENE} must end with the cube's free joint (nq 16), got nq {m.nq}")
    gripper = jnp.int32(names.index(m, "site", "gripper", "panda_pick"))
    cube = jnp.int32(names.index(m, "body", "box", "panda_pick"))
    sensors = jnp.asarray([m.sensor_adr[names.index(m, "sensor", s, "panda_pick")] for s in FLOOR_SENSORS], jnp.int32)
    scale = np.full(m.nu, action_scale, np.float32)
    scale[-1] = GRIPPER_OPEN
    pose = np.asarray(home.ctrl, np.float32).copy()
    pose[-1] = GRIPPER_OPEN
    rest = jnp.float32(home.qpos[-5])  # the cube's centre height on the floor (m)
    return mjzoo.task(
        physics,
        observe=Partial(observe, gripper, cube),
        resets=(sample_goal,),
        actuator=actuators.position_targets(m, scale, default_pose=pose),
        combinators=(functools.partial(trackers.with_action_history, length=2, observe=True),),
        rewards={
            "reach": (Partial(reach, gripper, cube), 1.0),
            "place": (Partial(place, cube), 4.0),
            "lifted": (named(Partial(lifted, cube, rest, jnp.float32(0.05)), "rest_height", "lift_height"), 2.0),
        },
        costs={
            "floor": (Partial(floor_contact, sensors), 0.25),
            "action_rate": (Partial(rewards.action_rate), 0.01),
        },
        terminate={"out_of_workspace": named(Partial(out_of_workspace, cube, jnp.float32(1.0)), "workspace")},
        time_limit=episode_steps,
        params={
            "qpos0": jnp.asarray(home.qpos, jnp.float32),
            "cube_low": (0.5, -0.1),
            "cube_high": (0.7, 0.1),
            "target_low": (0.5, -0.1, 0.15),
            "target_high": (0.7, 0.1, 0.3),
        },
    )


def _held_at_target(states) -> tuple[bool, float]:
    """Solved when the cube stays within 5 cm of the target over the last second; the
    score is the largest distance (m)."""
    cube = np.asarray(states.data.qpos[..., -7:-4])
    return base.held_near(states, lambda s: np.linalg.norm(cube - np.asarray(s.info["target"]), axis=-1), 0.05)


# Sampling planners (`mjzoo plan mppi panda_pick`): as the whole-body robots, 1024 samples
# over 0.5 s replanning every step, with a narrower search (0.3 rad) for the grasp.
PLANNING = base.sampling_setup(5.0, _held_at_target, horizon_steps=25, num_knots=4, noise_scale=0.3)
PANDA_PICK = base.EnvSpec(
    make=panda_pick, description="Franka Panda lifting a cube to a target (MPC-friendly)", planning=PLANNING
)
