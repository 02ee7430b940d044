"""The DeepMimic humanoid and its motion-capture clips, from the installed pybullet package.

pybullet's wheel ships ``pybullet_data`` (zlib licence): the DeepMimic humanoid
(``humanoid/humanoid.urdf``, 13 links, spherical and revolute joints, loaded by
pybullet at a quarter of its size) and its clips (``data/motions/humanoid3d_*.txt``,
e.g. walk: 39 frames at 30 fps; run: 25). Nothing is copied here: `humanoid_model`
builds the MJCF at run time from the installed URDF, as the locomotion tasks load
Brax's bundled models, and `walk_clips` reads the clips with
`mjzoo.motion.deepmimic_format.load`. Install the data with ``pip install pybullet`` (a
binary wheel, ~100 MB; nothing is compiled).

    clips = deepmimic.walk_clips()               # [walk, run] as mjzoo.motion.Clip
    task = deepmimic.walk()                      # alive reward only: AMP adds the style
    reference = motion.reference(clips, task.mj_model, dt=...)   # AMP's: amp.make(config, reference)
    task = deepmimic.walk_amp()                  # the walk with RSI from the walk clip: for `AMP`
    reference = deepmimic.walk_amp_reference(task)   # that clip, looping, at the control step

The model is the URDF in MuJoCo's z-up basis (`mjzoo.motion.deepmimic_format.to_z_up`):
x forward, y left, z up; the root a free joint, each spherical joint a ball joint,
each revolute joint a hinge (knees and elbows, the URDF's limits), fixed links welded.
Shapes (spheres, capsules, boxes) and masses (45 kg in all) are the URDF's; each link's
inertia is MuJoCo's from its shape and mass (the URDF's tensors are a placeholder 0.1).
Every degree of freedom has a motor, ctrl in [-1, 1] times pybullet's DeepMimic torque
limit for that joint (`MAX_TORQUE`, N m); a ball joint has three, one per local axis.
Only the floor collides with the body (no self-collisions: cheaper under MJX).

| task | control step | observation | terminated when | reward terms (weight) |
|---|---|---|---|---|
| walk | 1/30 s (8 x 1/240 s) | base z, quat, joints, base velocities, joint vel (75) | root z < 0.5 m | alive 1 |

`walk_amp` is the walk task imitating the walk clip (a loop, resampled to the control
step) by AMP (`mjzoo.algorithms.amp`, hyperparameters `AMP`: the discriminator sees
windows of 2 frames with the feet and hands as key bodies), starting at clip frames
(reference-state initialization) with probability `reference_init`; `style_error`
measures a run's knees and elbows against the clip.
"""

from __future__ import annotations

import functools
import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

import mjzoo
from mjzoo import motion
from mjzoo import physics as physics_lib
from mjzoo.builder import alive
from mjzoo.builder import named
from mjzoo.catalog import resets
from mjzoo.catalog import terminations
from mjzoo.envs import base
from mjzoo.envs import locomotion
from mjzoo.motion import deepmimic_format
from mjzoo.types import Task

__all__ = ["character_joints", "humanoid_model", "motion_path", "walk", "walk_amp", "walk_clips", "WALK_AMP"]

