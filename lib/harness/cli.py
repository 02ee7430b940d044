"""The `mjzoo` command line (also `python -m mjzoo`).

    mjzoo envs                    # list the registered tasks and their overrides
    mjzoo demo --steps 200        # random policy on every env, batched, prints returns
    mjzoo train ppo cartpole_balance --out runs/cb --config num_envs=128  # --resume runs/cb goes on
    mjzoo eval runs/cb            # reload the checkpoint, evaluate, write a video
    mjzoo plan mppi pendulum_swingup --offline  # a sampling planner, closed loop

A user's mistake (an unknown env, a bad --config or --env-overrides value, a missing or
incomplete run, an --out that holds a run, only damaged checkpoints) ends the command with
one line on stderr, ``mjzoo COMMAND: what is wrong``, and exit status 2, before anything is
written or (but for checkpoints) compiled. Other exceptions are bugs, with tracebacks.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import importlib
import json
import os
import sys
import time
import types
import typing
import warnings
from pathlib import Path
from typing import Annotated, Any, Iterator, Literal

import jax
import jax.numpy as jnp
import numpy as np
import tyro

import mjzoo

__all__ = ["main", "demo", "envs", "train", "evaluate", "plan", "UsageError"]

ALGORITHMS = ("ppo",)
PLANNERS = ("predictive_sampling", "cem", "mppi")
PLAN_FILES = ("summary.json",)
RUN_DEFAULTS = {"seed": 0, "eval_envs": 16, "updates_per_chunk": 10}  # how `train` drives a new run
_MISMATCH = object()  # what _as_type returns for a value of another type


class UsageError(Exception):
    """A user's mistake: `main` prints it as one line and exits with status 2."""


@contextlib.contextmanager
def _checking(*errors: type[Exception]) -> Iterator[None]:
    """Marks a block that only checks the user's input and builds from it (configs, the
    task): the ValueError, TypeError, KeyError and missing-file errors the library raises
    there (or just `errors`) are the user's mistakes, and become a `UsageError`. Outside
    such blocks they are bugs, and keep their tracebacks."""
    try:
        yield
    except errors or (ValueError, TypeError, KeyError, FileNotFoundError, FileExistsError, NotADirectoryError) as e:
        raise UsageError(e.args[0] if isinstance(e, KeyError) and e.args else str(e)) from e


def envs() -> None:
    """List the registered tasks with their overridable defaults."""
    for name in mjzoo.envs.names():
        overrides = ", ".join(f"{k}={v}" for k, v in mjzoo.envs.defaults(name).items())
        print(f"{name}\n    {overrides}")


def demo(env: tuple[str, ...] = (), num_envs: int = 32, steps: int = 250, seed: int = 0) -> None:
    """Roll out a uniformly random policy on each env (all by default) in a vmapped batch
    of `num_envs` and print the return of each first episode (up to `steps` steps)."""
    names = env or tuple(mjzoo.envs.names())
    with _checking():
        _at_least_one(num_envs=num_envs, steps=steps)
        for name in names:
            mjzoo.envs.factory(name)
    print(f"{'env':<18} {'obs':>5} {'act':>4} {'return (mean ± std)':>22} {'env-steps/s':>12}")
    for name in names:
        task = mjzoo.envs.make(name)
        run = jax.jit(_random_returns, static_argnums=(2, 3))
        keys = jax.random.split(jax.random.key(seed), num_envs)
        jax.block_until_ready(run(task, keys, steps, task.action_size))  # compile
        start = time.perf_counter()
        returns, obs_size = jax.block_until_ready(run(task, keys, steps, task.action_size))
        rate = num_envs * steps / (time.perf_counter() - start)
        returns = np.asarray(returns)
        print(
            f"{name:<18} {int(obs_size[0]):>5} {task.action_size:>4} "
            f"{returns.mean():>13.2f} ± {returns.std():<7.2f} {rate:>12,.0f}"
        )


def _random_returns(task: mjzoo.Task, keys: jax.Array, steps: int, nu: int):
    """Per env: the return of the first episode under uniform random controls."""
    low, high = task.model.actuator_ctrlrange[:, 0], task.model.actuator_ctrlrange[:, 1]

    def policy(obs, key):
        return jax.random.uniform(key, (nu,), minval=low, maxval=high)

    def one(key):
        reset_key, run_key = jax.random.split(key)
        state = mjzoo.reset(task, reset_key)
        _, trajectory = mjzoo.rollout(task, policy, state, run_key, steps)
        done = trajectory.next_state.terminated | trajectory.next_state.truncated
        alive = jnp.cumsum(done) - done == 0  # up to and including the first episode end
        obs_size = jnp.size(jax.tree.leaves(state.obs)[0])
        return jnp.sum(trajectory.next_state.reward * alive), obs_size

    return jax.vmap(one)(keys)


