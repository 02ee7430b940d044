"""Whole-body sampling MPC on real robots, in real time: replan latency and success.

For each robot task (`g1_standup`, `go1_trot`, `g1_track` on its walk clip,
`leap_cube_rotate`, `panda_pick`) and sampling planner, at 256, 1024 and 4096 samples
over the task's 0.5 s horizon (its `PLANNING` setup otherwise), the real-time runner
(`mjzoo.planning.realtime`, as `mjzoo plan` runs) simulates the task against the wall
clock: the world does not wait for a replan, and a slow planner falls behind as it would
on a robot. The planner rolls out on MJX (``--impl``: MuJoCo Warp where installed); the
world steps in C MuJoCo (``--world``), as
a robot's world costs the planner nothing (one G1 world's MJX step took 14 ms on an
H200, 70% of the wall clock, before a replan's share). Per row: replan latency (median, p95),
the achieved replan rate, the success rate over ``--episodes`` seeds by the task's own
measure, and its mean score. A replan is a `lax.scan` over the horizon's physics steps,
each over every sample at once: its latency per physics step (``ms_per_physics_step``)
is what bounds the rate. iLQR is left out: its derivatives cost (2n + 1) n forward
passes a planning step (n ~ 100 for the G1), a planner for small systems.

    python benchmarks/robot_mpc.py                                   # one GPU, ~25 minutes
    python benchmarks/robot_mpc.py --tasks go1_trot --planners mppi dial --samples 1024
    python benchmarks/robot_mpc.py --smoke                           # tiny sizes, on a CPU: checks the script

Results: ``benchmarks/results/robot_mpc/robot_mpc_<device>.json`` (each row as it finishes).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from cards import card_name  # noqa: E402

import mjzoo  # noqa: E402
import mjzoo.envs  # noqa: E402
from mjzoo import physics  # noqa: E402
from mjzoo.algorithms import cem  # noqa: E402
from mjzoo.algorithms import cma_es  # noqa: E402
from mjzoo.algorithms import dial  # noqa: E402
from mjzoo.algorithms import mppi  # noqa: E402
from mjzoo.algorithms import predictive_sampling  # noqa: E402
from mjzoo.harness.cli.arguments import UsageError  # noqa: E402
from mjzoo.harness.cli.arguments import parse_assignments  # noqa: E402
from mjzoo.planning import realtime  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PLANNERS = {m.__name__.rsplit(".", 1)[-1]: m for m in (predictive_sampling, mppi, cem, dial, cma_es)}
TASKS = {"g1_standup": {}, "go1_trot": {}, "g1_track": {"clips": "walk"}, "leap_cube_rotate": {}, "panda_pick": {}}


def physics_steps(plan_task: mjzoo.Task, horizon_steps: int, control_dt: float) -> int:
    """The sequential physics steps of one rollout: a replan's latency over them is the
    cost of one batched MJX step, what bounds the replanning rate."""
    return horizon_steps * round(control_dt / float(plan_task.model.opt.timestep))


def measure(
    task: str,
    planner: str,
    samples: int,
    episodes: int,
    smoke: bool,
    world: str,
    impl: str = "jax",
    clock: str = "wall",
    plan_physics: dict | None = None,
) -> dict:
    """One row: `episodes` closed loops of `planner` at `samples` on `task`, against the
    wall clock (or in simulated time: the world waits for each replan), the planner's
    model built with `plan_physics` (`mjzoo.physics.load`'s options: a coarser step, fewer
    solver iterations) over the task's own."""
    module = PLANNERS[planner]
    fields = mjzoo.envs.hyperparameters(task, planner)
    fields["num_samples"] = samples
    if "num_elites" in fields:
        fields["num_elites"] = mjzoo.envs.base.elite_count(samples)
    if smoke:
        fields.update(horizon_steps=4, num_knots=2)
    config, hyperparams = mjzoo.planning.configure(module, fields)
    seconds = 0.1 if smoke else None
    problem = mjzoo.envs.closed_loop_problem(
        task,
        module,
        config,
        seconds=seconds,
        backend="mjx",
        hyperparams=hyperparams,
        sim_backend=world,
        plan_overrides=plan_physics,
        impl=impl,
        **TASKS[task],
    )
    start = time.perf_counter()
    runs = []
    for seed in range(episodes):
        result, stats = realtime.realtime(problem, jax.random.key(seed), clock=clock)
        solved, score = problem.success(jax.device_get(result.states))
        runs.append({**stats, "success": bool(solved), "score": float(score)})
        print(
            f"  {task} {planner} {samples} seed {seed}: {stats['plan_hz']:.1f} Hz, solved {solved}, score {score:.3g}"
        )
    mean = lambda k: float(np.mean([r[k] for r in runs]))  # noqa: E731
    steps = physics_steps(problem.plan_task, config.horizon_steps, problem.sim_dt)
    return {
        "task": task,
        "planner": planner,
        "num_samples": samples,
        "horizon_s": config.horizon_steps * problem.sim_dt,
        "world": world,
        "impl": impl,
        "clock": clock,
        "plan_physics": plan_physics or {},
        "replan_ms": {"median": mean("plan_latency_ms"), "p95": mean("plan_latency_p95_ms")},
        "physics_steps": steps,
        "ms_per_physics_step": mean("plan_latency_ms") / steps,
        "plan_hz": mean("plan_hz"),
        "success_rate": mean("success"),
        "score": mean("score"),
        "episodes": episodes,
        "seconds_with_compile": time.perf_counter() - start,
        "runs": runs,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=list(TASKS))
    parser.add_argument("--planners", nargs="+", default=list(PLANNERS), choices=list(PLANNERS))
    parser.add_argument("--samples", nargs="+", type=int, default=[256, 1024, 4096])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument(
        "--world",
        choices=["native", "mjx"],
        default=None,
        help="where the simulated world steps (default: C MuJoCo; mjx: on the planner's physics)",
    )
    parser.add_argument(
        "--impl",
        choices=physics.IMPLS,
        default=None,
        help="the planner's physics (default: MuJoCo Warp where installed on a GPU, else MJX-JAX)",
    )
    parser.add_argument(
        "--clock",
        choices=["wall", "simulated"],
        default="wall",
        help="wall: real time (the world waits for no planner); simulated: the world waits for each replan",
    )
    parser.add_argument(
        "--plan-physics",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="the planner's model only, e.g. dt=0.01 iterations=2 ls_iterations=4 (mjzoo.physics.load's options)",
    )
    parser.add_argument("--smoke", action="store_true", help="8 samples, a 4-step horizon, 0.1 s, one episode")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "robot_mpc")
    args = parser.parse_args()
    if args.smoke:
        args.samples, args.episodes = [8], 1
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"robot_mpc_{card_name()}{'_smoke' if args.smoke else ''}.json"
    impl = args.impl or physics.default_impl()
    args.world = args.world or "native"
    try:
        plan_physics = parse_assignments(tuple(args.plan_physics), "--plan-physics")
    except UsageError as e:
        parser.error(str(e))
    not_numbers = [
        f"{k}={v!r}" for k, v in plan_physics.items() if isinstance(v, bool) or not isinstance(v, (int, float))
    ]
    if not_numbers:
        parser.error(f"--plan-physics: {', '.join(not_numbers)} is not NAME=NUMBER (e.g. dt=0.01)")
    rows = []
    for task in args.tasks:
        for planner in args.planners:
            for samples in args.samples:
                rows.append(
                    measure(
                        task, planner, samples, args.episodes, args.smoke, args.world, impl, args.clock, plan_physics
                    )
                )
                meta = {"device": jax.devices()[0].device_kind, "jax": jax.__version__, "smoke": args.smoke}
                path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
