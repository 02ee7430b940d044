"""Policy-guided sampling against plain sampling at equal samples, on the real robots.

For each task (`go1_trot`, `g1_standup`): PPO trains on the task itself (``mjzoo train
ppo TASK``, a run directory under ``--runs``; ``--run TASK=DIR`` reuses one), then at each
sample count MPPI plans closed loop twice from the same starts: plain (the task's
`PLANNING` setup) and guided by the trained policy (`mjzoo.planning.prior`: it plans
offsets to the policy's actions, applied in closed loop, and values the horizon's end by
its critic). The policy alone (its deterministic action at every control step, no
planner) is the third row, from the same starts. Per
row: the task's own success rate and mean score over ``--episodes`` seeds, replan
latency. ``--clock simulated`` (the default) makes the world wait for each replan, so the
rows compare what each finds with its samples, apart from its rate; ``--clock wall``
runs them in real time. The world steps in C MuJoCo, the planner on MJX (``--impl``).
Every training runs before this process starts JAX's backend (on a GPU it would hold the
memory the training needs). `pendulum_swingup` trains in a minute on a CPU: there (PPO
1.6M steps, offline closed loops in MJX, 6 seeds) MPPI with 16 samples guided by the
former open-loop plan (the policy's rollout read at the knots) held the pendulum up in 5
of 6 episodes, return 203; by offsets in closed loop, 6 of 6, return 232 (the policy
alone: 5 of 6, return 158).

    python benchmarks/guided_mpc.py --train-steps 50000000                 # one GPU
    python benchmarks/guided_mpc.py --tasks go1_trot --run go1_trot=runs/go1-trot-ppo
    python benchmarks/guided_mpc.py --smoke                                # tiny sizes, on a CPU
    python benchmarks/guided_mpc.py --tasks pendulum_swingup --train-steps 1600000 --samples 4 16 64 --episodes 6

Results: ``benchmarks/results/guided_mpc/guided_mpc_<device>.json`` (each row as it finishes).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING
from typing import Iterator

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from cards import card_name  # noqa: E402

from mjzoo import physics  # noqa: E402

# Nothing here may start JAX's backend before `mjzoo train` has trained: on a GPU it would
# take 75% of the memory the child needs. `mjzoo.envs` starts it on import (module-level
# arrays), so it and what plans are imported once training is done (`measure`).
if TYPE_CHECKING:
    from mjzoo.planning import prior as prior_lib
    from mjzoo.planning import realtime

ROOT = Path(__file__).resolve().parent.parent
TASKS = ("go1_trot", "g1_standup")
CPU_TASKS = ("pendulum_swingup",)  # trains in a minute on a CPU: the guidance checked there


def train(task: str, out: Path, steps: int, impl: str | None, smoke: bool) -> Path:
    """PPO on `task` through the CLI (its checkpoints, curves and metrics in `out`)."""
    config = ["num_envs=8", "unroll_length=4", "num_minibatches=2", "num_epochs=1"] if smoke else []
    if smoke:
        config += ["--eval-count", "1", "--eval-envs", "2"]
    argv = [sys.executable, "-m", "mjzoo", "train", "ppo", task, "--out", str(out), *(["--impl", impl] if impl else [])]
    argv += ["--config", f"total_steps={steps}", *config, "--no-video"]
    subprocess.run(argv, check=True)
    return out


def policy_alone(problem: realtime.Problem, prior: prior_lib.PolicyPrior, episodes: int) -> dict:
    """The policy's own closed loop: its deterministic action each control step, from the
    starts `realtime.realtime` draws for the same seeds."""
    import jax

    import mjzoo

    task = problem.sim_task
    steps = round(problem.seconds / problem.sim_dt)

    def episode(key):
        def body(state, k):
            nxt = mjzoo.running.transition(task, state, prior.act(state.obs), k)
            return nxt, nxt

        start = mjzoo.reset(task, jax.random.split(key, 3)[0])  # realtime's reset key
        return jax.lax.scan(body, start, jax.random.split(key, steps))[1]

    run = jax.jit(episode)
    outcomes = [problem.success(jax.device_get(run(jax.random.key(seed)))) for seed in range(episodes)]
    return {"success_rate": float(np.mean([s for s, _ in outcomes])), "score": float(np.mean([c for _, c in outcomes]))}


def planned(problem: realtime.Problem, episodes: int, clock: str) -> dict:
    """`episodes` closed loops of `problem` (seeds 0..episodes-1)."""
    import jax

    from mjzoo.planning import realtime

    runs = []
    for seed in range(episodes):
        result, stats = realtime.realtime(problem, jax.random.key(seed), clock=clock)
        solved, score = problem.success(jax.device_get(result.states))
        runs.append({"success": bool(solved), "score": float(score), "plan_latency_ms": stats["plan_latency_ms"]})
    mean = lambda k: float(np.mean([r[k] for r in runs]))  # noqa: E731
    return {"success_rate": mean("success"), "score": mean("score"), "replan_ms": mean("plan_latency_ms"), "runs": runs}


def measure(task: str, run: Path, samples: list[int], args: argparse.Namespace, impl: str) -> Iterator[dict]:
    """The policy alone, then plain and guided MPPI at each sample count, on `task`: each
    row as it finishes."""
    import mjzoo.envs
    from mjzoo.algorithms import mppi
    from mjzoo.harness.cli import runs as run_dirs
    from mjzoo.planning import prior as prior_lib

    prior = None
    for n in samples:
        fields = {**mjzoo.envs.hyperparameters(task, "mppi"), "num_samples": n}
        if args.smoke:
            fields.update(horizon_steps=4, num_knots=2)
        config, hyperparams = mjzoo.planning.configure(mppi, fields)
        problem = mjzoo.envs.closed_loop_problem(
            task,
            mppi,
            config,
            seconds=0.2 if args.smoke else None,
            backend="mjx",
            hyperparams=hyperparams,
            sim_backend="native",
            impl=impl,
        )
        if prior is None:  # one restore: the planning task is the same at every sample count
            prior = run_dirs.policy_prior(run, problem.plan_task)
            row = {
                "task": task,
                "planner": "policy alone",
                "num_samples": 0,
                **policy_alone(problem, prior, args.episodes),
            }
            print(f"  {task} policy alone: success {row['success_rate']:.2f}, score {row['score']:.3g}")
            yield row
        guided = dataclasses.replace(
            problem,
            hooks=prior_lib.guided(problem.hooks, prior),
            terminal_value=prior_lib.terminal_value(prior),
        )
        for name, p in (("mppi", problem), ("mppi + policy prior", guided)):
            start = time.perf_counter()
            row = {"task": task, "planner": name, "num_samples": n, **planned(p, args.episodes, args.clock)}
            row["seconds_with_compile"] = time.perf_counter() - start
            print(
                f"  {task} {name} {n}: success {row['success_rate']:.2f}, score {row['score']:.3g}, {row['replan_ms']:.1f} ms"
            )
            yield row


def write(path: Path, results: dict) -> None:
    """`results` as JSON at `path`, atomically: a run stopped partway keeps its rows."""
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(results, indent=1))
    os.replace(tmp, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS + CPU_TASKS)
    parser.add_argument("--samples", nargs="+", type=int, default=[16, 64, 256, 1024])
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--train-steps", type=int, default=50_000_000, help="PPO's env steps per task")
    parser.add_argument("--run", nargs="+", default=[], metavar="TASK=DIR", help="a trained PPO run to reuse")
    parser.add_argument("--runs", type=Path, default=ROOT / "runs" / "guided_mpc", help="where new runs go")
    parser.add_argument("--clock", choices=["simulated", "wall"], default="simulated")
    parser.add_argument("--impl", choices=physics.IMPLS, default=None, help="the planner's and PPO's physics")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: checks the script runs, on a CPU")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "guided_mpc")
    args = parser.parse_args()
    given = dict(text.split("=", 1) for text in args.run if "=" in text)
    if len(given) != len(args.run) or not set(given) <= set(TASKS + CPU_TASKS):
        parser.error(f"--run takes TASK=DIR with TASK one of {TASKS + CPU_TASKS}")
    if args.smoke:
        args.samples, args.episodes, args.train_steps = [8], 1, 64
        args.runs = Path(tempfile.mkdtemp(prefix="guided_mpc_"))
    args.out.mkdir(parents=True, exist_ok=True)
    meta, runs = {"clock": args.clock, "runs": []}, {}
    for task in args.tasks:  # every training first: JAX's backend starts in this process after them
        start = time.perf_counter()
        fresh = task not in given
        runs[task] = (
            train(task, args.runs / f"{task}-ppo", args.train_steps, args.impl, args.smoke)
            if fresh
            else Path(given[task])
        )
        seconds = time.perf_counter() - start if fresh else None
        meta["runs"].append(
            {
                "task": task,
                "run": str(runs[task]),
                "train_steps": args.train_steps if fresh else None,
                "train_seconds": seconds,
            }
        )
    import jax

    impl = args.impl or physics.default_impl()
    meta.update(device=jax.devices()[0].device_kind, jax=jax.__version__, impl=impl)
    path, rows = args.out / f"guided_mpc_{card_name()}{'_smoke' if args.smoke else ''}.json", []
    for task, run in runs.items():
        for row in measure(task, run, args.samples, args, impl):
            rows.append(row)
            write(path, {"meta": meta, "rows": rows})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
