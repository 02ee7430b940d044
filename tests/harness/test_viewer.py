"""The live viewer (`mjzoo.harness.viewer`) and `mjzoo view`: a real viser server on a
free port, driven from Python (`Viewer.step`, GUI handles' ``.value``, which run the
browser's callbacks). One pendulum simulation, one tiny planner and hand-made
recordings share their compiles through module fixtures; the offscreen frames and
video run in a fresh EGL process started first, so that it overlaps the rest. The last
tests open the same viewers in headless Chromium (`viewer.browser`) and read what it
draws, moving its sliders and pressing its buttons with mouse clicks."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
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
from mjzoo.harness.viewer import browser
from mjzoo.harness.viewer import scene
from mjzoo.harness.viewer.app import PLAN_RGB

ROOT = Path(__file__).resolve().parents[2]
ENV = "pendulum_swingup"
CLIP = ROOT / "envs" / "assets" / "cartpole_swingup_mppi.npz"

# `mjzoo view` with --seconds, --save-frames and --save-video (and the same frames as a
# GIF; and a clip beside itself, as panes), in a fresh process: MuJoCo reads MUJOCO_GL
# once, at import.
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
    clip = "envs/assets/cartpole_swingup_mppi.npz"
    viewing.view(clip, source=clip, seconds=0.2, port=0, host="127.0.0.1", save_frames=out / "pairs",
                 save_video=out / "pairs.mp4", render=config)
    print(len(seen["shown"].recorded))
    """
)


def _start(args: list[str], out: Path, env: dict[str, str]) -> subprocess.Popen:
    with open(out / "stdout", "w") as stdout, open(out / "stderr", "w") as stderr:
        return subprocess.Popen(args, env=env, stdout=stdout, stderr=stderr, close_fds=False, cwd=ROOT)


@pytest.fixture(scope="module", autouse=True)
def background(tmp_path_factory) -> dict[str, tuple[Path, subprocess.Popen | None]]:
    """The EGL run, started before any test of this module."""
    env = {**os.environ, "MUJOCO_GL": "egl"}
    saved = tmp_path_factory.mktemp("saved")
    started = {"saved": (saved, _start([sys.executable, "-c", SAVE_SCRIPT, str(saved)], saved, env))}
    yield started
    for _, process in started.values():
        if process.poll() is None:
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


@pytest.fixture(scope="module")
def planned():
    """A small MPPI planning the pendulum, paused (the tests step it)."""
    config = mppi.Config(num_samples=8, horizon_steps=20, num_knots=2)
    problem = mjzoo.envs.closed_loop_problem(ENV, mppi, config)
    shown = viewer.serve(viewer.planner(problem), port=0, host="127.0.0.1", playing=False)
    yield shown
    shown.stop()


def test_a_planner_draws_its_samples_and_plan(planned):
    planned.step(2)
    samples, plan = planned.trace_handles["samples"].points, planned.trace_handles["plan"].points
    assert samples.shape == (7 * 19, 2, 3) and plan.shape == (19, 2, 3)  # 7 samples, 20 points each
    assert np.all(np.isfinite(samples)) and np.ptp(samples[..., 0]) > 0
    assert planned.stats()["plan_latency_ms"] > 0
    assert sorted(k for k in planned.controls if k.startswith("config/")) == [
        "config/cvar_alpha",
        "config/noise_ramp",
        "config/noise_scale",
        "config/temperature",
        "config/termination_cost",
    ]
    compiles = planned.source.compiles
    planned.controls["config/temperature"].value = 0.0  # mppi.Config refuses it: no compile
    assert "temperature" in planned.message and planned.source.compiles == compiles


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