def _at_least_one(**flags: int) -> None:
    for name, value in ((k, v) for k, v in flags.items() if v < 1):
        raise UsageError(f"--{name.replace('_', '-')} must be >= 1, got {value}")


def _parse_assignments(pairs: tuple[str, ...], what: str) -> dict[str, Any]:
    """["a=1", "b=(64, 64)", "c=swish"] -> {"a": 1, "b": (64, 64), "c": "swish"}."""
    parsed = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        if not sep or not name:
            raise UsageError(f"{what}: expected NAME=VALUE, got {pair!r}")
        try:
            parsed[name] = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            parsed[name] = text  # a bare word: a string
    return parsed


def _algorithm(name: str, choices: tuple[str, ...] = ALGORITHMS):
    if name not in choices:
        raise UsageError(f"unknown algorithm {name!r}; choices: {', '.join(choices)}")
    return importlib.import_module(f"mjzoo.algorithms.{name}")


def _config(algorithm, env: str, overrides: dict[str, Any], what: str = "--config"):
    """The algorithm's Config: its defaults, then the env's, then `overrides` (from the
    command line or a saved config.json, whose user-supplied pieces cannot be rebuilt),
    each checked against its field's type first: ppo.Config compares, e.g., a string
    learning rate with 0 and fails without naming it."""
    hints = typing.get_type_hints(algorithm.Config)
    fields = [f.name for f in dataclasses.fields(algorithm.Config)]
    overrides = {k: v for k, v in overrides.items() if not str(v).startswith("<custom")}
    values = {**mjzoo.envs.hyperparameters(env, algorithm.__name__.split(".")[-1]), **overrides}
    unknown = sorted(set(values) - set(fields))
    if unknown:
        raise UsageError(f"{what}: unknown field(s) {unknown}; fields: {sorted(fields)}")
    for name, value in values.items():
        values[name] = _as_type(value, hints[name])
        if values[name] is _MISMATCH:
            raise UsageError(f"{what}: {name}={value!r} must be {_describe(hints[name])}")
    return algorithm.Config(**values)


