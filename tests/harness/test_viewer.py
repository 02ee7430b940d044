"""The live viewer (`mjzoo.harness.viewer`) and `mjzoo view`: a real viser server on a
free port, driven from Python (`Viewer.step`, GUI handles' ``.value``, which run the
browser's callbacks). One pendulum simulation, one tiny planner and hand-made
recordings share their compiles through module fixtures; the offscreen frames and
video run in a fresh EGL process, and the browser check in headless Chromium, both
started first so that they overlap the rest."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import urllib.request
from pathlib import Path

import imageio.v3 as iio
import mujoco
import numpy as np
import pytest

import mjzoo
from mjzoo.algorithms import mppi
from mjzoo.harness import datasets
from mjzoo.harness import viewer
from mjzoo.harness.cli import viewing
from mjzoo.harness.cli.arguments import UsageError
from mjzoo.harness.viewer import scene

ROOT = Path(__file__).resolve().parents[2]
ENV = "pendulum_swingup"
CLIP = ROOT / "envs" / "assets" / "cartpole_swingup_mppi.npz"

# `mjzoo view` with --seconds, --save-frames and --save-video (and the same frames as a
# GIF), in a fresh process: MuJoCo reads MUJOCO_GL once, at import.
SAVE_SCRIPT = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from mjzoo.harness.cli import viewing
    from mjzoo.harness.rendering import RenderConfig

    out, config, seen = Path(sys.argv[1]), RenderConfig(width=96, height=72, shadows=False), {}
    write = viewing._write
    viewing._write = lambda shown, *rest: (seen.setdefault("shown", shown), write(shown, *rest))
    viewing.view("pendulum_swingup", seconds=0.4, port=0, host="127.0.0.1", save_frames=out / "frames",
                 save_video=out / "view.mp4", render=config)
    write(seen["shown"], None, out / "view.gif", config)
    print(len(seen["shown"].recorded))
    """
)


def _start(args: list[str], out: Path, env: dict[str, str]) -> subprocess.Popen:
    with open(out / "stdout", "w") as stdout, open(out / "stderr", "w") as stderr:
        return subprocess.Popen(args, env=env, stdout=stdout, stderr=stderr, close_fds=False, cwd=ROOT)


@pytest.fixture(scope="module", autouse=True)
def background(tmp_path_factory) -> dict[str, tuple[Path, subprocess.Popen | None]]:
    """The EGL run and the browser check, started before any test of this module."""
    env = {**os.environ, "MUJOCO_GL": "egl"}
    saved = tmp_path_factory.mktemp("saved")
    started = {"saved": (saved, _start([sys.executable, "-c", SAVE_SCRIPT, str(saved)], saved, env))}
    shot = tmp_path_factory.mktemp("browser")
    script = [sys.executable, str(ROOT / "scripts" / "viewer_screenshot.py"), "--out", str(shot / "shot.png")]
    started["browser"] = (shot, _start(script, shot, env) if shutil.which("chromium") else None)
    yield started
    for _, process in started.values():
        if process is not None and process.poll() is None:
            process.kill()


def _finished(run: tuple[Path, subprocess.Popen]) -> tuple[Path, str]:
    out, process = run
    process.wait(timeout=240)
    assert process.returncode == 0, (out / "stderr").read_text()[-3000:]
    return out, (out / "stdout").read_text()


@pytest.fixture(scope="module")
def sim():
    """Two pendulums under slider controls, paused (the tests step them)."""
    shown = viewer.serve(
        viewer.env(mjzoo.envs.make(ENV), "sliders", num_envs=2), port=0, host="127.0.0.1", playing=False
    )
    shown.step()  # compiles
    yield shown
    shown.stop()


def test_scene_has_one_handle_per_body_group(sim):
    groups = scene.body_groups(sim.source.mj_model)
    assert [g.name for g in groups] == ["world", "pole"]
    assert [g.name for g in groups[1].geoms] == ["pole", "bob"]
    assert set(sim.scene.handles) == {(e, g.name) for e in (0, 1) for g in groups}
    assert sim.scene.offsets[1, 0] - sim.scene.offsets[0, 0] >= 1.0  # side by side
    with urllib.request.urlopen(f"http://127.0.0.1:{sim.port}", timeout=10) as page:
        assert page.status == 200


