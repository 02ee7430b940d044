"""Rendering recorded trajectories to frames and MP4 videos, on the host.

    _, traj = mjzoo.rollout(task, policy, state, key, num_steps=250)
    render_video(task.mj_model, traj.next_state.data.qpos, "runs/a/eval.mp4", fps=50)  # 1 / ctrl_dt

Each frame sets ``qpos`` (and mocap poses) into a `mujoco.MjData`, runs `mj_forward`
and draws it with `mujoco.Renderer`; videos are H.264 MP4 through imageio's ffmpeg
plugin (imageio-ffmpeg ships its own ffmpeg binary, so no system ffmpeg is needed).

OpenGL. MuJoCo picks its OpenGL backend from the environment variable ``MUJOCO_GL``
when ``mujoco`` is first imported, so set it before importing mujoco or mjzoo, e.g.
``MUJOCO_GL=egl python train.py``:

- ``egl``: headless; the choice for servers, CI and GPU machines. Needs libEGL and an
  EGL driver: on Debian/Ubuntu ``libegl1 libegl-mesa0 libgl1-mesa-dri`` (Mesa's CPU
  renderer, llvmpipe; present on mjzoo's development and CI image), or the NVIDIA
  driver, which renders on the GPU.
- ``osmesa``: headless, CPU only, slower; needs ``libosmesa6``.
- unset or ``glfw``: needs a display (a desktop session, or Xvfb).

On Mesa's CPU renderers a frame costs about 0.1 s (2 shared cores), most of it the
model's 4096-pixel shadow map: ``<visual><quality shadowsize="1024" offsamples="0"/>``
in the model XML makes it several times faster.

Without a working backend, creating the renderer fails; the functions here then print
one line saying so and return None, so a training run never dies for want of a video.
"""

from __future__ import annotations

import copy
import dataclasses
import os
import sys
import warnings
from pathlib import Path
from collections.abc import Iterator

import imageio.v2 as imageio
import mujoco
import numpy as np
from numpy.typing import ArrayLike

__all__ = ["RenderConfig", "render_frames", "render_video"]

Camera = str | int | None


@dataclasses.dataclass(frozen=True, kw_only=True)
class RenderConfig:
    """How every video and image mjzoo writes is drawn (end of training, `mjzoo eval`,
    `mjzoo plan`, the viewer's recordings) and how learning curves are plotted; KSim's
    render options. From the CLI: ``--render.NAME VALUE``."""

    # image size in pixels: full (videos) and small (previews, thumbnails)
    width: int = 640
    height: int = 480
    small_width: int = 320
    small_height: int = 240
    length_seconds: float | None = None  # None: the whole trajectory
    fps: float | None = None  # None: real time, 1 / the trajectory's time step
    slowdown: float = 1.0  # 2.0 plays at half speed
    # what is drawn
    shadows: bool = True
    reflections: bool = True
    contact_forces: bool = False
    contact_points: bool = False
    inertia: bool = False  # equivalent-inertia boxes
    markers: bool = False  # debug markers: site frames and the centre of mass
    # the camera: a model camera by name or id, else a free camera
    camera: str | int | None = None
    distance: float | None = None  # None: MuJoCo's default, fitted to the model
    azimuth: float | None = None  # degrees
    elevation: float | None = None  # degrees
    lookat: tuple[float, float, float] | None = None
    track_body: str | int | None = None  # the free camera follows this body
    # learning curves
    max_series_per_plot: int = 8
    plot_figsize: tuple[float, float] = (4.5, 3.0)  # inches per subplot

# Why a failure is remembered: the backend is fixed when mujoco is imported, so it
# cannot start working later, and a second attempt after a failed one can abort the
# whole process (seen with MUJOCO_GL=glfw and no display: libc++abi "recursive
# initialization" in mjr_makeContext). Holds the first failure's reason.
_no_opengl: str | None = None