def _root_positions(m: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """[nbody, 3] body positions of one frame."""
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    return d.xpos.copy()


def test_clips_of_other_frame_rates_play_in_step_side_by_side():
    model = mjzoo.envs.make("cartpole_swingup").mj_model
    clip = mjzoo.motion.load(CLIP, model)
    fast = mjzoo.motion.resample(clip, 2 * clip.fps, model)
    side = viewer.side_by_side([(model, clip), (model, fast)], spacing=1.5)
    assert side.num_frames == clip.num_frames and side.dt == pytest.approx(1 / clip.fps)
    shown = viewer.serve(side, port=0, host="127.0.0.1", playing=False)
    try:
        np.testing.assert_allclose(shown.scene.offsets[:, 0], [-0.75, 0.75])
        shown.controls["scrubber"].value = 10
        shown.step(5)  # five frames of the first clip: ten of the second
        assert side.indices() == [15, 30]
        pole = model.body("pole").id
        for e, frame in ((0, clip.qpos[15]), (1, fast.qpos[30])):
            drawn = shown.scene.handles[(e, "pole")].position - shown.scene.offsets[e]
            np.testing.assert_allclose(drawn, _root_positions(model, frame)[pole], atol=1e-6)
        shown.controls["scrubber"].value = clip.num_frames - 1
        shown.controls["loop"].value = False
        shown.step(3)
        assert side.indices() == [clip.num_frames - 1, fast.num_frames - 1]  # both at their ends
    finally:
        shown.stop()


def test_a_retargeted_clip_plays_beside_its_source_in_one_scene():
    # what `mjzoo view envs/assets/motions/g1/walk.npz --source humanoid3d_walk` shows
    g1, clip = viewing._target_clip(ROOT / "envs" / "assets" / "motions" / "g1" / "walk.npz", None, ())
    human, walk = viewing._source_clip("humanoid3d_walk", None)
    assert g1.nq == 36 and human.nq == 43 and clip.fps == walk.fps
    shown = viewer.serve(viewer.side_by_side([(g1, clip), (human, walk)]), port=0, host="127.0.0.1", playing=False)
    try:
        bodies = [{name for env, name in shown.scene.handles if env == e} for e in (0, 1)]
        assert {"pelvis", "left_wrist_yaw_link"} <= bodies[0] and {"root", "left_wrist"} <= bodies[1]
        assert shown.scene.offsets[1, 0] - shown.scene.offsets[0, 0] > 1.0  # apart, not overlapping
        shown.controls["scrubber"].value = 20
        for e, model, qpos, root in ((0, g1, clip.qpos[20], "pelvis"), (1, human, walk.qpos[20], "root")):
            drawn = shown.scene.handles[(e, root)].position - shown.scene.offsets[e]
            np.testing.assert_allclose(drawn, _root_positions(model, qpos)[model.body(root).id], atol=1e-6)
    finally:
        shown.stop()


@pytest.mark.parametrize(
    "target, flags, message",
    [
        (ENV, {"source": "walk"}, "--source: only beside a motion clip"),
        (str(CLIP), {"source": "no_such_clip"}, "no clip 'no_such_clip'"),
        (str(CLIP), {"source": "walk", "source_task": ENV}, "--source-task: only for a .npz --source"),
        ("no_such_env", {}, "no_such_env"),
        ("missing.npz", {}, "missing.npz: no such file"),
        ("runs/missing", {}, "runs/missing: no such run directory"),
        (ENV, {"sampled": True}, "--sampled: only for a run"),
        (ENV, {"config": ("temperature=1.0",)}, "--config: only for --planner"),
        (ENV, {"trace": ("pole",)}, "--trace: only for --planner"),
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
    pairs = sorted((out / "pairs").glob("frame_*.png"))
    assert len(pairs) >= 2 and iio.imread(pairs[0]).shape == (72, 2 * 96, 3)  # the two clips' panes
    assert (out / "pairs.mp4").stat().st_size > 0


def _has_pyav() -> bool:
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True


# --- in headless Chromium: what the page draws -------------------------------------------


@pytest.fixture(scope="module")
def page():
    """One headless Chromium tab (1280 x 560 page pixels) for the browser checks."""
    if browser.find_chromium() is None:
        pytest.skip("no chromium on PATH (Debian: apt-get install -y chromium): the browser checks need it")
    with browser.chromium() as tab:
        yield tab


def _rgb(shown: viewer.Viewer, geom: str = "bob") -> tuple[int, int, int]:
    """A geom's colour as the scene sends it: the pendulum's bob is orange, its pole grey, the floor dark."""
    found = next(g for group in shown.scene.groups for g in group.geoms if g.name == geom)
    return tuple(int(255 * c) for c in found.rgba[:3])


def _blobs(mask: np.ndarray, gap: int = 20) -> list[np.ndarray]:
    """Centres (x, y) of the groups of True pixels of `mask` [H, W] that `gap` empty
    columns part, left to right."""
    ys, xs = np.nonzero(mask)
    order = np.argsort(xs)
    groups = np.split(order, np.flatnonzero(np.diff(xs[order]) > gap) + 1) if len(xs) else []
    return [np.array([xs[g].mean(), ys[g].mean()]) for g in groups]


def _open(page: browser.Page, shown: viewer.Viewer) -> np.ndarray:
    """Shows `shown` in the tab (loaded once) and returns the scene once its bodies are drawn."""
    url = f"http://127.0.0.1:{shown.port}/"
    if page.evaluate("location.href") != url:
        page.open(url)
    bob = _rgb(shown)
    return page.until(lambda image: browser.colored(image, bob).sum() > 20)


def _wait_for(done, timeout: float = 30.0) -> None:
    deadline = time.time() + timeout
    while not done():
        assert time.time() < deadline, f"not within {timeout:.0f} s"
        time.sleep(0.02)


def test_the_browser_draws_the_scene(sim, page, tmp_path):
    image = _open(page, sim)
    iio.imwrite(tmp_path / "scene.png", image)
    bobs = _blobs(browser.colored(image, _rgb(sim)))
    assert len(bobs) == 2 and bobs[1][0] - bobs[0][0] > 100  # both pendulums, side by side
    assert browser.colored(image, PLAN_RGB).sum() == 0  # no planner: none of its red
    floor = np.all(np.abs(image.astype(int) - _rgb(sim, "floor")) < 30, axis=-1)  # shaded a little
    assert floor.mean() > 0.1


def test_a_slider_moved_in_the_browser_changes_the_scene(sim, page, tmp_path):
    """Reset, the torque slider to one end, ten steps: the two ends leave the bobs
    apart, each env's (the buttons and the slider clicked in the page)."""
    image, bob, shots = _open(page, sim), _rgb(sim), []
    for end, torque in ((1.0, 1.0), (0.0, -1.0)):
        page.click_button("Reset")
        page.move_slider("torque", end)
        # the slider's value reaches the server before the steps that should feel it
        _wait_for(lambda torque=torque: np.array_equal(sim.source.act_params, [torque]), timeout=60.0)
        for _ in range(10):  # each click once the last one's step is done, as a user watching it would
            steps = sim.source.steps
            page.click_button("Step")
            _wait_for(lambda steps=steps: sim.source.steps > steps)
        np.testing.assert_array_equal(sim.source.act_params, [torque])  # the click reached the server
        image = page.until(lambda shown, before=image: not np.array_equal(shown, before))
        iio.imwrite(tmp_path / f"torque{torque:+.0f}.png", image)
        shots.append(_blobs(browser.colored(image, bob)))
    sim.controls["ctrl/torque"].value = 0.0
    assert [len(s) for s in shots] == [2, 2]
    for pushed, pulled in zip(*shots):
        assert np.linalg.norm(pushed - pulled) > 5  # pixels


def test_a_planner_traces_several_points_each_along_its_own_path():
    """A humanoid's planned motion is the paths of several bodies: here the pole's centre
    of mass (its radius from the pivot is fixed) and the world body (still at the origin)."""
    config = mppi.Config(num_samples=8, horizon_steps=20, num_knots=2)
    source = viewer.planner(mjzoo.envs.closed_loop_problem(ENV, mppi, config), trace=("pole", "world"))
    source.advance()
    paths = source.frame().traces
    assert paths.shape == (8, 20, 2, 3)  # 7 samples and the plan, 20 steps, 2 points
    np.testing.assert_allclose(np.linalg.norm(paths[:, :, 0], axis=-1), 0.4975, atol=1e-3)
    assert np.ptp(paths[:, :, 0, 0]) > 0  # the pole swings along the plan
    np.testing.assert_array_equal(paths[:, :, 1], 0.0)
    with pytest.raises(KeyError, match="no body or site"):
        viewer.planner(mjzoo.envs.closed_loop_problem(ENV, mppi, config), trace=("pole", "tip"))


def test_the_browser_draws_the_planners_traces(planned, page, tmp_path):
    """The plan's red and the samples' lines on screen: hiding each one's handle takes its pixels away."""
    for _ in range(100):  # until it swings: a plan longer than the bob is wide
        planned.step()
        plan = planned.trace_handles["plan"].points
        if np.linalg.norm(plan - plan[0, 0], axis=-1).max() > 0.2:
            break
    shown = _open(page, planned)
    iio.imwrite(tmp_path / "planner.png", shown)
    assert browser.colored(shown, PLAN_RGB).sum() > 20  # the plan's red
    try:
        planned.trace_handles["samples"].visible = False
        no_samples = page.until(lambda image: not np.array_equal(image, shown))
        planned.trace_handles["plan"].visible = False
        neither = page.until(lambda image: not np.array_equal(image, no_samples))
    finally:
        for handle in planned.trace_handles.values():
            handle.visible = True
    assert np.any(shown != no_samples, axis=-1).sum() > 20  # the samples' pixels
    assert browser.colored(neither, PLAN_RGB).sum() == 0  # all the red was the plan's
