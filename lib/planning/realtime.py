"""Timed closed-loop runs of a sampling planner: in real time, or offline as one jit.

Real time: the simulation advances with the wall clock while the planner replans at a
target rate. The world does not wait for the planner: the simulation steps that fall due
while a replan computes run under the previous plan, as on a robot; then the new plan
takes over until the next replan tick. Reported: the achieved planning rate, the
latency of each replan, and the real-time factor (simulated / wall seconds). Offline:
the same problem as one jitted `lax.scan` (`closed_loop.run`), timed without its compile.
A problem's `terminal_value` (a critic, `mjzoo.planning.learned`) reaches every replan
as an argument of the jitted functions, its weights never baked in as constants.

    problem = Problem(mppi, config, sim_task, plan_task, seconds=6.0, hyperparams=mppi.Hyperparams())
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
from typing import Any
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo.physics import switch_impl
from mjzoo.planning import closed_loop
from mjzoo.planning.closed_loop import Hooks
from mjzoo.planning.closed_loop import Result
from mjzoo.planning.ensembles import Ensemble
from mjzoo.planning.ensembles import base_task
from mjzoo.planning.learned import TerminalValue
from mjzoo.planning.learned import as_terminal_value
from mjzoo.planning.learned import committed
from mjzoo.planning.native import Native
from mjzoo.planning.native import split as native_split
from mjzoo.planning.native import wrap as native_wrap
from mjzoo.planning.sampling import SamplingConfig
from mjzoo.running import control_dt
from mjzoo.running import reset
from mjzoo.tree import Packing
from mjzoo.types import Task

__all__ = ["Problem", "offline", "realtime", "BACKENDS", "default_backend", "planner_backends", "resolve_backend"]

BACKENDS = ("auto", "mjx", "native")


def default_backend() -> str:
    """ "native" (C MuJoCo rollouts) where JAX computes on a CPU, "mjx" on a GPU or TPU."""
    return "native" if jax.default_backend() == "cpu" else "mjx"


def planner_backends(planner: ModuleType) -> tuple[str, ...]:
    """Where `planner` plans: its module's ``BACKENDS`` (a planner that differentiates
    MJX, `ilqr`, has only "mjx"), by default both."""
    return tuple(getattr(planner, "BACKENDS", ("mjx", "native")))


def resolve_backend(planner: ModuleType, backend: str) -> str:
    """Where `planner` plans on `backend`: "mjx" or "native" as given; "auto": native on a
    CPU where the planner runs there, else mjx."""
    if backend != "auto":
        return backend
    preferred = default_backend()
    return preferred if preferred in planner_backends(planner) else "mjx"


@dataclasses.dataclass(frozen=True)
class Problem:
    """One closed-loop problem: who plans, on what, against which world, for how long.

    Attributes:
      planner: the planner module (`mjzoo.algorithms.mppi`, `cem`, `predictive_sampling`).
      config: its `Config` (structure).
      sim_task: the simulated world.
      plan_task: the planner's model of it (a `Task` or an `Ensemble`).
      seconds: simulated time to run.
      replan_every: simulation control steps per replan.
      hooks: the task's planner hooks (`closed_loop.Hooks`).
      success: optional ``states -> (solved, score)`` over the run's states [T].
      terminal_value: optional ``(model, state) -> value`` of each rollout's final
        state (a plain function is wrapped: `mjzoo.planning.as_terminal_value`).
      backend: where the physics runs, for planning and simulation alike: "mjx", or
        "native" (C MuJoCo, `mjzoo.planning.native`); "auto": native where JAX's
        default device is a CPU, MJX on a GPU.
      sim_backend: where the simulated world steps, if not on `backend`: "native" runs
        it in C MuJoCo beside an MJX planner, as a robot's world costs the planner
        nothing (one G1 world's MJX step took 14 ms on a GPU, C's a fraction of one).
        A planner on MuJoCo Warp starts each replan from the world's state carried onto
        Warp's data (`mjzoo.physics.switch_impl`).
      hyperparams: the planner's `Hyperparams` (numbers); None: its defaults.
        `mjzoo.planning.configure` gives (config, hyperparams) from one dict of fields.
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
    backend: str = "auto"
    hyperparams: Any | None = None
    sim_backend: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "terminal_value", as_terminal_value(self.terminal_value))
        if self.backend not in BACKENDS:
            raise ValueError(f"Problem: unknown backend {self.backend!r}; choose one of {BACKENDS}")
        if self.sim_backend not in (None, "mjx", "native"):
            raise ValueError(f"Problem: unknown sim_backend {self.sim_backend!r}; choose None, 'mjx' or 'native'")
        if self.backend == "native" and self.hooks.to_control is not None:
            raise ValueError(f"Problem: {closed_loop.NEEDS_JAX_ROLLOUTS}")
        supported = planner_backends(self.planner)
        if self.backend != "auto" and self.backend not in supported:
            name = self.planner.__name__.rsplit(".", 1)[-1]
            raise ValueError(
                f"Problem: {name} plans on {' or '.join(supported)} only, not {self.backend!r}: "
                f"{(self.planner.__doc__ or '').strip().splitlines()[0]}"
            )

    @property
    def physics(self) -> str:
        """The backend in use: "mjx" or "native" ("auto": native on a CPU where the
        planner runs there, else mjx; mjx for a policy in the loop, `Hooks.to_control`)."""
        in_jax = self.backend == "auto" and self.hooks.to_control is not None
        return resolve_backend(self.planner, "mjx" if in_jax else self.backend)

    @property
    def sim_physics(self) -> str:
        """Where the world steps: `sim_backend`, else where the planner's physics runs."""
        return self.sim_backend or self.physics

    @functools.cached_property
    def tasks(self) -> tuple[Task | Native, Task | Ensemble | Native]:
        """(simulation, planning task) on their backends: wrapped by `native.wrap` for C MuJoCo."""
        # The simulation's single rollout runs on the calling thread (no pool hand-off).
        sim = native_wrap(self.sim_task, num_threads=0) if self.sim_physics == "native" else self.sim_task
        return sim, native_wrap(self.plan_task) if self.physics == "native" else self.plan_task

    @functools.cached_property
    def sim_dt(self) -> float:
        """The simulation's control step (s), measured from one transition."""
        sim = self.tasks[0] if "tasks" in self.__dict__ else self.sim_task  # made already: no MJX compile
        return sim.engine.n_substeps * sim.engine.dt if isinstance(sim, Native) else control_dt(sim)

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
    if _impls_differ(problem):
        raise ValueError(
            "offline: the planner's physics and the world's are on different MJX implementations "
            "(MuJoCo Warp beside MJX-JAX or C MuJoCo); run it with realtime(problem, key, clock='simulated')"
        )
    reset_key, run_key = jax.random.split(key)
    sim_state = reset(problem.sim_task, reset_key)
    static = (problem.planner, problem.config)
    dynamic = (*problem.tasks, sim_state, run_key)
    counts = (problem.num_replans, problem.replan_every)
    functions = (problem.hooks, problem.terminal_value, problem.hyperparams)
    start = time.perf_counter()
    compiled = closed_loop.run.lower(*static, *dynamic, *counts, *functions).compile(compiler_options)
    compile_s = time.perf_counter() - start
    start = time.perf_counter()
    result = jax.block_until_ready(compiled(*dynamic, *functions))
    wall = time.perf_counter() - start
    return result, {
        "plan_hz": problem.num_replans / wall,
        "plan_latency_ms": 1e3 * wall / problem.num_replans,
        "realtime_factor": problem.seconds / wall,
        "compile_s": compile_s,
    }


