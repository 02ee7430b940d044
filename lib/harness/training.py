"""The training harness shared by the RL algorithms: a host loop over jitted chunks of
updates, with evaluation, metrics, checkpoints, a progress bar, curves and a video.

It drives an algorithm value (`mjzoo.learning.Algorithm`, e.g. `ppo.make(config)`):

    state, last = training.run(ppo.make(config), task, Settings(out_dir="runs/x"), hyperparams)

`run` checks the value and does the rest (in every process of a multi-process run
alike, `mjzoo.harness.distributed`; process 0 writes):

    out/config.json       the algorithm's config and hyperparameters, and the run settings
    out/metrics.jsonl     one JSON object per logged chunk: step, eval/return, losses, reward terms, perf/*
    out/tensorboard/      the same scalars for TensorBoard
    out/checkpoints/      atomic, exactly resumable train states
    out/curves.png        learning curves;  out/eval.mp4  the final policy (where GL exists)
    out/videos/           eval_<step>.mp4 every `video_every` evaluations
"""

from __future__ import annotations

import dataclasses
import functools
import io
import json
import shutil
import threading
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from mjzoo import tree
from mjzoo.harness import checkpoints
from mjzoo.harness import compilation
from mjzoo.harness import distributed
from mjzoo.harness import metrics as metrics_lib
from mjzoo.harness import plotting
from mjzoo.harness import rendering
from mjzoo.harness.devices import env_mesh_scope
from mjzoo.harness.devices import env_shardings
from mjzoo.harness.devices import replicate
from mjzoo.harness.devices import shard_envs
from mjzoo.harness.devices import template_data
from mjzoo.harness.settings import EvalSchedule
from mjzoo.harness.settings import Settings
from mjzoo.harness.settings import checkpoint_due
from mjzoo.harness.settings import config_dict
from mjzoo.harness.settings import hyperparams_dict
from mjzoo.learning.algorithm import Algorithm
from mjzoo.learning.algorithm import TrainingWarning
from mjzoo.learning.algorithm import check_algorithm
from mjzoo.learning.algorithm import check_state
from mjzoo.running import control_dt
from mjzoo.running import episode_steps
from mjzoo.types import Task

__all__ = [
    "RUN_FILES",
    "config_dict",
    "hyperparams_dict",
    "existing",
    "Hooks",
    "PhysicsCapacityError",
    "Settings",
    "physics_info",
    "run",
    "seconds_to_steps",
]


# A chunk still compiling this long after init is a cold compile (a cached one loads in ~2 s).
COLD_GRACE_S = 5.0
RUN_FILES = (
    "config.json",
    "metrics.jsonl",
    "checkpoints",
    "tensorboard",
    "curves.png",
    "eval.mp4",
    "videos",
)  # `run` writes


def existing(out: Path, names: tuple[str, ...] = RUN_FILES) -> list[str]:
    """Which of `names` already exist in `out` (folders with a trailing slash)."""
    return [n + "/" * (out / n).is_dir() for n in names if (out / n).exists()]


def _claim(out: Path, settings: Settings) -> None:
    """Refuses an out_dir that holds another run, unless told to resume or replace it:
    a user's files are never overwritten without asking."""
    found = [] if settings.resume else existing(out)
    if found and not settings.overwrite:
        raise FileExistsError(
            f"training: {out} already holds a run ({', '.join(found)}); resume it "
            "(Settings(resume=True)), choose another out_dir, or replace it (overwrite=True)"
        )
    distributed.barrier("mjzoo.training: out_dir checked")  # by all before it changes (the others write after chunk 1)
    for path in [out / name.rstrip("/") for name in found] if distributed.is_primary() else []:
        shutil.rmtree(path) if path.is_dir() else path.unlink()


