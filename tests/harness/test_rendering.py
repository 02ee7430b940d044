"""Rendering: every RenderConfig option changes the pixels where it should (EGL, in a
fresh process), a one-line notice without OpenGL, and errors before any OpenGL work."""

from __future__ import annotations

import ctypes.util
import dataclasses
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import imageio.v3 as iio
import mujoco
import numpy as np
import pytest

from mjzoo.harness import rendering
from mjzoo.harness.rendering import RenderConfig

# A pendulum, a mocap box and a named camera; a small shadow map keeps CPU rendering fast.
PENDULUM_XML = """
<mujoco>
  <visual><quality shadowsize="512" offsamples="0"/></visual>
  <worldbody>
    <light pos="0 0 3"/>
    <geom type="plane" size="2 2 0.1" rgba=".3 .3 .3 1"/>
    <camera name="side" pos="0 -3 1" xyaxes="1 0 0 0 0.3 1"/>
    <body name="pole" pos="0 0 1.2">
      <joint name="hinge" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.8" size="0.05" rgba="1 .5 0 1"/>
    </body>
    <body name="target" mocap="true" pos="0.8 0 0.2">
      <geom type="box" size="0.1 0.1 0.1" rgba="0 .6 1 1"/>
    </body>
  </worldbody>
</mujoco>
"""

# A red box resting on a reflective floor (1 mm into it: four contacts), sliding along x,
# lit at a slant so its shadow falls beside it, towards the camera;
# contact points magenta and force arrows green, drawn large enough to count.
BOX_XML = """
<mujoco>
  <visual>
    <quality shadowsize="512" offsamples="0"/>
    <rgba contactpoint="1 0 1 1" contactforce="0 1 0 1"/>
    <scale contactwidth="0.3" contactheight="0.05" forcewidth="0.1"/>
    <map force="0.05"/>
  </visual>
  <asset><material name="mirror" reflectance="0.5" rgba=".5 .5 .5 1"/></asset>
  <worldbody>
    <light pos="-0.6 0.6 1.5" dir="0.6 -0.6 -1.5"/>
    <light directional="true" dir="0 0 -1" castshadow="false" diffuse=".4 .4 .4"/>
    <geom type="plane" size="2 2 0.1" material="mirror"/>
    <camera name="top" pos="0 0 3" xyaxes="1 0 0 0 1 0"/>
    <body name="box" pos="0 0 0.099">
      <joint name="x" type="slide" axis="1 0 0"/>
      <geom type="box" size="0.1 0.1 0.1" rgba="1 0 0 1"/>
      <site name="tip" pos="0 0 0.1" size="0.02"/>
    </body>
  </worldbody>
</mujoco>
"""

T = 8


def egl_installed() -> bool:
    """libEGL and an EGL driver (glvnd vendor file) are on this Linux machine."""
    vendors = Path("/usr/share/glvnd/egl_vendor.d")
    return ctypes.util.find_library("EGL") is not None and vendors.is_dir() and any(vendors.iterdir())


