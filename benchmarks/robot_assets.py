"""Packs robots' models for a machine without them (the GPU machines have no asset wheels).

    python benchmarks/robot_assets.py g1 go1 berkeley_humanoid --out .robots/robots.tar.xz

Each robot's Menagerie folder and Playground scene folder, found as `mjzoo.robots.models`
finds them here, go into one archive laid out as an EnvPool asset wheel's module, so the
same lookup finds them there once the archive is unpacked onto the Python path:

    mkdir -p /tmp/robots && tar -xJf .robots/robots.tar.xz -C /tmp/robots && export PYTHONPATH=/tmp/robots

(.robots/ is git-ignored: a device call takes it when its carry names it.)
Prints the archive's size: a device call carries at most 64 MiB with the working tree.
"""

from __future__ import annotations

import argparse
import io
import tarfile
from pathlib import Path

from mjzoo.robots import models

MODULE = models.WHEELS[0]  # the module name the archive poses as


def members(robots: list[str]) -> dict[Path, Path]:
    """{path inside the archive: folder here} for each robot's model and scenes."""
    root = Path(MODULE) / models.WHEEL_ROOT
    found = {}
    for robot in robots:
        name = models.canonical(robot)
        found[root / models.WHEEL_MENAGERIE / name] = models.menagerie(name, download=False)
        scenes = Path(models.PLAYGROUND_FOLDERS[name]) / "xmls"
        found[root / models.WHEEL_PLAYGROUND / scenes] = models.playground_xmls(name)
    return found


def pack(robots: list[str], out: Path) -> int:
    """Writes the archive to `out` (xz); returns its size in bytes."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with tarfile.open(out, "w:xz") as archive:
        init = tarfile.TarInfo(f"{MODULE}/__init__.py")
        archive.addfile(init, io.BytesIO(b""))
        for inside, here in members(robots).items():
            archive.add(here, arcname=str(inside))
    return out.stat().st_size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("robots", nargs="+", help="Menagerie names or aliases (g1, t1, go1, ...)")
    parser.add_argument("--out", type=Path, default=Path(".robots/robots.tar.xz"))
    args = parser.parse_args()
    unknown = [r for r in args.robots if models.canonical(r) not in models.PLAYGROUND_FOLDERS]
    if unknown:
        parser.error(f"no Playground scenes for {unknown}; robots with them: {sorted(models.PLAYGROUND_FOLDERS)}")
    try:
        size = pack(args.robots, args.out)
    except models.ModelNotFoundError as error:
        parser.error(str(error))
    print(f"wrote {args.out}: {size / 2**20:.1f} MiB")


if __name__ == "__main__":
    main()