class Hooks(NamedTuple):
    """Callbacks `run` calls as it goes: to watch a run, or to drive one in a test (a fake
    clock advanced by them, a fake background compile). Each is optional.

    Attributes:
      on_chunk: ``(updates done, the chunk's metrics on the device)``, as soon as a chunk
        has run, before `run` reads the clock that times it.
      on_evaluation: ``(step, eval return)``, as soon as an evaluation has run, before
        `run` reads the clock that times it.
      on_metrics: ``(step, metrics)``, each chunk's full metrics, as `run` has gathered
        them (what a metrics line would hold, whatever `Settings` logs).
      compile_evaluation: how the evaluation compiles in the background while training
        goes on: ``(function, *args, background=bool) -> handle`` with
        `threading.Thread`'s `join(timeout)` and `is_alive()` (or None: compiled);
        default `compilation.compile_ahead`.
      compile_chunk: how the training chunk compiles (or loads from the cache) on a
        thread while init runs: ``(lowered chunk) -> handle`` as above; default
        `compilation.compile_ahead`. A handle still alive `COLD_GRACE_S` after init is
        a cold compile, and the evaluation's compile starts beside it.
    """

    on_chunk: Callable[[int, dict[str, jax.Array]], None] | None = None
    on_evaluation: Callable[[int, float], None] | None = None
    on_metrics: Callable[[int, dict[str, float]], None] | None = None
    compile_evaluation: Callable[..., Any] = compilation.compile_ahead
    compile_chunk: Callable[..., Any] = compilation.compile_ahead


NO_HOOKS = Hooks()


@functools.lru_cache(maxsize=8)  # runs in one process with one algorithm value share the compile
def _chunk_fn(update: Callable, length: int):
    def chunk(task: Task, state):
        with env_mesh_scope():  # Warp's physics splits over the devices by it (batching.vmap_transition)
            state, metrics = jax.lax.scan(lambda s, _: update(task, s), state, None, length=length)
        return state, jax.tree.map(jnp.nanmean, metrics)  # NaN: nothing to report that update

    return jax.jit(chunk, donate_argnums=1)


@functools.lru_cache(maxsize=8)
def _evaluate_fn(evaluate: Callable):
    return jax.jit(evaluate, static_argnums=(3, 4))


def _resume(out_dir: Path, state: Any) -> Any:
    """The newest intact checkpoint (a `checkpoints.DamagedCheckpointWarning` if it is
    not the newest), with metrics.jsonl cut back to it (lines after it would be written
    again) and the damaged newer ones set aside (saving their steps again would fail)."""
    restored, step, skipped = checkpoints.restore_newest_intact(out_dir / "checkpoints", like=state)
    distributed.barrier("mjzoo.training: restored")  # every process has read before process 0 tidies up
    for damaged, _ in skipped if distributed.is_primary() else ():
        checkpoints.set_aside(out_dir / "checkpoints", damaged)
    metrics_path = out_dir / "metrics.jsonl"
    if metrics_path.exists() and distributed.is_primary():
        kept = [line for line in metrics_lib.read_metrics(metrics_path) if line["step"] <= step]
        metrics_path.write_text("".join(json.dumps(line) + "\n" for line in kept))
    return restored


def seconds_to_steps(task: Task, seconds: float) -> int:
    """`seconds` of simulated time as a count of the task's control steps (the nearest
    count, at least 1), e.g. a rollout length given in seconds (KSim's
    rollout_length_seconds). Measures `mjzoo.control_dt` (one compiled step)."""
    return max(1, round(seconds / control_dt(task)))  # round, not int: 5 / 0.02 is 249.99...


def _eval_steps(task: Task, settings: Settings) -> int:
    """The evaluation's length in control steps: eval_steps, eval_seconds at the task's
    control rate (the nearest count, at least 1), or the task's episode length."""
    if settings.eval_steps is not None:
        return settings.eval_steps
    if settings.eval_seconds is not None:
        return seconds_to_steps(task, settings.eval_seconds)
    return episode_steps(
        task,
        "training.Settings (eval_steps=None: the task's own episode length)",
        "eval_steps or eval_seconds",
    )


@functools.lru_cache(maxsize=8)
def _init_fn(init: Callable):
    return jax.jit(init)


def physics_info(task: Task) -> dict[str, Any]:
    """The physics implementation a task runs on, and Warp's capacities, for config.json
    (nothing for a task without an `mjx.Model`, which the harness also trains)."""
    model = getattr(task, "model", None)
    if not isinstance(model, mjx.Model):
        return {}
    info: dict[str, Any] = {"impl": model.impl.value}
    template = template_data(task)
    if template is not None and model.impl == mjx.Impl.WARP:
        info.update(max_contacts=int(template._impl.naconmax), max_constraints=int(template._impl.njmax))
    return info


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


