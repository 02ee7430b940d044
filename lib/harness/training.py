"""The training harness shared by the RL algorithms: a host loop over jitted chunks of
updates, with evaluation, metrics, checkpoints, a progress bar, curves and a video.

An algorithm is any module that satisfies `Algorithm` (`init`, `update`, `evaluate`
and `PER_ENV_FIELDS`), run with a config that satisfies `AlgorithmConfig`
(`num_updates`, `steps_per_update`); `run` checks both and does the rest:

    out/config.json       the algorithm config and the run settings
    out/metrics.jsonl     one JSON object per chunk: step, eval/return, losses, reward terms, steps/s
    out/tensorboard/      the same scalars for TensorBoard
    out/checkpoints/      atomic, exactly resumable train states
    out/curves.png        learning curves;  out/eval.mp4  the final policy (where GL exists)
"""

from __future__ import annotations

import dataclasses
import functools
import json
import shutil
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding, PartitionSpec
from mujoco import mjx

from mjzoo.harness import checkpoints, metrics as metrics_lib, plotting, rendering
from mjzoo.types import Task

__all__ = [
    "RUN_FILES",
    "Algorithm",
    "AlgorithmConfig",
    "PhysicsCapacityError",
    "Settings",
    "TrainingWarning",
    "check_algorithm",
    "config_dict",
    "existing",
    "physics_info",
    "replicate",
    "run",
    "shard_envs",
]  # fmt: skip

class TrainingWarning(UserWarning):
    """Training has gone wrong in a way its metrics show (an algorithm's `diagnose`)."""


RUN_FILES = ("config.json", "metrics.jsonl", "checkpoints", "tensorboard", "curves.png", "eval.mp4")  # what `run` writes


class AlgorithmConfig(Protocol):
    """What `run` reads of an algorithm's config (a frozen dataclass, static under jit)."""

    @property
    def num_updates(self) -> int: ...  # updates in the whole run

    @property
    def steps_per_update(self) -> int: ...  # env steps one update collects (for the step axis)


class Algorithm(Protocol):
    """The contract of an algorithm module, which `run` trains.

    The state `init` returns is a dataclass pytree (a checkpoint saves it whole) with
    an int32 scalar field `updates`, the number of updates done. `run` jits `init` and
    `evaluate` (config static; `num_envs` and `num_steps` static too), and a whole
    chunk of `update`s as one `lax.scan`.

    Attributes:
      PER_ENV_FIELDS: names of the state's fields whose leaves have a leading
        [num_envs] axis (env states, recurrent carries); `run` shards them over the
        devices, and replicates the rest. ``()``: all replicated. A dotted name reaches
        into a nested state (AMP's ``"ppo.collector"``).

    Optionally ``diagnose(history) -> str | None``: given every chunk's metrics so far,
    a warning `run` prints (once per new message) when training has gone wrong in a way
    the numbers show (AMP: the discriminator has won).
    """

    PER_ENV_FIELDS: Sequence[str]

    def init(self, config: Any, task: Task, key: jax.Array) -> Any:
        """A fresh training state."""

    def update(self, config: Any, task: Task, state: Any) -> tuple[Any, dict[str, jax.Array]]:
        """One update; metrics are scalars (NaN: nothing to report this update)."""

    def evaluate(self, config: Any, task: Task, state: Any, key: jax.Array, num_envs: int, num_steps: int) -> tuple:
        """(mean return, per-env returns [num_envs], env 0's `mjzoo.Trajectory` or None)."""


def check_algorithm(algorithm: Any, config: Any) -> None:
    """Raises one TypeError naming everything `algorithm` or `config` lacks of the
    `Algorithm` / `AlgorithmConfig` contract."""
    missing = [f"{name}()" for name in ("init", "update", "evaluate") if not callable(getattr(algorithm, name, None))]
    fields = getattr(algorithm, "PER_ENV_FIELDS", None)
    if not (isinstance(fields, (tuple, list)) and all(isinstance(f, str) for f in fields)):
        missing.append("PER_ENV_FIELDS (a tuple of the state's per-env field names; () if none)")
    missing += [f"config.{name}" for name in ("num_updates", "steps_per_update") if not hasattr(config, name)]
    if missing:
        name = getattr(algorithm, "__name__", type(algorithm).__name__)
        raise TypeError(f"training.run: {name} is not an algorithm of the training.Algorithm contract; "
                        f"it lacks {', '.join(missing)}")  # fmt: skip