def _as_type(value: Any, hint: Any) -> Any:
    """`value` as a field annotated `hint` holds it (JSON's lists as tuples, 1e6 as an
    int), or _MISMATCH. Objects (networks, optimizers, functions) come only from Python."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return next((v for v in (_as_type(value, arm) for arm in args) if v is not _MISMATCH), _MISMATCH)
    if origin is Literal:
        return value if value in args else _MISMATCH
    if origin is tuple and isinstance(value, (tuple, list)):
        arms = [args[0]] * len(value) if len(args) == 2 and args[1] is Ellipsis else list(args)
        items = [_as_type(v, arm) for v, arm in zip(value, arms)]
        return tuple(items) if len(arms) == len(value) and all(i is not _MISMATCH for i in items) else _MISMATCH
    if hint is int and isinstance(value, float) and value.is_integer():
        return int(value)
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if hint in (bool, int, float, str, type(None)) and type(value) is hint:
        return value
    return _MISMATCH


def _describe(hint: Any) -> str:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(arm) for arm in args)
    if origin is Literal:
        return "one of " + ", ".join(map(repr, args))
    if origin is tuple:
        return f"a tuple of {getattr(args[0], '__name__', args[0])}, e.g. (64, 64)"
    simple = {bool: "True or False", int: "an int", float: "a number", str: "a string", type(None): "None"}
    return simple.get(hint, f"a {getattr(hint, '__name__', hint)} (set in Python, not here)")


def _episode_steps(env: str, overrides: dict[str, Any]) -> int:
    return {**mjzoo.envs.defaults(env), **overrides}["episode_steps"]


def train(
    algorithm: Annotated[Literal["ppo"], tyro.conf.Positional],
    env: Annotated[str, tyro.conf.Positional],
    out: Path | None = None,
    config: tuple[str, ...] = (),
    env_overrides: tuple[str, ...] = (),
    total_steps: int | None = None,
    resume: Path | None = None,
    seed: int | None = None,
    eval_envs: int | None = None,
    updates_per_chunk: int | None = None,
    video: bool = True,
) -> None:
    """Train ALGORITHM on ENV, writing config.json, metrics.jsonl, TensorBoard events,
    checkpoints, curves.png and eval.mp4 to --out (default runs/ENV-ALGORITHM), which
    must not hold a run already.

    --config takes NAME=VALUE fields of the algorithm's Config (defaults: the env's);
    --env-overrides NAME=VALUE overrides of the env (see `mjzoo envs`); --resume DIR
    continues the run in DIR from its newest intact checkpoint with its saved settings
    (--seed, --eval-envs and --updates-per-chunk too, unless given again, for the same
    result as an uninterrupted run). A new run's: --seed 0 --eval-envs 16 --updates-per-chunk 10.
    """
    from mjzoo.harness import checkpoints, training

    with _checking():
        module = _algorithm(algorithm)
        if resume is not None:
            out, env_values, config_values, run_settings = _resumed(resume, out, env, algorithm, env_overrides, config)
        else:
            env_values = _parse_assignments(env_overrides, "--env-overrides")
            config_values = _parse_assignments(config, "--config")
            run_settings = dict(RUN_DEFAULTS)
        given = {"seed": seed, "eval_envs": eval_envs, "updates_per_chunk": updates_per_chunk}
        run_settings.update({k: v for k, v in given.items() if v is not None})
        if total_steps is not None:
            config_values["total_steps"] = total_steps
        cfg = _config(module, env, config_values)
        task = mjzoo.envs.make(env, **env_values)
        if resume is None:
            out = out or Path("runs") / f"{env}-{algorithm}"
            _refuse_existing(out, (*training.RUN_FILES, "task.json"), f"continue it with --resume {out}, or choose a new --out")
        settings = training.Settings(out_dir=out, eval_steps=_episode_steps(env, env_values), video=video,
                                     resume=resume is not None, **run_settings)  # fmt: skip
    if resume is None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "task.json").write_text(json.dumps({"env": env, "overrides": env_values}, indent=2))
    with _checking(checkpoints.CheckpointError):  # resuming: only damaged ones, or another network's
        _, last = module.train(cfg, task, settings)
    print(f"final eval/return {last.get('eval/return', float('nan')):.2f}")
    print(f"curves: {out / 'curves.png'}")
    print(f"video:  {out / 'eval.mp4'}" if (out / "eval.mp4").exists() else "video:  (not written)")


def _resumed(resume: Path, out: Path | None, env: str, algorithm: str, env_overrides: tuple[str, ...],
             config: tuple[str, ...]) -> tuple[Path, dict, dict, dict]:  # fmt: skip
    """(out, env overrides, config values, run settings) of the run `--resume` continues,
    checked against what the command line says of it."""
    if out is not None and out != resume:
        raise UsageError(f"--out {out} and --resume {resume}: a resumed run stays in its directory; give one")
    if env_overrides:
        raise UsageError("--env-overrides: a resumed run keeps the env overrides it started with")
    saved, info = _read_run(resume, "--resume ")
    for what, ours, theirs in (("env", env, saved["env"]), ("algorithm", algorithm, info["algorithm"])):
        if ours != theirs:
            raise UsageError(f"--resume {resume}: that run's {what} is {theirs}, not {ours}")
    config_values = {**info["config"], **_parse_assignments(config, "--config")}
    run_settings = {**RUN_DEFAULTS, **{k: v for k, v in info.get("settings", {}).items() if k in RUN_DEFAULTS}}
    return resume, saved["overrides"], config_values, run_settings


def _read_run(run: Path, flag: str) -> tuple[dict, dict]:
    """task.json and config.json of a directory `mjzoo train` wrote, checked complete
    (a checkpoint included) before anything is built from them."""
    from mjzoo.harness import checkpoints

    where = f"{flag}{run}"
    if not run.is_dir():
        raise UsageError(f"{where}: {'not a directory' if run.exists() else 'no such run directory'}")
    loaded = {}
    for name, keys in (("task.json", ("env", "overrides")), ("config.json", ("algorithm", "config"))):
        if not (run / name).is_file():
            raise UsageError(f"{where}: not a complete run, it has no {name} (`mjzoo train` writes one)")
        try:
            loaded[name] = json.loads((run / name).read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise UsageError(f"{where}: {name} is not valid JSON ({e})") from None
        if not isinstance(loaded[name], dict) or not all(isinstance(loaded[name].get(k), (str, dict)) for k in keys):
            raise UsageError(f"{where}: {name} lacks {' or '.join(keys)} (not written by `mjzoo train`?)")
    if checkpoints.latest_step(run / "checkpoints") is None:
        raise UsageError(f"{where}: not a complete run, it has no checkpoint in {run / 'checkpoints'}")
    return loaded["task.json"], loaded["config.json"]


def _refuse_existing(out: Path, markers: tuple[str, ...], hint: str) -> None:
    """Refuses an --out that is a file or holds a run, before anything is written to it."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: is a file, not a directory")
    from mjzoo.harness import training

    found = training.existing(out, markers)
    if found:
        raise UsageError(f"--out {out} already holds a run ({', '.join(found)}): {hint}")