class _Loop:
    """`run`'s host loop, one chunk at a time: train, evaluate when due, write the
    metrics line, checkpoint, show progress, check capacity and diagnose."""

    def __init__(
        self,
        algorithm: Algorithm,
        task: Task,
        settings: Settings,
        out: Path | None,
        key: jax.Array,
        eval_steps: int,
        launched: float,
        shown: dict[str, str],
        chunk_ahead: threading.Thread | None,
        clock: Callable[[], float],
        hooks: Hooks,
    ) -> None:
        self.algorithm, self.settings, self.clock, self.hooks = algorithm, settings, clock, hooks
        self.task, self.host_task = replicate(task), task  # videos are drawn by one process, from its own copy
        self.out, self.key, self.launched, self.shown = out, key, launched, shown
        self.per_chunk = _per_chunk(algorithm, settings)
        self.chunk = _chunk_fn(algorithm.update, self.per_chunk)
        self.chunk_ahead = chunk_ahead  # the chunk compiling while init ran (`_compile_chunk_ahead`)
        self.evaluate, self.eval_steps = _evaluate_fn(algorithm.evaluate), eval_steps
        self.total_updates = -(-algorithm.num_updates // self.per_chunk) * self.per_chunk
        self.schedule = EvalSchedule(settings, launched, self.total_updates)
        self.writer = metrics_lib.MetricsWriter(out) if out is not None and distributed.is_primary() else None
        self.progress = metrics_lib.Progress(
            self.total_updates * algorithm.steps_per_update,
            "train",
            file=None if distributed.is_primary() else io.StringIO(),
        )
        self.last: dict[str, float] = {}
        self.history: list[dict[str, float]] = []
        self.warned: str | None = None
        self.trajectory = None  # the latest evaluation's, for the final video
        self.evaluations = 0  # in this launch, for video_every
        self.video: tuple[int, Path] | None = None  # (step, path) of the latest videos/eval_<step>.mp4
        self.pending: dict[str, float] = {}  # once-only metrics waiting for the next metrics line
        self.ahead: threading.Thread | None = None  # the evaluation compiling in the background
        self.overlaps = compilation.overlaps_safely(getattr(task, "model", None))  # not Warp on a GPU
        # Whether the run has said how long it will take (only a CPU run, showing progress, does).
        self.noted = not (settings.progress and distributed.is_primary() and jax.default_backend() == "cpu")
        self.timed = (0, 0.0)  # env steps and seconds of the chunks timed for that forecast
        self.saved = launched  # when the last checkpoint was written
        if settings.profile_memory and (silent := metrics_lib.device_memory()[1]):
            warnings.warn(
                f"training: profile_memory: {', '.join(silent)} report no memory statistics "
                "(memory_stats() is None, as on XLA's CPU); nothing is recorded for them",
                TrainingWarning,
                stacklevel=3,
            )

    def done(self, state: Any) -> bool:
        return int(state.updates) >= self.total_updates

    def step(self, state: Any) -> Any:
        """Trains one chunk and does its bookkeeping; returns the new state."""
        start = self.clock()
        shapes = compilation.described(state) if not self.history else None  # before the chunk donates it
        if shapes is not None and self.overlaps and compilation.still_compiling(self.chunk_ahead, COLD_GRACE_S):
            self.compile_evaluation_ahead(shapes)  # a cold compile: the evaluation's goes beside it, not after
        compilation.wait(self.chunk_ahead, "training: the chunk")  # compiling it twice at once would waste a core
        self.chunk_ahead = None
        if shapes is not None and not self.overlaps:  # nothing may compile while Warp runs: init first, then
            jax.block_until_ready(state)  # the evaluation's compile and the chunk's, each alone
            self.compile_evaluation_ahead(shapes)
        # A CPU run's forecast is timed on chunks that neither compile nor run beside a compile
        # (or, should the evaluation's compile outlast 5% of the run, beside it), a second of them.
        late = not self.noted and 20 * int(state.updates) >= self.total_updates
        timed = not self.noted and bool(self.history) and (late or not compilation.still_compiling(self.ahead, 0.0))
        state, chunk_metrics = self.chunk(self.task, state)
        if shapes is not None and self.overlaps and self.ahead is None:  # while the first chunk runs, not while it
            self.compile_evaluation_ahead(shapes)  # traces: beside a cached chunk's load it slowed the first update
        jax.block_until_ready(state)
        updates, per_chunk = int(state.updates), self.per_chunk
        if self.hooks.on_chunk is not None:
            self.hooks.on_chunk(updates, chunk_metrics)
        end = self.clock()
        step, number = updates * self.algorithm.steps_per_update, updates // per_chunk
        metrics = {
            "perf/steps_per_s": per_chunk * self.algorithm.steps_per_update / max(end - start, 1e-9),
            **{k: float(v) for k, v in distributed.fetch(chunk_metrics).items() if np.isfinite(v)},
        }
        if not self.history:  # this launch's first chunk: compile (and init) included
            metrics["perf/first_update_s"] = self.pending["perf/first_update_s"] = end - self.launched
            self.shown["first"] = f"{end - self.launched:.1f}s"
        if timed and updates < self.total_updates:
            self._forecast(per_chunk * self.algorithm.steps_per_update, end - start, late)
        with self.progress.paused():  # the bar's steps/s is the training rate
            final = updates >= self.total_updates
            compiled = not compilation.still_compiling(self.ahead, 0.0)  # else the budget puts the evaluation off
            due = (
                self.schedule.due(number, final, end, compiled, (updates - per_chunk, updates)),
                checkpoint_due(self.settings, number, final, end - self.saved),
            )
            evaluated, save = (bool(x) for x in distributed.agree(due))  # process 0's clock: one collective for both
            metrics.update(self._evaluate(state, step, final) if evaluated else {"perf/eval_s": 0.0})
        metrics["perf/elapsed_s"] = self.clock() - self.launched
        if self.settings.profile_memory:
            metrics.update(metrics_lib.device_memory()[0])
        self._write(state, step, number, metrics, evaluated, save)
        if self.settings.progress:
            self.progress.update(step, **self.shown, sps=f"{metrics['perf/steps_per_s']:,.0f}")
        if self.hooks.on_metrics is not None:
            self.hooks.on_metrics(step, metrics)
        self.last = metrics
        self.history.append(metrics)
        _check_capacity(self.task, metrics)
        self.warned = _diagnose(self.algorithm, self.history, self.warned) if distributed.is_primary() else None
        return state

    def _forecast(self, steps: int, seconds: float, late: bool) -> None:
        """Adds a timed chunk; after a second of them (or 5% of the run), prints the rate
        and how long the run takes at it."""
        steps, seconds = self.timed[0] + steps, self.timed[1] + seconds
        self.timed, self.noted = (steps, seconds), seconds >= 1.0 or late
        if self.noted:
            self.progress.note(_cpu_note(steps / max(seconds, 1e-9), self))

    def compile_evaluation_ahead(self, state: Any) -> None:
        """Compiles the evaluation on a background thread while the first chunk runs
        (`compilation.compile_ahead`). `state` is described by shapes and shardings
        (`compilation.described`); the key is a real one, as a key's description lowers to
        another program. On Warp's GPU physics it compiles now, on this thread, and `step`
        calls it before the chunk runs (`compilation.overlaps_safely`)."""
        key = jax.random.fold_in(self.key, 0)
        s = self.settings
        self.ahead = self.hooks.compile_evaluation(
            self.evaluate, self.task, state, key, s.eval_envs, self.eval_steps, background=self.overlaps
        )

    def _evaluate(self, state: Any, step: int, final: bool) -> dict[str, float]:
        """Evaluates (`settings.eval_envs` episodes) and writes a video when one is due."""
        start = self.clock()
        compilation.wait(self.ahead, "training: the evaluation")  # compiling it twice at once would waste a core
        self.ahead = None
        compiled = self.clock()  # the budget is for evaluating: waiting for the compile is a one-off
        key, s = jax.random.fold_in(self.key, int(state.updates)), self.settings
        returns, _, trajectory = self.evaluate(self.task, state, key, s.eval_envs, self.eval_steps)
        eval_return = float(np.mean(distributed.fetch(returns)))  # waits for it
        if self.hooks.on_evaluation is not None:
            self.hooks.on_evaluation(step, eval_return)
        result = {"eval/return": eval_return, "perf/eval_s": self.clock() - start}
        self.schedule.spent(self.clock() - compiled)
        self.evaluations += 1
        self.shown["ret"] = f"{result['eval/return']:.1f}"
        due = s.video_every and self.evaluations % s.video_every == 0
        self.trajectory = distributed.fetch(trajectory) if self.out and (due or final and s.video) else trajectory
        if due and self.out is not None and self.trajectory is not None and distributed.is_primary():
            start = self.clock()
            path = write_video(self.host_task, self.trajectory, self.out / "videos" / f"eval_{step}.mp4", s.render)
            self.video = (step, path) if path is not None else self.video
            result["perf/video_s"] = self.clock() - start
        return result

    def _write(
        self, state: Any, step: int, number: int, metrics: dict[str, float], evaluated: bool, save: bool
    ) -> None:
        """The metrics line (every `log_every` chunks and at each evaluation) and the checkpoint."""
        if self.out is None:
            return
        s = self.settings
        if self.writer is not None and (evaluated or number % s.log_every == 0):
            shared = ("eval/", "perf/", "memory/")  # what a run that logs no training metrics still writes
            kept = metrics if s.log_train_metrics else {k: v for k, v in metrics.items() if k.startswith(shared)}
            self.writer.write(step, {**self.pending, **kept})
            self.pending = {}
        if save:
            checkpoints.save(self.out / "checkpoints", step, state)  # by every process, as orbax needs
            self.saved = self.clock()

    def close(self) -> None:
        self.progress.close()
        if self.writer is not None:
            self.writer.close()


# Own every buffer once (the chunk donates the state; XLA may hand out one buffer for equal
# constants, which cannot be donated twice), strongly typed as the chunk returns it (a weak
# type compiled the second chunk again). One jit: leaf by leaf compiled a program per shape.
@jax.jit
def _owned(state: Any) -> Any:
    return jax.tree.map(jnp.copy, tree.strongly_typed(state))


def _start(
    algorithm: Algorithm,
    task: Task,
    hyperparams: Any,
    settings: Settings,
    out: Path | None,
    key: jax.Array,
    physics: dict[str, Any],
) -> Any:
    """The initial (or resumed: its hyperparameters too) train state, placed on the
    devices, config.json written."""
    state = _init_fn(algorithm.init)(task, hyperparams, key)
    check_state(algorithm, state, "training.run")
    state = shard_envs(_owned(state), algorithm.per_env_fields)
    if out is not None:
        # Restore (each process its shards) before writing anything: a run that cannot resume is left as it was.
        if settings.resume and checkpoints.latest_step(out / "checkpoints") is not None:
            state = _resume(out, state)
        out.mkdir(parents=True, exist_ok=True)
        run_info = {
            "algorithm": algorithm.name,
            "config": config_dict(algorithm.config),
            "hyperparams": hyperparams_dict(getattr(state, "hyperparams", hyperparams)),  # a resumed run's own
            "physics": physics,
            "settings": {k: str(v) if isinstance(v, Path) else v for k, v in dataclasses.asdict(settings).items()},
        }
        if distributed.is_primary():
            (out / "config.json").write_text(json.dumps(run_info, indent=2))
    return state


def run(
    algorithm: Algorithm,
    task: Task,
    settings: Settings,
    hyperparams: Any = None,
    *,
    clock: Callable[[], float] = time.perf_counter,
    hooks: Hooks = NO_HOOKS,
) -> tuple[Any, dict[str, float]]:
    """Trains `task` with `algorithm` (`mjzoo.learning.Algorithm`, e.g. `ppo.make(config)`)
    and `hyperparams` (None: the algorithm's defaults; a resumed run continues with the
    ones its checkpoint holds); returns the final state and the last chunk's metrics
    (all of them, whatever `settings` logs; it always evaluated).

    `clock` times everything the loop schedules by (evaluations, checkpoints, perf/*);
    `hooks` (`Hooks`) are called as the run goes.

    Metrics of note: perf/steps_per_s (training only), perf/eval_s (evaluating in this
    chunk; 0 without; the first includes compiling), perf/video_s, perf/first_update_s
    (once: from this call to the end of the first chunk, compiles included),
    perf/elapsed_s (since this call)."""
    launched = clock()
    if settings.compile_cache:
        compilation.enable_cache()
    check_algorithm(algorithm, "training.run")
    hyperparams = algorithm.hyperparams if hyperparams is None else hyperparams
    eval_steps = _eval_steps(task, settings)  # a wrong length fails here, before anything is written
    out = Path(settings.out_dir) if settings.out_dir else None
    if out is not None:
        _claim(out, settings)
    key, physics = jax.random.key(settings.seed), physics_info(task)
    chunk_ahead = _compile_chunk_ahead(algorithm, task, hyperparams, settings, key, hooks.compile_chunk)
    state = _start(algorithm, task, hyperparams, settings, out, key, physics)
    shown = {"physics": physics["impl"]} if physics else {}
    loop = _Loop(algorithm, task, settings, out, key, eval_steps, launched, shown, chunk_ahead, clock, hooks)
    try:
        while not loop.done(state):
            state = loop.step(state)
    finally:
        loop.close()
    if out is not None and distributed.is_primary():
        _finish(out, loop, settings)
    return state, loop.last


def _per_chunk(algorithm: Algorithm, settings: Settings) -> int:
    """Updates per chunk: `updates_per_chunk`, fewer where the default schedule's
    `eval_count` evaluations need more chunks than that gives (a chunk boundary costs a
    host sync, milliseconds); a run shorter than one chunk is one chunk of its length."""
    per_chunk = settings.updates_per_chunk
    if settings.eval_every is None and settings.eval_count:
        per_chunk = min(per_chunk, max(1, algorithm.num_updates // settings.eval_count))
    return min(per_chunk, max(1, algorithm.num_updates))


def _compile_chunk_ahead(
    algorithm: Algorithm,
    task: Task,
    hyperparams: Any,
    settings: Settings,
    key: jax.Array,
    compile_ahead: Callable[..., Any] = compilation.compile_ahead,
) -> threading.Thread | None:
    """Starts compiling the training chunk on a thread (or loading it from the cache) from
    the shapes init will return (`eval_shape`, whose trace init's call reuses) and the
    shardings `shard_envs` will give them, while init compiles. Traced here: tracing
    holds the GIL. Not on Warp's GPU physics (`compilation.overlaps_safely`)."""
    if not compilation.overlaps_safely(getattr(task, "model", None)):
        return None
    shapes = _init_fn(algorithm.init).eval_shape(task, hyperparams, key)
    shardings = env_shardings(shapes, algorithm.per_env_fields)
    described = lambda x, s: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=s)  # noqa: E731 (strong, as `_owned`)
    state = jax.tree.map(described, shapes, shardings)
    chunk = _chunk_fn(algorithm.update, _per_chunk(algorithm, settings))
    try:
        return compile_ahead(chunk.lower(replicate(task), state))
    except Exception:  # noqa: BLE001 (the chunk's own call raises it where it belongs)
        return None


def _cpu_note(rate: float, loop: _Loop) -> str:
    """The line a run on a CPU prints after its first chunk that ran alone (the first
    compiles; one beside the evaluation's compile ran at a 14th of the later rate on a
    busy 2-core CPU): its rate, how long the run takes at it, and where training belongs."""
    total = loop.total_updates * loop.algorithm.steps_per_update
    return (
        f"training on a CPU: {rate:,.0f} env-steps/s, so {total:,} steps take about {_about(total / rate)}; "
        "training belongs on a GPU (mjzoo uses one wherever JAX finds it)"
    )


def _about(seconds: float) -> str:
    """A duration as a person reads it: 40 s, 12 min, 3 h 05 min."""
    if seconds < 60:
        return f"{seconds:.0f} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 60 else f"{minutes // 60} h {minutes % 60:02d} min"


def _diagnose(algorithm: Algorithm, history: list[dict[str, float]], warned: str | None) -> str | None:
    """Warns with the algorithm's `diagnose` message when it is new; returns the last one warned."""
    diagnose = getattr(algorithm, "diagnose", None)
    message = diagnose(history) if diagnose is not None else None
    if message and message != warned:
        warnings.warn(message, TrainingWarning, stacklevel=3)
        return message
    return warned


def _finish(out: Path, loop: _Loop, settings: Settings) -> None:
    """Learning curves (drawn as settings.render says), and a video of the final
    evaluation's first episode (a copy of its videos/ one if `video_every` made that)."""
    plotting.plot_curves(out / "metrics.jsonl", out / "curves.png", config=settings.render)
    if not settings.video or loop.trajectory is None:
        return
    final_step = int(loop.total_updates * loop.algorithm.steps_per_update)
    if loop.video is not None and loop.video[0] == final_step:
        shutil.copyfile(loop.video[1], out / "eval.mp4")
    else:
        write_video(loop.host_task, loop.trajectory, out / "eval.mp4", settings.render)


def write_video(task: Task, trajectory: Any, path: Path, config: rendering.RenderConfig | None = None) -> Path | None:
    """An MP4 of a single-env trajectory ([T] leaves) as `config` says (default
    `RenderConfig()`): `rendering.trajectory_video`, kept here for `mjzoo eval`.
    Returns `path`, or None without an OpenGL backend."""
    return rendering.trajectory_video(task, trajectory, path, config or rendering.RenderConfig())
