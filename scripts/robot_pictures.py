"""The pictures of docs/robots.md: each robot joystick's start state, and the terrain grid.

    MUJOCO_GL=egl python scripts/robot_pictures.py            # writes docs/images/robots/*.png

Renders with C MuJoCo (`mujoco.Renderer`) the state `mjzoo.reset` gives each task (the
robot in its keyframe pose; on a terrain, on a tile of the row the curriculum starts
from, here the hardest row so the steps show), with a tracking camera looking at the base.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jax
import mujoco
import numpy as np

OUT = Path(__file__).resolve().parent.parent / "docs" / "images" / "robots"
SHOTS = {  # picture: (robot, terrain, camera distance m)
    "g1_flat": ("g1", "flat", 2.4),
    "t1_flat": ("t1", "flat", 2.4),
    "berkeley_humanoid_flat": ("berkeley_humanoid", "flat", 2.0),
    "go1_flat": ("go1", "flat", 1.4),
    "go1_rough": ("go1", "rough", 2.2),
    "go1_stairs": ("go1", "stairs", 2.6),
    "g1_rough": ("g1", "rough", 3.2),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", choices=sorted(SHOTS), default=sorted(SHOTS))
    parser.add_argument("--width", type=int, default=480)
    parser.add_argument("--height", type=int, default=360)
    args = parser.parse_args()

    from PIL import Image

    from mjzoo import running
    from mjzoo.envs import robot_joystick

    OUT.mkdir(parents=True, exist_ok=True)
    for name in args.only:
        robot, terrain, distance = SHOTS[name]
        level = 1.0 if terrain != "flat" else 0.0
        task = robot_joystick.robot_joystick(robot, terrain=terrain, level=level)
        state = jax.jit(running.reset)(task, jax.random.key(3))
        m = task.mj_model
        d = mujoco.MjData(m)
        d.qpos[:] = np.asarray(state.data.qpos)
        mujoco.mj_forward(m, d)
        camera = mujoco.MjvCamera()
        camera.lookat[:] = d.qpos[:3] - [0.0, 0.0, 0.1 * distance]
        camera.distance, camera.azimuth, camera.elevation = distance, 135.0, -20.0
        with mujoco.Renderer(m, args.height, args.width) as renderer:
            renderer.update_scene(d, camera)
            pixels = renderer.render()
        path = OUT / f"{name}.png"
        Image.fromarray(pixels).save(path, optimize=True)
        print(f"{path} ({path.stat().st_size // 1024} KiB)", flush=True)


if __name__ == "__main__":
    main()
