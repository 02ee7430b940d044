"""`mjzoo collect`: a trained policy's or a sampling planner's episodes, written as one
.npz of motion data (e.g. reference motions for imitation)."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from types import ModuleType
from typing import Annotated, Any

import jax
import numpy as np
import tyro

import mjzoo
from mjzoo.harness.cli import runs
from mjzoo.harness.cli.arguments import (PLANNERS, UsageError, algorithm_module, at_least_one, build_config,
                                         checking, episode_steps, parse_assignments)  # fmt: skip
from mjzoo.planning import closed_loop
from mjzoo.planning.realtime import Problem

__all__ = ["collect", "as_arrays"]


def collect(
    source: Annotated[str, tyro.conf.Positional],
    out: Path,
    task: str | None = None,
    env_overrides: tuple[str, ...] = (),
    episodes: int = 16,
    steps: int | None = None,
    config: tuple[str, ...] = (),
    seed: int = 0,
    overwrite: bool = False,
) -> None:
    """Roll out SOURCE for --episodes episodes and write them to --out, an .npz file,
    which must not exist unless --overwrite.

    SOURCE is a run directory: its policy, deterministic, on the task of its task.json
    or of --task, as in `mjzoo eval`. Or a planner, predictive_sampling, cem or mppi,
    closed loop on the task --task names, with --config NAME=VALUE fields of its Config,
    as in `mjzoo plan`. --env-overrides NAME=VALUE change the task. Each episode runs
    for --steps control steps, by default the task's episode length (a planner: the
    length of `mjzoo plan`'s run), and goes on past an early end: cut each at its
    first terminated or truncated step.

    For N episodes of T steps the file holds the states' qpos [N, T+1, nq], qvel [N,
    T+1, nv], time [N, T+1] and obs [N, T+1, ...], the first state included (a dict
    observation: obs/KEY for each entry), and each step's action [N, T, nu] (the
    controls applied), reward, terminated and truncated [N, T].
    """
    with checking():
        at_least_one(episodes=episodes)
        if out.suffix != ".npz":
            raise UsageError(f"--out {out}: expected a file name ending in .npz")
        if out.exists() and not overwrite:
            raise UsageError(f"--out {out} exists: give --overwrite to replace it, or choose a new --out")
        if source in PLANNERS:
            spec, problem = task, _problem(source, task, env_overrides, config, steps)
        elif config:
            raise UsageError("--config: only for a planner; a run keeps its own config")
        else:
            trained = runs.load(Path(source), task, env_overrides)
            spec, steps = trained.spec, episode_steps(trained.task, trained.spec, steps)
    keys = jax.random.split(jax.random.key(seed), episodes)
    if source in PLANNERS:
        rolled = _planned(problem.planner, problem.config, problem.sim_task, problem.plan_task, problem.hooks,
                                keys, problem.num_replans, problem.replan_every)  # fmt: skip
    else:  # past the checks: restoring compiles PPO's init, whose errors are bugs
        params = trained.module.policy_params(runs.restore(Path(source), trained))
        rolled = _acted(trained.module, trained.cfg, trained.task, params, keys, steps)
    arrays = as_arrays(*jax.device_get(rolled))
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez(out, **arrays)
    print(f"{out}: {episodes} episodes of {arrays['action'].shape[1]} steps on {spec}")


def _problem(name: str, spec: str | None, env_overrides: tuple[str, ...], config: tuple[str, ...],
             steps: int | None) -> Problem:  # fmt: skip
    """The planner's closed-loop problem on `spec`, as `mjzoo plan` builds it."""
    if spec is None:
        raise UsageError(f"--task: a planner needs the task to plan on, e.g. {name} --task pendulum_swingup")
    module = algorithm_module(name, PLANNERS)
    cfg = build_config(module, spec, parse_assignments(config, "--config"))
    problem = mjzoo.envs.closed_loop_problem(spec, module, cfg, **parse_assignments(env_overrides, "--env-overrides"))
    if steps is None:
        return problem
    at_least_one(steps=steps)
    return dataclasses.replace(problem, seconds=steps * problem.sim_dt)  # in whole replans


@functools.partial(jax.jit, static_argnums=(0, 1, 6, 7))
def _planned(planner: ModuleType, config: Any, sim_task: mjzoo.Task, plan_task: Any, hooks: closed_loop.Hooks,
             keys: jax.Array, num_replans: int, replan_every: int):  # fmt: skip
    """keys [N] -> (first states [N], states after each step [N, T], controls [N, T, nu])."""

    def one(key):
        reset_key, run_key = jax.random.split(key)
        first = mjzoo.reset(sim_task, reset_key)
        result = closed_loop.run(planner, config, sim_task, plan_task, first, run_key, num_replans, replan_every, hooks)
        return first, result.states, result.controls

    return jax.vmap(one)(keys)


@functools.partial(jax.jit, static_argnums=(0, 1, 5))
def _acted(algorithm: ModuleType, config: Any, task: mjzoo.Task, params: Any, keys: jax.Array, steps: int):
    """keys [N] -> (first states [N], states after each step [N, T], actions [N, T, nu])
    of a trained deterministic policy (`algorithm.policy`)."""
    act = algorithm.policy(config, task, deterministic=True)

    def one(key):
        reset_key, run_key = jax.random.split(key)
        first = mjzoo.reset(task, reset_key)
        _, trajectory = mjzoo.rollout(task, lambda obs, k: act(params, obs, k), first, run_key, steps)
        return first, trajectory.next_state, trajectory.action

    return jax.vmap(one)(keys)


def as_arrays(first: mjzoo.State, after: mjzoo.State, actions: np.ndarray) -> dict[str, np.ndarray]:
    """The file's arrays from first states [N], the states after each step [N, T] and
    the actions [N, T, nu] (see `collect`)."""

    def states(first_leaf, after_leaf) -> np.ndarray:  # [N] and [N, T] -> [N, T+1]
        return np.concatenate([np.asarray(first_leaf)[:, None], np.asarray(after_leaf)], axis=1)

    arrays = {name: states(getattr(first.data, name), getattr(after.data, name)) for name in ("qpos", "qvel", "time")}
    for (path, first_obs), after_obs in zip(jax.tree_util.tree_leaves_with_path(first.obs), jax.tree.leaves(after.obs)):
        key = jax.tree_util.keystr(path, simple=True, separator="/")
        arrays[f"obs/{key}" if key else "obs"] = states(first_obs, after_obs)
    return {**arrays, "action": np.asarray(actions), "reward": np.asarray(after.reward),
            "terminated": np.asarray(after.terminated), "truncated": np.asarray(after.truncated)}  # fmt: skip
