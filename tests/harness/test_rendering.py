"""Rendering: real frames and MP4 with an OpenGL backend, a one-line notice without."""

from __future__ import annotations

import ctypes.util
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import imageio.v3 as iio
import mujoco
import numpy as np
import pytest

from mjzoo.harness import rendering

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

T = 8


def egl_installed() -> bool:
    """libEGL and an EGL driver (glvnd vendor file) are on this Linux machine."""
    vendors = Path("/usr/share/glvnd/egl_vendor.d")
    return ctypes.util.find_library("EGL") is not None and vendors.is_dir() and any(vendors.iterdir())


# In a fresh process, because MuJoCo reads MUJOCO_GL once, at import.
RENDER_SCRIPT = textwrap.dedent(
    """
    import json, sys
    import jax, mujoco, numpy as np
    from mjzoo.harness.rendering import render_frames, render_video

    jax.numpy.zeros(1).block_until_ready()  # JAX running, as in a training process

    xml, out = sys.argv[1], sys.argv[2]
    model = mujoco.MjModel.from_xml_string(xml)
    qpos = np.linspace(0, 2.5, {T})[:, None]
    box = np.tile([0.8, 0.0, 0.2], ({T}, 1, 1))
    moved = box + np.array([0.0, 0.0, 0.6])
    size = dict(width=160, height=120)
    swing = render_frames(model, qpos, mocap_pos=box, **size)
    video = render_video(model, qpos, out + "/videos/pendulum.mp4", fps=10, mocap_pos=box, **size)
    if swing is not None:
        np.savez(
            out + "/frames.npz",
            swing=swing,
            again=render_frames(model, qpos[[0, 0]], mocap_pos=box[:2], **size),
            moved=render_frames(model, qpos[:1], mocap_pos=moved[:1], **size),
            side=render_frames(model, qpos[:1], mocap_pos=box[:1], camera="side", **size),
        )
    print(json.dumps({{"video": None if video is None else str(video)}}))
    """
).format(T=T)


@pytest.mark.parametrize("backend", ["egl", "glfw without a display"])
@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")  # iio.imread starts ffmpeg from this JAX process
def test_renders_video_and_frames_or_reports_no_backend(tmp_path, backend):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["MUJOCO_GL"] = backend.split()[0]
    result = subprocess.run(
        [sys.executable, "-c", RENDER_SCRIPT, PENDULUM_XML, str(tmp_path)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        close_fds=False,  # lets Python use posix_spawn: no fork of this multithreaded (JAX) process
    )
    assert result.returncode == 0, result.stderr
    video = json.loads(result.stdout.strip().splitlines()[-1])["video"]
    if backend != "egl":
        assert video is None
    elif egl_installed():  # then a None would hide a bug behind the no-backend notice
        assert video is not None, result.stderr

    if video is None:  # no backend: one line per call and nothing else, nothing written
        notices = result.stderr.strip().splitlines()
        assert len(notices) == 2 and all(line.startswith("mjzoo: no OpenGL backend") for line in notices)
        assert notices[1].endswith(f"skipping video {tmp_path}/videos/pendulum.mp4")
        assert not (tmp_path / "videos").exists() and not (tmp_path / "frames.npz").exists()
        return

    assert result.stderr == ""  # no warnings either (e.g. JAX's on ffmpeg's fork)
    frames = np.load(tmp_path / "frames.npz")
    swing = frames["swing"]
    assert swing.shape == (T, 120, 160, 3) and swing.dtype == np.uint8
    assert np.abs(swing[0].astype(int) - swing[T // 2]).mean() > 0.5  # the pendulum moved
    np.testing.assert_array_equal(frames["again"][0], swing[0])  # same pose, same picture
    np.testing.assert_array_equal(frames["again"][1], swing[0])
    assert np.abs(frames["moved"][0].astype(int) - swing[0]).mean() > 0.5  # mocap poses are applied
    assert np.abs(frames["side"][0].astype(int) - swing[0]).mean() > 5  # another camera, another view

    assert video == str(tmp_path / "videos" / "pendulum.mp4")
    assert os.path.getsize(video) > 0
    assert sorted(p.name for p in (tmp_path / "videos").iterdir()) == ["pendulum.mp4"]  # no partial file left
    decoded = iio.imread(video)
    assert decoded.shape == (T, 120, 160, 3)
    # The video shows the rendered frames, in order (up to H.264 losses).
    errors = np.abs(decoded.astype(int) - swing.astype(int)).mean(axis=(1, 2, 3))
    assert errors.max() < 6, errors
    assert np.abs(decoded[0].astype(int) - swing[T // 2]).mean() > errors[0]


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
        (dict(qpos=np.zeros((4, 2))), r"qpos must have shape \[T, 1\], got \[4, 2\]"),
        (dict(qpos=np.zeros(4)), r"qpos must have shape \[T, 1\]"),
        (dict(qpos=np.zeros((0, 1))), "no frames"),
        (dict(qpos=qpos, mocap_pos=np.zeros((4, 3))), r"mocap_pos must have shape .*\[4, 1, 3\], got \[4, 3\]"),
        (dict(qpos=qpos, mocap_quat=np.zeros((3, 1, 4))), r"mocap_quat must have shape .*\[4, 1, 4\]"),
        (dict(qpos=qpos, camera="top"), r"no camera named 'top'.*\['side'\]"),
        (dict(qpos=qpos, camera=1), r"camera id 1 out of range \[-1, 1\)"),
        (dict(qpos=qpos, width=0), "width and height"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message):
            rendering.render_frames(model, **kwargs)
    with pytest.raises(ValueError, match="fps"):
        rendering.render_video(model, qpos, tmp_path / "v.mp4", fps=0)
    assert no_opengl == []


def test_large_images_enlarge_the_framebuffer_of_a_copy(model, no_opengl):
    rendering.render_frames(model, np.zeros((1, 1)), width=1280, height=720, camera="side")
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
    frames = rendering._Frames(model, qpos, None, None, width=32, height=24, camera=None)
    # Reach 30 + 10 m along x (x20 the size), 1 + 10 m along y (x5.5).
    np.testing.assert_allclose(frames.model.geom_size[0, :2], [40.0, 11.0])
    np.testing.assert_allclose(frames.model.mat_texrepeat[0], [80.0, 22.0])
    np.testing.assert_allclose(frames.model.geom_size[1, :2], [2.0, 2.0])  # a wall is left alone
    np.testing.assert_allclose(model.geom_size[0, :2], [2.0, 2.0])  # the caller's model is untouched