@dataclasses.dataclass
class _Compiled:
    """`realtime`'s loop, compiled: replan and simulation step over packed states, the
    states themselves (packed) and the keys, every argument committed to the device."""

    replan: Callable
    step: Callable
    after_rollout: Callable
    sims: Packing
    plans: Packing
    sim_state: Any
    planner_state: Any
    step_keys: list
    plan_keys: list


def _compiled(problem: Problem, key: jax.Array, total_steps: int) -> _Compiled:
    planner, config, hooks = problem.planner, problem.config, problem.hooks
    plan_task = problem.tasks[1]
    reset_key, plan_key, key = jax.random.split(key, 3)
    # Every argument committed to the device like the jit outputs it alternates with: an
    # uncommitted one would compile the function again, mid-run.
    step_keys = list(committed(jax.random.split(key, total_steps + 1)))
    plan_keys = list(committed(jax.random.split(plan_key, total_steps + 1)))
    sim_state = committed(reset(problem.sim_task, reset_key))
    to_plan = _functions(problem, "to_plan", lambda: _to_planner(problem))
    first_plan = _functions(
        problem,
        "first_plan",
        lambda: jax.jit(lambda s, h: closed_loop.first_plan(planner, config, plan_task, to_plan(s), hooks, h)),
    )
    planner_state = committed(first_plan(sim_state, problem.hyperparams))
    # The loop carries both states packed, a few arrays each (`mjzoo.tree.Packing`): a
    # simulation state's ~100 leaves cost more to pass through a jit than a small step.
    sims, plans = Packing.of(sim_state), Packing.of(planner_state)
    replan, step, after_rollout, pack = _functions(problem, (sims, plans), lambda: _loop(problem, sims, plans))
    sim_state, planner_state = pack(sim_state, planner_state)
    # Compile before the clock starts (every argument committed, of fixed dtypes: once).
    value = problem.terminal_value
    jax.block_until_ready(
        (replan(planner_state, sim_state, plan_keys[-1], value), step(planner_state, sim_state, step_keys[-1]))
    )
    if hooks.post_rollout is not None:
        jax.block_until_ready(after_rollout(sim_state, planner_state))
    return _Compiled(replan, step, after_rollout, sims, plans, sim_state, planner_state, step_keys, plan_keys)