def _check_state(algorithm: Algorithm, state: Any) -> None:
    """The state `init` made has the fields the harness and PER_ENV_FIELDS name."""
    def has(path: str) -> bool:
        node = state
        for name in path.split("."):
            if not dataclasses.is_dataclass(node) or not hasattr(node, name):
                return False
            node = getattr(node, name)
        return True

    wrong = [n for n in ("updates", *algorithm.PER_ENV_FIELDS) if not has(n)]
    if wrong:
        raise TypeError(f"training.run: the state {algorithm.__name__}.init returns ({type(state).__name__}) must be "
                        f"a dataclass with the fields {wrong} (updates, and each of PER_ENV_FIELDS)")  # fmt: skip


@dataclasses.dataclass(frozen=True, kw_only=True)
class Settings:
    """How a run is driven (not what is learned)."""

    out_dir: Path | None = None
    seed: int = 0
    updates_per_chunk: int = 10
    eval_envs: int = 16
    eval_steps: int | None = None  # None: the task's own episode length, int(task.time_limit)
    video: bool = True
    checkpoint_every: int = 1  # chunks between checkpoints; 0: never
    resume: bool = False  # continue the run in out_dir from its newest intact checkpoint
    overwrite: bool = False  # replace a run already in out_dir: its files are deleted first
    progress: bool = True

    def __post_init__(self):
        for field in ("updates_per_chunk", "eval_envs", "eval_steps"):
            if field == "eval_steps" and self.eval_steps is None:
                continue
            if getattr(self, field) < 1:
                raise ValueError(f"training.Settings: {field}={getattr(self, field)!r} must be >= 1")
        if self.checkpoint_every < 0:
            raise ValueError(f"training.Settings: checkpoint_every={self.checkpoint_every!r} must be >= 0")


def existing(out: Path, names: tuple[str, ...] = RUN_FILES) -> list[str]:
    """Which of `names` already exist in `out` (folders with a trailing slash)."""
    return [n + "/" * (out / n).is_dir() for n in names if (out / n).exists()]


def _claim(out: Path, settings: Settings) -> None:
    """Refuses an out_dir that holds another run, unless told to resume or replace it:
    a user's files are never overwritten without asking."""
    found = [] if settings.resume else existing(out)
    if found and not settings.overwrite:
        raise FileExistsError(f"training: {out} already holds a run ({', '.join(found)}); resume it "
                              "(Settings(resume=True)), choose another out_dir, or replace it (overwrite=True)")  # fmt: skip
    for name in found:
        path = out / name.rstrip("/")
        shutil.rmtree(path) if path.is_dir() else path.unlink()


def config_dict(config: Any) -> dict[str, Any]:
    """A dataclass config as JSON-ready data; user-supplied functions become their names."""

    def plain(value):
        if isinstance(value, (bool, int, float, str)) or value is None:
            return value
        if isinstance(value, (tuple, list)):
            return [plain(v) for v in value]
        return f"<custom {type(value).__name__}>"

    return {f.name: plain(getattr(config, f.name)) for f in dataclasses.fields(config)}


def shard_envs(train_state: Any, per_env_fields: Sequence[str], devices: list | None = None) -> Any:
    """Places the leaves of a train state's `per_env_fields` (an algorithm's
    `PER_ENV_FIELDS`) across devices (leading axis), the rest replicated. Under jit,
    XLA then splits the env batch and averages gradients.

    On one device this commits the state to it: jit compiles separately for
    uncommitted inputs and for its own (committed) outputs, which would cost a second
    compile on the second chunk."""
    devices = devices or jax.devices()
    if len(devices) == 1:
        return jax.device_put(train_state, devices[0])
    if (data := _data0(train_state)) is not None and data.impl == mjx.Impl.WARP:
        raise NotImplementedError(
            f"training on {len(devices)} devices needs impl='jax' for now: MuJoCo Warp's contact pool "
            "belongs to one call on one device, and splitting it is not supported yet"
        )
    mesh = jax.sharding.Mesh(np.array(devices), ("envs",))
    split, whole = NamedSharding(mesh, PartitionSpec("envs")), NamedSharding(mesh, PartitionSpec())

    def place(node: Any, paths: list[list[str]]) -> Any:
        if [] in paths:  # this node is per-env
            return jax.tree.map(lambda x: jax.device_put(x, split if jnp.ndim(x) else whole), node)
        if not paths or not dataclasses.is_dataclass(node):
            return jax.device_put(node, whole)
        return dataclasses.replace(node, **{
            f.name: place(getattr(node, f.name), [p[1:] for p in paths if p[0] == f.name])
            for f in dataclasses.fields(node)
        })  # fmt: skip

    return place(train_state, [path.split(".") for path in per_env_fields])