def render_frames(
    mj_model: mujoco.MjModel,
    qpos: ArrayLike,
    *,
    mocap_pos: ArrayLike | None = None,
    mocap_quat: ArrayLike | None = None,
    width: int = 640,
    height: int = 480,
    camera: Camera = None,
) -> np.ndarray | None:
    """Renders one image per row of `qpos`.

    Args:
      mj_model: the host model (`Task.mj_model`); not modified.
      qpos: [T, nq] joint positions, e.g. ``trajectory.next_state.data.qpos``.
      mocap_pos: [T, nmocap, 3] mocap body positions; None keeps the model's.
      mocap_quat: [T, nmocap, 4] mocap body orientations; None keeps the model's.
      width, height: image size in pixels.
      camera: a camera name or id from the model; None (or -1) for the default free
        camera looking at the whole model.

    Returns:
      [T, height, width, 3] uint8 RGB images, or None if no OpenGL backend works
      (after printing one line saying so).
    """
    frames = _Frames(mj_model, qpos, mocap_pos, mocap_quat, width, height, camera)
    renderer = frames.open_renderer("frames")
    if renderer is None:
        return None
    with renderer:
        images = np.empty((frames.length, height, width, 3), np.uint8)
        for t, image in enumerate(frames.render(renderer)):
            images[t] = image
    return images


def render_video(
    mj_model: mujoco.MjModel,
    qpos: ArrayLike,
    path: str | Path,
    fps: float,
    *,
    mocap_pos: ArrayLike | None = None,
    mocap_quat: ArrayLike | None = None,
    width: int = 640,
    height: int = 480,
    camera: Camera = None,
) -> Path | None:
    """Renders one frame per row of `qpos` into an H.264 MP4 video at `path`.

    Arguments as for `render_frames`, plus the output `path` (parent directories are
    created) and the frame rate `fps`, usually ``1 / ctrl_dt`` for real time. Frames
    are encoded as they are drawn, so a long video does not have to fit in memory;
    the file appears under `path` only when complete.

    Returns:
      `path`, or None if no OpenGL backend works (after printing one line saying so).
    """
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    path = Path(path)
    frames = _Frames(mj_model, qpos, mocap_pos, mocap_quat, width, height, camera)
    renderer = frames.open_renderer(f"video {path}")
    if renderer is None:
        return None
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.stem}.partial{path.suffix}")  # ffmpeg infers the container from the suffix
    try:
        with warnings.catch_warnings():
            # JAX warns at every fork; imageio-ffmpeg forks only to exec ffmpeg at once.
            warnings.filterwarnings("ignore", r"os\.fork\(\) was called", RuntimeWarning)
            # macro_block_size=2: H.264 with yuv420p needs even sizes; imageio's default
            # of 16 would rescale common sizes such as 250x250.
            with (
                renderer,
                imageio.get_writer(
                    partial, format="FFMPEG", mode="I", fps=fps, codec="libx264", macro_block_size=2
                ) as writer,
            ):
                for image in frames.render(renderer):
                    writer.append_data(image)
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)
    return path


