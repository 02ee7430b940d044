"""A sampling planner solving a task closed loop, live: the viewer's `Planning` source.

Each `advance()` replans once from the simulated state (timed: the latency shown) and
then steps the simulation `replan_every` control steps under the new plan, as
`mjzoo.planning.closed_loop.run` does, one jitted call each. The traces drawn are a
subset of the replan's own samples (the same key, so the same knots: exact for
predictive sampling and MPPI, CEM's explore samples aside) and the chosen plan, rolled
out in the planning task, as positions of one or more sites or bodies (a body by its
centre of mass) over the horizon: a humanoid's planned motion shows as the paths of its
pelvis, feet and hands.

The planner's `Config` is a static argument of these jitted functions: a new value
(`set_config`) compiles them again, keeping the simulated and the planner's state. Its
`Hyperparams` (the sliders: temperature, noise scale, ...) live in the planner state: a
new value runs at once, without compiling.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjzoo.harness.viewer.sources import Frame
from mjzoo.harness.viewer.sources import float_parameters
from mjzoo.harness.viewer.sources import host_poses
from mjzoo.planning import closed_loop
from mjzoo.planning import sampling
from mjzoo.planning.ensembles import base_task
from mjzoo.planning.realtime import Problem
from mjzoo.running import fill_transition_entries
from mjzoo.running import reset
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Planning", "trace_point", "config_floats"]


def trace_point(mj_model: mujoco.MjModel, name: str | None = None) -> tuple[str, int]:
    """("body" or "site", id) of the point traces follow: `name` (a body or a site), or
    by default the model's first site, else its last body (the end of a chain). A body
    is traced by its centre of mass."""
    if name is None:
        return ("site", 0) if mj_model.nsite else ("body", mj_model.nbody - 1)
    for kind, obj in (("body", mujoco.mjtObj.mjOBJ_BODY), ("site", mujoco.mjtObj.mjOBJ_SITE)):
        found = mujoco.mj_name2id(mj_model, obj, name)
        if found >= 0:
            return kind, found
    bodies = [mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(mj_model.nbody)]
    raise KeyError(f"trace point {name!r}: the model has no body or site of that name; bodies: {bodies}")


def config_floats(settings: Any) -> dict[str, float]:
    """The float fields of a planner's settings (its `Hyperparams`: the ones sliders set)."""
    values = {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)}
    return {name: float(v) for name, v in values.items() if not isinstance(v, (bool, int, str)) and np.ndim(v) == 0}