def _functions(problem: Problem, name: Any, make: Callable[[], Any]) -> Any:
    """`make()`, made once per problem: a problem's later episodes call the jitted
    functions of its first, so they compile once, not once an episode."""
    made = problem.__dict__.setdefault("_jitted", {})  # a frozen dataclass's own cache
    if name not in made:
        made[name] = make()
    return made[name]


def _loop(problem: Problem, sims: Packing, plans: Packing) -> tuple[Callable, ...]:
    """The real-time loop's jitted (replan, step, after_rollout, pack) over packed states."""
    planner, config, hooks = problem.planner, problem.config, problem.hooks
    sim_task, plan_task = problem.tasks
    to_plan = _functions(problem, "to_plan", lambda: _to_planner(problem))

    def replan_packed(p, s, k, v):
        state = to_plan(sims.unpack(s))
        return plans.pack(closed_loop.replan(planner, config, plan_task, plans.unpack(p), state, k, hooks, v))

    def step_packed(p, s, k):
        state, control = closed_loop.sim_step(config, sim_task, plans.unpack(p), sims.unpack(s), k, hooks)
        return sims.pack(state), control

    # Native: jits around host calls of C (`native.split`), not one jit through
    # `jax.pure_callback`, whose ~0.3 ms a call a replan and every simulation step would pay.
    compile_ = lambda physics: native_split if physics == "native" else jax.jit  # noqa: E731
    after_rollout = jax.jit(lambda s, p: sims.pack(closed_loop.after_rollout(hooks, sims.unpack(s), plans.unpack(p))))
    pack = jax.jit(lambda s, p: (sims.pack(s), plans.pack(p)))
    return compile_(problem.physics)(replan_packed), compile_(problem.sim_physics)(step_packed), after_rollout, pack


def _impls_differ(problem: Problem) -> bool:
    """Whether the planner's MJX implementation differs from the world's."""
    return problem.physics != "native" and base_task(problem.plan_task).model.impl != problem.sim_task.model.impl


def _to_planner(problem: Problem) -> Callable[[Any], Any]:
    """The world's state as the planner's physics holds it: the state itself where both
    step on one implementation (or the planner in C MuJoCo, which replays MJX-JAX states);
    else carried onto a state of the planner's (a planner on MuJoCo Warp beside a world in
    C MuJoCo or on MJX-JAX: `mjzoo.physics.switch_impl`), its metrics as the planner's."""
    if not _impls_differ(problem):
        return lambda state: state
    like = committed(reset(base_task(problem.plan_task), jax.random.key(0)))

    def to_plan(state: Any) -> Any:
        metrics = {k: state.metrics.get(k, v) for k, v in like.metrics.items()}
        return state.replace(data=switch_impl(state.data, like.data), metrics=metrics)

    return to_plan


def _stack(problem: Problem, packing: Packing, packed: list) -> Any:
    """The run's [T] states, from the loop's T packed ones (unpacked in one jit, made once
    per problem)."""
    unpack = _functions(problem, ("unpack", packing), lambda: jax.jit(packing.unpack))
    return unpack(jax.tree.map(lambda *x: jnp.stack(x), *packed))