def evaluate(run: Annotated[Path, tyro.conf.Positional], episodes: int = 16, seed: int = 1, video: Path | None = None) -> None:
    """Reload RUN's newest intact checkpoint, run deterministic episodes, print the mean
    return and write a video (default RUN/eval.mp4)."""
    from mjzoo.harness import checkpoints, training

    with _checking():
        _at_least_one(episodes=episodes)
        saved, info = _read_run(run, "")
        module = _algorithm(info["algorithm"])
        cfg = _config(module, saved["env"], info["config"], str(run / "config.json"))
        task = mjzoo.envs.make(saved["env"], **saved["overrides"])
        steps = _episode_steps(saved["env"], saved["overrides"])
    template = module.init(cfg, task, jax.random.key(0))
    with _checking(checkpoints.CheckpointError):
        state, _, _ = checkpoints.restore_newest_intact(run / "checkpoints", like=template)
    mean, returns, trajectory = jax.jit(module.evaluate, static_argnums=(0, 4, 5))(
        cfg, task, state, jax.random.key(seed), episodes, steps
    )
    print(f"{saved['env']}: mean return {float(mean):.2f} ± {float(jnp.std(returns)):.2f} over {episodes} episodes")
    path = training.write_video(task, trajectory, video or run / "eval.mp4")
    if path is not None:
        print(f"video: {path}")


def plan(
    algorithm: Annotated[Literal["predictive_sampling", "cem", "mppi"], tyro.conf.Positional],
    env: Annotated[str, tyro.conf.Positional],
    out: Path | None = None,
    seconds: float | None = None,
    offline: bool = False,
    plan_hz: float | None = None,
    config: tuple[str, ...] = (),
    seed: int = 0,
    video: bool = True,
) -> None:
    """Solve ENV closed loop with a sampling planner and write summary.json (success,
    final_cost, plan_hz, plan_latency_ms), plan.png and plan.mp4 to --out (default
    runs/ENV-ALGORITHM-plan).

    By default the simulation runs in wall-clock time and the planner replans at
    --plan-hz (default: the env's replanning period); --offline runs the whole episode
    as one jitted scan instead. --config takes NAME=VALUE fields of the planner's Config
    (defaults: the env's); the planning task and hooks are the env's (`mjzoo.envs.planning`).
    """
    from mjzoo.harness import plan_report
    from mjzoo.planning import realtime

    with _checking():
        for flag, value in (("--seconds", seconds), ("--plan-hz", plan_hz)):
            if value is not None and not value > 0:
                raise UsageError(f"{flag} must be > 0, got {value}")
        mjzoo.envs.planning(env)
        module = _algorithm(algorithm, PLANNERS)
        cfg = _config(module, env, _parse_assignments(config, "--config"))
        out = out or Path("runs") / f"{env}-{algorithm}-plan"
        _refuse_existing(out, PLAN_FILES, "choose a new --out")
        problem = mjzoo.envs.closed_loop_problem(env, module, cfg, seconds)
    key = jax.random.key(seed)
    result, stats = realtime.offline(problem, key) if offline else realtime.realtime(problem, key, plan_hz)
    summary = plan_report.write(out, problem, result, stats, video, env=env, algorithm=algorithm,
                                 mode="offline" if offline else "realtime")  # fmt: skip
    print(json.dumps(summary, indent=2))
    print(f"plot:  {out / 'plan.png'}")
    print(f"video: {out / 'plan.mp4'}" if (out / "plan.mp4").exists() else "video: (not written)")


def main(argv: list[str] | None = None) -> None:
    """Runs one command. A `UsageError` becomes one line `mjzoo COMMAND: message` on
    stderr and exit status 2; tyro reports its own parse errors, also with status 2."""
    args = sys.argv[1:] if argv is None else list(argv)
    command = next((a for a in args if not a.startswith("-")), "")
    commands = {"demo": demo, "envs": envs, "train": train, "eval": evaluate, "plan": plan}
    try:
        with _one_line_warnings(command):
            tyro.extras.subcommand_cli_from_dict(commands, prog="mjzoo", args=args)
        sys.stdout.flush()  # a reader that went away shows here, not at exit
    except UsageError as e:
        print(f"mjzoo {command}: {' '.join(str(e).split())}", file=sys.stderr)
        raise SystemExit(2) from None
    except BrokenPipeError:  # `mjzoo envs | head -1`: stop quietly, as Python's docs advise
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the exit's flush writes nowhere
        raise SystemExit(1) from None


@contextlib.contextmanager
def _one_line_warnings(command: str) -> Iterator[None]:
    """The library's own warnings (e.g. checkpoints.DamagedCheckpointWarning) are news for
    the user: one line each, `mjzoo COMMAND: warning: ...`; others keep Python's format."""
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        if category.__module__.startswith("mjzoo."):
            print(f"mjzoo {command}: warning: {' '.join(str(message).split())}", file=sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = shown

