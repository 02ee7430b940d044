"""Running a sampling planner closed loop, offline (one jit) or in real time, and the
files a run writes (what `mjzoo plan` does).

Real time: the simulation advances with the wall clock while the planner replans at a
target rate. The world does not wait for the planner: the simulation steps that fall due
while a replan computes run under the previous plan, as on a robot; then the new plan
takes over until the next replan tick. Reported: the achieved planning rate, the
latency of each replan, and the real-time factor (simulated / wall seconds).

    out/summary.json   success, score, final_cost, plan_hz, plan_latency_ms, ...
    out/plan.png       cost and controls over time
    out/plan.mp4       the run (where an OpenGL backend exists)
"""

from __future__ import annotations

import dataclasses
import functools
import json
import time
from pathlib import Path
from types import ModuleType
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo import closed_loop, rendering
from mjzoo.closed_loop import Hooks, Result
from mjzoo.planning import Ensemble, SamplingConfig
from mjzoo.running import complete, reset
from mjzoo.types import Task

__all__ = ["Setup", "for_env", "control_dt", "offline", "realtime", "write"]


@dataclasses.dataclass(frozen=True)
class Setup:
    """One closed-loop problem: who plans, on what, against which world, for how long."""

    planner: ModuleType
    config: SamplingConfig
    sim_task: Task
    plan_task: Task | Ensemble
    seconds: float
    replan_every: int = 1
    hooks: Hooks = Hooks()
    success: Callable[[Any], tuple[bool, float]] | None = None

    @functools.cached_property
    def sim_dt(self) -> float:
        """The simulation's control step (s), measured from one transition."""
        return control_dt(self.sim_task)

    @property
    def num_replans(self) -> int:
        return max(1, round(self.seconds / (self.sim_dt * self.replan_every)))


def for_env(name: str, planner: ModuleType, config: SamplingConfig, seconds: float | None = None) -> Setup:
    """The registered env `name`'s documented closed-loop problem (`mjzoo.envs.planning`):
    the env as the world, its planning view as the model, its hooks and success test."""
    import mjzoo.envs

    env = mjzoo.envs.planning(name)
    return Setup(
        planner=planner, config=config, sim_task=mjzoo.envs.make(name, episode_steps=10**9),
        plan_task=env.plan_task(functools.partial(mjzoo.envs.make, name), episode_steps=10**9),
        seconds=seconds or env.seconds, replan_every=env.replan_every, hooks=env.hooks, success=env.success,
    )  # fmt: skip


def control_dt(task: Task) -> float:
    """A task's control step (s), measured from one transition from a reset."""
    state = reset(task, jax.random.key(0))
    after = jax.jit(lambda s: task.step(task.model, s, jnp.zeros(task.action_size), jax.random.key(0)))(state)
    return float(after.data.time - state.data.time)


def offline(
    setup: Setup, key: jax.Array, compiler_options: dict[str, Any] | None = None
) -> tuple[Result, dict[str, float]]:
    """The whole run as one jitted `lax.scan` (`closed_loop.run`). Timing excludes the
    compile; the per-replan latency includes the simulation steps in between.
    `compiler_options` go to XLA for this compile only (e.g. to undo a global
    ``--xla_backend_optimization_level=0`` for a long run)."""
    reset_key, run_key = jax.random.split(key)
    sim_state = reset(setup.sim_task, reset_key)
    args = (setup.planner, setup.config, setup.sim_task, setup.plan_task, sim_state, run_key,
            setup.num_replans, setup.replan_every, setup.hooks)  # fmt: skip
    start = time.perf_counter()
    compiled = closed_loop.run.lower(*args).compile(compiler_options)
    compile_s = time.perf_counter() - start
    start = time.perf_counter()
    result = jax.block_until_ready(compiled(*args[2:6], args[8]))
    wall = time.perf_counter() - start
    return result, {"plan_hz": setup.num_replans / wall, "plan_latency_ms": 1e3 * wall / setup.num_replans,
                    "realtime_factor": setup.seconds / wall, "compile_s": compile_s}  # fmt: skip


