"""`mjzoo view`: a live browser viewer (`mjzoo.harness.viewer`) of a task, a trained run,
a sampling planner or a recording (a motion clip beside its source clip too), with
KSim's viewer options (a duration, frames or a video of what was shown)."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Annotated
from typing import Any
from typing import Literal

import imageio.v3 as iio
import mujoco
import numpy as np
import tyro

import mjzoo
from mjzoo.harness import datasets
from mjzoo.harness import rendering
from mjzoo.harness.cli import runs
from mjzoo.harness.cli.arguments import PLANNERS
from mjzoo.harness.cli.arguments import UsageError
from mjzoo.harness.cli.arguments import algorithm_module
from mjzoo.harness.cli.arguments import as_usage_errors
from mjzoo.harness.cli.arguments import at_least_one
from mjzoo.harness.cli.arguments import build_planner
from mjzoo.harness.cli.arguments import parse_assignments
from mjzoo.harness.rendering import RenderConfig

__all__ = ["view", "target_kind"]

Kind = Literal["run", "dataset", "clip", "task"]
_FRAME = "frame_{:05d}.png"
_SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0)


def view(
    target: Annotated[str, tyro.conf.Positional],
    task: str | None = None,
    env_overrides: tuple[str, ...] = (),
    controls: Literal["zero", "random", "sliders"] = "zero",
    planner: Literal["predictive_sampling", "cem", "mppi", "dial", "cma_es", "ilqr"] | None = None,
    config: tuple[str, ...] = (),
    sampled: bool = False,
    num_envs: int = 1,
    seconds: float | None = None,
    speed: float = 1.0,
    port: int = 8080,
    host: str = "0.0.0.0",
    track_body: str | None = None,
    trace: tuple[str, ...] = (),
    source: str | None = None,
    source_task: str | None = None,
    seed: int = 0,
    save_frames: Path | None = None,
    save_video: Path | None = None,
    overwrite: bool = False,
    render: RenderConfig = RenderConfig(),
) -> None:
    """Show TARGET live in a browser (http://localhost:PORT) until Ctrl-C, or for
    --seconds simulated seconds.

    TARGET is recognised in this order: a directory holding config.json is a trained
    run (its newest checkpoint's policy, deterministic unless --sampled; its task
    as in `mjzoo eval`, or --task); a directory holding dataset.npz (or that file) is
    a `mjzoo collect` dataset, played back with a timeline (--num-envs episodes side
    by side; its task from meta.json, or --task); another .npz file is a motion clip
    (mjzoo.motion), on the model of --task, by default the registered env its file
    name starts with (cartpole_swingup_mppi.npz: cartpole_swingup), or else the
    Playground scene of the robot its folder names (envs/assets/motions/g1/walk.npz:
    the G1's, as mjzoo.motion.retarget made it); anything else is a
    task spec, a registered env or package.module:factory, run under --controls (zero,
    uniform random, or a slider per actuator), or solved live by --planner with
    --config NAME=VALUE fields of its Config, drawing its sampled rollouts and plan as
    paths of --trace (bodies or sites). --env-overrides NAME=VALUE change the task;
    --num-envs runs a batch side by side; --speed 0.25-4 sets the playback speed;
    --track-body makes the camera follow a body.

    --source CLIP plays a clip beside a motion clip TARGET, in step, in one scene: the
    human clip a robot's clip was retargeted from. CLIP is a DeepMimic clip (a name of
    pybullet's, walk or humanoid3d_walk, or a .txt file) on DeepMimic's humanoid, or a
    .npz clip (mjzoo.motion's or IsaacLab's humanoid-AMP layout) on --source-task's
    model, found from its name and folder as TARGET's is:

        mjzoo view envs/assets/motions/g1/walk.npz --source humanoid3d_walk

    --save-frames DIR writes each displayed frame as DIR/frame_NNNNN.png, and
    --save-video PATH (.mp4 or .gif) a video of them, when the viewer ends, drawn
    offscreen as --render.NAME VALUE says; existing files are kept unless --overwrite.

    Args:
      target: a run directory, a dataset, a motion clip (.npz) or a task spec.
      task: the task to show a run, dataset or clip on, instead of the one it names.
      env_overrides: NAME=VALUE changes to the task's factory arguments.
      controls: the actions of a task spec without --planner: zero, random or sliders.
      planner: solve the task live with this sampling planner.
      config: NAME=VALUE fields of the planner's Config.
      sampled: a run's policy samples its actions instead of taking the mean.
      num_envs: envs (or a dataset's episodes) shown side by side.
      seconds: stop after this many simulated seconds; default: run until Ctrl-C.
      speed: playback speed, 0.25 to 4 times real time.
      port: the port the viewer's page is served on.
      host: the address the viewer listens on.
      track_body: a body the camera follows.
      trace: the bodies or sites whose paths the planner's samples and plan draw (a humanoid's: pelvis, feet, hands).
      source: a clip played beside a clip TARGET: a DeepMimic clip name or .txt file, or a .npz clip.
      source_task: the task whose model a .npz --source is on, instead of the one its name gives.
      seed: the random seed of resets, random controls and the planner.
      save_frames: write each displayed frame to this directory as PNG.
      save_video: write a video of the displayed frames (.mp4 or .gif) when the viewer ends.
      overwrite: replace existing frames or video.
      render: how saved frames and videos are drawn.
    """
    from mjzoo.harness import viewer

    with as_usage_errors():
        kind = _check_flags(target, controls, planner, config, sampled, num_envs, seconds, speed, port, trace)
        _check_source_flags(target, kind, source, source_task, num_envs)
        _check_outputs(save_frames, save_video, overwrite)
        if source is None:
            flags = (controls, planner, config, sampled, num_envs, seed, trace)
            shown_source = _source(kind, target, task, env_overrides, *flags)
        else:
            pair = [_target_clip(Path(target), task, env_overrides), _source_clip(source, source_task)]
            shown_source = viewer.side_by_side(pair)
        _check_body(shown_source.mj_model, track_body)
    shown = viewer.serve(
        shown_source,
        port,
        host=host,
        speed=speed,
        track_body=track_body,
        record=save_frames is not None or save_video is not None,
    )
    print(
        f"mjzoo view: {target} at http://localhost:{shown.port} ({'Ctrl-C to stop' if seconds is None else f'{seconds:g} s'})"
    )
    try:
        shown.wait(seconds)
    finally:
        shown.stop()
    _write(shown, save_frames, save_video, render)


def target_kind(target: str) -> Kind:
    """What TARGET names (see `view`): "run", "dataset", "clip" or "task"."""
    path = Path(target)
    if path.is_dir() and (path / "config.json").is_file():
        return "run"
    if path.is_dir() and (path / datasets.ARRAYS).is_file() or path.name == datasets.ARRAYS:
        return "dataset"
    if path.suffix == ".npz":
        return "clip"
    if path.is_dir():
        raise UsageError(f"{target}: a directory without config.json (a run) or {datasets.ARRAYS} (a dataset)")
    if "/" in target and ":" not in target:  # a path, not a registered name or module:factory
        raise UsageError(f"{target}: no such run directory, dataset or file")
    return "task"


def _check_flags(
    target: str,
    controls: str,
    planner: str | None,
    config: tuple[str, ...],
    sampled: bool,
    num_envs: int,
    seconds: float | None,
    speed: float,
    port: int,
    trace: tuple[str, ...] = (),
) -> Kind:
    """The flags that do not fit TARGET's kind, or are out of range."""
    kind = target_kind(target)
    at_least_one(num_envs=num_envs)
    if seconds is not None and not seconds > 0:
        raise UsageError(f"--seconds must be > 0, got {seconds}")
    if speed not in _SPEEDS:
        raise UsageError(f"--speed must be one of {', '.join(f'{s:g}' for s in _SPEEDS)}, got {speed:g}")
    if not 0 <= port < 65536:
        raise UsageError(f"--port must be 0 (any free port) to 65535, got {port}")
    wrong = {
        "--controls": controls != "zero" and kind != "task",
        "--planner": planner is not None and kind != "task",
        "--sampled": sampled and kind != "run",
        "--config": bool(config) and planner is None,
        "--trace": bool(trace) and planner is None,
    }
    for flag, bad in wrong.items():
        if bad:
            needs = {"--sampled": "a run", "--config": "--planner", "--trace": "--planner"}.get(flag, "a task")
            raise UsageError(f"{flag}: only for {needs}; {target} is a {kind}")
    if planner is not None and (controls != "zero" or num_envs > 1):
        raise UsageError("--planner: plans one env; --controls and --num-envs do not apply")
    return kind


def _check_source_flags(target: str, kind: Kind, source: str | None, source_task: str | None, num_envs: int) -> None:
    if source is not None and kind != "clip":
        raise UsageError(f"--source: only beside a motion clip (.npz); {target} is a {kind}")
    if source is not None and num_envs > 1:
        raise UsageError("--source: plays one clip beside TARGET; --num-envs does not apply")
    if source_task is not None and not (source or "").endswith(".npz"):
        raise UsageError("--source-task: only for a .npz --source (a DeepMimic clip plays on DeepMimic's humanoid)")


def _source_clip(source: str, task: str | None) -> tuple[mujoco.MjModel, mjzoo.motion.Clip]:
    """The --source clip and its model: a DeepMimic clip on the DeepMimic humanoid, or a
    .npz clip (mjzoo.motion's or IsaacLab's) on --source-task's model."""
    from mjzoo.envs import deepmimic

    path = Path(source)
    if path.suffix == ".npz":
        if not path.is_file():
            raise UsageError(f"--source {source}: no such file")
        model = _clip_model(path, task, {}, "--source-task")
        with np.load(path, allow_pickle=False) as f:
            isaaclab = "dof_names" in f
        return model, (mjzoo.motion.isaaclab_npz(path, model) if isaaclab else mjzoo.motion.load(path, model))
    if path.suffix == ".txt" and not path.is_file():
        raise UsageError(f"--source {source}: no such file")
    file = path if path.suffix == ".txt" else deepmimic.motion_path(source.removeprefix("humanoid3d_"))
    human = deepmimic.humanoid_model()
    return human, mjzoo.motion.deepmimic_format.load(file, human, deepmimic.character_joints())


def _check_outputs(frames: Path | None, video: Path | None, overwrite: bool) -> None:
    """Refuses outputs that exist (unless --overwrite) or a video type we do not write."""
    if video is not None:
        if video.suffix.lower() not in (".mp4", ".gif"):
            raise UsageError(f"--save-video {video}: must end in .mp4 or .gif")
        if video.exists() and not overwrite:
            raise UsageError(f"--save-video {video} already exists: give --overwrite to replace it")
    if frames is not None:
        if frames.exists() and not frames.is_dir():
            raise UsageError(f"--save-frames {frames}: is a file, not a directory")
        if frames.is_dir() and any(frames.glob("frame_*.png")) and not overwrite:
            raise UsageError(f"--save-frames {frames} already holds frames: give --overwrite to replace them")


def _check_body(mj_model: mujoco.MjModel, name: str | None) -> None:
    if name is not None and mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_BODY, name) < 0:
        bodies = [mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(1, mj_model.nbody)]
        raise UsageError(f"--track-body {name!r}: no such body; bodies: {', '.join(map(str, bodies))}")


def _source(
    kind: Kind,
    target: str,
    task: str | None,
    env_overrides: tuple[str, ...],
    controls: str,
    planner: str | None,
    config: tuple[str, ...],
    sampled: bool,
    num_envs: int,
    seed: int,
    trace: tuple[str, ...],
) -> Any:
    """The viewer source TARGET names."""
    from mjzoo.harness import viewer

    if kind == "run":
        return _run(Path(target), task, env_overrides, sampled, num_envs, seed)
    if kind in ("dataset", "clip"):
        return _recording(kind, Path(target), task, env_overrides, num_envs)
    if task is not None:
        raise UsageError(f"--task: TARGET {target} is itself the task")
    overrides = parse_assignments(env_overrides, "--env-overrides")
    if planner is None:
        return viewer.env(mjzoo.envs.make(target, **overrides), controls, num_envs, seed)
    module = algorithm_module(planner, PLANNERS)
    cfg, hyperparams = build_planner(module, target, parse_assignments(config, "--config"))
    problem = mjzoo.envs.closed_loop_problem(target, module, cfg, hyperparams=hyperparams, **overrides)
    return viewer.planner(problem, seed, trace=trace or None)


def _run(run: Path, task: str | None, env_overrides: tuple[str, ...], sampled: bool, num_envs: int, seed: int) -> Any:
    """A trained run's policy from its newest intact checkpoint (as `mjzoo eval` reads it)."""
    from mjzoo.harness import viewer

    trained = runs.load(run, task, env_overrides)
    act = trained.module.policy(trained.cfg, trained.task, deterministic=not sampled)
    params = trained.module.policy_params(runs.restore(run, trained))
    return viewer.policy(trained.task, act, params, num_envs, seed)


def _recording(kind: Kind, path: Path, task: str | None, env_overrides: tuple[str, ...], num_envs: int) -> Any:
    from mjzoo.harness import viewer

    if not path.exists():
        raise UsageError(f"{path}: no such file")
    overrides = parse_assignments(env_overrides, "--env-overrides")
    if kind == "dataset":
        directory = path if path.is_dir() else path.parent
        data = datasets.load(directory)
        spec = task or data.source.get("task")
        if spec is None:
            raise UsageError(f"{directory}: its meta.json names no task; give --task")
        own = data.source.get("env_overrides", {}) if spec == data.source.get("task") else {}
        model = mjzoo.envs.make(spec, **{**own, **overrides}).mj_model
        return viewer.recording(model, data, episodes=num_envs)
    return viewer.recording(*_target_clip(path, task, env_overrides))


def _target_clip(path: Path, task: str | None, env_overrides: tuple[str, ...]) -> tuple[mujoco.MjModel, Any]:
    """A motion clip TARGET and the model of --task (or of the env its name gives)."""
    if not path.is_file():
        raise UsageError(f"{path}: no such file")
    overrides = parse_assignments(env_overrides, "--env-overrides")
    return _clip_model(path, task, overrides, "--task"), mjzoo.motion.load_file(path)


def _clip_model(path: Path, task: str | None, overrides: dict[str, Any], flag: str) -> mujoco.MjModel:
    """The model a clip file is on: `task`'s, the env its name starts with, or the
    Playground scene of the robot its folder is named after."""
    from mjzoo.robots import models
    from mjzoo.robots import scenes

    spec = task or _env_of_clip(path)
    if spec is not None:
        return mjzoo.envs.make(spec, **overrides).mj_model
    if models.canonical(path.parent.name) in models.PLAYGROUND_FOLDERS:
        return scenes.spec(path.parent.name).compile()
    raise UsageError(f"{path}: a motion clip holds no model; name its task with {flag} ENV")


def _env_of_clip(path: Path) -> str | None:
    """The registered env a clip's file name starts with (the longest such name), if any."""
    found = [n for n in mjzoo.envs.names() if path.stem == n or path.stem.startswith(n + "_")]
    return max(found, key=len) if found else None


def _write(shown: Any, frames: Path | None, video: Path | None, render: RenderConfig) -> None:
    """The displayed frames as PNGs and/or a video, drawn offscreen."""
    if not (frames or video) or not shown.recorded:
        return
    dt = 1.0 / shown.display_hz  # a frame per display: the video runs as the viewer did
    if hasattr(shown.source, "models"):
        _write_side_by_side(shown, frames, video, render, dt)
        return
    model = shown.source.mj_model
    qpos, mocap_pos, mocap_quat = (np.stack(x) for x in zip(*shown.recorded))
    config = rendering.with_model_camera(render, model)
    drawn = {"mocap_pos": mocap_pos, "mocap_quat": mocap_quat, "dt": dt, "config": config}
    images = None
    if frames is not None or (video is not None and video.suffix.lower() == ".gif"):
        images = rendering.render_frames(model, qpos, **drawn)
    if images is not None and frames is not None:
        frames.mkdir(parents=True, exist_ok=True)
        for i, image in enumerate(images):
            iio.imwrite(frames / _FRAME.format(i), image)
        print(f"frames: {len(images)} in {frames}")
    if video is not None and video.suffix.lower() == ".gif" and images is not None:
        video.parent.mkdir(parents=True, exist_ok=True)
        iio.imwrite(video, images, duration=1000 * dt * render.slowdown, loop=0)
        print(f"video: {video}")
    elif video is not None and rendering.render_video(model, qpos, video, **drawn) is not None:
        print(f"video: {video}")


def _write_side_by_side(shown: Any, frames: Path | None, video: Path | None, render: RenderConfig, dt: float) -> None:
    """Models side by side as panes side by side: each drawn by itself (a renderer holds
    one model's meshes), all from one free camera that follows each one's root body
    (3 m away, from the front-left, unless --render says otherwise)."""
    if render.camera is None and render.track_body is None and render.lookat is None:
        seen = {"distance": 3.0, "azimuth": 135.0, "elevation": -15.0}
        seen = {k: v if getattr(render, k) is None else getattr(render, k) for k, v in seen.items()}
        render = dataclasses.replace(render, track_body=1, **seen)
    panes = []
    for e, model in enumerate(shown.source.models):
        qpos, mocap_pos, mocap_quat = (np.stack(x) for x in zip(*(entry[e] for entry in shown.recorded)))
        config = render
        drawn = {"mocap_pos": mocap_pos, "mocap_quat": mocap_quat, "dt": dt, "config": config}
        pane = rendering.render_frames(model, qpos, **drawn)
        if pane is None:
            return
        panes.append(pane)
    images = np.concatenate(panes, axis=2)  # [T, H, W * models, 3]
    if frames is not None:
        frames.mkdir(parents=True, exist_ok=True)
        for i, image in enumerate(images):
            iio.imwrite(frames / _FRAME.format(i), image)
        print(f"frames: {len(images)} in {frames}")
    if video is not None:
        video.parent.mkdir(parents=True, exist_ok=True)
        if video.suffix.lower() == ".gif":
            iio.imwrite(video, images, duration=1000 * dt * render.slowdown, loop=0)
        else:
            with warnings.catch_warnings():  # JAX warns at every fork; imageio-ffmpeg forks only to exec ffmpeg
                warnings.filterwarnings("ignore", r"os\.fork\(\) was called", RuntimeWarning)
                fps = 1 / (dt * render.slowdown)  # macro_block_size=2: even sizes kept, not rescaled to 16s
                iio.imwrite(video, images, extension=".mp4", fps=fps, codec="libx264", macro_block_size=2)
        print(f"video: {video}")