def test_poses_change_after_steps(sim):
    sim.controls["ctrl/torque"].value = 1.0
    np.testing.assert_array_equal(sim.source.act_params, [1.0])
    before = [np.array(sim.scene.handles[(e, "pole")].wxyz) for e in (0, 1)]
    frames = sim.frames_shown
    sim.step(3)
    after = [np.array(sim.scene.handles[(e, "pole")].wxyz) for e in (0, 1)]
    assert all(not np.allclose(b, a) for b, a in zip(before, after))
    assert sim.frames_shown == frames + 1  # three jitted calls, one displayed frame


def test_a_slider_changes_the_task_in_the_next_step_without_a_compile(sim):
    sim.step()
    traces = sim.source.traces
    sim.controls["param/upright_weight"].value = 0.0
    assert float(mjzoo.params(sim.source.task)["upright_weight"]) == 0.0
    sim.step()
    np.testing.assert_array_equal(sim.source.frame().terms["upright"], [0.0, 0.0])
    sim.controls["param/upright_weight"].value = 1.5
    sim.step()
    assert np.all(sim.source.frame().terms["upright"] > 0)
    assert sim.source.traces == traces  # the same compiled step throughout


def test_one_env_shown_and_a_tracked_body(sim):
    sim.controls["env"].value = "1"
    assert [h.visible for (e, _), h in sorted(sim.scene.handles.items())] == [False, False, True, True]
    sim.controls["track"].value = "pole"
    assert sim.track == 1
    sim.step()
    sim.controls["env"].value, sim.controls["track"].value = "all", "none"
    assert sim.track is None and all(h.visible for h in sim.scene.handles.values())


def test_a_planner_draws_its_samples_and_plan():
    config = mppi.Config(num_samples=8, horizon_steps=6, num_knots=2)
    problem = mjzoo.envs.closed_loop_problem(ENV, mppi, config)
    shown = viewer.serve(viewer.planner(problem), port=0, host="127.0.0.1", playing=False)
    try:
        shown.step(2)
        samples, plan = shown.trace_handles["samples"].points, shown.trace_handles["plan"].points
        assert samples.shape == (7 * 5, 2, 3) and plan.shape == (5, 2, 3)  # 7 samples, 6 points each
        assert np.all(np.isfinite(samples)) and np.ptp(samples[..., 0]) > 0
        assert shown.stats()["plan_latency_ms"] > 0
        assert sorted(k for k in shown.controls if k.startswith("config/")) == [
            "config/cvar_alpha",
            "config/noise_scale",
            "config/temperature",
            "config/termination_cost",
        ]
        compiles = shown.source.compiles
        shown.controls["config/temperature"].value = 0.0  # mppi.Config refuses it: no compile
        assert "temperature" in shown.message and shown.source.compiles == compiles
    finally:
        shown.stop()


def _dataset(task: mjzoo.Task, episodes: int = 2, steps: int = 12) -> datasets.Dataset:
    """A swinging pendulum's states written as `mjzoo collect` would (poses by MuJoCo)."""
    model = task.mj_model
    qpos = np.linspace(0, 3, (steps + 1) * episodes).reshape(episodes, steps + 1, 1) + [[[0.0]], [[1.0]]]
    xpos, xquat = np.zeros(qpos.shape[:2] + (model.nbody, 3)), np.zeros(qpos.shape[:2] + (model.nbody, 4))
    data = mujoco.MjData(model)
    for i in np.ndindex(qpos.shape[:2]):
        data.qpos[:] = qpos[i]
        mujoco.mj_kinematics(model, data)
        xpos[i], xquat[i] = data.xpos, data.xquat
    zeros = lambda *shape: np.zeros((episodes,) + shape, np.float32)  # noqa: E731
    return datasets.Dataset(
        qpos=qpos,
        qvel=zeros(steps + 1, 1),
        time=zeros(steps + 1),
        xpos=xpos,
        xquat=xquat,
        obs=zeros(steps + 1, 3),
        action=zeros(steps, 1),
        ctrl=zeros(steps, 1),
        reward=zeros(steps),
        reward_terms={"upright": zeros(steps)},
        terminated=np.zeros((episodes, steps), bool),
        truncated=np.zeros((episodes, steps), bool),
        length=np.full(episodes, steps),
        dt=0.02,
        joint_names=("hinge",),
        body_names=("world", "pole"),
        actuator_names=("torque",),
        source={"task": ENV, "env_overrides": {}},
        seed=0,
        deterministic=True,
    )


