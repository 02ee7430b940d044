"""`mjzoo collect`: a trained policy's or a sampling planner's episodes, written as a
dataset directory (`mjzoo.harness.datasets`): the arrays, their meta.json and one
motion clip per episode, the reference motions imitation (AMP) reads."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Annotated
from typing import Any

import tyro

import mjzoo
from mjzoo.harness import datasets
from mjzoo.harness.cli import runs
from mjzoo.harness.cli.arguments import PLANNERS
from mjzoo.harness.cli.arguments import ConfigFields
from mjzoo.harness.cli.arguments import EnvOverrides
from mjzoo.harness.cli.arguments import Overwrite
from mjzoo.harness.cli.arguments import UsageError
from mjzoo.harness.cli.arguments import algorithm_module
from mjzoo.harness.cli.arguments import as_usage_errors
from mjzoo.harness.cli.arguments import at_least_one
from mjzoo.harness.cli.arguments import build_planner
from mjzoo.harness.cli.arguments import episode_steps
from mjzoo.harness.cli.arguments import parse_assignments
from mjzoo.planning.realtime import Problem

__all__ = ["collect"]

# Deployable policies by (algorithm, config, deterministic, task spec, overrides): the
# same policy function keeps `datasets.record_policy`'s compile within a process.
_POLICIES: dict[tuple, Any] = {}


def collect(
    source: Annotated[str, tyro.conf.Positional],
    out: Path,
    task: str | None = None,
    env_overrides: EnvOverrides = (),
    episodes: int = 16,
    steps: int | None = None,
    config: ConfigFields = (),
    seed: int = 0,
    sampled: bool = False,
    overwrite: Overwrite = False,
) -> None:
    """Roll out SOURCE for --episodes episodes and write them as a dataset to the
    directory --out, which must not hold one unless --overwrite (other files stay).

    SOURCE is a run directory: its policy on the task of its task.json or of --task,
    as in `mjzoo eval`, with deterministic actions (the mean), or with sampled ones
    given --sampled. Or a planner, predictive_sampling, cem, mppi, dial, cma_es or ilqr, closed loop on
    the task that --task names, with --config NAME=VALUE fields of its Config, as
    in `mjzoo plan`. Each of --env-overrides NAME=VALUE changes the task. Each
    episode runs for --steps control steps, by default the task's episode length (a
    planner: the length of `mjzoo plan`'s run), and goes on past an early end; its
    length is recorded.

    The dataset: dataset.npz (for N episodes of T steps: qpos, qvel, time, body poses
    xpos and xquat, obs [N, T+1, ...]; action, ctrl, reward, reward/TERM, terminated,
    truncated [N, T]; length [N]), meta.json (names, shapes, dt, the source, the seed)
    and motions/episode_NNN.npz, one mjzoo.motion clip per episode, cut at its length.

    Args:
      source: a run directory, or a planner: predictive_sampling, cem, mppi, dial, cma_es or ilqr.
      out: the dataset's directory.
      task: the task, a registered env or package.module:factory; a planner's is required,
        a run's defaults to its task.json's.
      episodes: episodes to record, one env each.
      steps: control steps per episode; default: the task's episode length.
      seed: the random seed of the resets and the policy's (or planner's) samples.
      sampled: a run's policy acts with sampled actions, not the mean.
    """
    with as_usage_errors():
        at_least_one(episodes=episodes)
        _check_out(out, overwrite)
        if source in PLANNERS:
            if sampled:
                raise UsageError("--sampled: only for a run's policy; a planner's controls are sampled anyway")
            problem, about = _problem(source, task, env_overrides, config, steps)
        elif config:
            raise UsageError("--config: only for a planner; a run keeps its own config")
        else:
            trained = runs.load(Path(source), task, env_overrides)
            steps = episode_steps(trained.task, trained.spec, steps)
            about = {
                "run": source,
                "algorithm": trained.module.__name__.split(".")[-1],
                "task": trained.spec,
                "env_overrides": trained.overrides,
            }
    if source in PLANNERS:
        dataset = datasets.record_planner(problem, seed, episodes, steps, source=about)
    else:  # past the checks: restoring compiles PPO's init, whose errors are bugs
        params = trained.module.policy_params(runs.restore(Path(source), trained))
        act = _policy(trained, not sampled)
        dataset = datasets.record_policy(
            trained.task, act, params, seed, episodes, steps, deterministic=not sampled, source=about
        )
    for path in datasets.save(out, dataset, overwrite=overwrite):
        print(path)
    print(
        f"{out}: {episodes} episodes of {dataset.num_steps} steps on {about['task']}, mean length "
        f"{dataset.length.mean():.1f}, mean return {dataset.returns().mean():.2f}"
    )


def _check_out(out: Path, overwrite: bool) -> None:
    """Refuses an --out that is not a dataset directory, or holds one (unless --overwrite)."""
    if out.suffix == ".npz":
        raise UsageError(
            f"--out {out}: names a directory (dataset.npz, meta.json and motions/ go in it), not an "
            f".npz file; e.g. --out {out.with_suffix('')}"
        )
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: is a file, not a directory")
    found = datasets.existing(out)
    if found and not overwrite:
        raise UsageError(
            f"--out {out} already holds a dataset ({found[0]}, ...): give --overwrite to replace it, "
            "or choose a new --out"
        )


def _problem(
    name: str, spec: str | None, env_overrides: tuple[str, ...], config: tuple[str, ...], steps: int | None
) -> tuple[Problem, dict[str, Any]]:
    """The planner's closed-loop problem on `spec`, as `mjzoo plan` builds it, and its
    description for meta.json."""
    if spec is None:
        raise UsageError(f"--task: a planner needs the task to plan on, e.g. {name} --task pendulum_swingup")
    if steps is not None:
        at_least_one(steps=steps)
    module = algorithm_module(name, PLANNERS)
    cfg, hyperparams = build_planner(module, spec, parse_assignments(config, "--config"))
    overrides = parse_assignments(env_overrides, "--env-overrides")
    problem = mjzoo.envs.closed_loop_problem(spec, module, cfg, hyperparams=hyperparams, **overrides)
    fields = {**_fields(cfg), **_fields(hyperparams)}
    about = {"planner": name, "task": spec, "env_overrides": overrides, "config": _json(fields)}
    return problem, about


def _policy(trained: runs.Trained, deterministic: bool) -> Any:
    """The run's deployable policy (`module.policy`), one function per task and mode."""
    overrides = json.dumps(trained.overrides, sort_keys=True, default=str)
    key = (trained.module.__name__, trained.cfg, deterministic, trained.spec, overrides)
    if key not in _POLICIES:
        _POLICIES[key] = trained.module.policy(trained.cfg, trained.task, deterministic=deterministic)
    return _POLICIES[key]


def _fields(cfg: Any) -> dict[str, Any]:
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)}


def _json(value: Any) -> Any:
    """`value` with what JSON cannot hold (networks, functions) as its text."""
    return json.loads(json.dumps(value, default=str))