SCALE = 0.25  # pybullet loads the URDF with globalScaling=0.25; the clips are in those metres
# Per-joint torque limits (N m) of pybullet's DeepMimic humanoid environment.
MAX_TORQUE = {
    "chest": 200.0,
    "neck": 50.0,
    "right_hip": 200.0,
    "right_knee": 150.0,
    "right_ankle": 90.0,
    "right_shoulder": 100.0,
    "right_elbow": 60.0,
    "left_hip": 200.0,
    "left_knee": 150.0,
    "left_ankle": 90.0,
    "left_shoulder": 100.0,
    "left_elbow": 60.0,
}
# DeepMimic's physics runs at 240 Hz under a 30 Hz policy; Brax's MJX solver settings.
OPTIONS = dict(locomotion.MJX_OPTIONS, dt=1.0 / 240.0, ctrl_dt=1.0 / 30.0)
_INSTALL = "pip install pybullet  (its wheel ships pybullet_data: the DeepMimic humanoid and clips)"
_STANDING_HEIGHT = 0.885  # m: the root's height with straight legs, feet flat 4 mm above the floor
_Y_UP = deepmimic_format.Y_UP_TO_Z_UP
KEY_BODIES = ("right_ankle", "left_ankle", "right_wrist", "left_wrist")  # the feet and hands
STYLE_JOINTS = ("right_knee", "left_knee", "right_elbow", "left_elbow")  # the hinges: angles compare directly
# AMP on the walk clip by style alone (`mjzoo train amp mjzoo.envs.deepmimic:walk_amp`), for a GPU: AMP's
# paper's 2-frame windows and gradient penalty (w_gp / 2 = 5), its discriminator (1024, 512).
AMP = dict(
    num_envs=4096,
    unroll_length=32,
    num_minibatches=32,
    num_epochs=5,
    learning_rate=2e-5,
    entropy_coef=0.0,
    discount=0.95,
    total_steps=200_000_000,
    policy_hidden_sizes=(1024, 512),
    value_hidden_sizes=(1024, 512),
    task_weight=0.0,
    style_weight=1.0,
    num_frames=2,
    key_bodies=KEY_BODIES,
    disc_hidden_sizes=(1024, 512),
    disc_learning_rate=1e-5,
    gradient_penalty_weight=5.0,
    disc_minibatches=32,
)


def data_path() -> Path:
    """The installed ``pybullet_data`` folder; ModuleNotFoundError saying how to install it."""
    spec = importlib.util.find_spec("pybullet_data")
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError(
            f"the DeepMimic humanoid and clips come from the package pybullet_data, which is not installed: {_INSTALL}"
        )
    return Path(next(iter(spec.submodule_search_locations)))


def motion_path(clip: str) -> Path:
    """The installed DeepMimic clip ``data/motions/humanoid3d_<clip>.txt`` (e.g. "walk",
    "run", "jump", "backflip"); ValueError listing the clips if there is no such one."""
    folder = data_path() / "data" / "motions"
    path = folder / f"humanoid3d_{clip}.txt"
    if not path.is_file():
        known = sorted(p.stem.removeprefix("humanoid3d_") for p in folder.glob("humanoid3d_*.txt"))
        raise ValueError(f"deepmimic.motion_path: no clip {clip!r}; pybullet_data has {known}")
    return path


@functools.lru_cache(maxsize=4)
def humanoid_xml(armature: float = 0.01, damping: float = 1.0, friction: float = 0.9) -> str:
    """MJCF text of the DeepMimic humanoid (module docstring), built from the installed
    URDF; `armature` (kg m^2) and `damping` (N m s/rad) on every joint, `friction` the
    sliding friction of every contact (pybullet's DeepMimic: 0.9)."""
    urdf = _urdf()
    links = {link.get("name"): link for link in urdf.iter("link")}
    children: dict[str, list[ET.Element]] = {}
    for joint in urdf.iter("joint"):
        children.setdefault(joint.find("parent").get("link"), []).append(joint)
    top = _root_link(urdf, links, children)
    body = _body(top, links, children, joint=None)
    body.set("pos", f"0 0 {_STANDING_HEIGHT}")
    mjcf = ET.fromstring(_SKELETON.format(armature=armature, damping=damping, friction=friction))
    mjcf.find("worldbody").append(body)
    actuators = mjcf.find("actuator")
    for joint in body.iter("joint"):
        _add_motors(actuators, joint)
    return ET.tostring(mjcf, encoding="unicode")


def humanoid_model() -> mujoco.MjModel:
    """The DeepMimic humanoid compiled (nq 43, nv 34, nu 28); ModuleNotFoundError if
    pybullet_data is not installed."""
    return mujoco.MjModel.from_xml_string(humanoid_xml())


