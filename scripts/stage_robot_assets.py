"""Copy what the robots' scenes use out of the installed EnvPool asset wheels into a folder
laid out as those wheels are, small enough to travel with a run to another machine.

    python scripts/stage_robot_assets.py go1 g1 --out .robots
    PYTHONPATH=.robots python benchmarks/robots.py ...       # on the other machine

A wheel's G1 folder holds 38 MB of meshes, most for models the scenes do not load (the
hands); only the XML files and the meshes, textures and heightfields the compiled scene
names are copied.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from mjzoo.robots import models
from mjzoo.robots import scenes


def stage(robot: str, out: Path) -> int:
    """Copies `robot`'s scene files into `out`; returns the bytes copied."""
    spec = scenes.spec(robot)
    used = {Path(item.file).name for group in (spec.meshes, spec.textures, spec.hfields) for item in group if item.file}
    name = models.canonical(robot)
    root = out / models.WHEELS[-1] / models.WHEEL_ROOT  # where `models` looks inside a wheel
    places = {
        models.playground_xmls(robot): root / models.WHEEL_PLAYGROUND / models.PLAYGROUND_FOLDERS[name] / "xmls",
        models.menagerie(robot): root / models.WHEEL_MENAGERIE / name,
    }
    copied = 0
    for source, target in places.items():
        for path in source.rglob("*"):
            if path.is_file() and (path.suffix == ".xml" or path.name in used or path.name == "LICENSE"):
                (target / path.relative_to(source)).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(path, target / path.relative_to(source))
                copied += path.stat().st_size
    (out / models.WHEELS[-1] / "__init__.py").touch()
    return copied


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("robots", nargs="+")
    parser.add_argument("--out", type=Path, default=Path(".robots"))
    args = parser.parse_args()
    for robot in args.robots:
        print(f"{robot}: {stage(robot, args.out) / 1e6:.1f} MB", flush=True)


if __name__ == "__main__":
    main()