class _Frames:
    """A validated trajectory to draw: checks every argument before any OpenGL work,
    so a wrong shape or camera name is an error whether or not a backend works."""

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        qpos: ArrayLike,
        mocap_pos: ArrayLike | None,
        mocap_quat: ArrayLike | None,
        width: int,
        height: int,
        camera: Camera,
    ) -> None:
        self.qpos = _trajectory("qpos", qpos, (mj_model.nq,))
        self.length = self.qpos.shape[0]
        self.mocap_pos = _optional("mocap_pos", mocap_pos, (self.length, mj_model.nmocap, 3))
        self.mocap_quat = _optional("mocap_quat", mocap_quat, (self.length, mj_model.nmocap, 4))
        if width < 1 or height < 1:
            raise ValueError(f"width and height must be >= 1, got {width}x{height}")
        self.width, self.height = int(width), int(height)
        self.camera = _camera_id(mj_model, camera)
        # Drawn from a copy: the renderer draws into the model's offscreen buffer, which
        # may need enlarging, and the floor may need extending.
        self.model = copy.copy(mj_model)
        self.model.vis.global_.offwidth = max(width, mj_model.vis.global_.offwidth)
        self.model.vis.global_.offheight = max(height, mj_model.vis.global_.offheight)
        _extend_floors(self.model, self.qpos)

    def open_renderer(self, what: str) -> mujoco.Renderer | None:
        global _no_opengl
        if _no_opengl is None:
            try:
                with warnings.catch_warnings():  # glfw warns on every failed call; the notice says it once
                    warnings.simplefilter("ignore")
                    return mujoco.Renderer(self.model, height=self.height, width=self.width)
            except Exception as err:  # the backends fail in many ways: ImportError, FatalError, ...
                _no_opengl = " ".join(f"{type(err).__name__}: {err}".split())
        print(
            f"mjzoo: no OpenGL backend (MUJOCO_GL={os.environ.get('MUJOCO_GL', 'unset')}; {_no_opengl}) - "
            f"set MUJOCO_GL=egl or osmesa before importing mujoco - skipping {what}",
            file=sys.stderr,
            flush=True,
        )
        return None

    def render(self, renderer: mujoco.Renderer) -> Iterator[np.ndarray]:
        data = mujoco.MjData(self.model)
        for t in range(self.length):
            data.qpos[:] = self.qpos[t]
            if self.mocap_pos is not None:
                data.mocap_pos[:] = self.mocap_pos[t]
            if self.mocap_quat is not None:
                data.mocap_quat[:] = self.mocap_quat[t]
            mujoco.mj_forward(self.model, data)
            renderer.update_scene(data, camera=self.camera)
            yield renderer.render()


def _extend_floors(model: mujoco.MjModel, qpos: np.ndarray, margin: float = 10.0) -> None:
    """Grows each plane's drawn extent to cover every free body's path plus `margin` (m),
    in place. A plane collides everywhere but is drawn only over its size, so a runner
    otherwise leaves the floor behind; its texture repeats are scaled with the size, so
    the checker squares keep their size."""
    free = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    if free.size == 0:
        return
    xy = np.stack([qpos[:, model.jnt_qposadr[j] : model.jnt_qposadr[j] + 2] for j in free], 1)  # [T, free, 2]
    level = (model.geom_bodyid == 0) & np.all(model.geom_quat == (1, 0, 0, 0), 1)  # floors, not walls
    for g in np.flatnonzero((model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE) & level):
        size = model.geom_size[g, :2]
        if np.any(size == 0):  # already drawn without end
            continue
        reach = np.abs(xy - model.geom_pos[g, :2]).max((0, 1)) + margin
        scale = np.maximum(reach / size, 1.0)
        model.geom_size[g, :2] = size * scale
        material = model.geom_matid[g]
        if material >= 0 and not model.mat_texuniform[material] and np.sum(model.geom_matid == material) == 1:
            model.mat_texrepeat[material] = model.mat_texrepeat[material] * scale


def _trajectory(name: str, value: ArrayLike, tail: tuple[int, ...]) -> np.ndarray:
    array = np.asarray(value, np.float64)
    if array.ndim != 1 + len(tail) or array.shape[1:] != tail:
        raise ValueError(f"{name} must have shape [T, {', '.join(map(str, tail))}], got {list(array.shape)}")
    if array.shape[0] == 0:
        raise ValueError(f"{name} holds no frames (T = 0)")
    return array


def _optional(name: str, value: ArrayLike | None, shape: tuple[int, ...]) -> np.ndarray | None:
    if value is None:
        return None
    array = np.asarray(value, np.float64)
    if array.shape != shape:
        raise ValueError(f"{name} must have shape [T, nmocap, {shape[-1]}] = {list(shape)}, got {list(array.shape)}")
    return array


def _camera_id(mj_model: mujoco.MjModel, camera: Camera) -> int:
    names = [mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(mj_model.ncam)]
    if camera is None:
        return -1
    if isinstance(camera, str):
        if camera not in names:
            raise ValueError(f"no camera named {camera!r} in the model; it has {names}")
        return names.index(camera)
    if not -1 <= camera < mj_model.ncam:
        raise ValueError(f"camera id {camera} out of range [-1, {mj_model.ncam}); the model's cameras are {names}")
    return int(camera)
