"""Rendering recorded trajectories to frames and MP4 videos, on the host, as one
`RenderConfig` says.

    _, traj = mjzoo.rollout(task, policy, state, key, num_steps=250)
    trajectory_video(task, traj, "runs/a/eval.mp4", RenderConfig(length_seconds=5, track_body="torso"))
    render_video(task.mj_model, traj.next_state.data.qpos, "runs/a/raw.mp4", dt=0.02)  # dt: seconds per row

Each frame sets ``qpos`` (and mocap poses) into a `mujoco.MjData`, runs `mj_forward`
(so contacts and their forces are those of the drawn state) and draws it with
`mujoco.Renderer`; videos are H.264 MP4 through imageio's ffmpeg plugin (imageio-ffmpeg
ships its own ffmpeg binary, so no system ffmpeg is needed).

Time. ``dt`` is the trajectory's time per row. A video holds ``fps`` frames per
simulated second (default real time, ``1 / dt``): a lower rate draws every k-th row, a
higher one repeats rows. The file plays at ``fps / slowdown`` frames per second, so it
runs at ``1 / slowdown`` of real time with every frame kept (no frame is repeated for
slow motion). Without ``dt`` each row is one frame at ``fps``.

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
in the model XML, or ``RenderConfig(shadows=False)``, makes it several times faster.

Without a working backend, creating the renderer fails; the functions here then print
one line saying so and return None, so a training run never dies for want of a video.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING
from typing import Any

import imageio.v2 as imageio
import mujoco
import numpy as np
from numpy.typing import ArrayLike

from mjzoo.harness.render_config import RenderConfig

if TYPE_CHECKING:
    from mjzoo.types import Task

__all__ = [
    "RenderConfig",
    "render_frames",
    "render_video",
    "trajectory_video",
    "first_episode_rows",
    "with_model_camera",
]

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
    dt: float | None = None,
    config: RenderConfig = RenderConfig(),
    small: bool = False,
) -> np.ndarray | None:
    """Renders the frames a video of this trajectory holds, as `config` says.

    Args:
      mj_model: the host model (`Task.mj_model`); not modified.
      qpos: [T, nq] joint positions, e.g. ``trajectory.next_state.data.qpos``.
      mocap_pos: [T, nmocap, 3] mocap body positions; None keeps the model's.
      mocap_quat: [T, nmocap, 4] mocap body orientations; None keeps the model's.
      dt: the trajectory's time per row (s). Needed for ``config.length_seconds``
        unless ``config.fps`` is set (without `dt`, each row is one frame).
      config: size, time, what is drawn and the camera.
      small: draw at ``config.small_width x small_height`` instead of ``width x height``.

    Returns:
      [F, height, width, 3] uint8 RGB images, F = T for the defaults, or None if no
      OpenGL backend works (after printing one line saying so).
    """
    frames = _Frames(mj_model, qpos, mocap_pos, mocap_quat, dt=dt, fps=None, config=config, small=small)
    renderer = frames.open_renderer("frames")
    if renderer is None:
        return None
    with renderer:
        images = np.empty((len(frames.qpos), frames.height, frames.width, 3), np.uint8)
        for t, image in enumerate(frames.render(renderer)):
            images[t] = image
    return images


def render_video(
    mj_model: mujoco.MjModel,
    qpos: ArrayLike,
    path: str | Path,
    fps: float | None = None,
    *,
    mocap_pos: ArrayLike | None = None,
    mocap_quat: ArrayLike | None = None,
    dt: float | None = None,
    config: RenderConfig = RenderConfig(),
    small: bool = False,
) -> Path | None:
    """Renders a trajectory into an H.264 MP4 video at `path`, as `config` says.

    Arguments as for `render_frames`, plus the output `path` (parent directories are
    created) and `fps`, the frames per simulated second, which overrides ``config.fps``;
    with neither, real time ``1 / dt``. One of `dt`, `fps` and ``config.fps`` is needed.
    The file's frame rate is ``fps / config.slowdown``. Frames are encoded as they are
    drawn, so a long video does not have to fit in memory; the file appears under
    `path` only when complete.

    Returns:
      `path`, or None if no OpenGL backend works (after printing one line saying so).
    """
    frames = _Frames(mj_model, qpos, mocap_pos, mocap_quat, dt=dt, fps=fps, config=config, small=small)
    if frames.fps is None:
        raise ValueError(
            "render_video needs the frame rate: pass dt= (the trajectory's time per row), fps= or config.fps"
        )
    path = Path(path)
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
            writer = imageio.get_writer(
                partial,
                format="FFMPEG",
                mode="I",
                fps=frames.fps / config.slowdown,
                codec="libx264",
                macro_block_size=2,
            )
            with renderer, writer:
                for image in frames.render(renderer):
                    writer.append_data(image)
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)
    return path


def trajectory_video(
    task: Task,
    trajectory: Any,
    path: str | Path,
    config: RenderConfig = RenderConfig(),
    *,
    first_episode: bool = True,
) -> Path | None:
    """Renders one environment's trajectory (`mjzoo.rollout`'s, or an algorithm's
    ``evaluate``: leaves [T, ...]) into an MP4 at `path`, as `config` says.

    With `first_episode` the video ends where the trajectory's first episode does
    (`first_episode_rows`): an evaluation runs its batch on for a fixed number of steps,
    past env 0's fall. The time step is read from ``next_state.data.time``; the camera
    is `with_model_camera`'s.

    Returns:
      `path`, or None if no OpenGL backend works (after printing one line saying so).
    """
    from mjzoo.combinators import AutoResetState
    from mjzoo.layers import find

    state = trajectory.next_state
    data, rows = state.data, None
    if first_episode:
        resets = find(state, AutoResetState, None) is not None
        rows = first_episode_rows(state.terminated, state.truncated, resets)
    qpos, time = np.asarray(data.qpos)[:rows], np.asarray(data.time, np.float64).reshape(-1)[:rows]
    if len(time) > 1 and time[1] > time[0]:
        dt = float(time[1] - time[0])
    else:  # one row, or an episode reset at the first step: measure the task's own step
        from mjzoo.running import control_dt

        dt = control_dt(task)
    return render_video(
        task.mj_model,
        qpos,
        path,
        mocap_pos=np.asarray(data.mocap_pos)[:rows],
        mocap_quat=np.asarray(data.mocap_quat)[:rows],
        dt=dt,
        config=with_model_camera(config, task.mj_model),
    )


def first_episode_rows(terminated: ArrayLike, truncated: ArrayLike, resets: bool = False) -> int:
    """How many rows of a trajectory show its first episode: up to and including the
    first row whose transition ended it (all T rows if none did).

    Args:
      terminated: [T] bool, ``next_state.terminated`` of each row.
      truncated: [T] bool, ``next_state.truncated``.
      resets: the task starts its next episode inside its step (`mjzoo.with_auto_reset`),
        so the ending row already shows the new episode's start and is left out too
        (one row is kept at least: a video has a frame).
    """
    done = np.asarray(terminated, bool).reshape(-1) | np.asarray(truncated, bool).reshape(-1)
    if not done.any():
        return len(done)
    return max(1, int(np.argmax(done)) + (0 if resets else 1))


def with_model_camera(config: RenderConfig, mj_model: mujoco.MjModel) -> RenderConfig:
    """`config` with the model's first camera when it chooses no camera (neither
    ``camera`` nor a free-camera field) and the model has one: task authors put their
    best view there."""
    if config.camera is None and not config.free_camera and mj_model.ncam:
        return dataclasses.replace(config, camera=0)
    return config


class _Frames:
    """A validated trajectory to draw: checks every argument before any OpenGL work,
    so a wrong shape or camera name is an error whether or not a backend works."""

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        qpos: ArrayLike,
        mocap_pos: ArrayLike | None,
        mocap_quat: ArrayLike | None,
        *,
        dt: float | None,
        fps: float | None,
        config: RenderConfig,
        small: bool,
    ) -> None:
        qpos = _trajectory("qpos", qpos, (mj_model.nq,))
        mocap_pos = _optional("mocap_pos", mocap_pos, (len(qpos), mj_model.nmocap, 3))
        mocap_quat = _optional("mocap_quat", mocap_quat, (len(qpos), mj_model.nmocap, 4))
        for name, value in (("dt", dt), ("fps", fps)):
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be > 0, got {value!r}")
        rows, self.fps = _timing(len(qpos), dt, config.fps if fps is None else fps, config.length_seconds)
        self.qpos = qpos[rows]
        self.mocap_pos = None if mocap_pos is None else mocap_pos[rows]
        self.mocap_quat = None if mocap_quat is None else mocap_quat[rows]
        self.width, self.height = (config.small_width, config.small_height) if small else (config.width, config.height)
        self.camera = _camera(mj_model, config)
        self.option = _scene_option(config)
        self.flags = {
            mujoco.mjtRndFlag.mjRND_SHADOW: config.shadows,
            mujoco.mjtRndFlag.mjRND_REFLECTION: config.reflections,
        }
        # Drawn from a copy: the renderer draws into the model's offscreen buffer, which
        # may need enlarging, and the floor may need extending.
        self.model = copy.copy(mj_model)
        self.model.vis.global_.offwidth = max(self.width, mj_model.vis.global_.offwidth)
        self.model.vis.global_.offheight = max(self.height, mj_model.vis.global_.offheight)
        _extend_floors(self.model, self.qpos)

    def open_renderer(self, what: str) -> mujoco.Renderer | None:
        global _no_opengl
        if _no_opengl is None:
            try:
                with warnings.catch_warnings():  # glfw warns on every failed call; the notice says it once
                    warnings.simplefilter("ignore")
                    renderer = mujoco.Renderer(self.model, height=self.height, width=self.width)
                for flag, on in self.flags.items():  # kept by the scene: Renderer.render restores them after each frame
                    renderer.scene.flags[flag] = on
                return renderer
            except Exception as err:  # noqa: BLE001 - the backends fail in many ways: ImportError, FatalError, ...
                _no_opengl = " ".join(f"{type(err).__name__}: {err}".split())
        print(
            f"mjzoo: no OpenGL backend (MUJOCO_GL={os.environ.get('MUJOCO_GL', 'unset')}; {_no_opengl}) - "
            f"set MUJOCO_GL=egl or osmesa before importing mujoco - skipping {what}",
            file=sys.stderr,
            flush=True,
        )
        return None

    def render(self, renderer: mujoco.Renderer) -> Iterator[np.ndarray]:
        """Yields [height, width, 3] uint8 images, one per frame."""
        data = mujoco.MjData(self.model)
        for t in range(len(self.qpos)):
            data.qpos[:] = self.qpos[t]
            if self.mocap_pos is not None:
                data.mocap_pos[:] = self.mocap_pos[t]
            if self.mocap_quat is not None:
                data.mocap_quat[:] = self.mocap_quat[t]
            mujoco.mj_forward(self.model, data)  # positions, and the contacts and forces drawn
            renderer.update_scene(data, camera=self.camera, scene_option=self.option)
            yield renderer.render()


def _timing(length: int, dt: float | None, fps: float | None, seconds: float | None) -> tuple[np.ndarray, float | None]:
    """The rows to draw, [F] indices into [T = length], and the frames per simulated
    second (None when neither `dt` nor `fps` is known: then every row is drawn).

    Frame k shows simulated time k / fps, i.e. the row at or before it: rows are
    skipped below real time and repeated above it, so playback at `fps` is real time."""
    if dt is None and fps is None:
        if seconds is not None:
            raise ValueError("RenderConfig: length_seconds needs the trajectory's time step: pass dt= (or an fps)")
        return np.arange(length), None
    dt = 1.0 / fps if dt is None else dt  # without dt, each row is one frame
    fps = 1.0 / dt if fps is None else fps
    duration = length * dt if seconds is None else min(length * dt, seconds)
    count = max(1, round(duration * fps))
    # 1e-6: k / (fps * dt) is k less a rounding error at real time, which floor would drop a row for.
    return np.minimum(np.floor(np.arange(count) / (fps * dt) + 1e-6).astype(int), length - 1), fps


def _camera(mj_model: mujoco.MjModel, config: RenderConfig) -> int | mujoco.MjvCamera:
    """A model camera's id, -1 for MuJoCo's default free camera, or a free (or
    tracking) camera with the config's distance, angles and lookat."""
    if config.camera is not None:
        return _camera_id(mj_model, config.camera)
    if not config.free_camera:
        return -1
    camera = mujoco.MjvCamera()
    mujoco.mjv_defaultFreeCamera(mj_model, camera)  # the fit to the model, for the fields left None
    if config.track_body is not None:
        camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
        camera.trackbodyid = _body_id(mj_model, config.track_body)
    for name in ("distance", "azimuth", "elevation"):
        if getattr(config, name) is not None:
            setattr(camera, name, getattr(config, name))
    if config.lookat is not None:
        camera.lookat[:] = config.lookat
    return camera


def _scene_option(config: RenderConfig) -> mujoco.MjvOption:
    option = mujoco.MjvOption()
    option.flags[mujoco.mjtVisFlag.mjVIS_CONTACTFORCE] = config.contact_forces
    option.flags[mujoco.mjtVisFlag.mjVIS_CONTACTPOINT] = config.contact_points
    option.flags[mujoco.mjtVisFlag.mjVIS_INERTIA] = config.inertia
    option.flags[mujoco.mjtVisFlag.mjVIS_COM] = config.markers
    if config.markers:
        option.frame = mujoco.mjtFrame.mjFRAME_SITE
    return option


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


def _camera_id(mj_model: mujoco.MjModel, camera: str | int) -> int:
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


def _body_id(mj_model: mujoco.MjModel, body: str | int) -> int:
    names = [mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_BODY, i) for i in range(mj_model.nbody)]
    if isinstance(body, str):
        if body not in names:
            raise ValueError(f"RenderConfig: track_body: no body named {body!r} in the model; it has {names}")
        return names.index(body)
    if not 0 <= body < mj_model.nbody:
        raise ValueError(
            f"RenderConfig: track_body: body id {body} out of range [0, {mj_model.nbody}); the bodies are {names}"
        )
    return int(body)