# Everything drawn with EGL, in one fresh process (MuJoCo reads MUJOCO_GL once, at
# import, and importing mjzoo takes seconds): images into frames.npz, videos under out/.
RENDER_SCRIPT = textwrap.dedent(
    """
    import json, sys
    import jax, mujoco, numpy as np
    from mjzoo.harness.rendering import RenderConfig, render_frames, render_video

    jax.numpy.zeros(1).block_until_ready()  # JAX running, as in a training process

    pendulum_xml, box_xml, out = sys.argv[1:4]
    model = mujoco.MjModel.from_xml_string(pendulum_xml)
    qpos = np.linspace(0, 2.5, {T})[:, None]
    box = np.tile([0.8, 0.0, 0.2], ({T}, 1, 1))
    moved = box + np.array([0.0, 0.0, 0.6])
    size = RenderConfig(width=160, height=120)
    swing = render_frames(model, qpos, mocap_pos=box, config=size)
    video = render_video(model, qpos, out + "/videos/pendulum.mp4", fps=10, mocap_pos=box, config=size)
    print(json.dumps({{"video": None if video is None else str(video)}}))
    if swing is None:
        sys.exit()

    drawn = dict(
        swing=swing,
        again=render_frames(model, qpos[[0, 0]], mocap_pos=box[:2], config=size),
        moved=render_frames(model, qpos[:1], mocap_pos=moved[:1], config=size),
        side=render_frames(model, qpos[:1], mocap_pos=box[:1], config=RenderConfig(width=160, height=120, camera="side")),
    )
    model = mujoco.MjModel.from_xml_string(box_xml)
    rest = np.zeros((1, 1))
    view = dict(width=64, height=48, distance=1.5)  # the whole box, and floor around it
    options = dict(
        small=dict(small_width=32, small_height=24), points=dict(contact_points=True), forces=dict(contact_forces=True),
        inertia=dict(inertia=True), markers=dict(markers=True), no_shadows=dict(shadows=False),
        no_reflections=dict(reflections=False), near=dict(distance=1.0), far=dict(distance=3.0),
        azimuth=dict(azimuth=30.0), elevation=dict(elevation=-89.0), lookat=dict(lookat=(0.3, 0.0, 0.0)),
    )
    drawn["base"] = render_frames(model, rest, config=RenderConfig(**view))
    for name, fields in options.items():
        drawn[name] = render_frames(model, rest, config=RenderConfig(**{{**view, **fields}}), small=name == "small")
    drawn["top"] = render_frames(model, rest, config=RenderConfig(width=64, height=48, camera="top"))

    slide = np.linspace(0, 0.9, 10)[:, None]  # 10 rows, 0.1 s apart: 1 m/s along x
    drawn["tracked"] = render_frames(model, slide, config=RenderConfig(**view, track_body="box"))
    drawn["fixed"] = render_frames(model, slide, config=RenderConfig(**view, lookat=(0.45, 0.0, 0.0)))
    for name, fields in dict(every_row=dict(), half_second=dict(length_seconds=0.5), fps5=dict(fps=5.0), fps20=dict(fps=20.0)).items():
        drawn[name] = render_frames(model, slide, dt=0.1, config=RenderConfig(**view, **fields))
    np.savez(out + "/frames.npz", **drawn)
    for name, fields in dict(real=dict(), slow=dict(fps=5.0, slowdown=2.0), cut=dict(length_seconds=0.35)).items():
        render_video(model, slide, out + f"/videos/{{name}}.mp4", dt=0.1, config=RenderConfig(**view, **fields))
    """
).format(T=T)


@pytest.fixture(scope="module")
def drawn(tmp_path_factory) -> dict[str, SimpleNamespace]:
    """RENDER_SCRIPT's runs with EGL and with glfw but no display, started together:
    each spends seconds importing mjzoo, so on two cores this halves the wait.
    Each: returncode, stdout, stderr and its output folder."""
    runs = {}
    for backend in ("egl", "glfw"):
        out = tmp_path_factory.mktemp(backend)
        env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
        env["MUJOCO_GL"] = backend
        with open(out / "stdout", "w") as stdout, open(out / "stderr", "w") as stderr:
            runs[backend] = (
                out,
                subprocess.Popen(
                    [sys.executable, "-c", RENDER_SCRIPT, PENDULUM_XML, BOX_XML, str(out)],
                    env=env,
                    stdout=stdout,
                    stderr=stderr,
                    close_fds=False,  # lets Python use posix_spawn: no fork of this multithreaded (JAX) process
                ),
            )
    for _, process in runs.values():
        process.wait(timeout=120)
    return {
        backend: SimpleNamespace(
            returncode=process.returncode,
            stdout=(out / "stdout").read_text(),
            stderr=(out / "stderr").read_text(),
            out=out,
        )
        for backend, (out, process) in runs.items()
    }


@pytest.fixture(scope="module")
def egl(drawn) -> SimpleNamespace:
    """What the EGL process drew: its run, the images and the pendulum video's path."""
    run = drawn["egl"]
    assert run.returncode == 0, run.stderr
    video = json.loads(run.stdout.strip().splitlines()[0])["video"]
    if video is None:
        assert not egl_installed(), run.stderr  # else a None would hide a bug behind the no-backend notice
        pytest.skip("no EGL on this machine")
    return SimpleNamespace(**vars(run), video=video, frames=dict(np.load(run.out / "frames.npz")))


def red(image: np.ndarray) -> np.ndarray:
    """[..., H, W] mask of the box's pixels."""
    r, g, b = np.moveaxis(image.astype(int), -1, 0)
    return (r > 120) & (g < 60) & (b < 60)


def colour(image: np.ndarray, rgb: tuple[int, int, int]) -> int:
    """How many pixels have the hue of a saturated colour given by 0/1 channels
    (shaded or not): each wanted channel 60 above each other one."""
    channels = np.moveaxis(image.astype(int), -1, 0)
    want = np.array(rgb, bool)
    return int(np.sum(channels[want].min(0) > channels[~want].max(0) + 60))


def changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[..., H, W] mask of the pixels that differ clearly."""
    return np.abs(a.astype(int) - b.astype(int)).sum(-1) > 30


def centre(image: np.ndarray) -> np.ndarray:
    """(x, y) centroid of the box's pixels."""
    ys, xs = np.nonzero(red(image))
    assert len(xs) > 0, "the box is not in view"
    return np.array([xs.mean(), ys.mean()])


@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")  # iio.imread starts ffmpeg from this JAX process
def test_renders_video_and_frames_with_egl(egl):
    assert egl.stderr == ""  # no warnings either (e.g. JAX's on ffmpeg's fork)
    frames = egl.frames
    swing = frames["swing"]
    assert swing.shape == (T, 120, 160, 3) and swing.dtype == np.uint8
    assert np.abs(swing[0].astype(int) - swing[T // 2]).mean() > 0.5  # the pendulum moved
    np.testing.assert_array_equal(frames["again"][0], swing[0])  # same pose, same picture
    np.testing.assert_array_equal(frames["again"][1], swing[0])
    assert np.abs(frames["moved"][0].astype(int) - swing[0]).mean() > 0.5  # mocap poses are applied
    assert np.abs(frames["side"][0].astype(int) - swing[0]).mean() > 5  # another camera, another view

    videos = egl.out / "videos"
    assert egl.video == str(videos / "pendulum.mp4")
    assert not [p for p in videos.iterdir() if "partial" in p.name]  # no partial file left
    decoded = iio.imread(egl.video)
    assert decoded.shape == (T, 120, 160, 3)
    # The video shows the rendered frames, in order (up to H.264 losses).
    errors = np.abs(decoded.astype(int) - swing.astype(int)).mean(axis=(1, 2, 3))
    assert errors.max() < 6, errors
    assert np.abs(decoded[0].astype(int) - swing[T // 2]).mean() > errors[0]


def test_sizes(egl):
    assert egl.frames["base"].shape == (1, 48, 64, 3)
    assert egl.frames["small"].shape == (1, 24, 32, 3)  # small=True draws small_width x small_height


def test_contact_points_and_forces_are_drawn(egl):
    base = egl.frames["base"][0]
    assert colour(base, (1, 0, 1)) == 0 and colour(base, (0, 1, 0)) == 0
    assert colour(egl.frames["points"][0], (1, 0, 1)) > 10  # magenta discs at the box's corners
    assert colour(egl.frames["forces"][0], (0, 1, 0)) > 5  # green arrows out of the floor


def test_inertia_boxes_and_markers_are_drawn(egl):
    base = egl.frames["base"][0]
    assert changed(egl.frames["inertia"][0], base).sum() > 50
    assert changed(egl.frames["markers"][0], base).sum() > 10  # the site's frame and the centre of mass


def test_shadows_and_reflections_darken_and_mirror_the_floor(egl):
    base = egl.frames["base"][0]
    floor = ~red(base)
    no_shadow = egl.frames["no_shadows"][0]
    shadow = changed(no_shadow, base) & floor
    assert shadow.sum() > 10  # the shadow beside the box, on the floor
    assert no_shadow[shadow].astype(int).sum() > base[shadow].astype(int).sum()  # lit without it
    assert (changed(egl.frames["no_reflections"][0], base) & floor).sum() > 10  # the box's mirror image


def test_free_camera_fields(egl):
    frames = egl.frames
    near, far = red(frames["near"][0]).sum(), red(frames["far"][0]).sum()
    assert near > 3 * far > 0  # farther away, the box is smaller
    for name in ("azimuth", "elevation", "top"):
        assert changed(frames[name][0], frames["base"][0]).sum() > 50, name
    assert np.abs(centre(frames["lookat"][0]) - centre(frames["base"][0]))[0] > 3  # looking beside the box


def test_tracked_body_stays_centred(egl):
    tracked = np.array([centre(image) for image in egl.frames["tracked"]])
    fixed = np.array([centre(image) for image in egl.frames["fixed"]])
    assert np.ptp(fixed[:, 0]) > 10  # the box crosses a fixed camera's view
    assert np.ptp(tracked, axis=0).max() < 1.0  # and stays put in the tracking one
    np.testing.assert_allclose(tracked[0], [31.5, 23.5], atol=3)  # in the middle


def test_length_and_fps_choose_the_rows(egl):
    frames = egl.frames
    every = frames["every_row"]
    assert len(every) == 10
    np.testing.assert_array_equal(frames["half_second"], every[:5])
    np.testing.assert_array_equal(frames["fps5"], every[::2])  # below real time: rows skipped
    np.testing.assert_array_equal(frames["fps20"], np.repeat(every, 2, axis=0))  # above: repeated


@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")
@pytest.mark.parametrize(("name", "frames", "fps"), [("real", 10, 10.0), ("slow", 5, 2.5), ("cut", 4, 10.0)])
def test_video_frames_and_rate(egl, name, frames, fps):
    path = egl.out / "videos" / f"{name}.mp4"
    assert iio.imread(path).shape == (frames, 48, 64, 3)
    assert iio.immeta(path, plugin="FFMPEG")["fps"] == pytest.approx(fps)  # slow: 5 frames per sim s, at half speed


def test_without_a_display_prints_one_line_per_call(drawn):
    run = drawn["glfw"]
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout.strip().splitlines()[0])["video"] is None
    notices = run.stderr.strip().splitlines()
    assert len(notices) == 2 and all(line.startswith("mjzoo: no OpenGL backend") for line in notices)
    assert notices[1].endswith(f"skipping video {run.out}/videos/pendulum.mp4")
    assert not (run.out / "videos").exists() and not (run.out / "frames.npz").exists()


@pytest.fixture
def model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(PENDULUM_XML)


@pytest.fixture
def no_opengl(monkeypatch):
    """Makes creating a renderer fail as it does without a display or EGL."""
    made = []

    def renderer(model, height, width):
        made.append((model, height, width))
        raise mujoco.FatalError("an OpenGL platform library has not been loaded into this process")

    monkeypatch.setattr(mujoco, "Renderer", renderer)
    monkeypatch.setattr(rendering, "_no_opengl", None)  # forget failures of earlier tests
    return made


def test_without_opengl_prints_one_line_and_returns_none(model, no_opengl, tmp_path, capsys):
    path = tmp_path / "out" / "video.mp4"
    assert rendering.render_video(model, np.zeros((3, 1)), path, fps=30) is None
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("mjzoo: no OpenGL backend (MUJOCO_GL=")
    assert "FatalError: an OpenGL platform library" in lines[0] and "MUJOCO_GL=egl or osmesa" in lines[0]
    assert lines[0].endswith(f"skipping video {path}")
    assert not path.parent.exists()

    # Later calls say it again but do not try again: a retry can abort the process.
    assert rendering.render_frames(model, np.zeros((3, 1))) is None
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("mjzoo: no OpenGL backend") and line.endswith("skipping frames")
    assert len(no_opengl) == 1


def test_bad_arguments_are_errors_before_any_opengl(model, no_opengl, tmp_path):
    qpos = np.zeros((4, 1))
    cases = [
        ({"qpos": np.zeros((4, 2))}, r"qpos must have shape \[T, 1\], got \[4, 2\]"),
        ({"qpos": np.zeros(4)}, r"qpos must have shape \[T, 1\]"),
        ({"qpos": np.zeros((0, 1))}, "no frames"),
        ({"qpos": qpos, "mocap_pos": np.zeros((4, 3))}, r"mocap_pos must have shape .*\[4, 1, 3\], got \[4, 3\]"),
        ({"qpos": qpos, "mocap_quat": np.zeros((3, 1, 4))}, r"mocap_quat must have shape .*\[4, 1, 4\]"),
        ({"qpos": qpos, "config": RenderConfig(camera="top")}, r"no camera named 'top'.*\['side'\]"),
        ({"qpos": qpos, "config": RenderConfig(camera=1)}, r"camera id 1 out of range \[-1, 1\)"),
        ({"qpos": qpos, "config": RenderConfig(track_body="torso")}, r"track_body: no body named 'torso'.*'pole'"),
        ({"qpos": qpos, "config": RenderConfig(track_body=3)}, r"track_body: body id 3 out of range \[0, 3\)"),
        ({"qpos": qpos, "config": RenderConfig(length_seconds=1.0)}, "length_seconds needs the trajectory's time step"),
        ({"qpos": qpos, "dt": 0.0}, "dt must be > 0"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message):
            rendering.render_frames(model, **kwargs)
    with pytest.raises(ValueError, match="fps must be > 0"):
        rendering.render_video(model, qpos, tmp_path / "v.mp4", fps=0)
    with pytest.raises(ValueError, match="render_video needs the frame rate: pass dt="):
        rendering.render_video(model, qpos, tmp_path / "v.mp4")
    assert no_opengl == []


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"width": 0}, "width=0 is invalid; expected an integer >= 1"),
        ({"small_height": 2.5}, "small_height=2.5 is invalid; expected an integer >= 1"),
        ({"fps": 0.0}, "fps=0.0 is invalid; expected > 0 or None"),
        ({"length_seconds": -1.0}, "length_seconds=-1.0 is invalid; expected > 0 or None"),
        ({"slowdown": 0.0}, "slowdown=0.0 is invalid; expected > 0"),
        ({"distance": float("nan")}, "distance=nan is invalid; expected > 0 or None"),
        ({"lookat": (0.0, 1.0)}, "lookat=\\(0.0, 1.0\\) is invalid; expected 3 finite numbers"),
        ({"max_series_per_plot": 0}, "max_series_per_plot=0 is invalid; expected an integer >= 1"),
        ({"plot_figsize": (4.0, 0.0)}, "plot_figsize=\\(4.0, 0.0\\) is invalid; expected 2 numbers > 0"),
        ({"camera": "side", "distance": 2.0}, "camera='side' is a model camera; distance set a free camera"),
        ({"lookat": (0.0, 0.0, 0.0), "track_body": "box"}, "lookat and track_body"),
    ],
)
def test_config_values_are_checked(fields, message):
    with pytest.raises(ValueError, match=f"^RenderConfig: {message}"):
        RenderConfig(**fields)