def replicate(tree: Any, devices: list | None = None) -> Any:
    """Copies every array of `tree` (e.g. a Task) onto all `devices`, to run beside a
    state placed by `shard_envs`."""
    devices = devices or jax.devices()
    if len(devices) == 1:
        return jax.device_put(tree, devices[0])
    mesh = jax.sharding.Mesh(np.array(devices), ("envs",))
    return jax.device_put(tree, NamedSharding(mesh, PartitionSpec()))


@functools.lru_cache(maxsize=8)  # runs in one process with one config share the compile
def _chunk_fn(algorithm: ModuleType, config: Any, length: int):
    def chunk(task: Task, state):
        state, metrics = jax.lax.scan(lambda s, _: algorithm.update(config, task, s), state, None, length=length)
        return state, jax.tree.map(jnp.nanmean, metrics)  # NaN: nothing to report that update

    return jax.jit(chunk, donate_argnums=1)


@functools.lru_cache(maxsize=8)
def _evaluate_fn(algorithm: ModuleType):
    return jax.jit(algorithm.evaluate, static_argnums=(0, 4, 5))


def _resume(out_dir: Path, state: Any) -> Any:
    """The newest intact checkpoint (a `checkpoints.DamagedCheckpointWarning` if it is
    not the newest), with metrics.jsonl cut back to it (lines after it would be written
    again) and the damaged newer ones set aside (saving their steps again would fail)."""
    restored, step, skipped = checkpoints.restore_newest_intact(out_dir / "checkpoints", like=state)
    for damaged, _ in skipped:
        checkpoints.set_aside(out_dir / "checkpoints", damaged)
    metrics_path = out_dir / "metrics.jsonl"
    if metrics_path.exists():
        kept = [line for line in metrics_lib.read_metrics(metrics_path) if line["step"] <= step]
        metrics_path.write_text("".join(json.dumps(line) + "\n" for line in kept))
    return restored


def _eval_steps(task: Task, settings: Settings) -> int:
    if settings.eval_steps is not None:
        return settings.eval_steps
    if getattr(task, "time_limit", None) is None:
        raise ValueError("training.Settings: eval_steps=None evaluates the task's own episode length, but the task "
                         "has no time limit (mjzoo.with_time_limit); give eval_steps")  # fmt: skip
    return int(task.time_limit)


@functools.lru_cache(maxsize=8)
def _init_fn(algorithm: ModuleType):
    return jax.jit(algorithm.init, static_argnums=0)


def physics_info(task: Task) -> dict[str, Any]:
    """The physics implementation a task runs on, and Warp's capacities, for config.json
    (nothing for a task without an `mjx.Model`, which the harness also trains)."""
    model = getattr(task, "model", None)
    if not isinstance(model, mjx.Model):
        return {}
    info: dict[str, Any] = {"impl": model.impl.value}
    template = _data0(task)
    if template is not None and model.impl == mjx.Impl.WARP:
        info.update(max_contacts=int(template._impl.naconmax), max_constraints=int(template._impl.njmax))
    return info


def _data0(task: Any):
    """The first Data in a pytree (a task's load-time template; None if it holds none)."""
    found = [x for x in jax.tree.leaves(task, is_leaf=lambda x: isinstance(x, mjx.Data)) if isinstance(x, mjx.Data)]
    return found[0] if found else None


def _check_capacity(task: Task, metrics: dict[str, float]) -> None:
    """Stops a Warp run whose physics outgrew its contact or constraint capacity: from then
    on it drops contacts, and learns from wrong physics."""
    share = metrics.get("env/physics/capacity_overflow", 0.0)
    if share > 0:
        raise PhysicsCapacityError(
            f"the physics overflowed its capacity in {share:.2%} of the env steps of the last chunk: MuJoCo Warp "
            "dropped contacts or constraints. Raise the physics options max_contacts and max_constraints "
            "(per world; e.g. --env-overrides max_contacts=64 max_constraints=256)"
        )


class PhysicsCapacityError(RuntimeError):
    """A Warp run's contacts or constraints overflowed the capacities of its physics."""


