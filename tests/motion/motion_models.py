"""Small models and analytic motions shared by the tests of `mjzoo.motion`.

TORSO: a free body "torso" (qpos 0..6, qvel 0..5) carrying a hinge "h1" (qpos 7, qvel 6)
and, below it, a hinge "h2" (qpos 8, qvel 7). nq = 9, nv = 8.

`analytic(fps, num_frames)` is a motion of it known in closed form at time t (s):
  root position   (0.5 t, 0.1 sin t, 1)
  root rotation   q = qz(a) qy(b), a = 0.8 t, b = 0.3 sin t (yaw, then pitch in the turned frame)
  root velocity   linear (0.5, 0.1 cos t, 0) in the world frame; angular in the body frame
                  R^T (a' z + Rz(a) b' y) = (-a' sin b, b', a' cos b)
  hinges          h1 = sin 2t, h2 = 0.5 cos t
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjzoo.motion import Clip

TORSO_XML = """
<mujoco>
  <worldbody>
    <body name="torso" pos="0 0 1">
      <freejoint name="root"/>
      <geom type="box" size="0.1 0.1 0.1" mass="2"/>
      <body name="thigh" pos="0 0 -0.1">
        <joint name="h1" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.03" mass="0.5"/>
        <body name="shin" pos="0 0 -0.3">
          <joint name="h2" type="hinge" axis="0 1 0"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.03" mass="0.5"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
TORSO = mujoco.MjModel.from_xml_string(TORSO_XML)
JOINTS = ("root", "h1", "h2")


def axis_quat(axis: int, angle: np.ndarray) -> np.ndarray:
    """[T, 4] rotations by `angle` [T] about the x (0), y (1) or z (2) axis (w, x, y, z)."""
    q = np.zeros((len(angle), 4))
    q[:, 0], q[:, axis + 1] = np.cos(angle / 2), np.sin(angle / 2)
    return q


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros_like(a)
    for i in range(len(a)):
        mujoco.mju_mulQuat(out[i], a[i], b[i])
    return out


def analytic(fps: float, num_frames: int, name: str = "analytic") -> Clip:
    """The closed-form motion above, sampled at `fps` for `num_frames` frames."""
    t = np.arange(num_frames) / fps
    a, b, da, db = 0.8 * t, 0.3 * np.sin(t), 0.8 * np.ones_like(t), 0.3 * np.cos(t)
    qpos = np.zeros((num_frames, 9))
    qpos[:, 0:3] = np.stack([0.5 * t, 0.1 * np.sin(t), np.ones_like(t)], axis=1)
    qpos[:, 3:7] = quat_mul(axis_quat(2, a), axis_quat(1, b))
    qpos[:, 7], qpos[:, 8] = np.sin(2 * t), 0.5 * np.cos(t)
    qvel = np.zeros((num_frames, 8))
    qvel[:, 0:3] = np.stack([0.5 * np.ones_like(t), 0.1 * np.cos(t), np.zeros_like(t)], axis=1)
    qvel[:, 3:6] = np.stack([-da * np.sin(b), db, da * np.cos(b)], axis=1)
    qvel[:, 6], qvel[:, 7] = 2 * np.cos(2 * t), -0.5 * np.sin(t)
    return Clip(name=name, fps=float(fps), qpos=qpos, qvel=qvel, joint_names=JOINTS)


def world_angular_velocity(clip: Clip) -> np.ndarray:
    """[T, 3] the root's angular velocity in the world frame: R(q) w_body."""
    out = np.zeros((clip.num_frames, 3))
    for i in range(clip.num_frames):
        mujoco.mju_rotVecQuat(out[i], clip.qvel[i, 3:6], clip.qpos[i, 3:7])
    return out
