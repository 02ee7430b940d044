"""The commands that look at tasks, train, evaluate and plan (`mjzoo collect` is in
trajectories.py). Each takes a task spec: a registered env, or ``package.module:factory``
(a function returning a `mjzoo.Task`, its keyword arguments the --env-overrides)."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Annotated
from typing import Any
from typing import Literal

import jax
import jax.numpy as jnp
import numpy as np
import tyro

import mjzoo
from mjzoo import learning
from mjzoo.harness.cli import runs
from mjzoo.harness.cli.arguments import PLANNERS
from mjzoo.harness.cli.arguments import ConfigFields
from mjzoo.harness.cli.arguments import EnvOverrides
from mjzoo.harness.cli.arguments import Impl
from mjzoo.harness.cli.arguments import RunTask
from mjzoo.harness.cli.arguments import UsageError
from mjzoo.harness.cli.arguments import algorithm_module
from mjzoo.harness.cli.arguments import as_usage_errors
from mjzoo.harness.cli.arguments import at_least_one
from mjzoo.harness.cli.arguments import build_algorithm
from mjzoo.harness.cli.arguments import build_planner
from mjzoo.harness.cli.arguments import episode_steps
from mjzoo.harness.cli.arguments import imitated
from mjzoo.harness.cli.arguments import parse_assignments
from mjzoo.harness.cli.arguments import settings_flags
from mjzoo.harness.cli.arguments import slug
from mjzoo.harness.rendering import RenderConfig

__all__ = ["envs", "demo", "train", "evaluate", "plan", "Schedule"]

PLAN_FILES = ("summary.json",)
RUN_DEFAULTS = {"seed": 0, "eval_envs": 16, "updates_per_chunk": 10}  # how `train` drives a new run
# training.Settings that are not a run's own: where it is and how this process shows it
_NOT_KEPT = ("out_dir", "resume", "overwrite", "progress", "video")


# When a run evaluates, records and logs (KSim's validation and logging options): those
# of `training.Settings`' fields, with their types, defaults and comments, as flags.
Schedule = settings_flags(
    "Schedule",
    "When a run evaluates, records and logs (KSim's validation and logging options). A flag "
    "left at its default keeps a new run's default, or what a resumed run was started with.",
    (
        "eval_every",
        "eval_count",
        "eval_budget",
        "eval_every_seconds",
        "eval_first_seconds",
        "eval_steps",
        "eval_seconds",
        "video_every",
        "log_every",
        "log_train_metrics",
        "profile_memory",
        "checkpoint_every",
        "checkpoint_every_seconds",
    ),
)
SCHEDULE_DEFAULTS = Schedule()


def envs() -> None:
    """List the registered tasks with their overridable defaults."""
    for name in mjzoo.envs.names():
        overrides = ", ".join(f"{k}={v}" for k, v in mjzoo.envs.defaults(name).items())
        print(f"{name}\n    {overrides}")


def demo(env: tuple[str, ...] = (), num_envs: int = 32, steps: int = 250, seed: int = 0) -> None:
    """Roll out a uniformly random policy on each env (all registered ones by default)
    in a vmapped batch of --num-envs envs and print the return of each first episode,
    up to --steps steps.

    Args:
      env: the registered envs to roll out; default: all of them.
      num_envs: envs per batch, each with its own reset.
      steps: control steps per env, at most.
      seed: the random seed of the resets and actions.
    """
    names = env or tuple(mjzoo.envs.names())
    with as_usage_errors():
        at_least_one(num_envs=num_envs, steps=steps)
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
    """Per env: the return of the first episode under uniform random actions (over the
    ctrlranges, or [-1, 1] where the task's actuator takes its own: `to_controls`)."""

    def policy(obs, key):
        return learning.to_controls(task, jax.random.uniform(key, (nu,), minval=-1.0, maxval=1.0))

    def one(key):
        reset_key, run_key = jax.random.split(key)
        state = mjzoo.reset(task, reset_key)
        _, trajectory = mjzoo.rollout(task, policy, state, run_key, steps)
        done = trajectory.next_state.terminated | trajectory.next_state.truncated
        alive = jnp.cumsum(done) - done == 0  # up to and including the first episode end
        obs_size = jnp.size(jax.tree.leaves(state.obs)[0])
        return jnp.sum(trajectory.next_state.reward * alive), obs_size

    task = mjzoo.batching.sized(task, keys.shape[0])  # Warp: a contact pool for every env
    return jax.vmap(one)(keys)


def train(
    algorithm: Annotated[Literal["ppo", "amp", "sac", "fast_td3"], tyro.conf.Positional],
    env: Annotated[str, tyro.conf.Positional],
    out: Path | None = None,
    config: ConfigFields = (),
    env_overrides: EnvOverrides = (),
    total_steps: int | None = None,
    rollout_seconds: float | None = None,
    resume: Path | None = None,
    seed: int | None = None,
    eval_envs: int | None = None,
    updates_per_chunk: int | None = None,
    video: bool = True,
    impl: Impl = None,
    schedule: Annotated[Schedule, tyro.conf.OmitArgPrefixes] = SCHEDULE_DEFAULTS,
    render: RenderConfig = RenderConfig(),
    coordinator: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
) -> None:
    """Train ALGORITHM on ENV (a registered env or package.module:factory), writing
    task.json, config.json, metrics.jsonl, TensorBoard events, checkpoints, curves.png
    and eval.mp4 to --out (default runs/ENV-ALGORITHM), which must not hold a run.

    --config takes NAME=VALUE fields of the algorithm's Config and Hyperparams (one flat
    list, split by its `configure`), over the env's defaults;
    a factory has none, so the Config's own apply; --rollout-seconds gives its
    unroll_length in simulated seconds. --env-overrides takes NAME=VALUE
    overrides of the env, as `mjzoo envs` lists them, or a factory's keyword arguments.
    --impl picks the physics (MJX's JAX implementation or MuJoCo Warp; default Warp
    where it is installed and a CUDA GPU is present). Evaluation runs the task's
    episode length unless --eval-steps or --eval-seconds say otherwise, by default at
    least --eval-count times, evenly spaced; --eval-every, --log-every and the rest
    schedule it otherwise; --render.NAME VALUE sets how the videos and curves are drawn.
    On a CPU, the run says early how long it will take at the rate it measures.

    --resume DIR continues the run in DIR from its newest intact checkpoint with its
    saved settings, --seed, --eval-envs and --updates-per-chunk included unless given
    again, for the same result as an uninterrupted run. A new run's defaults: seed 0,
    eval envs 16, updates per chunk at most 10.

    On several hosts, start the same command on each with --coordinator HOST:PORT (process
    0's address), --num-processes N and --process-id I, or set JAX_COORDINATOR_ADDRESS,
    JAX_NUM_PROCESSES and JAX_PROCESS_ID (SLURM's srun and Open MPI's mpirun need none):
    each process trains its share of the envs, and process 0 writes --out, which every
    process must reach.

    Args:
      algorithm: the learner, ppo, amp, sac or fast_td3.
      env: the task, a registered env or package.module:factory.
      out: the run's directory; default runs/ENV-ALGORITHM.
      total_steps: env steps to train for; default: the env's (or the Config's).
      rollout_seconds: each update's unroll length in simulated seconds (sets unroll_length).
      resume: continue the run in this directory from its newest intact checkpoint.
      seed: the run's random seed; default 0 (a resumed run: its own).
      eval_envs: envs per evaluation; default 16 (a resumed run: its own).
      updates_per_chunk: updates per jitted chunk, at most; default 10 (a resumed run: its own).
      video: write eval.mp4 of the final evaluation.
      schedule: when the run evaluates, records and logs.
      render: how the videos and curves are drawn.
      coordinator: several hosts: process 0's HOST:PORT.
      num_processes: several hosts: how many processes train together.
      process_id: several hosts: this process's number, 0 to num_processes - 1.
    """
    from mjzoo.harness import checkpoints
    from mjzoo.harness import devices
    from mjzoo.harness import distributed
    from mjzoo.harness import training

    with as_usage_errors():
        distributed.initialize(coordinator, num_processes, process_id)  # before anything touches JAX's devices
        module = algorithm_module(algorithm)
        if resume is not None:
            out, env_values, config_values, run_settings = _resumed(
                resume, out, env, algorithm, env_overrides, config, impl
            )
        else:
            env_values = {**parse_assignments(env_overrides, "--env-overrides"), **({"impl": impl} if impl else {})}
            config_values, run_settings = parse_assignments(config, "--config"), dict(RUN_DEFAULTS)
        given = {
            "seed": seed,
            "eval_envs": eval_envs,
            "updates_per_chunk": updates_per_chunk,
            **_changed(schedule, SCHEDULE_DEFAULTS),
        }
        run_settings.update({k: v for k, v in given.items() if v is not None})
        run_settings["render"] = _render(run_settings.pop("render", None), render)
        task = mjzoo.envs.make(env, **env_values)
        config_values.update(_lengths(task, total_steps, rollout_seconds))
        cfg, hyperparams = build_algorithm(module, env, config_values)
        data = imitated(module, env, task, env_values)  # AMP: the env's reference, an error now if it has none
        devices.check_split(cfg.num_envs)
        if run_settings.get("eval_steps") is None and run_settings.get("eval_seconds") is None:
            mjzoo.episode_steps(task, env, "--eval-steps or --eval-seconds")  # its evaluation's length
        if resume is None:
            out = out or Path("runs") / f"{slug(env)}-{algorithm}"
            hint = f"continue it with --resume {out}, or choose a new --out"
            runs.refuse_existing(out, (*training.RUN_FILES, "task.json"), hint)
        settings = training.Settings(out_dir=out, video=video, resume=resume is not None, **run_settings)
    distributed.barrier("mjzoo train: --out checked")  # by every process, before process 0 writes there
    if resume is None and distributed.is_primary():
        out.mkdir(parents=True, exist_ok=True)
        (out / "task.json").write_text(json.dumps({"env": env, "overrides": env_values}, indent=2))
    # resuming: only damaged checkpoints, or another network's; Warp: capacities outgrown
    with as_usage_errors(checkpoints.CheckpointError, training.PhysicsCapacityError):
        _, last = training.run(module.make(cfg, *data), task, settings, hyperparams)
    if not distributed.is_primary():
        return
    print(f"final eval/return {last.get('eval/return', float('nan')):.2f}")
    print(f"curves: {out / 'curves.png'}")
    print(f"video:  {out / 'eval.mp4'}" if (out / "eval.mp4").exists() else "video:  (not written)")


def _lengths(task: mjzoo.Task, total_steps: int | None, rollout_seconds: float | None) -> dict[str, int]:
    """The Config fields --total-steps and --rollout-seconds set (KSim's rollout_length_seconds:
    unroll_length in the task's control steps)."""
    from mjzoo.harness import training

    lengths = {} if total_steps is None else {"total_steps": total_steps}
    if rollout_seconds is not None:
        if not rollout_seconds > 0:
            raise UsageError(f"--rollout-seconds must be > 0, got {rollout_seconds}")
        lengths["unroll_length"] = training.seconds_to_steps(task, rollout_seconds)
    return lengths


def _render(saved: dict | None, given: RenderConfig) -> RenderConfig:
    """A resumed run's render config (JSON) with the --render flags given again on top."""
    return RenderConfig(**{**(saved or {}), **_changed(given, RenderConfig())})


def _changed(given: Any, default: Any) -> dict[str, Any]:
    """The fields of dataclass `given` that differ from `default`: the flags given."""
    return {k: v for k, v in dataclasses.asdict(given).items() if v != getattr(default, k)}


def _resumed(
    resume: Path,
    out: Path | None,
    env: str,
    algorithm: str,
    env_overrides: tuple[str, ...],
    config: tuple[str, ...],
    impl: str | None,
) -> tuple[Path, dict, dict, dict]:
    """(out, env overrides, config values, run settings) of the run `--resume` continues,
    checked against what the command line says of it. Its task is built as the first run
    built it (task.json's overrides), on the physics implementation it ran on
    (config.json) where the env names `impl` as an option, unless --impl names one."""
    if out is not None and out != resume:
        raise UsageError(f"--out {out} and --resume {resume}: a resumed run stays in its directory; give one")
    if env_overrides:
        raise UsageError("--env-overrides: a resumed run keeps the env overrides it started with")
    saved, info = runs.read_run(resume, "--resume ")
    if saved is None:
        raise UsageError(f"--resume {resume}: not a complete run, it has no task.json (`mjzoo train` writes one)")
    for what, ours, theirs in (("env", env, saved["env"]), ("algorithm", algorithm, info["algorithm"])):
        if ours != theirs:
            raise UsageError(f"--resume {resume}: that run's {what} is {theirs}, not {ours}")
    # The hyperparameters come back with the checkpoint; these are for the config's checks.
    config_values = {**info["config"], **info.get("hyperparams", {}), **parse_assignments(config, "--config")}
    from mjzoo.harness import training

    kept = {f.name for f in dataclasses.fields(training.Settings)} - set(_NOT_KEPT)
    run_settings = {**RUN_DEFAULTS, **{k: v for k, v in info.get("settings", {}).items() if k in kept}}
    # A factory's **params does not count: it may be the task's parameters (docs/own-task.md's).
    named = mjzoo.envs.accepts(env, "impl", catch_all=False)
    physics_impl = impl or (info.get("physics", {}).get("impl") if named else None)
    return (
        resume,
        {**saved["overrides"], **({"impl": physics_impl} if physics_impl else {})},
        config_values,
        run_settings,
    )


def evaluate(
    run: Annotated[Path, tyro.conf.Positional],
    task: RunTask = None,
    env_overrides: EnvOverrides = (),
    episodes: int = 16,
    steps: int | None = None,
    seed: int = 1,
    video: Path | None = None,
    render: RenderConfig = RenderConfig(),
) -> None:
    """Reload RUN's newest intact checkpoint, run deterministic episodes of --steps
    steps, by default the task's episode length, print the mean return and write a
    video, by default RUN/eval.mp4.

    The task is the one RUN/task.json names, with its overrides. --task names another,
    a registered env or package.module:factory; a run trained from Python has no
    task.json and needs it. --env-overrides NAME=VALUE go on top, e.g. to evaluate
    under other physics. --render.NAME VALUE sets how the video is drawn.

    Args:
      run: the run's directory (`mjzoo train --out`).
      episodes: deterministic episodes, one env each.
      steps: control steps per episode; default: the task's episode length.
      seed: the random seed of the resets.
      video: where to write the video of the first episode; default RUN/eval.mp4.
      render: how the video is drawn.
    """
    from mjzoo.harness import training

    with as_usage_errors():
        at_least_one(episodes=episodes)
        trained = runs.load(run, task, env_overrides)
        steps = episode_steps(trained.task, trained.spec, steps)
    state = runs.restore(run, trained)
    returns, _, trajectory = jax.jit(trained.module.evaluate, static_argnums=(0, 4, 5))(
        trained.cfg, trained.task, state, jax.random.key(seed), episodes, steps
    )
    print(
        f"{trained.spec}: mean return {float(jnp.mean(returns)):.2f} ± {float(jnp.std(returns)):.2f} over {episodes} episodes"
    )
    path = training.write_video(trained.task, trajectory, video or run / "eval.mp4", render)
    if path is not None:
        print(f"video: {path}")


def plan(
    algorithm: Annotated[Literal["predictive_sampling", "cem", "mppi", "dial", "cma_es", "ilqr"], tyro.conf.Positional],
    env: Annotated[str, tyro.conf.Positional],
    out: Path | None = None,
    seconds: float | None = None,
    offline: bool = False,
    plan_hz: float | None = None,
    config: ConfigFields = (),
    env_overrides: EnvOverrides = (),
    seed: int = 0,
    video: bool = True,
    impl: Impl = None,
    backend: Literal["auto", "mjx", "native"] = "auto",
    sim_backend: Literal["mjx", "native"] | None = None,
    prior: Path | None = None,
    render: RenderConfig = RenderConfig(),
) -> None:
    """Solve ENV (a registered env or package.module:factory) closed loop with a
    planner and write summary.json (success, final_cost, plan_hz, plan_latency_ms),
    plan.png and plan.mp4 to --out (default runs/ENV-ALGORITHM-plan).

    By default the simulation runs in wall-clock time and the planner replans at the
    rate --plan-hz, by default the env's replanning period; --offline runs the whole
    episode as one jitted scan instead. --config takes NAME=VALUE fields of the
    planner's Config, over the env's defaults; --env-overrides NAME=VALUE change the
    env; --impl picks its physics (as for train); --backend where the planner's
    rollouts and the simulation run: mjx, or native (C MuJoCo through mujoco.rollout:
    the fast choice on a CPU); auto: native on a CPU, mjx on a GPU; --render.NAME VALUE sets how the
    video is drawn. The planning task, hooks, success
    test and length (--seconds) are the env's,
    from mjzoo.envs.planning: for a factory its module's PLANNING, else one episode,
    replanning every step, with no success test (final_cost tells).

    Args:
      algorithm: the planner (ilqr: on MJX only, a CPU included).
      env: the task, a registered env or package.module:factory.
      out: the run's directory; default runs/ENV-ALGORITHM-plan.
      seconds: simulated seconds to run; default: the env's planning setup (or one episode).
      offline: run the whole episode as one jitted scan, not in wall-clock time.
      plan_hz: replans per wall-clock second; default: the env's replanning period.
      seed: the random seed of the reset and the planner's samples.
      video: write plan.mp4.
      backend: where rollouts run: mjx, native (C MuJoCo), or auto (native on a CPU).
      sim_backend: where the simulated world steps, if not where the rollouts run:
        native beside an MJX planner on a GPU (a robot's world costs it nothing).
      prior: a PPO or AMP run directory trained on ENV: the planner plans offsets to its
        policy's actions, in closed loop, and values the horizon's end by its critic (PPO's).
      render: how the video is drawn.
    """
    from mjzoo.harness import plan_report
    from mjzoo.planning import prior as planning_prior
    from mjzoo.planning import realtime

    with as_usage_errors():
        for flag, value in (("--seconds", seconds), ("--plan-hz", plan_hz)):
            if value is not None and not value > 0:
                raise UsageError(f"{flag} must be > 0, got {value}")
        mjzoo.envs.planning(env)
        module = algorithm_module(algorithm, PLANNERS)
        cfg, hyperparams = build_planner(module, env, parse_assignments(config, "--config"))
        out = out or Path("runs") / f"{slug(env)}-{algorithm}-plan"
        runs.refuse_existing(out, PLAN_FILES, "choose a new --out")
        overrides = {**parse_assignments(env_overrides, "--env-overrides"), **({"impl": impl} if impl else {})}
        problem = mjzoo.envs.closed_loop_problem(
            env, module, cfg, seconds, backend=backend, hyperparams=hyperparams, sim_backend=sim_backend, **overrides
        )
        problem.tasks  # noqa: B018 (native tasks are checked here: a refusal is one line)
        if prior is not None:
            guide = runs.policy_prior(prior, problem.sim_task)
            problem = dataclasses.replace(
                problem,
                hooks=planning_prior.guided(problem.hooks, guide),
                terminal_value=planning_prior.terminal_value(guide),
            )
    key = jax.random.key(seed)
    result, stats = realtime.offline(problem, key) if offline else realtime.realtime(problem, key, plan_hz)
    summary = plan_report.write(
        out,
        problem,
        result,
        stats,
        video,
        env=env,
        algorithm=algorithm,
        mode="offline" if offline else "realtime",
        prior=None if prior is None else str(prior),
        render=render,
    )
    print(json.dumps(summary, indent=2))
    print(f"plot:  {out / 'plan.png'}")
    print(f"video: {out / 'plan.mp4'}" if (out / "plan.mp4").exists() else "video: (not written)")