def test_config_round_trips_through_json():
    config = RenderConfig(width=64, fps=12.5, lookat=(1.0, 2.0, 3.0), camera=None, plot_figsize=(2.0, 1.0))
    again = RenderConfig(**json.loads(json.dumps(dataclasses.asdict(config))))
    assert again == config and isinstance(again.lookat, tuple)


@pytest.mark.parametrize(
    ("length", "dt", "fps", "seconds", "rows", "rate"),
    [
        (5, None, None, None, [0, 1, 2, 3, 4], None),  # no time known: every row
        (5, None, 30.0, None, [0, 1, 2, 3, 4], 30.0),  # no dt: each row a frame at fps
        (6, 0.02, None, None, [0, 1, 2, 3, 4, 5], 50.0),  # real time
        (6, 0.02, 25.0, None, [0, 2, 4], 25.0),
        (6, 0.02, None, 0.06, [0, 1, 2], 50.0),
        (4, 0.1, 15.0, None, [0, 0, 1, 2, 2, 3], 15.0),  # frame k at k / 15 s: rows at or before it
        (3, 0.1, None, 100.0, [0, 1, 2], 10.0),  # longer than the trajectory: all of it
    ],
)
def test_timing_picks_the_row_at_each_frame_time(length, dt, fps, seconds, rows, rate):
    picked, got = rendering._timing(length, dt, fps, seconds)
    assert picked.tolist() == rows and got == rate


