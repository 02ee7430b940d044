"""The CPU planning peer: Judo (PyPI `judo-rai`) planning its own tasks, headless.

Run with Judo's own Python (a separate venv, made by ``benchmarks/judo_env.sh``, since
Judo pins its own mujoco), e.g. as a subprocess of ``benchmarks/planner_cpu.py``:

    .judo/venv/bin/python benchmarks/judo_peer.py --out judo.json \\
        --tasks cartpole cylinder_push --optimizers ps cem mppi --sample-factors 1 4
    .judo/venv/bin/python benchmarks/judo_peer.py --out judo_leap.json --tasks leap_cube \\
        --sample-factors 1 --seconds 120 --leap-meshes MENAGERIE/leap_hand/assets

For each task x optimizer x sample factor, Judo's `Controller` (shipped task overrides,
`num_rollouts` times the factor) closes the loop on Judo's `MJSimulation` (C MuJoCo),
replanning every ``1 / control_freq`` (20 Hz) of *simulated* time, as Judo's simulation
and controller nodes do at real time; the simulation applies the last plan through
Judo's `SplineData` in between. Per row it reports the wall time of one replan
(`Controller.update_action`, which samples knots, rolls out with `mujoco.rollout` and
updates the nominal) after warm-up, the part of it spent inside `mujoco.rollout`, and
the closed-loop success over ``--seeds`` random initial states.

Judo's own default runs `mujoco.rollout` on one thread per rollout; here the pool has
``--threads`` threads (default: physical cores), ``--threads 0`` restores Judo's default.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path
from typing import Any

import judo.tasks.base
import mujoco
import numpy as np
from judo.app.structs import SplineData
from judo.controller import Controller
from judo.controller import ControllerConfig
from judo.optimizers import get_registered_optimizers
from judo.simulation import MJSimulation
from judo.utils.mj_rollout_backend import MJRolloutBackend
from mujoco.rollout import Rollout

# Every Judo task downloads a mesh archive from GitHub on construction; the benchmark runs
# offline instead: cart-pole and push use no meshes, and the LEAP hand's meshes come from
# MuJoCo Menagerie (``--leap-meshes``, the files of the same names). They are visual only in
# Judo's LEAP scene (density 0, no contacts, every body has its own inertial), so Judo's
# physics is unchanged by whichever meshes fill the folder.
judo.tasks.base.download_and_extract_meshes = lambda *args, **kwargs: None
LEAP_MESHES = Path(judo.MODEL_PATH) / "meshes" / "leap"  # where Judo's LEAP scene reads them
LEAP_MESH_FILES = "palm_right base proximal medial distal tip thumb_base thumb_proximal thumb_distal thumb_tip".split()
LEAP_DROP_Z = -0.3  # Judo's LeapCube resets the cube when it falls below this height (m)
GOALS_TO_SOLVE = 10  # mjzoo's leap_cube_rotate: solved at 10 goals before the first drop

WARMUP_REPLANS = 5  # per episode, left out of the latency statistics
LAST_SECONDS = 1.0  # cart-pole's success window at the end of the run
PUSH_TOLERANCES = (0.05, 0.1, 0.3)  # m; 0.3 is Judo's own `CylinderPush.success`


class _TimedRollout:
    """`mujoco.rollout.Rollout` on a fixed thread pool, recording each call's wall time.

    Judo's backend keeps one MjData per rollout; the C pool indexes data by thread, so
    only the first `nthread` of them are handed over.
    """

    def __init__(self, nthread: int) -> None:
        self.inner = Rollout(nthread=nthread)
        self.ndata = max(nthread, 1)
        self.seconds: list[float] = []

    def rollout(self, models: list, datas: list, *args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        out = self.inner.rollout(models, datas[: self.ndata], *args, **kwargs)
        self.seconds.append(time.perf_counter() - start)
        return out

    def close(self) -> None:
        self.inner.close()


def _backend(model: mujoco.MjModel, num_rollouts: int, threads: int) -> MJRolloutBackend:
    """Judo's CPU backend, its pool swapped for a timed one of `threads` threads (0: Judo's)."""
    backend = MJRolloutBackend(model, num_rollouts)
    backend._rollout_obj.close()
    backend._rollout_obj = _TimedRollout(threads or num_rollouts)
    return backend


# The stages of `Controller.update_action` outside `mujoco.rollout`, timed per call.
STAGES = (
    "_pre_optimization",
    "_sample_controls",
    "_post_rollout",
    "_update_iteration",
    "update_traces",
)


def _time_stages(ctrl: Controller) -> dict[str, list[float]]:
    """Wraps the controller's replan stages (on the instance) to record their wall times (s)."""
    seconds: dict[str, list[float]] = {name: [] for name in STAGES}

    def timed(name: str) -> Any:
        method = getattr(ctrl, name)

        def call(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            out = method(*args, **kwargs)
            seconds[name].append(time.perf_counter() - start)
            return out

        return call

    for name in STAGES:
        setattr(ctrl, name, timed(name))
    return seconds


def _controller(task_name: str, optimizer: str, factor: int, threads: int) -> Controller:
    """Judo's controller at the task's shipped overrides, with `factor` x the rollouts."""
    task_cls, _ = judo.tasks.get_registered_tasks()[task_name]
    task = task_cls()
    opt_cls, opt_cfg_cls = get_registered_optimizers()[optimizer]
    opt_cfg = opt_cfg_cls()
    opt_cfg.set_override(task_name)
    opt_cfg.num_rollouts *= factor
    ctrl_cfg = ControllerConfig()
    ctrl_cfg.set_override(task_name)
    backend = _backend(task.model, opt_cfg.num_rollouts, threads)
    return Controller(ctrl_cfg, task, opt_cls(opt_cfg, task.nu), rollout_backend=backend)


def _score(task_name: str, sim: MJSimulation) -> float:
    """Cart-pole: |pole angle from upright| (rad); push: cylinder-to-goal distance (m)."""
    qpos = sim.task.data.qpos
    if task_name == "cartpole":
        return float(abs(np.angle(np.exp(1j * qpos[1]))))
    return float(np.linalg.norm(qpos[2:4] - sim.task.config.goal_pos[:2]))


def fill_leap_meshes(source: Path) -> None:
    """Copies Menagerie's LEAP meshes from `source` into Judo's mesh folder (in Judo's own
    environment) where they are missing; one clear error naming a missing file."""
    LEAP_MESHES.mkdir(parents=True, exist_ok=True)
    for name in LEAP_MESH_FILES:
        target = LEAP_MESHES / f"{name}.obj"
        if not target.exists():
            mesh = source / f"{name}.obj"
            if not mesh.is_file():
                raise SystemExit(f"judo_peer: --leap-meshes {source} has no {name}.obj (Menagerie's leap_hand/assets)")
            shutil.copyfile(mesh, target)


def _count_goals(sim: MJSimulation) -> dict[str, list[float]]:
    """Records, on Judo's LEAP simulation, the times of goals reached and of drops: its
    `post_sim_step` redraws the goal when the cube is within 0.4 rad of it and resets the
    cube (drawing a goal too) when it falls below `LEAP_DROP_Z`."""
    task, events = sim.task, {"goals": [], "drops": []}
    post_sim_step = task.post_sim_step

    def counted() -> None:
        dropped, goal = task.data.qpos[2] < LEAP_DROP_Z, task.goal_quat
        post_sim_step()
        if dropped:
            events["drops"].append(float(task.data.time))
        elif task.goal_quat is not goal:
            events["goals"].append(float(task.data.time))

    task.post_sim_step = counted
    return events


def episode(task_name: str, optimizer: str, factor: int, threads: int, seed: int, seconds: float) -> dict:
    """One closed-loop run from a random initial state (Judo's `Task.reset`, seeded).

    Returns per-replan wall times (s) of the whole replan and of `mujoco.rollout` in it,
    and the score: cart-pole the max |angle| over the last second, push the final distance,
    LEAP cube the goals reached before the cube first drops.
    """
    # Judo samples resets, goals and planner noise from numpy's global RNG.
    np.random.seed(seed)
    sim = MJSimulation(init_task=task_name)
    events = _count_goals(sim) if task_name == "leap_cube" else None
    ctrl = _controller(task_name, optimizer, factor, threads)
    timed: _TimedRollout = ctrl.rollout_backend._rollout_obj
    stages = _time_stages(ctrl)
    period = 1.0 / ctrl.controller_cfg.control_freq
    # The simulation's own step (sim.timestep is the planning model's: the LEAP hand's
    # simulation steps 0.002 s under a planning step of 0.01 s).
    dt = float(sim.task.sim_model.opt.timestep)
    steps = round(seconds / dt)
    next_replan, spline, replan_s, tail = 0.0, None, [], []
    for step in range(steps):
        if sim.task.data.time >= next_replan - 1e-9:
            ctrl.update_states(sim.sim_state)
            start = time.perf_counter()
            ctrl.update_action()
            replan_s.append(time.perf_counter() - start)
            # The plan as Judo's simulation node receives and applies it.
            spline = SplineData(ctrl.times, ctrl.nominal_knots).spline()
            next_replan += period
        sim.step(spline(sim.task.data.time))
        if events is None and (steps - 1 - step) * dt < LAST_SECONDS - 1e-9:
            tail.append(_score(task_name, sim))
    ctrl.rollout_backend._rollout_obj.close()
    out = {"seed": seed, "replan_s": replan_s, "rollout_s": list(timed.seconds), "stages_s": stages}
    if events is not None:  # the goals before the first drop, as mjzoo's leap_cube_rotate counts them
        first_drop = min(events["drops"], default=np.inf)
        return {**out, **events, "score": float(sum(t < first_drop for t in events["goals"]))}
    return {
        **out,
        "score": max(tail) if task_name == "cartpole" else _score(task_name, sim),
        "judo_success": bool(sim.task.success(sim.task.sim_model, sim.task.data)),
    }


def _stats_ms(seconds: list[float]) -> dict[str, float]:
    ms = 1e3 * np.asarray(seconds)
    return {
        "median": float(np.median(ms)),
        "p95": float(np.percentile(ms, 95)),
        "mean": float(ms.mean()),
    }


def settings(task_name: str, optimizer: str, factor: int, threads: int) -> dict:
    """Everything of Judo's shipped configuration that the row relies on."""
    ctrl = _controller(task_name, optimizer, factor, threads)
    ctrl.rollout_backend._rollout_obj.close()
    model, task = ctrl.model, ctrl.task
    return {
        "controller": dataclasses.asdict(ctrl.controller_cfg),
        "optimizer": dataclasses.asdict(ctrl.optimizer_cfg),
        "knot_times_s": ctrl.spline_timesteps.tolist(),
        "horizon_steps": int(ctrl.num_timesteps),
        "sim_timestep_s": float(model.opt.timestep),
        "physics_substeps": task.physics_substeps,
        "actuator_ctrlrange": task.actuator_ctrlrange.tolist(),
        "task_config": {k: np.asarray(v).tolist() for k, v in dataclasses.asdict(task.config).items()},
        "rollout_threads": threads or ctrl.optimizer_cfg.num_rollouts,
        "sim_spline": "zero (SplineData default, as Judo's simulation node)",
    }


def row(
    task_name: str,
    optimizer: str,
    factor: int,
    threads: int,
    seeds: int,
    seconds: float,
) -> dict:
    """Latency and success of one task x optimizer x sample factor over `seeds` episodes."""
    runs = [episode(task_name, optimizer, factor, threads, s, seconds) for s in range(seeds)]
    replan = [t for r in runs for t in r["replan_s"][WARMUP_REPLANS:]]
    rollout = [t for r in runs for t in r["rollout_s"][WARMUP_REPLANS:]]
    overhead = [a - b for r in runs for a, b in zip(r["replan_s"][WARMUP_REPLANS:], r["rollout_s"][WARMUP_REPLANS:])]
    scores = np.array([r["score"] for r in runs])
    stages = {k: [t for r in runs for t in r["stages_s"][k][WARMUP_REPLANS:]] for k in STAGES}
    # The rest: Judo's backend around the C call (tiling x0, copying outputs), loop glue.
    stages["other"] = list(np.array(overhead) - np.sum([stages[k] for k in STAGES], 0))
    out = {
        "task": task_name,
        "optimizer": optimizer,
        "sample_factor": factor,
        "settings": settings(task_name, optimizer, factor, threads),
        "replans_timed": len(replan),
        "replan_ms": _stats_ms(replan),
        "rollout_ms": _stats_ms(rollout),
        "overhead_ms": _stats_ms(overhead),
        "overhead_stages_ms": {k: _stats_ms(v) for k, v in stages.items()},
        "scores": scores.tolist(),
        "mean_score": float(scores.mean()),
    }
    out["num_rollouts"] = out["settings"]["optimizer"]["num_rollouts"]
    if task_name == "leap_cube":
        out["success_rate"] = float(np.mean(scores >= GOALS_TO_SOLVE))
        out["goals"] = [len(r["goals"]) for r in runs]
        out["drops"] = [len(r["drops"]) for r in runs]
        out["score_meaning"] = f"goals reached before the cube first drops; success >= {GOALS_TO_SOLVE}"
        return out
    out["judo_success_rate"] = float(np.mean([r["judo_success"] for r in runs]))
    if task_name == "cartpole":
        out["success_rate"] = float(np.mean(scores < 0.2))
        out["score_meaning"] = "max |pole angle from upright| (rad) over the last 1 s; success < 0.2"
    else:
        for tol in PUSH_TOLERANCES:
            out[f"success_rate_{tol}"] = float(np.mean(scores < tol))
        out["success_rate"] = out["success_rate_0.05"]
        out["score_meaning"] = "final cylinder-to-goal distance (m); success < 0.05 (also 0.1, and 0.3 as Judo's own)"
    return out


def _physical_cores() -> int:
    try:
        lines = subprocess.run(["lscpu", "-p=core,socket"], capture_output=True, text=True, check=True).stdout
        return len({ln for ln in lines.splitlines() if ln and not ln.startswith("#")})
    except (OSError, subprocess.CalledProcessError):
        return os.cpu_count() or 1


def _cpu_model() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        return next(ln.split(":", 1)[1].strip() for ln in out.splitlines() if ln.startswith("Model name"))
    except (OSError, subprocess.CalledProcessError, StopIteration):
        return platform.processor()


def _loadavg() -> str:
    return Path("/proc/loadavg").read_text().strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--tasks", nargs="+", default=["cartpole", "cylinder_push"])
    parser.add_argument("--optimizers", nargs="+", default=["ps", "cem", "mppi"])
    parser.add_argument("--sample-factors", nargs="+", type=int, default=[1, 4])
    parser.add_argument("--seconds", type=float, default=8.0, help="simulated seconds per episode")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument(
        "--leap-meshes",
        type=Path,
        default=None,
        help="Menagerie's leap_hand/assets folder: fills Judo's LEAP mesh folder offline (leap_cube)",
    )
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="rollout threads; 0: Judo's (one per rollout)",
    )
    args = parser.parse_args()
    threads = _physical_cores() if args.threads is None else args.threads
    if "leap_cube" in args.tasks:
        if args.leap_meshes is None and not LEAP_MESHES.is_dir():
            parser.error("leap_cube needs --leap-meshes (Menagerie's leap_hand/assets): Judo's own are online")
        if args.leap_meshes is not None:
            fill_leap_meshes(args.leap_meshes)

    load_before = _loadavg()
    rows = []
    for task_name in args.tasks:
        for optimizer in args.optimizers:
            for factor in args.sample_factors:
                load = _loadavg()
                rows.append(row(task_name, optimizer, factor, threads, args.seeds, args.seconds))
                rows[-1]["loadavg_before_after"] = [load, _loadavg()]
                r = rows[-1]
                print(
                    f"{task_name} {optimizer} x{factor}: {r['replan_ms']['median']:.2f} ms",
                    file=sys.stderr,
                )
    result = {
        "peer": "judo",
        "judo_version": metadata.version("judo-rai"),
        "mujoco_version": mujoco.__version__,
        "numpy_version": np.__version__,
        "python": platform.python_version(),
        "cpu_model": _cpu_model(),
        "cpus": os.cpu_count(),
        "physical_cores": _physical_cores(),
        "rollout_threads": threads or "judo default (one per rollout)",
        "judo_default_threads": "num_rollouts (MJRolloutBackend: Rollout(nthread=num_rollouts))",
        "seconds": args.seconds,
        "seeds": args.seeds,
        "replan_period_s": "1 / control_freq of simulated time (first sim step at or after each tick)",
        "warmup_replans_per_episode": WARMUP_REPLANS,
        "latency": "wall time of Controller.update_action (perf_counter), closed loop, after warm-up",
        "overhead": "replan minus the mujoco.rollout call inside it (sampling, splines, rewards, update, traces)",
        "loadavg_before": load_before,
        "loadavg_after": _loadavg(),
        "rows": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(
        f"{'task':14} {'opt':5} {'K':>4} {'replan ms med/p95':>18} {'rollout ms':>10} {'overhead ms':>11} "
        f"{'success':>7} {'score':>7}"
    )
    for r in rows:
        print(
            f"{r['task']:14} {r['optimizer']:5} {r['num_rollouts']:4d} "
            f"{r['replan_ms']['median']:8.2f} / {r['replan_ms']['p95']:7.2f} {r['rollout_ms']['median']:10.2f} "
            f"{r['overhead_ms']['median']:11.2f} {r['success_rate']:7.2f} {r['mean_score']:7.3f}"
        )


if __name__ == "__main__":
    main()