def character_joints() -> tuple[str, ...]:
    """The humanoid's moving joints in the URDF's order, which is the order of the
    values in a DeepMimic frame (not MuJoCo's depth-first one: the hips come between
    the neck and the shoulders): chest, neck, right_hip, right_knee, ..., left_elbow."""
    return tuple(j.get("name") for j in _urdf().iter("joint") if j.get("type") != "fixed")


def walk_clips(names: tuple[str, ...] = ("walk", "run")) -> list[motion.Clip]:
    """The installed DeepMimic clips `names` as checked clips of `humanoid_model` (z-up,
    velocities from position differences per second; see `mjzoo.motion.deepmimic_format`)."""
    m = humanoid_model()
    return [deepmimic_format.load(motion_path(n), m, character_joints(), name=n) for n in names]


def walk(
    *,
    episode_steps: int = 300,
    alive_weight: float = 1.0,
    min_height: float = 0.5,
    reset_noise: float = 0.01,
    **physics_options: Any,
) -> Task:
    """The DeepMimic humanoid free to move (module docstring's table), for AMP: no
    reward but "alive" (`alive_weight` per step not fallen), terminated when the root is
    below `min_height` (m), truncated after `episode_steps` control steps (10 s). Resets
    stand it upright (arms down), with uniform noise of `reset_noise` (rad, rad/s) on
    the knees' and elbows' positions and velocities; start from the clips instead with
    `mjzoo.catalog.resets.reference_state`. Physics options override `OPTIONS`."""
    physics = physics_lib.load(humanoid_xml(), **{**OPTIONS, **physics_options})
    m = physics.mj_model
    return mjzoo.task(
        physics,
        observe=locomotion.free_base_observation(m),
        start=locomotion.at_pose,
        resets=(
            named(resets.joint_position_noise(m, reset_noise), "reset_noise"),
            named(resets.joint_velocities(m, reset_noise), "reset_noise"),
        ),
        terminate={"fallen": named(terminations.base_too_low(m, min_height), "min_height")},
        rewards={"alive": (alive, alive_weight)},
        time_limit=episode_steps,
        params={"qpos0": locomotion.reset_pose(m)},
    )


def walk_amp(*, reference_init: float = 0.8, episode_steps: int = 300, **overrides: Any) -> Task:
    """`walk(**overrides)` for `AMP` imitating the walk clip (`walk_amp_reference`), a
    fraction `reference_init` in [0, 1] of its episodes starting at a clip frame
    (`resets.reference_state`)."""
    task = walk(episode_steps=episode_steps, **overrides)
    if reference_init:
        ref = walk_amp_reference(task, **overrides)
        observe = locomotion.free_base_observation(task.mj_model)
        task = resets.with_resets(task, resets.reference_state(ref, reference_init), observe=observe)
    return task


def walk_amp_reference(task: Task, *, ctrl_dt: float = OPTIONS["ctrl_dt"], **_: Any) -> motion.Reference:
    """The walk clip on `task`'s model (`walk_amp(ctrl_dt=ctrl_dt, ...)`), looping, one
    frame per control step: what AMP imitates. The control step is the override, not
    `motion.check_reference`'s measured one: measuring compiles a step of this humanoid,
    minutes on a CPU (`walk` has checked that it is a whole number of physics steps)."""
    return motion.reference(walk_clips(("walk",)), task.mj_model, dt=float(ctrl_dt), loop=True)