def test_trajectory_video_takes_time_step_and_first_camera(model, monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(rendering, "render_video", lambda *args, **kwargs: calls.append((args, kwargs)))
    data = SimpleNamespace(
        qpos=np.zeros((5, 1)), time=np.arange(1, 6) * 0.04, mocap_pos=np.zeros((5, 1, 3)), mocap_quat=np.ones((5, 1, 4))
    )
    task = SimpleNamespace(mj_model=model)
    trajectory = SimpleNamespace(next_state=_next_states(data, ended=None))
    for config, camera in [
        (RenderConfig(), 0),  # the model's first camera
        (RenderConfig(camera="side"), "side"),
        (RenderConfig(distance=3.0), None),  # a free camera was asked for
    ]:
        rendering.trajectory_video(task, trajectory, tmp_path / "v.mp4", config)
        (args, kwargs), *_ = calls[::-1]
        assert args[0] is model and args[2] == tmp_path / "v.mp4"
        assert kwargs["dt"] == pytest.approx(0.04) and kwargs["config"].camera == camera
        np.testing.assert_array_equal(kwargs["mocap_quat"], data.mocap_quat)


def _next_states(data, ended: int | None, layers=()) -> SimpleNamespace:
    """A trajectory's next states over `data` ([T] rows), terminated at row `ended`."""
    terminated = np.arange(len(data.time)) == ended
    return SimpleNamespace(data=data, terminated=terminated, truncated=np.zeros_like(terminated), layers=layers)


@pytest.mark.parametrize(
    "terminated, truncated, resets, rows",
    [
        ([0, 0, 0, 0, 0], [0, 0, 0, 0, 0], False, 5),  # no end: every row
        ([0, 0, 1, 0, 1], [0, 0, 0, 0, 0], False, 3),  # up to and including the first end
        ([0, 0, 0, 0, 0], [0, 1, 0, 0, 0], False, 2),  # a time limit ends it too
        ([0, 0, 1, 0, 0], [0, 0, 0, 0, 0], True, 2),  # auto-reset: the ending row is the next start
        ([1, 0, 0, 0, 0], [0, 0, 0, 0, 0], True, 1),  # a frame at least
    ],
)
def test_first_episode_rows_end_at_the_first_termination_or_truncation(terminated, truncated, resets, rows):
    assert rendering.first_episode_rows(terminated, truncated, resets) == rows


def test_an_episode_that_terminates_early_makes_a_video_of_that_many_frames(model, monkeypatch, tmp_path):
    from mjzoo.combinators import AutoResetState

    calls = []
    monkeypatch.setattr(rendering, "render_video", lambda *args, **kwargs: calls.append((args, kwargs)))
    data = SimpleNamespace(
        qpos=np.arange(8.0)[:, None],
        time=np.arange(1, 9) * 0.04,
        mocap_pos=np.zeros((8, 1, 3)),
        mocap_quat=np.ones((8, 1, 4)),
    )
    task = SimpleNamespace(mj_model=model)
    resetting = AutoResetState(final_obs=np.zeros((8, 1)))  # with_auto_reset's record, as `layers` holds it
    for states, first_episode, rows in [
        (_next_states(data, ended=2), True, 3),  # the fall is the last frame
        (_next_states(data, ended=2, layers=resetting), True, 2),  # row 2 is already the next episode
        (_next_states(data, ended=2), False, 8),  # the whole trajectory, when asked for
    ]:
        rendering.trajectory_video(
            task, SimpleNamespace(next_state=states), tmp_path / "v.mp4", first_episode=first_episode
        )
        (args, kwargs), *_ = calls[::-1]
        np.testing.assert_array_equal(args[1], data.qpos[:rows])
        assert len(kwargs["mocap_pos"]) == len(kwargs["mocap_quat"]) == rows
        assert kwargs["dt"] == pytest.approx(0.04)


def test_large_images_enlarge_the_framebuffer_of_a_copy(model, no_opengl):
    rendering.render_frames(model, np.zeros((1, 1)), config=RenderConfig(width=1280, height=720, camera="side"))
    ((used, height, width),) = no_opengl
    assert (width, height) == (1280, 720)
    assert (used.vis.global_.offwidth, used.vis.global_.offheight) == (1280, 720)
    assert (model.vis.global_.offwidth, model.vis.global_.offheight) == (640, 480)  # the caller's is untouched


def test_floors_are_drawn_under_the_whole_path_with_checker_squares_kept():
    model = mujoco.MjModel.from_xml_string("""
    <mujoco>
      <asset>
        <texture name="checker" type="2d" builtin="checker" width="8" height="8"/>
        <material name="grid" texture="checker" texrepeat="4 4"/>
      </asset>
      <worldbody>
        <geom name="floor" type="plane" size="2 2 0.1" material="grid"/>
        <geom name="wall" type="plane" size="2 2 0.1" pos="3 0 0" zaxis="1 0 0"/>
        <body name="runner" pos="0 0 0.5"><freejoint/><geom type="sphere" size="0.1"/></body>
      </worldbody>
    </mujoco>""")
    qpos = np.zeros((3, 7))
    qpos[:, 0] = [0.0, 15.0, 30.0]  # runs 30 m along +x
    qpos[:, 1] = [0.0, -1.0, 0.0]
    config = RenderConfig(width=32, height=24)
    frames = rendering._Frames(model, qpos, None, None, dt=None, fps=None, config=config, small=False)
    # Reach 30 + 10 m along x (x20 the size), 1 + 10 m along y (x5.5).
    np.testing.assert_allclose(frames.model.geom_size[0, :2], [40.0, 11.0])
    np.testing.assert_allclose(frames.model.mat_texrepeat[0], [80.0, 22.0])
    np.testing.assert_allclose(frames.model.geom_size[1, :2], [2.0, 2.0])  # a wall is left alone
    np.testing.assert_allclose(model.geom_size[0, :2], [2.0, 2.0])  # the caller's model is untouched
