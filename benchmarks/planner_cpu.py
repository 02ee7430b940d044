"""Sampling MPC on a CPU, side by side with Judo: replan latency and closed-loop success.

For cart-pole and cylinder push, predictive sampling, CEM and MPPI plan at Judo's shipped
settings (32 rollouts, 4 knots, a 1 s horizon of 25 steps of 0.04 s for the cart-pole
and 50 of 0.02 s for the push, replanning at 20 Hz) and at 4x the rollouts; DIAL and
CMA-ES plan at the same settings (Judo has neither), iLQR over the same horizon on MJX
alone (it differentiates JAX physics; its row has no sample count). mjzoo runs its
real-time runner (`mjzoo.planning.realtime`, as `mjzoo plan` does) on each backend:
native (C MuJoCo through `mujoco.rollout`) and MJX on the CPU; the planning model takes
Judo's time step, the simulation is the env's own. Judo (PyPI `judo-rai`, in its own
environment: ``bash benchmarks/judo_env.sh``) runs its own tasks in the same run, through
``benchmarks/judo_peer.py``, with the same number of rollout threads. ``--tasks leap_cube``
adds the LEAP hand turning a cube to goal orientations (Judo's flagship) at Judo's
shipped LEAP settings, which are the env's registered ones (1 s of 20 control steps on
the task's own model), beside Judo on its own LEAP task, which runs offline with
Menagerie's LEAP meshes in place of the ones it downloads (they are visual only there).
Each peer plans on its own scene: Judo's (elliptic cones, 100 Newton iterations, the
cube's pips as collision geoms) and mjzoo's (Playground's LEAP scene and solver settings).

Per row: replan latency (median, p95), the part spent in C MuJoCo's rollouts (native and
Judo), the rest (the fixed overhead of a replan), the achieved rate and the closed-loop
success over seeds (cart-pole: within 0.2 rad of upright over the last second; push:
cylinder within 0.05 m of its goal at the end). By default both peers replan every
0.05 s of *simulated* time in a busy loop (``--clock simulated``, as judo_peer.py runs
Judo); ``--clock wall`` runs mjzoo's real-time runner against the wall clock instead:
the simulation runs at wall-clock rate and waits for no planner, so a slow replan acts
late (its sleeps between replans leave the CPU to cool: measured, the same replan then
takes ~1.5x longer).

    python benchmarks/planner_cpu.py                       # everything, ~25 minutes
    python benchmarks/planner_cpu.py --tasks cartpole --planners mppi --backends native --no-judo
    python benchmarks/planner_cpu.py --clock wall --planners mppi dial cma_es --no-judo --seeds 3 \
        --out benchmarks/results/planner_cpu/planner_cpu_wall.json
    python benchmarks/planner_cpu.py --clock wall --planners dial --backends native --no-judo --seeds 3 \
        --out benchmarks/results/planner_cpu/planner_cpu_wall_dial_native.json
    python benchmarks/planner_cpu.py --clock wall --tasks cartpole cylinder_push --planners ilqr --backends mjx \
        --no-judo --seeds 3 --out benchmarks/results/planner_cpu/planner_cpu_wall_ilqr.json
    python benchmarks/planner_cpu.py --tasks leap_cube --planners ps mppi cem --backends native --no-judo \
        --sample-factors 1 --seeds 5 --seconds 120 --clock wall \
        --out benchmarks/results/planner_cpu/planner_cpu_leap_wall_120s.json   # 40 s: ..._leap_wall.json
    python benchmarks/planner_cpu.py --tasks leap_cube --planners mppi --backends native --sample-factors 1 \
        --seeds 3 --seconds 120 --out benchmarks/results/planner_cpu/planner_cpu_leap_judo.json
    python benchmarks/planner_cpu.py --tasks cartpole --backends native --no-judo --seeds 6 --clock wall \
        --planners ps mppi cem --sample-factors 1 --config noise_scale=0.1 noise_ramp=2 \
        --out benchmarks/results/planner_cpu/planner_cpu_cartpole_wall.json

``--config NAME=VALUE`` sets planner fields after Judo's settings (each for the planners
that have it); a row records them under "overrides".
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

import mjzoo
import mjzoo.envs
from mjzoo.algorithms import cem
from mjzoo.algorithms import cma_es
from mjzoo.algorithms import dial
from mjzoo.algorithms import ilqr
from mjzoo.algorithms import mppi
from mjzoo.algorithms import predictive_sampling
from mjzoo.harness.cli import arguments
from mjzoo.planning import native
from mjzoo.planning import realtime
from mjzoo.robots import models

ROOT = Path(__file__).resolve().parent.parent
PLANNERS = {"ps": predictive_sampling, "cem": cem, "mppi": mppi, "dial": dial, "cma_es": cma_es, "ilqr": ilqr}
JUDO_PLANNERS = ("ps", "cem", "mppi")  # the optimizers Judo ships, run beside ours
GRADIENT = ("ilqr",)  # planners on MJX's derivatives: no samples, no knots, no native backend
# Judo's shipped settings per task: its horizon in planning steps of its time step (None:
# the planning model keeps the task's own steps, the LEAP hand's 0.01 s physics under 0.05 s
# control; its noise and ramp are the env's registered ones, Judo's).
TASKS = {
    "cartpole": dict(env="cartpole_swingup", plan_dt=0.04, horizon_steps=25),
    "cylinder_push": dict(env="cylinder_push", plan_dt=0.02, horizon_steps=50),
    "leap_cube": dict(env="leap_cube_rotate", plan_dt=None, horizon_steps=20),
}
DEFAULT_TASKS = ("cartpole", "cylinder_push")  # leap_cube on request: its runs are long
JUDO_ROLLOUTS, JUDO_KNOTS, RATE_HZ = 32, 4, 20.0


def problem(
    task: str, planner: str, samples: int, backend: str, seconds: float, overrides: dict | None = None
) -> realtime.Problem:
    """The env's closed-loop problem, planned at Judo's settings on `backend`, with the
    planner's fields in `overrides` (those it has) set last."""
    spec = TASKS[task]
    setup = mjzoo.envs.planning(spec["env"])
    module = PLANNERS[planner]
    fields = mjzoo.envs.hyperparameters(spec["env"], module.__name__.rsplit(".", 1)[-1])
    fields["horizon_steps"] = spec["horizon_steps"]
    if planner not in GRADIENT:
        fields.update(num_samples=samples, num_knots=JUDO_KNOTS)
    if "num_elites" in fields:
        fields["num_elites"] = max(2, samples // 8)
    fields.update(_planner_fields(module, overrides or {}))
    steps = {"dt": spec["plan_dt"], "ctrl_dt": spec["plan_dt"]} if spec["plan_dt"] else {}
    env_overrides = {**setup.plan_overrides, **steps, "episode_steps": 10**9}
    plan_task = mjzoo.envs.make(spec["env"], **env_overrides)
    plan_task = setup.plan_view(plan_task) if setup.plan_view else plan_task
    sim_task = mjzoo.envs.make(spec["env"], episode_steps=10**9)
    config, hyperparams = mjzoo.planning.configure(module, fields)
    return realtime.Problem(
        module,
        config,
        sim_task,
        plan_task,
        seconds=seconds,
        replan_every=setup.replan_every,
        hooks=setup.hooks,
        success=setup.success,
        backend=backend,
        hyperparams=hyperparams,
    )


def _planner_fields(module, overrides: dict) -> dict:
    """The entries of `overrides` that are fields of the planner `module`'s Config or Hyperparams."""
    owned = {f.name for cls in (module.Config, module.Hyperparams) for f in dataclasses.fields(cls)}
    return {k: v for k, v in overrides.items() if k in owned}


def measure(
    task: str, planner: str, samples: int, backend: str, seconds: float, seeds: int, clock: str, overrides: dict
) -> dict:
    runs = []
    p = problem(task, planner, samples, backend, seconds, overrides)
    build = time.perf_counter()
    p.tasks  # noqa: B018 (native: builds and checks the C side)
    build = time.perf_counter() - build
    for seed in range(seeds):
        result, stats = realtime.realtime(p, jax.random.key(seed), plan_hz=RATE_HZ, clock=clock)
        solved, score = p.success(jax.device_get(result.states))
        runs.append({**stats, "success": bool(solved), "score": float(score)})
    mean = lambda k: float(np.mean([r[k] for r in runs]))  # noqa: E731
    row = {
        "task": task,
        "planner": planner,
        "num_samples": samples,
        "backend": backend,
        "peer": "mjzoo",
        "replan_ms": {"median": mean("plan_latency_ms"), "p95": mean("plan_latency_p95_ms")},
        "plan_hz": mean("plan_hz"),
        "sim_step_ms": mean("sim_step_ms"),
        "success_rate": mean("success"),
        "score": mean("score"),
        "seeds": seeds,
        "clock": clock,
        "overrides": _planner_fields(PLANNERS[planner], overrides),
        "setup_s": build,
        "runs": runs,
    }
    if backend == "native":
        row["rollout_ms"] = {"median": mean("plan_physics_ms")}
        row["overhead_ms"] = {"median": row["replan_ms"]["median"] - row["rollout_ms"]["median"]}
    return row


def judo(args, out: Path) -> dict | None:
    python = Path(args.judo_python)
    if not python.exists():
        print(f"judo: {python} not found (bash benchmarks/judo_env.sh makes it); Judo's rows are left out")
        return None
    command = [
        str(python),
        str(ROOT / "benchmarks" / "judo_peer.py"),
        "--out",
        str(out),
        "--tasks",
        *args.tasks,
        "--optimizers",
        *[p for p in args.planners if p in JUDO_PLANNERS],
        "--sample-factors",
        *map(str, args.sample_factors),
        "--seconds",
        str(args.seconds),
        "--seeds",
        str(args.seeds),
        "--threads",
        str(args.threads),
    ]
    if "leap_cube" in args.tasks:  # Judo's LEAP scene reads its (visual) meshes from Menagerie's offline
        command += ["--leap-meshes", str(models.menagerie("leap_hand", download=False) / "assets")]
    subprocess.run(command, check=True, env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    return json.loads(out.read_text())


def _numbers(items: list[str], parser: argparse.ArgumentParser) -> dict[str, int | float]:
    """{"noise_ramp": 2} from ["noise_ramp=2"] (the CLI's reader; ints stay ints), or one
    line of error where a value is not a number."""
    try:
        fields = arguments.parse_assignments(tuple(items), "--config")
    except arguments.UsageError as error:
        parser.error(str(error))
    for name, value in fields.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            parser.error(f"--config {name}={value!r}: expected NAME=NUMBER")
    return fields


def table(rows: list[dict]) -> str:
    lines = [
        "| task | planner | K | backend | replan ms (median / p95) | C rollouts ms | overhead ms | Hz | success |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        rollout = r.get("rollout_ms", {}).get("median")
        overhead = r.get("overhead_ms", {}).get("median")
        fmt = lambda x: "" if x is None else f"{x:.2f}"  # noqa: E731
        lines.append(
            f"| {r['task']} | {r['planner']} | {r['num_samples']} | {r['backend']} | "
            f"{r['replan_ms']['median']:.2f} / {r['replan_ms']['p95']:.2f} | {fmt(rollout)} | {fmt(overhead)} | "
            f"{fmt(r.get('plan_hz'))} | {r['success_rate']:.2f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=list(DEFAULT_TASKS), choices=list(TASKS))
    parser.add_argument("--planners", nargs="+", default=list(PLANNERS), choices=list(PLANNERS))
    parser.add_argument("--sample-factors", nargs="+", type=int, default=[1, 4])
    parser.add_argument("--backends", nargs="+", default=["native", "mjx"], choices=["native", "mjx"])
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument(
        "--clock",
        default="simulated",
        choices=["simulated", "wall"],
        help="simulated: replan every 0.05 s of simulated time with no sleeping, as judo_peer.py "
        "does (the like-for-like latency); wall: mjzoo plan's real-time runner",
    )
    parser.add_argument(
        "--config",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="planner fields set after Judo's settings, each for the planners that have it "
        "(e.g. noise_scale=0.1 noise_ramp=2)",
    )
    parser.add_argument("--threads", type=int, default=native.physical_cores())
    parser.add_argument("--judo-python", default=str(ROOT / ".judo" / "venv" / "bin" / "python"))
    parser.add_argument("--no-judo", action="store_true")
    parser.add_argument(
        "--out", type=Path, default=ROOT / "benchmarks" / "results" / "planner_cpu" / "planner_cpu.json"
    )
    args = parser.parse_args()
    overrides = _numbers(args.config, parser)
    load = [os.getloadavg()]
    rows = []
    for task in args.tasks:
        for planner in args.planners:
            gradient = planner in GRADIENT
            for factor in [1] if gradient else args.sample_factors:
                for backend in [b for b in args.backends if not (gradient and b == "native")]:
                    samples = 0 if gradient else JUDO_ROLLOUTS * factor
                    row = measure(task, planner, samples, backend, args.seconds, args.seeds, args.clock, overrides)
                    rows.append(row)
                    print(table([row]).splitlines()[-1], flush=True)
                    save(args, rows, [], load + [os.getloadavg()])  # a run stopped midway keeps its rows
    judo_rows = []
    if not args.no_judo:
        with tempfile.TemporaryDirectory() as tmp:
            peer = judo(args, Path(tmp) / "judo.json")
        for r in (peer or {}).get("rows", []):
            judo_rows.append(
                {
                    "task": r["task"],
                    "planner": r["optimizer"],
                    "num_samples": r["settings"]["optimizer"]["num_rollouts"],
                    "backend": "judo",
                    "peer": "judo",
                    "replan_ms": r["replan_ms"],
                    "rollout_ms": r["rollout_ms"],
                    "overhead_ms": r["overhead_ms"],
                    "plan_hz": None,
                    "success_rate": r["success_rate"],
                    "score": r.get("mean_score"),
                    "seeds": len(r.get("scores", [])),
                    **{k: r[k] for k in ("goals", "drops", "scores") if k in r},
                }
            )
    load.append(os.getloadavg())
    ratios = save(args, rows, judo_rows, load)
    print(table(sorted(rows + judo_rows, key=lambda r: (r["task"], r["planner"], r["num_samples"], r["backend"]))))
    print("native / judo replan latency:", json.dumps({k: round(v, 2) for k, v in ratios.items()}))
    print(f"wrote {args.out}")


def save(args: argparse.Namespace, rows: list[dict], judo_rows: list[dict], load: list) -> dict[str, float]:
    """Writes the run's JSON to ``args.out``; returns native/Judo replan-latency ratios."""
    ratios = {}
    for r in rows:
        peer = [
            j
            for j in judo_rows
            if (j["task"], j["planner"], j["num_samples"]) == (r["task"], r["planner"], r["num_samples"])
        ]
        if peer and r["backend"] == "native":
            ratios[f"{r['task']}/{r['planner']}/{r['num_samples']}"] = (
                r["replan_ms"]["median"] / peer[0]["replan_ms"]["median"]
            )
    result = {
        "machine": {
            "cpu": platform.processor() or platform.machine(),
            "cores": os.cpu_count(),
            "physical_cores": native.physical_cores(),
            "loadavg_before_after": load,
        },
        "rollout_threads": args.threads,
        "seconds": args.seconds,
        "rate_hz": RATE_HZ,
        "native_over_judo_latency": ratios,
        "command": shlex.join(["python", *sys.argv]),
        "rows": rows + judo_rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    return ratios


if __name__ == "__main__":
    sys.exit(main())