def style_error(task: Task, reference: motion.Reference, qpos, window: int = 15) -> float:
    """The mean knee and elbow angle error (rad) of a run's windows of `window` frames
    (default 0.5 s) to their nearest windows of the task's looping reference (taken
    twice over, so windows across its end exist): `motion.nearest_window_error`.
    `qpos` [T, nq] of a run of `walk_amp` (`task`: its model), T >= `window`;
    `reference` the looping clip (`walk_amp_reference(task)`)."""
    if not isinstance(reference, motion.Reference):
        raise TypeError(
            "deepmimic.style_error: reference must be a motion.Reference (deepmimic.walk_amp_reference(task)), "
            f"got {type(reference).__name__}"
        )
    qpos, m = np.asarray(qpos), task.mj_model
    if qpos.ndim != 2 or qpos.shape[1] != m.nq:
        raise ValueError(f"deepmimic.style_error: qpos has shape {qpos.shape}; expected [T, {m.nq}]")
    columns = [m.jnt_qposadr[m.joint(name).id] for name in STYLE_JOINTS]
    twice = np.concatenate([np.asarray(reference.qpos)] * 2)
    return motion.nearest_window_error(twice, qpos, columns, window)


# --- URDF -> MJCF -------------------------------------------------------------------

_SKELETON = """<mujoco model="deepmimic_humanoid">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.004166666666666667"/>
  <default>
    <joint armature="{armature}" damping="{damping}"/>
    <geom contype="0" conaffinity="1" condim="3" friction="{friction} 0.005 0.0001" rgba="0.8 0.6 0.4 1"/>
    <motor ctrlrange="-1 1"/>
  </default>
  <visual><headlight ambient="0.4 0.4 0.4" diffuse="0.6 0.6 0.6"/></visual>
  <asset>
    <texture name="grid" type="2d" builtin="checker" rgb1="0.2 0.3 0.4" rgb2="0.3 0.4 0.5" width="256" height="256"/>
    <material name="grid" texture="grid" texrepeat="8 8" reflectance="0.1"/>
  </asset>
  <worldbody>
    <light pos="0 0 4" dir="0 0 -1" directional="true"/>
    <geom name="floor" type="plane" size="0 0 0.05" material="grid" contype="1" conaffinity="0"/>
  </worldbody>
  <actuator/>
</mujoco>"""
_SIDE_RGBA = {"right": "0.8 0.35 0.3 1", "left": "0.3 0.45 0.8 1"}


@functools.lru_cache(maxsize=1)
def _urdf() -> ET.Element:
    # The shipped file ends in a NUL byte, which XML parsers refuse.
    return ET.fromstring((data_path() / "humanoid" / "humanoid.urdf").read_text().strip("\x00 \r\n\t"))


def _root_link(urdf: ET.Element, links: dict, children: dict) -> str:
    """The link that carries the free joint: the URDF's root, skipping a shapeless base
    welded at the origin (this URDF's "base", 0.1 g)."""
    child_links = {j.find("child").get("link") for j in urdf.iter("joint")}
    top = next(name for name in links if name not in child_links)
    below = children.get(top, [])
    while links[top].find("collision") is None and len(below) == 1 and below[0].get("type") == "fixed":
        top = below[0].find("child").get("link")
        below = children.get(top, [])
    return top


def _body(name: str, links: dict, children: dict, joint: ET.Element | None) -> ET.Element:
    """The MJCF body of link `name` entered through URDF `joint` (None: the free root),
    with its geoms and, recursively, its children."""
    body = ET.Element("body", name=name)
    if joint is None:
        ET.SubElement(body, "freejoint", name="root")
    else:
        xyz, rpy = _origin(joint)
        body.set("pos", _fmt(_Y_UP @ xyz * SCALE))
        if np.any(rpy):
            body.set("quat", _fmt(_quat(_Y_UP @ _rpy_matrix(rpy) @ _Y_UP.T)))
        _add_joint(body, joint)
    link = links[name]
    collisions = link.findall("collision")
    mass = float(link.find("inertial/mass").get("value"))
    for geom in collisions:
        body.append(_geom(geom, mass / len(collisions), name))
    if not collisions:
        ET.SubElement(body, "inertial", pos="0 0 0", mass=str(mass), diaginertia="1e-5 1e-5 1e-5")
    for child in children.get(name, []):
        body.append(_body(child.find("child").get("link"), links, children, child))
    return body