def realtime(setup: Setup, key: jax.Array, plan_hz: float | None = None) -> tuple[Result, dict[str, float]]:
    """Simulates `setup.seconds` of wall-clock time, replanning at `plan_hz` (default:
    every `replan_every` simulation steps' worth of time) or as fast as planning allows."""
    planner, config, hooks = setup.planner, setup.config, setup.hooks
    sim_dt = setup.sim_dt
    period = 1.0 / plan_hz if plan_hz else sim_dt * setup.replan_every
    total_steps = round(setup.seconds / sim_dt)
    reset_key, plan_key, key = jax.random.split(key, 3)
    # Committed to the device like every jit output, so the loop's calls match the warm-up compile.
    sim_state = jax.device_put(complete(setup.sim_task, reset(setup.sim_task, reset_key)), jax.devices()[0])
    first = jax.jit(lambda s: closed_loop.first_plan(planner, config, setup.plan_task, s, hooks))
    replan = jax.jit(lambda p, s, k: closed_loop.replan(planner, config, setup.plan_task, p, s, k, hooks))
    step = jax.jit(lambda p, s, k: closed_loop.sim_step(config, setup.sim_task, p, s, k, hooks))
    planner_state = first(sim_state)
    # Compile before the clock starts, for the first state and for states the loop makes
    # (their leaves can differ in weak type from a reset's, which would recompile mid-run).
    later_plan = replan(planner_state, sim_state, key)
    later_state, _ = step(later_plan, sim_state, key)
    jax.block_until_ready((replan(later_plan, later_state, key), step(later_plan, later_state, key)))

    states, controls, plan_costs, latencies = [], [], [], []
    begin = time.perf_counter()

    def advance_until(wall: float, plan) -> None:
        nonlocal sim_state
        due = min(total_steps, int((wall - begin) / sim_dt))
        while len(states) < due:
            sim_state, control = step(plan, sim_state, jax.random.fold_in(key, len(states)))
            states.append(sim_state)
            controls.append(control)

    while len(states) < total_steps:
        tick = time.perf_counter()
        new_plan = jax.block_until_ready(replan(planner_state, sim_state, jax.random.fold_in(plan_key, len(latencies))))
        latencies.append(time.perf_counter() - tick)
        advance_until(time.perf_counter(), planner_state)  # the world did not wait
        planner_state = new_plan
        plan_costs.append(planner_state.cost)
        advance_until(tick + period, planner_state)
        time.sleep(max(0.0, tick + period - time.perf_counter()))
    wall = time.perf_counter() - begin
    stacked = jax.tree.map(lambda *xs: jnp.stack(xs), *states)
    result = Result(stacked, jnp.stack(controls), -stacked.reward, jnp.stack(plan_costs), planner_state)
    return result, {"plan_hz": len(latencies) / wall, "plan_latency_ms": 1e3 * float(np.median(latencies)),
                    "plan_latency_p95_ms": 1e3 * float(np.percentile(latencies, 95)),
                    "realtime_factor": total_steps * sim_dt / wall}  # fmt: skip


def write(out: Path, setup: Setup, result: Result, stats: dict[str, float], video: bool = True, **extra: Any) -> dict:
    """Writes summary.json, plan.png and (where GL exists) plan.mp4 to `out`; returns the summary.

    final_cost is the mean per-step cost (-reward) over the last second of the run."""
    out.mkdir(parents=True, exist_ok=True)
    states = jax.device_get(result.states)
    time_s = np.asarray(states.data.time)
    costs, controls = np.asarray(result.costs), np.asarray(result.controls)
    solved, score = setup.success(states) if setup.success else (None, None)
    summary = {**extra, "success": solved, "score": score,
               "final_cost": float(np.mean(costs[time_s >= time_s[-1] - 1.0 + 1e-6])),
               **{k: float(v) for k, v in stats.items()}}  # fmt: skip
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    _plot(out / "plan.png", time_s, costs, controls, setup.sim_task)
    if video:
        mj = setup.sim_task.mj_model
        rendering.render_video(mj, np.asarray(states.data.qpos), out / "plan.mp4", 1.0 / setup.sim_dt,
                               mocap_pos=np.asarray(states.data.mocap_pos), mocap_quat=np.asarray(states.data.mocap_quat),
                               camera=0 if mj.ncam else None)  # fmt: skip
    return summary


def _plot(path: Path, time_s: np.ndarray, costs: np.ndarray, controls: np.ndarray, task: Task) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
    top.plot(time_s, costs)
    top.set_ylabel("cost per step (-reward)")
    for i in range(controls.shape[1]):
        bottom.plot(time_s, controls[:, i], label=task.mj_model.actuator(i).name or f"u{i}")
    bottom.set_ylabel("control")
    bottom.set_xlabel("time (s)")
    bottom.legend(loc="upper right", fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
