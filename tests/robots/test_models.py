"""Robot models (`mjzoo.robots`): each source in its order, the missing-model error, and
each walking robot's Playground scene compiling offline from EnvPool's wheels (the
test extra installs them)."""

from __future__ import annotations

import sys
import types
from pathlib import Path

import pytest

from mjzoo import robots
from mjzoo.robots import scenes


@pytest.fixture(autouse=True)
def _no_user_root(monkeypatch):
    monkeypatch.delenv(robots.models.ROOT_VARIABLE, raising=False)


def _fake_checkout(root: Path, robot: str) -> Path:
    (root / robot).mkdir(parents=True)
    (root / robot / "LICENSE").write_text("a license")
    return root / robot


def test_the_wheels_hold_the_walking_robots():
    for alias, wheel in (("g1", "humanoid"), ("t1", "humanoid"), ("berkeley_humanoid", "humanoid"), ("go1", "large")):
        path = robots.menagerie(alias)
        assert path.name == robots.canonical(
            alias
        ) and f"envpool_assets_mujoco_{'playground_' if wheel == 'humanoid' else ''}{wheel}" in str(path)
        assert robots.license(alias).read_text().strip()  # the model's own license travels with it
        assert (robots.playground_xmls(alias) / scenes.FLAT_SCENE).is_file()


def test_a_user_root_comes_first(tmp_path, monkeypatch):
    mine = _fake_checkout(tmp_path, "unitree_g1")
    assert robots.menagerie("g1", root=tmp_path) == mine
    monkeypatch.setenv(robots.models.ROOT_VARIABLE, str(tmp_path))
    assert robots.menagerie("g1") == mine
    assert robots.where("g1")[0] == robots.models.Source("root", mine)
    # A robot the checkout lacks falls through to the next source.
    assert "envpool" in str(robots.menagerie("go1"))
    with pytest.raises(FileNotFoundError, match="root='/no/such/folder' is not a folder"):
        robots.menagerie("g1", root="/no/such/folder")


def _fake_package(monkeypatch, cache_dir: Path, cached: set[str], downloads: list[str]):
    """A stand-in for the `mujoco-menagerie` package: its registry, cache and download."""

    class Robot:
        def __init__(self, name):
            self.name = name

        def path(self):
            downloads.append(self.name)
            return _fake_checkout(cache_dir / "downloaded", self.name)

    class Cache:
        def is_cached(self, robot):
            return robot.name in cached

        def model_path(self, robot):
            return cache_dir / robot.name

    package = types.SimpleNamespace(
        names=lambda: ["unitree_g1", "unitree_go1", "agility_cassie"],
        get=Robot,
        Cache=Cache,
        MenagerieError=RuntimeError,
    )
    monkeypatch.setitem(sys.modules, "mujoco_menagerie", package)


def test_the_menagerie_package_cache_before_the_wheels_and_its_download_after(tmp_path, monkeypatch):
    downloads: list[str] = []
    _fake_package(monkeypatch, tmp_path, cached={"unitree_g1"}, downloads=downloads)
    assert robots.menagerie("g1") == tmp_path / "unitree_g1"  # cached: before the wheels
    assert "envpool" in str(robots.menagerie("go1")) and not downloads  # not cached, in a wheel
    assert robots.menagerie("agility_cassie") == tmp_path / "downloaded" / "agility_cassie"  # in no wheel
    assert downloads == ["agility_cassie"]
    with pytest.raises(robots.ModelNotFoundError):
        robots.menagerie("agility_cassie_2", download=True)  # not in the package's registry either


def test_a_missing_model_names_the_three_ways_to_get_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco_menagerie", None)  # the package not installed
    with pytest.raises(robots.ModelNotFoundError) as error:
        robots.menagerie("agility_cassie")
    message = str(error.value)
    assert "'agility_cassie' not found" in message and "\n" not in message
    assert all(way in message for way in ("MENAGERIE_ROOT", "pip install mujoco-menagerie", "mjzoo[robots]"))
    with pytest.raises(KeyError, match="no scenes for 'agility_cassie'"):
        robots.playground_xmls("agility_cassie")


@pytest.mark.parametrize("robot, nu", [("go1", 12), ("g1", 29), ("t1", 23), ("berkeley_humanoid", 12)])
def test_scenes_compile_offline(robot, nu):
    physics = scenes.load(robot, ctrl_dt=0.02)
    assert physics.mj_model.nu == nu and physics.mj_model.nkey >= 1
    assert physics.n_substeps == round(0.02 / physics.mj_model.opt.timestep)
