"""The `mjzoo` command line (also `python -m mjzoo`).

    mjzoo envs                    # list the registered tasks and their overrides
    mjzoo demo --steps 200        # random policy on every env, batched, prints returns
    mjzoo train ppo cartpole_balance --out runs/cb --config num_envs=128 learning_rate=3e-4
    mjzoo train ppo cartpole_balance --resume runs/cb
    mjzoo eval runs/cb            # reload the checkpoint, evaluate, write a video
"""

from __future__ import annotations

import ast
import dataclasses
import json
import time
from pathlib import Path
from typing import Annotated, Any, Literal

import jax
import jax.numpy as jnp
import numpy as np
import tyro

import mjzoo
import mjzoo.envs

__all__ = ["main", "demo", "envs", "train", "evaluate"]

ALGORITHMS = ("ppo",)


def envs() -> None:
    """List the registered tasks with their overridable defaults."""
    for name in mjzoo.envs.names():
        overrides = ", ".join(f"{k}={v}" for k, v in mjzoo.envs.defaults(name).items())
        print(f"{name}\n    {overrides}")


def demo(env: tuple[str, ...] = (), num_envs: int = 32, steps: int = 250, seed: int = 0) -> None:
    """Roll out a uniformly random policy on each env (all by default) in a vmapped batch
    of `num_envs` and print the return of each first episode (up to `steps` steps)."""
    names = env or tuple(mjzoo.envs.names())
    if num_envs < 1 or steps < 1:
        raise SystemExit("demo: --num-envs and --steps must be >= 1")
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


def _parse_assignments(pairs: tuple[str, ...], what: str) -> dict[str, Any]:
    """["a=1", "b=(64, 64)", "c=swish"] -> {"a": 1, "b": (64, 64), "c": "swish"}."""
    parsed = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        if not sep or not name:
            raise SystemExit(f"{what}: expected NAME=VALUE, got {pair!r}")
        try:
            parsed[name] = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            parsed[name] = text  # a bare word: a string
    return parsed


def _algorithm(name: str):
    import importlib

    return importlib.import_module(f"mjzoo.algorithms.{name}")


def _config(algorithm, env: str, overrides: dict[str, Any]):
    """The algorithm's Config: its defaults, then the env's, then `overrides` (from the
    command line or a saved config.json, whose user-supplied pieces cannot be rebuilt)."""
    fields = {f.name: f for f in dataclasses.fields(algorithm.Config)}
    overrides = {k: v for k, v in overrides.items() if not str(v).startswith("<custom")}
    values = {**mjzoo.envs.hyperparameters(env, algorithm.__name__.split(".")[-1]), **overrides}
    unknown = sorted(set(values) - set(fields))
    if unknown:
        raise SystemExit(f"--config: unknown field(s) {unknown}; fields: {sorted(fields)}")
    for name, value in values.items():  # JSON and literal lists back to the tuples Config holds
        if isinstance(value, list):
            values[name] = tuple(value)
    try:
        return algorithm.Config(**values)
    except (ValueError, TypeError) as e:
        raise SystemExit(str(e)) from None


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
    seed: int = 0,
    eval_envs: int = 16,
    updates_per_chunk: int = 10,
    video: bool = True,
) -> None:
    """Train ALGORITHM on ENV, writing config.json, metrics.jsonl, TensorBoard events,
    checkpoints, curves.png and eval.mp4 to --out (default runs/ENV-ALGORITHM).

    --config takes NAME=VALUE fields of the algorithm's Config (defaults: the env's);
    --env-overrides NAME=VALUE overrides of the env (see `mjzoo envs`); --resume DIR
    continues the run in DIR from its newest checkpoint with its saved settings.
    """
    from mjzoo.harness import training

    if resume is not None:
        saved = json.loads((resume / "task.json").read_text())
        env, out = saved["env"], resume
        env_values = saved["overrides"]
        config_values = {**json.loads((resume / "config.json").read_text())["config"], **_parse_assignments(config, "--config")}
    else:
        env_values = _parse_assignments(env_overrides, "--env-overrides")
        config_values = _parse_assignments(config, "--config")
    if total_steps is not None:
        config_values["total_steps"] = total_steps
    module = _algorithm(algorithm)
    cfg = _config(module, env, config_values)
    task = mjzoo.envs.make(env, **env_values)
    out = out or Path("runs") / f"{env}-{algorithm}"
    out.mkdir(parents=True, exist_ok=True)
    (out / "task.json").write_text(json.dumps({"env": env, "overrides": env_values}, indent=2))
    eval_steps = _episode_steps(env, env_values)
    settings = training.Settings(out_dir=out, seed=seed, updates_per_chunk=updates_per_chunk, eval_envs=eval_envs,
                                 eval_steps=eval_steps, video=video, resume=resume is not None)  # fmt: skip
    _, last = module.train(cfg, task, settings)
    print(f"final eval/return {last.get('eval/return', float('nan')):.2f}")
    print(f"curves: {out / 'curves.png'}")
    print(f"video:  {out / 'eval.mp4'}" if (out / "eval.mp4").exists() else "video:  (not written)")


def evaluate(run: Annotated[Path, tyro.conf.Positional], episodes: int = 16, seed: int = 1, video: Path | None = None) -> None:
    """Reload RUN's newest checkpoint, run deterministic episodes, print the mean return
    and write a video (default RUN/eval.mp4)."""
    from mjzoo.harness import checkpoints, training

    saved = json.loads((run / "task.json").read_text())
    info = json.loads((run / "config.json").read_text())
    module = _algorithm(info["algorithm"])
    cfg = _config(module, saved["env"], info["config"])
    task = mjzoo.envs.make(saved["env"], **saved["overrides"])
    state = checkpoints.restore(run / "checkpoints", like=module.init(cfg, task, jax.random.key(0)))
    steps = _episode_steps(saved["env"], saved["overrides"])
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

    try:
        mjzoo.envs.planning(env)
    except KeyError as e:
        raise SystemExit(str(e.args[0])) from None
    module = _algorithm(algorithm)
    problem = mjzoo.envs.closed_loop_problem(env, module, _config(module, env, _parse_assignments(config, "--config")), seconds)
    key = jax.random.key(seed)
    result, stats = realtime.offline(problem, key) if offline else realtime.realtime(problem, key, plan_hz)
    out = out or Path("runs") / f"{env}-{algorithm}-plan"
    summary = plan_report.write(out, problem, result, stats, video, env=env, algorithm=algorithm,
                                 mode="offline" if offline else "realtime")  # fmt: skip
    print(json.dumps(summary, indent=2))
    print(f"plot:  {out / 'plan.png'}")
    print(f"video: {out / 'plan.mp4'}" if (out / "plan.mp4").exists() else "video: (not written)")


def main(argv: list[str] | None = None) -> None:
    tyro.extras.subcommand_cli_from_dict(
        {"demo": demo, "envs": envs, "train": train, "eval": evaluate, "plan": plan}, args=argv
    )


if __name__ == "__main__":
    main()