def _timings(wall: float, latencies: list, step_seconds: list, physics_seconds: list, simulated_s: float) -> dict:
    """`realtime`'s report of where the `wall` seconds went (see there)."""
    ms = lambda xs, q=50: 1e3 * float(np.percentile(xs, q)) if xs else float("nan")  # noqa: E731
    return {
        "plan_hz": len(latencies) / wall,
        "plan_latency_ms": ms(latencies),
        "plan_latency_p95_ms": ms(latencies, 95),
        "plan_physics_ms": ms(physics_seconds),
        "sim_step_ms": ms(step_seconds),
        "busy": (sum(latencies) + sum(step_seconds)) / wall,
        "realtime_factor": simulated_s / wall,
    }


def realtime(
    problem: Problem, key: jax.Array, plan_hz: float | None = None, clock: str = "wall"
) -> tuple[Result, dict[str, float]]:
    """Simulates `problem.seconds` of wall-clock time, replanning at `plan_hz` (default:
    every `replan_every` simulation steps' worth of time) or as fast as planning allows.
    ``clock="simulated"``: the simulation waits for each replan instead and nothing
    sleeps (the planner's rate in simulated time, its latency measured as a busy loop
    measures it, as Judo's simulated-time runs do).

    Returns the run and where its time went: the achieved ``plan_hz``, each replan's
    latency (median, p95), of which ``plan_physics_ms`` was C MuJoCo's rollouts on the
    native backend (all of a replan's calls), the simulation's cost per control step
    (``sim_step_ms``), the busy share of the wall clock and the real-time factor."""
    if clock not in ("wall", "simulated"):
        raise ValueError(f"realtime: clock must be 'wall' or 'simulated', got {clock!r}")
    plan_task = problem.tasks[1]  # before sim_dt: a native simulation knows its step
    sim_dt = problem.sim_dt
    period = 1.0 / plan_hz if plan_hz else sim_dt * problem.replan_every
    total_steps = round(problem.seconds / sim_dt)
    loop = _compiled(problem, key, total_steps)
    replan, step, hooks, value = loop.replan, loop.step, problem.hooks, problem.terminal_value
    sim_state, planner_state = loop.sim_state, loop.planner_state
    c_calls = plan_task.engine.seconds if isinstance(plan_task, Native) else None  # each C call's seconds
    if c_calls is not None:
        c_calls.clear()
    physics_seconds = []  # each replan's C seconds: the sum of its calls (DIAL's iterations make several)

    states, controls, plan_states, latencies, step_seconds = [], [], [], [], []
    simulated = clock == "simulated"
    begin = time.perf_counter()

    def advance_to(due: int, plan) -> None:
        nonlocal sim_state
        while len(states) < min(total_steps, due):
            tick = time.perf_counter()
            sim_state, control = jax.block_until_ready(step(plan, sim_state, loop.step_keys[len(states)]))
            step_seconds.append(time.perf_counter() - tick)
            states.append(sim_state)
            controls.append(control)

    due_at = lambda wall: int((wall - begin) / sim_dt)  # noqa: E731  steps due by a wall time
    while len(states) < total_steps:
        tick = time.perf_counter()
        replan_key = loop.plan_keys[len(latencies) % total_steps]
        calls_before = len(c_calls) if c_calls is not None else 0
        new_plan = jax.block_until_ready(replan(planner_state, sim_state, replan_key, value))
        latencies.append(time.perf_counter() - tick)
        if c_calls is not None:
            physics_seconds.append(sum(c_calls[calls_before:]))
        if not simulated:
            advance_to(due_at(time.perf_counter()), planner_state)  # the world did not wait
        planner_state = new_plan
        if hooks.post_rollout is not None:
            sim_state = loop.after_rollout(sim_state, planner_state)
        plan_states.append(planner_state)
        if simulated:  # the world waits for each replan: one period of steps follows it
            advance_to(round(len(latencies) * period / sim_dt), planner_state)
        else:
            advance_to(due_at(tick + period), planner_state)
            time.sleep(max(0.0, tick + period - time.perf_counter()))
    wall = time.perf_counter() - begin
    stacked, plan_states = _stack(problem, loop.sims, states), _stack(problem, loop.plans, plan_states)
    result = Result(stacked, jnp.stack(controls), -stacked.reward, plan_states.cost, loop.plans.unpack(planner_state))
    return result, _timings(wall, latencies, step_seconds, physics_seconds, total_steps * sim_dt)