class Planning:
    """`problem`'s planner closed loop on its simulation task, one environment."""

    num_envs = 1

    def __init__(
        self, problem: Problem, seed: int = 0, num_traces: int = 16, points: str | Sequence[str] | None = None
    ):
        self.problem, self.config = problem, problem.config
        defaults = problem.planner.Hyperparams()
        self.hyperparams = defaults if problem.hyperparams is None else problem.hyperparams
        self.mj_model, self.dt = problem.sim_task.mj_model, problem.sim_dt
        names = [points] if points is None or isinstance(points, str) else list(points)
        if not names:
            raise ValueError("Planning: name at least one body or site to trace, or None for the default")
        plan_model = base_task(problem.plan_task).mj_model
        self.points = [trace_point(plan_model, name) for name in names]
        self.num_traces = min(num_traces, problem.config.num_samples - 1)
        self.traces, self.compiles, self.steps, self.latencies = 0, 0, 0, []
        self._compile()
        self.reset(seed)
        self.advance()  # compile before serving
        self.reset(seed)

    def _compile(self) -> None:
        """The jitted replan, simulation steps and traces for `self.config` (static)."""
        self.compiles += 1
        self._replan = jax.jit(self._replan_fn)
        self._after = jax.jit(self._after_fn)  # traces and simulation steps: one compile

    def reset(self, seed: int = 0) -> None:
        self.key = jax.random.key(seed)
        reset_key, self.key = jax.random.split(self.key)
        self.sim_state = fill_transition_entries(self.problem.sim_task, reset(self.problem.sim_task, reset_key))
        self.planner_state = closed_loop.first_plan(
            self.problem.planner,
            self.config,
            self.problem.plan_task,
            self.sim_state,
            self.problem.hooks,
            self.hyperparams,
        )
        self.paths, self.latencies, self.steps = None, [], 0

    def advance(self) -> int:
        """One replan (timed), then `replan_every` simulation steps; returns the steps."""
        p = self.problem
        self.key, plan_key, sim_key = jax.random.split(self.key, 3)
        tick = time.perf_counter()
        new = jax.block_until_ready(
            self._replan(p.plan_task, self.planner_state, self.sim_state, plan_key, p.terminal_value)
        )
        self.latencies = (self.latencies + [time.perf_counter() - tick])[-50:]
        self.paths, self.sim_state = self._after(
            p.plan_task, p.sim_task, self.planner_state, new, self.sim_state, plan_key, sim_key
        )
        self.planner_state = new
        self.steps += p.replan_every
        return p.replan_every

    def latency_ms(self) -> float:
        return 1e3 * float(np.median(self.latencies)) if self.latencies else float("nan")

    def parameters(self) -> dict[str, np.ndarray]:
        return float_parameters(self.problem.sim_task)

    def set_parameters(self, **values: Any) -> None:
        """New numbers for the world and, where it has them, the planner's task."""
        p = self.problem
        plan_task = p.plan_task
        if isinstance(plan_task, Task):
            known = float_parameters(plan_task)
            plan_task = plan_task.with_params(**{k: v for k, v in values.items() if k in known})
        self.problem = dataclasses.replace(p, sim_task=p.sim_task.with_params(**values), plan_task=plan_task)

    def set_config(self, **values: Any) -> None:
        """New planner settings (checked by their own validation), keeping the states:
        `Hyperparams` fields go into the planner state, with no compile (a new
        noise_scale resets the sampling std it sets); `Config` fields compile again."""
        names = {f.name for f in dataclasses.fields(self.hyperparams)}
        numbers = {k: v for k, v in values.items() if k in names}
        structure = {k: v for k, v in values.items() if k not in names}
        config = dataclasses.replace(self.config, **structure)  # both checked before either is kept
        hyperparams = dataclasses.replace(self.hyperparams, **numbers)
        self.config, self.hyperparams = config, hyperparams
        self.problem = dataclasses.replace(self.problem, config=config, hyperparams=hyperparams)
        # The state's hyperparams as `init` makes them (float32, committed): no retrace.
        fresh = self.problem.planner.init(config, self.problem.plan_task, hyperparams)
        changes = {"hyperparams": fresh.hyperparams, **({"std": fresh.std} if "noise_scale" in numbers else {})}
        self.planner_state = self.planner_state.replace(**changes)
        if structure:
            self._compile()

    def frame(self) -> Frame:
        data = self.sim_state.data
        qpos, mocap_pos, mocap_quat, t, metrics = jax.device_get(
            (data.qpos[None], data.mocap_pos[None], data.mocap_quat[None], data.time, self.sim_state.metrics)
        )
        xpos, xquat = host_poses(self.mj_model, qpos, mocap_pos, mocap_quat)
        terms = {k[len("reward/") :]: np.asarray(v)[None] for k, v in metrics.items() if k.startswith("reward/")}
        paths = None if self.paths is None else np.asarray(self.paths)
        return Frame(qpos, mocap_pos, mocap_quat, xpos, xquat, float(t), terms, paths)

    # --- jitted (self.config and the problem's hooks are constants of the trace) -----

    def _replan_fn(self, plan_task, planner_state, sim_state, key, value):
        self.traces += 1
        return closed_loop.replan(
            self.problem.planner, self.config, plan_task, planner_state, sim_state, key, self.problem.hooks, value
        )

    def _after_fn(
        self, plan_task, sim_task: Task, old, new, sim_state: State, plan_key: jax.Array, sim_key: jax.Array
    ) -> tuple[jax.Array, State]:
        """(the traces of this replan, the simulation `replan_every` steps on under `new`)."""
        return self._traces_fn(plan_task, old, new, sim_state, plan_key), self._simulate_fn(
            sim_task, new, sim_state, sim_key
        )

    def _simulate_fn(self, sim_task: Task, planner_state, sim_state: State, key: jax.Array) -> State:
        def body(state: State, key: jax.Array) -> tuple[State, None]:
            return closed_loop.sim_step(self.config, sim_task, planner_state, state, key, self.problem.hooks)[0], None

        return jax.lax.scan(body, sim_state, jax.random.split(key, self.problem.replan_every))[0]

    def _traces_fn(self, plan_task, old, new, sim_state: State, key: jax.Array) -> jax.Array:
        """[S + 1, H, P, 3] positions of the P trace points along S of the replan's
        samples and along the chosen plan (last)."""
        hooks, config = self.problem.hooks, self.config
        start = hooks.to_planner(sim_state) if hooks.to_planner else sim_state
        task = base_task(plan_task)
        low, high = sampling.control_limits(plan_task)
        shifted = sampling.shift(config, old, start.data.time)
        sample_key = jax.random.split(key)[0]  # as `sampling.sample_around` splits it
        samples = sampling.sample_knots(sample_key, shifted.knots, shifted.std, config.num_samples, low, high)
        knots = jnp.concatenate([samples[1 : 1 + self.num_traces], new.knots[None]])
        sequences = sampling.controls(config, knots, low, high)  # [S + 1, H, nu]
        return jax.vmap(lambda c: self._follow(task, fill_transition_entries(task, start), c))(sequences)

    def _follow(self, task: Task, start: State, sequence: jax.Array) -> jax.Array:
        def body(state: State, action: jax.Array) -> tuple[State, jax.Array]:
            state = transition(task, state, action, jax.random.key(0))
            # A body by its centre of mass: a hinge's body origin stays put.
            where = [(state.data.site_xpos if kind == "site" else state.data.xipos)[i] for kind, i in self.points]
            return state, jnp.stack(where)

        return jax.lax.scan(body, start, sequence)[1]