def test_the_scrubber_shows_the_recorded_frame(tmp_path):
    data = _dataset(mjzoo.envs.make(ENV))
    datasets.save(tmp_path / "data", data)
    assert viewing.target_kind(str(tmp_path / "data")) == "dataset"
    source = viewing._source("dataset", str(tmp_path / "data"), None, (), "zero", None, (), False, 2, 0, None)
    shown = viewer.serve(source, port=0, host="127.0.0.1", playing=False)
    try:
        shown.controls["scrubber"].value = 7
        for e in (0, 1):
            np.testing.assert_allclose(
                shown.scene.handles[(e, "pole")].position - shown.scene.offsets[e], data.xpos[e, 7, 1], atol=1e-6
            )
            np.testing.assert_allclose(shown.scene.handles[(e, "pole")].wxyz, data.xquat[e, 7, 1], atol=1e-6)
        shown.controls["loop"].value = False
        shown.step(20)
        assert source.index == data.num_steps  # stopped at the end
    finally:
        shown.stop()


def test_a_clip_plays_on_the_env_its_name_starts_with():
    assert viewing.target_kind(str(CLIP)) == "clip" and viewing._env_of_clip(CLIP) == "cartpole_swingup"
    source = viewing._source("clip", str(CLIP), None, (), "zero", None, (), False, 1, 0, None)
    clip = mjzoo.motion.load_file(CLIP)
    shown = viewer.serve(source, port=0, host="127.0.0.1", playing=False)
    try:
        shown.controls["scrubber"].value = 100
        last = clip.body_names[-1]
        np.testing.assert_allclose(shown.scene.handles[(0, last)].position, clip.body_pos[100, -1], atol=1e-5)
    finally:
        shown.stop()


@pytest.mark.parametrize(
    "target, flags, message",
    [
        ("no_such_env", {}, "no_such_env"),
        ("missing.npz", {}, "missing.npz: no such file"),
        ("runs/missing", {}, "runs/missing: no such run directory"),
        (ENV, {"sampled": True}, "--sampled: only for a run"),
        (ENV, {"config": ("temperature=1.0",)}, "--config: only for --planner"),
        (ENV, {"speed": 3.0}, "--speed must be one of"),
        (str(CLIP), {"controls": "random"}, "--controls: only for a task"),
        (ENV, {"save_video": "EXISTING"}, "already exists: give --overwrite"),
        (ENV, {"save_video": "out.avi"}, "must end in .mp4 or .gif"),
    ],
)
def test_bad_input_is_one_line(tmp_path, target, flags, message):
    existing = tmp_path / "view.mp4"
    existing.write_bytes(b"")
    if flags.get("save_video"):
        flags = {
            **flags,
            "save_video": existing if flags["save_video"] == "EXISTING" else tmp_path / flags["save_video"],
        }
    with pytest.raises(UsageError) as error:
        viewing.view(target, port=0, **flags)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_save_frames_and_video(background):
    out, stdout = _finished(background["saved"])
    count = int(stdout.strip().splitlines()[-1])
    frames = sorted((out / "frames").glob("frame_*.png"))
    assert count >= 2 and len(frames) == count
    assert iio.imread(frames[0]).shape == (72, 96, 3)
    assert (
        len(iio.imread(out / "view.mp4", plugin="pyav")) == count
        if _has_pyav()
        else (out / "view.mp4").stat().st_size > 0
    )
    assert 2 <= len(iio.imread(out / "view.gif", index=None)) <= count  # Pillow merges repeated frames


def _has_pyav() -> bool:
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True


def test_the_browser_draws_the_scene(background):
    if background["browser"][1] is None:
        pytest.skip("no chromium on PATH (Debian: apt-get install -y chromium): the browser check needs it")
    out, stdout = _finished(background["browser"])
    result = json.loads(stdout.strip().splitlines()[-1])
    assert result["ok"], result
    assert (out / "shot.png").stat().st_size > 0