def _add_joint(body: ET.Element, joint: ET.Element) -> None:
    kind, name = joint.get("type"), joint.get("name")
    if kind == "spherical":
        ET.SubElement(body, "joint", name=name, type="ball")
    elif kind in ("revolute", "continuous"):
        axis = np.array([float(v) for v in joint.find("axis").get("xyz").split()])
        element = ET.SubElement(body, "joint", name=name, type="hinge", axis=_fmt(_Y_UP @ axis))
        limit = joint.find("limit")
        if kind == "revolute" and limit is not None:
            element.set("range", f"{float(limit.get('lower'))} {float(limit.get('upper'))}")
    elif kind != "fixed":
        raise ValueError(
            f"deepmimic.humanoid_xml: URDF joint {name!r} has type {kind!r}; "
            "expected spherical, revolute, continuous or fixed"
        )


def _geom(collision: ET.Element, mass: float, link: str) -> ET.Element:
    """A geom for a URDF collision shape (sphere, capsule, box or cylinder) in the z-up
    basis; its mass gives the link its inertia."""
    xyz, rpy = _origin(collision)
    centre, turn = _Y_UP @ xyz * SCALE, _Y_UP @ _rpy_matrix(rpy)  # turn: the shape's axes, z-up body frame
    shape = next(iter(collision.find("geometry")))
    geom = ET.Element("geom", name=f"{link}_{shape.tag}", mass=f"{mass:.6g}")
    side = link.split("_")[0]
    if side in _SIDE_RGBA:
        geom.set("rgba", _SIDE_RGBA[side])
    size = {k: float(v) * SCALE for k, v in shape.attrib.items() if k in ("radius", "length")}
    if shape.tag == "sphere":
        geom.attrib.update(type="sphere", size=f"{size['radius']:.6g}", pos=_fmt(centre))
    elif shape.tag in ("capsule", "cylinder"):
        half = 0.5 * size["length"] * turn[:, 2]  # URDF capsules and cylinders lie along their z axis
        ends = _fmt(np.r_[centre - half, centre + half])
        geom.attrib.update(type=shape.tag, size=f"{size['radius']:.6g}", fromto=ends)
    elif shape.tag == "box":
        half = 0.5 * SCALE * np.array([float(v) for v in shape.get("size").split()])
        geom.attrib.update(type="box", size=_fmt(half), pos=_fmt(centre), quat=_fmt(_quat(turn)))
    else:
        raise ValueError(
            f"deepmimic.humanoid_xml: link {link!r} has a {shape.tag!r} shape; "
            "expected sphere, capsule, cylinder or box"
        )
    return geom


def _add_motors(actuators: ET.Element, joint: ET.Element) -> None:
    name, kind = joint.get("name"), joint.get("type")
    gear = MAX_TORQUE.get(name, 100.0)
    if kind == "ball":
        for i, axis in enumerate("xyz"):
            ET.SubElement(actuators, "motor", name=f"{name}_{axis}", joint=name, gear=_fmt(np.eye(3)[i] * gear))
    else:
        ET.SubElement(actuators, "motor", name=name, joint=name, gear=f"{gear:g}")


def _origin(element: ET.Element) -> tuple[np.ndarray, np.ndarray]:
    """(xyz, rpy) of the element's <origin>, zeros where absent."""
    attrib = {} if element.find("origin") is None else element.find("origin").attrib
    return tuple(np.array([float(v) for v in attrib.get(key, "0 0 0").split()]) for key in ("xyz", "rpy"))


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF's fixed-axis roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    quat = np.zeros(4)
    mujoco.mju_euler2Quat(quat, rpy, "XYZ")
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)


def _quat(mat: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(mat, np.float64).ravel())
    return quat


def _fmt(values: np.ndarray) -> str:
    return " ".join(f"{v:.6g}" for v in np.where(np.abs(values) < 1e-12, 0.0, values))


WALK_AMP = base.EnvSpec(
    make=walk_amp,
    description="the DeepMimic humanoid imitating its walk clip (AMP)",
    amp=AMP,
    reference=walk_amp_reference,
)
