"""Timed closed-loop runs of a sampling planner: in real time, or offline as one jit.

Real time: the simulation advances with the wall clock while the planner replans at a
target rate. The world does not wait for the planner: the simulation steps that fall due
while a replan computes run under the previous plan, as on a robot; then the new plan
takes over until the next replan tick. Reported: the achieved planning rate, the
latency of each replan, and the real-time factor (simulated / wall seconds). Offline:
the same problem as one jitted `lax.scan` (`closed_loop.run`), timed without its compile.
A problem's `terminal_value` (a critic, `mjzoo.planning.learned`) reaches every replan
as an argument of the jitted functions, its weights never baked in as constants.

    problem = Problem(mppi, config, sim_task, plan_task, seconds=6.0)
    result, stats = realtime(problem, key)        # stats: plan_hz, plan_latency_ms, ...
    result, stats = offline(problem, key)

`mjzoo.envs.closed_loop_problem(name, ...)` gives each env's tested problem, and
`mjzoo.harness.plan_report.write` the files `mjzoo plan` writes.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from types import ModuleType
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo.planning import closed_loop
from mjzoo.planning.closed_loop import Hooks, Result
from mjzoo.planning.learned import TerminalValue, as_terminal_value, committed
from mjzoo.planning.rollouts import Ensemble
from mjzoo.planning.sampling import SamplingConfig
from mjzoo.running import control_dt, reset
from mjzoo.types import Task

__all__ = ["Problem", "offline", "realtime"]


@dataclasses.dataclass(frozen=True)
class Problem:
    """One closed-loop problem: who plans, on what, against which world, for how long.

    Attributes:
      planner: the planner module (`mjzoo.algorithms.mppi`, `cem`, `predictive_sampling`).
      config: its `Config`.
      sim_task: the simulated world.
      plan_task: the planner's model of it (a `Task` or an `Ensemble`).
      seconds: simulated time to run.
      replan_every: simulation control steps per replan.
      hooks: the task's planner hooks (`closed_loop.Hooks`).
      success: optional ``states -> (solved, score)`` over the run's states [T].
      terminal_value: optional ``(model, state) -> value`` of each rollout's final
        state (a plain function is wrapped: `mjzoo.planning.as_terminal_value`).
    """

    planner: ModuleType
    config: SamplingConfig
    sim_task: Task
    plan_task: Task | Ensemble
    seconds: float
    replan_every: int = 1
    hooks: Hooks = Hooks()
    success: Callable[[Any], tuple[bool, float]] | None = None
    terminal_value: TerminalValue | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "terminal_value", as_terminal_value(self.terminal_value))

    @functools.cached_property
    def sim_dt(self) -> float:
        """The simulation's control step (s), measured from one transition."""
        return control_dt(self.sim_task)

    @property
    def num_replans(self) -> int:
        return max(1, round(self.seconds / (self.sim_dt * self.replan_every)))


def offline(
    problem: Problem, key: jax.Array, compiler_options: dict[str, Any] | None = None
) -> tuple[Result, dict[str, float]]:
    """The whole run as one jitted `lax.scan` (`closed_loop.run`). Timing excludes the
    compile; the per-replan latency includes the simulation steps in between.
    `compiler_options` go to XLA for this compile only (e.g. to undo a global
    ``--xla_backend_optimization_level=0`` for a long run)."""
    reset_key, run_key = jax.random.split(key)
    sim_state = reset(problem.sim_task, reset_key)
    static = (problem.planner, problem.config)
    counts = (problem.num_replans, problem.replan_every)
    dynamic = (problem.sim_task, problem.plan_task, sim_state, run_key)
    functions = (problem.hooks, problem.terminal_value)
    start = time.perf_counter()
    compiled = closed_loop.run.lower(*static, *dynamic, *counts, *functions).compile(compiler_options)
    compile_s = time.perf_counter() - start
    start = time.perf_counter()
    result = jax.block_until_ready(compiled(*dynamic, *functions))
    wall = time.perf_counter() - start
    return result, {"plan_hz": problem.num_replans / wall, "plan_latency_ms": 1e3 * wall / problem.num_replans,
                    "realtime_factor": problem.seconds / wall, "compile_s": compile_s}  # fmt: skip


def realtime(problem: Problem, key: jax.Array, plan_hz: float | None = None) -> tuple[Result, dict[str, float]]:
    """Simulates `problem.seconds` of wall-clock time, replanning at `plan_hz` (default:
    every `replan_every` simulation steps' worth of time) or as fast as planning allows."""
    planner, config, hooks, value = problem.planner, problem.config, problem.hooks, problem.terminal_value
    sim_dt = problem.sim_dt
    period = 1.0 / plan_hz if plan_hz else sim_dt * problem.replan_every
    total_steps = round(problem.seconds / sim_dt)
    reset_key, plan_key, key = jax.random.split(key, 3)
    # Committed to the device like every jit output, so the loop's calls match the warm-up compile.
    sim_state = committed(reset(problem.sim_task, reset_key))
    first = jax.jit(lambda s: closed_loop.first_plan(planner, config, problem.plan_task, s, hooks))
    replan = jax.jit(lambda p, s, k, v: closed_loop.replan(planner, config, problem.plan_task, p, s, k, hooks, v))
    step = jax.jit(lambda p, s, k: closed_loop.sim_step(config, problem.sim_task, p, s, k, hooks))
    planner_state = first(sim_state)
    # Compile before the clock starts, for the first state and for states the loop makes
    # (their leaves can differ in weak type from a reset's, which would recompile mid-run).
    later_plan = replan(planner_state, sim_state, key, value)
    later_state, _ = step(later_plan, sim_state, key)
    jax.block_until_ready((replan(later_plan, later_state, key, value), step(later_plan, later_state, key)))

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
        replan_key = jax.random.fold_in(plan_key, len(latencies))
        new_plan = jax.block_until_ready(replan(planner_state, sim_state, replan_key, value))
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
