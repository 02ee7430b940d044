"""A robot's scene as physics: Playground's MJX scene for it (feet-only collisions, its
sensors and keyframes), on flat ground or with a terrain grid in place of the floor.

    physics = scenes.load("go1")                                        # flat
    physics = scenes.load("g1", terrain.grid(("rough", "stairs_up")), ctrl_dt=0.02)
"""

from __future__ import annotations

import os
from typing import Any

import mujoco

from mjzoo import physics as physics_lib
from mjzoo.robots import models
from mjzoo.robots import terrain as terrain_lib

__all__ = ["FLAT_SCENE", "spec", "load"]

FLAT_SCENE = "scene_mjx_feetonly_flat_terrain.xml"


def spec(robot: str, scene: str = FLAT_SCENE, root: str | os.PathLike | None = None) -> mujoco.MjSpec:
    """Playground's scene file `scene` for `robot`, parsed with everything it includes
    (`mjzoo.robots.assets`), as an editable `mujoco.MjSpec`."""
    xmls = models.playground_xmls(robot)
    if not (xmls / scene).is_file():
        found = sorted(p.name for p in xmls.glob("scene*.xml"))
        raise FileNotFoundError(f"{robot}: Playground has no scene {scene!r}; its scenes: {found}")
    # from_file: its includes resolve next to the scene; meshes come from the Menagerie model (assets)
    return mujoco.MjSpec.from_file(str(xmls / scene), assets=models.assets(robot, root))


def load(
    robot: str,
    terrain: terrain_lib.Terrain | None = None,
    *,
    scene: str = FLAT_SCENE,
    root: str | os.PathLike | None = None,
    **physics_options: Any,
) -> physics_lib.Physics:
    """`robot`'s scene compiled for MJX with `physics_options` (`mjzoo.physics.load`'s),
    its floor replaced by `terrain` (a heightfield geom named "terrain") if given."""
    edited = spec(robot, scene, root)
    if terrain is not None:
        terrain_lib.add_to_spec(edited, terrain)
    label = f"{models.canonical(robot)}:{scene}" + ("" if terrain is None else "+terrain")
    return physics_lib.of_spec(edited, label=label, **physics_options)