def run(algorithm: Algorithm, config: AlgorithmConfig, task: Task, settings: Settings) -> tuple[Any, dict[str, float]]:
    """Trains `task` with `algorithm` under `config`; returns the final state and metrics."""
    check_algorithm(algorithm, config)
    eval_steps = _eval_steps(task, settings)
    out = Path(settings.out_dir) if settings.out_dir else None
    if out is not None:
        _claim(out, settings)
    key, physics = jax.random.key(settings.seed), physics_info(task)
    state = _init_fn(algorithm)(config, task, key)
    _check_state(algorithm, state)
    if out is not None:
        # Restore before writing anything: a run that cannot resume is left as it was.
        if settings.resume and checkpoints.latest_step(out / "checkpoints") is not None:
            state = _resume(out, state)
        out.mkdir(parents=True, exist_ok=True)
        run_info = {"algorithm": algorithm.__name__.split(".")[-1], "config": config_dict(config),
                    "physics": physics,
                    "settings": {k: str(v) if isinstance(v, Path) else v for k, v in dataclasses.asdict(settings).items()}}  # fmt: skip
        (out / "config.json").write_text(json.dumps(run_info, indent=2))
    # Own every buffer once: the chunk donates the state, and XLA may hand out one buffer
    # for equal constants (two zero arrays), which cannot be donated twice.
    state, task = shard_envs(jax.tree.map(jnp.copy, state), algorithm.PER_ENV_FIELDS), replicate(task)
    chunk = _chunk_fn(algorithm, config, settings.updates_per_chunk)
    evaluate = _evaluate_fn(algorithm)
    total_chunks = -(-config.num_updates // settings.updates_per_chunk)
    writer = metrics_lib.MetricsWriter(out) if out is not None else None
    progress = metrics_lib.Progress(total_chunks * settings.updates_per_chunk * config.steps_per_update, "train")
    shown = {"physics": physics["impl"]} if physics else {}
    last: dict[str, float] = {}
    history: list[dict[str, float]] = []
    warned = None
    trajectory = None
    started = time.perf_counter()
    try:
        while int(state.updates) < total_chunks * settings.updates_per_chunk:
            start = time.perf_counter()
            state, chunk_metrics = chunk(task, state)
            jax.block_until_ready(state)
            seconds = time.perf_counter() - start
            eval_key = jax.random.fold_in(key, int(state.updates))
            eval_return, _, trajectory = evaluate(config, task, state, eval_key, settings.eval_envs, eval_steps)
            step = int(state.updates) * config.steps_per_update
            last = {"eval/return": float(eval_return), "perf/steps_per_s": settings.updates_per_chunk * config.steps_per_update / seconds,
                    "perf/elapsed_s": time.perf_counter() - started,
                    **{k: float(v) for k, v in chunk_metrics.items() if np.isfinite(v)}}  # fmt: skip
            if writer is not None:
                writer.write(step, last)
                chunks_done = int(state.updates) // settings.updates_per_chunk
                if settings.checkpoint_every and chunks_done % settings.checkpoint_every == 0:
                    checkpoints.save(out / "checkpoints", step, state)
            if settings.progress:
                progress.update(step, **shown, ret=f"{last['eval/return']:.1f}", sps=f"{last['perf/steps_per_s']:,.0f}")
            history.append(last)
            _check_capacity(task, last)
            warned = _diagnose(algorithm, history, warned)
    finally:
        progress.close()
        if writer is not None:
            writer.close()
    if out is not None:
        _finish(out, task, trajectory, settings)
    return state, last


def _diagnose(algorithm: Algorithm, history: list[dict[str, float]], warned: str | None) -> str | None:
    """Warns with the algorithm's `diagnose` message when it is new; returns the last one warned."""
    diagnose = getattr(algorithm, "diagnose", None)
    message = diagnose(history) if diagnose is not None else None
    if message and message != warned:
        warnings.warn(message, TrainingWarning, stacklevel=3)
        return message
    return warned


def _finish(out: Path, task: Task, trajectory, settings: Settings) -> None:
    """Learning curves and a video of the last evaluation episode."""
    plotting.plot_curves(out / "metrics.jsonl", out / "curves.png")
    if settings.video and trajectory is not None:
        write_video(task, trajectory, out / "eval.mp4")


def write_video(task: Task, trajectory, path: Path) -> Path | None:
    """Renders a single-env trajectory ([T] leaves) at its own control rate, through the
    model's first camera if it has one."""
    data = jax.device_get(trajectory.next_state.data)
    times = np.asarray(data.time)
    fps = 1.0 / float(times[1] - times[0]) if len(times) > 1 and times[1] > times[0] else 50.0
    return rendering.render_video(
        task.mj_model, np.asarray(data.qpos), path, fps, mocap_pos=np.asarray(data.mocap_pos),
        mocap_quat=np.asarray(data.mocap_quat), camera=0 if task.mj_model.ncam else None,
    )  # fmt: skip
