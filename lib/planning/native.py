"""Native rollouts: a planning task's physics in C MuJoCo (`mujoco.rollout`), its costs
from the task's own reward terms, evaluated in JAX on the states C returns.

On a CPU, MJX is 14-40x slower than C MuJoCo; on a GPU MJX is the right engine. Wrap the
planning task (or an `Ensemble`: one C model per member) once, and plan with it where a
task goes:

    plan_task = planning.native.wrap(task)  # C models, a thread pool, checks of the task
    state, controls = jax.jit(mppi.plan, static_argnums=0)(config, plan_task, state, env_state, key)
    replan = planning.native.split(functools.partial(mppi.plan, config, plan_task))  # host loop: faster

A replan stays one jit: the controls a rollout applies are computed in JAX from its
actions (the task's own step, its physics recorded, not run), C MuJoCo rolls them out
through `jax.pure_callback` (`split`: the same as jits around host calls of C,
without the callback's ~0.3 ms a call), and the returned states are replayed through the task's own
`transition` (its physics replaced by C's states: `mjzoo.physics.StandIn`), which gives
the reward terms, terminations and observations. After a step, `data` holds:
  from C MuJoCo        time, qpos, qvel, act, sensordata (sensors are computed before a
                       step integrates: in C and in MJX alike, they describe the state
                       one physics step before qpos)
  applied by the task  ctrl, qfrc_applied, xfrc_applied, mocap_pos, mocap_quat: sent to
                       C as controls at every physics step (mocap is not part of C's
                       physics state)
  recomputed in JAX    body, geom and site poses (`mjx.kinematics`), centres of mass and
                       spatial velocities (`mjx.com_pos`, `mjx.com_vel`), from the state
                       before the last physics step, where MJX's step leaves them
Everything else (contacts, constraint forces, accelerations, actuator forces) exists only
inside C's step: `wrap` raises at construction if the task's reward or termination
reads any of it (found by probing: perturbing the field changes them), and if the
controls the task applies depend on the physics state (a PD actuator evaluated per
substep): a rollout's controls must be known before it runs.

C MuJoCo resets a diverging simulation to qpos0 where MJX produces NaN; a rollout whose
time steps backwards is NaN from there on, so the task's divergence guard sees what it
would see on MJX.
"""

from __future__ import annotations

import contextvars
import copy
import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjzoo import physics
from mjzoo.planning.ensembles import Ensemble
from mjzoo.planning.ensembles import masked_cost
from mjzoo.planning.learned import TerminalValue
from mjzoo.planning.learned import as_terminal_value
from mjzoo.planning.native_engine import APPLIED
from mjzoo.planning.native_engine import Engine
from mjzoo.planning.native_engine import physical_cores
from mjzoo.running import fill_transition_entries
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Native", "wrap", "rollout_costs", "split", "transition_native"]

Array = jax.Array
FROM_C = ("time", "qpos", "qvel", "act", "sensordata")  # what C returns after each step
_HINTS = {
    "contact": "a touch or contact sensor",
    "efc": "a touch or force sensor",
    "cfrc": "a force or torque sensor",
    "qacc": "an accelerometer or framelinacc sensor",
    "actuator_force": "an actuatorfrc sensor",
    "qfrc": "a jointactuatorfrc sensor",
}


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Native:
    """A planning task (or an `Ensemble`) whose rollouts run in C MuJoCo; make it with
    `wrap`. Its numbers stay leaves (reward weights, targets: no recompile); the C
    models are fixed when it is made."""

    task: Task | Ensemble
    engine: Engine = dataclasses.field(metadata={"static": True})


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class _Recorder(physics.StandIn):
    """Physics that only advances time: what a step applies, without simulating it."""

    model: mjx.Model

    def substep(self, data: mjx.Data) -> mjx.Data:
        return data.replace(time=data.time + self.model.opt.timestep)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class _Replay(physics.StandIn):
    """Physics that returns C MuJoCo's state after the control step (`after`), with the
    poses MJX's step would leave, computed from the state before its last physics step."""

    model: mjx.Model
    after: dict[str, Array]
    before: dict[str, Array]

    def substep(self, data: mjx.Data) -> mjx.Data:
        pre = data.replace(**self.before)
        pre = mjx.com_vel(self.model, mjx.com_pos(self.model, mjx.kinematics(self.model, pre)))
        return pre.replace(**{k: v.astype(getattr(data, k).dtype) for k, v in self.after.items()})


def wrap(task: Task | Ensemble, *, num_threads: int | None = None, chunk_size: int | None = None) -> Native:
    """`task` with its rollouts in C MuJoCo.

    Args:
      task: the planning task, or an `Ensemble` of M models of it (one C model each).
      num_threads: rollout threads (default: the physical cores; 0: the calling thread,
        best for a simulation's single rollout).
      chunk_size: rollouts per thread-pool task (default: an even split over threads,
        best for the short, equal rollouts of a planner).

    Raises:
      ValueError: naming what C MuJoCo cannot give this task (see the module docstring).
    """
    variants = task if isinstance(task, Ensemble) else Ensemble(task, {})
    base = variants.task
    if base.model.impl != mjx.Impl.JAX:
        raise ValueError(
            "planning.native: the task's physics is MuJoCo Warp; native rollouts replay C MuJoCo's "
            "states through MJX's JAX implementation: load the planning task with impl='jax'"
        )
    start = _start_state(base)
    models = _host_models(base.mj_model, base.model, variants.fields)
    present = [f for f in APPLIED if getattr(mujoco.MjData(models[0]), f).size > 0]
    probed = _probe(base, start, present)
    if probed.state_dependent:
        raise ValueError(
            "planning.native: the controls this task applies depend on the physics state (e.g. a PD "
            "actuator evaluated every physics step, or an action latency read from qpos); native "
            "rollouts need every control before the rollout starts: plan with backend='mjx'"
        )
    threads = physical_cores() if num_threads is None else num_threads
    engine = Engine(models, probed.n_substeps, threads, chunk_size)
    engine.vary(probed.changed)
    engine.direct = probed.direct
    result = Native(task, engine)
    _reads(result, start, probed)
    return result


def _host_models(mj_model: mujoco.MjModel, model: mjx.Model, fields: dict[str, Array]) -> list[mujoco.MjModel]:
    """One C model per ensemble member: `mj_model` with the numbers `model` (the task's
    MJX model, maybe edited: heavier links, other gains) holds where they differ, then
    the member's `fields` ([M] leading axis) set."""
    edited = {}
    for f in dataclasses.fields(model):
        value = getattr(model, f.name, None)
        if isinstance(value, (jax.Array, np.ndarray)) and hasattr(mj_model, f.name):
            host = getattr(mj_model, f.name)
            if isinstance(host, np.ndarray) and host.size == np.size(value):
                value = np.asarray(value, host.dtype).reshape(host.shape)
                if not np.array_equal(value, host) and not np.allclose(value, host, rtol=1e-6, atol=0):
                    edited[f.name] = value
    count = max((len(v) for v in fields.values()), default=1)
    models = []
    for m in range(count):
        host = copy.deepcopy(mj_model) if fields or edited else mj_model
        for name, value in [*edited.items(), *((k, np.asarray(v[m])) for k, v in fields.items())]:
            if not hasattr(host, name):
                raise ValueError(f"planning.native: the ensemble varies {name!r}, which the C model has no field for")
            getattr(host, name)[...] = value.reshape(getattr(host, name).shape)
        models.append(host)
    return models


def _fill_transition_entries(task: Task, state: State) -> State:
    """`mjzoo.fill_transition_entries` for a native task: the structure of a transition, found without
    tracing MJX's physics (the same structure: a stand-in returns the same `Data`)."""
    return fill_transition_entries(task.replace(model=_Recorder(task.model)), state)


def _applied(task: Task, fields: list[str], start: State, actions: Array, keys: Array) -> Array:
    """[H, ncontrol] what the task's step applies in each of H control steps, in C's order."""
    recording = task.replace(model=_Recorder(task.model))

    def body(state: State, inputs) -> tuple[State, Array]:
        state = transition(recording, state, *inputs)
        return state, jnp.concatenate([jnp.ravel(getattr(state.data, f)).astype(jnp.float32) for f in fields])

    return jax.lax.scan(body, start, (actions, keys))[1]


def _replay(
    task: Task,
    start: State,
    actions: Array,
    keys: Array,
    c_states: dict,
    n_substeps: int,
    unroll: int = 1,
):
    """The task's transitions over C's states (one rollout, [H x n_substeps] each):
    (final state, [H] rewards, [H] terminated)."""
    horizon = actions.shape[0]
    with_start = {
        k: jnp.concatenate([getattr(start.data, k)[None].astype(jnp.float32), c_states[k]])
        for k in ("time", "qpos", "qvel", "act")
    }
    after = {k: v[n_substeps::n_substeps] for k, v in with_start.items()}
    after["sensordata"] = c_states["sensordata"][n_substeps - 1 :: n_substeps]
    before = {k: with_start[k][n_substeps - 1 :: n_substeps][:horizon] for k in ("qpos", "qvel")}

    def body(state: State, inputs) -> tuple[State, tuple[Array, Array]]:
        action, key, a, b = inputs
        state = transition(task.replace(model=_Replay(task.model, a, b)), state, action, key)
        return state, (state.reward, state.terminated)

    final, (rewards, terminated) = jax.lax.scan(body, start, (actions, keys, after, before), unroll=unroll)
    return final, rewards, terminated


def _roll(engine: Engine, base: Task, models: Any, start: State, controls: Array, keys: Array) -> dict[str, Array]:
    """C rollouts of controls [N, H, nu] under each of M models ([M] leading axis of
    `models`, an `mjx.Model` batch): {field: [M, N, H x n_substeps, ...]}."""
    num_models = jax.tree.leaves(models)[0].shape[0]
    if engine.direct:  # the step applies its action as ctrl (C clamps it to the range): no step to run
        applied = jnp.broadcast_to(controls.astype(jnp.float32), (num_models, *controls.shape))
    else:
        applied_one = lambda model, c: _applied(base.replace(model=model), engine.fields, start, c, keys)
        applied = jax.vmap(lambda model: jax.vmap(lambda c: applied_one(model, c))(controls))(models)
    applied = jnp.repeat(applied, engine.n_substeps, axis=2)  # the same inputs every physics step
    shape = applied.shape[:3]
    out_shapes = (
        jax.ShapeDtypeStruct((*shape, engine.width), jnp.float32),
        jax.ShapeDtypeStruct((*shape, engine.sizes["sensordata"]), jnp.float32),
    )
    d = start.data
    history = d.history if d.history is not None else jnp.zeros((0,))
    args = (
        d.time,
        d.qpos,
        d.qvel,
        d.act,
        history,
        d.qacc_warmstart,
        [getattr(d, f) for f in engine.held],
        applied,
    )
    host = _HOST.get()
    if host is not None:  # `split` traces: C's outputs come from the host, or its inputs go there
        out = host.call(engine, args, out_shapes)
    else:
        out = jax.pure_callback(engine, out_shapes, *args, vmap_method="sequential")
    return _from_c(engine, *out)


def _from_c(engine: Engine, states: Array, sensordata: Array) -> dict[str, Array]:
    """C's outputs (`Engine.__call__`) as {field of `FROM_C`: [..., size]} (time: [...])."""
    ends = np.cumsum([1, engine.sizes["qpos"], engine.sizes["qvel"]])
    time, qpos, qvel, act = jnp.split(jnp.asarray(states), ends, axis=-1)
    return {"time": time[..., 0], "qpos": qpos, "qvel": qvel, "act": act, "sensordata": jnp.asarray(sensordata)}


_HOST: contextvars.ContextVar = contextvars.ContextVar("mjzoo_native_host", default=None)


class _Host:
    """A C call site's part while `split` traces: the first calls get the outputs C gave
    (`given`); the later ones hand their inputs out (`calls`) and get zeros, which no
    output of the traced stage depends on."""

    def __init__(self, given: list):
        self.given, self.calls, self.seen = given, [], 0

    def call(self, engine: Engine, args: tuple, out_shapes: tuple) -> tuple:
        if self.seen < len(self.given):
            out = tuple(self.given[self.seen])
        else:
            self.calls.append((engine, args))
            out = tuple(jnp.zeros(s.shape, s.dtype) for s in out_shapes)
        self.seen += 1
        return out


def split(fn: Callable) -> Callable:
    """`jax.jit(fn)` for a function that runs C MuJoCo (a replan or a simulation step on
    `Native` tasks), as jits around calls of C MuJoCo from the host.

    One jit reaches C through `jax.pure_callback`, which costs ~0.3 ms a call on a CPU:
    more than a whole replan's work besides physics. Here, for a function that calls C
    n times in sequence (n = 1 for a replan, n = `iterations` for DIAL's and CMA-ES's,
    unrolled by `planning.iterate`, each call needing the last one's result), stage j < n
    computes the inputs of call j from the outputs of calls < j (its trace of `fn` hands
    them out; XLA drops the rest), the host runs C, and stage n computes `fn` with every
    output passed in. n + 1 jits; same result, same key use. A function whose C call
    sits in a `lax.scan` (traced once, run many times: a planner's own loop that is not
    `planning.iterate`'s) runs as one jit instead, C through `jax.pure_callback`.
    """
    plans: dict = {}

    def stage(treedef, j: int, plan: dict):
        def run_stage(given: list, leaves: list):
            host = _Host(given)
            token = _HOST.set(host)
            try:
                result = fn(*jax.tree.unflatten(treedef, leaves))
            finally:
                _HOST.reset(token)
            if j == 0:
                plan["calls"] = len(host.calls)
            if j == plan["calls"]:
                return result
            engine, inputs = host.calls[0]
            plan["engines"][j] = engine
            return inputs

        return jax.jit(run_stage)

    def run(*args):
        # Flattened once, in Python (an mjx.Data flattens slowly); the jits take the list.
        leaves, treedef = jax.tree.flatten(args)
        plan = plans.setdefault(treedef, {"stages": [], "engines": {}, "calls": None, "whole": None})
        if plan["whole"] is not None:
            return plan["whole"](leaves)
        given: list = []
        while True:
            j = len(given)
            if j == len(plan["stages"]):
                plan["stages"].append(stage(treedef, j, plan))
            try:
                out = plan["stages"][j](given, leaves)
            except jax.errors.UnexpectedTracerError:  # C's inputs were a scan body's: they cannot leave it
                plan["whole"] = jax.jit(lambda ls: fn(*jax.tree.unflatten(treedef, ls)))
                return plan["whole"](leaves)
            if j == plan["calls"]:
                return out
            given.append(plan["engines"][j](*jax.tree.map(np.asarray, out)))

    return run


def rollout_costs(
    task: Native,
    state: State,
    controls: Array,
    key: Array,
    terminal_value: TerminalValue | None = None,
    unroll: int = 1,
    termination_cost: float | Array = 0.0,
) -> tuple[Array, Array]:
    """`mjzoo.planning.rollout_costs` with the physics in C MuJoCo: ([M, N] costs,
    [] control step dt) of controls [N, H, nu] from `state`, costed alike
    (`mjzoo.planning.masked_cost`: nothing counts after a rollout's first termination)."""
    terminal_value = as_terminal_value(terminal_value)
    variants = task.task if isinstance(task.task, Ensemble) else Ensemble(task.task, {})
    base, engine = variants.task, task.engine
    start = _fill_transition_entries(base, state)
    keys = jax.random.split(key, controls.shape[1])
    if variants.fields:
        models = jax.vmap(lambda f: base.model.replace(**f))(variants.fields)
    else:
        models = jax.tree.map(lambda x: x[None], base.model)
    c_states = _roll(engine, base, models, start, controls, keys)

    def cost(model, actions: Array, sample: dict) -> Array:
        final, rewards, terminated = _replay(
            base.replace(model=model),
            start,
            actions,
            keys,
            sample,
            engine.n_substeps,
            unroll,
        )
        value = terminal_value(model, final) if terminal_value is not None else 0.0
        return masked_cost(rewards, terminated, value, termination_cost)

    per_model = lambda model, states: jax.vmap(cost, in_axes=(None, 0, 0))(model, controls, states)
    costs = jax.vmap(per_model)(models, c_states)
    return costs, jnp.float32(engine.n_substeps * engine.dt)


def transition_native(task: Native, state: State, action: Array, key: Array) -> State:
    """`mjzoo.transition` with the physics of the step in C MuJoCo: a simulation that
    steps in C (one control step: one C rollout of its physics steps)."""
    if isinstance(task.task, Ensemble):
        raise TypeError("planning.native: a simulation steps one model, not an Ensemble")
    base = task.task
    models = jax.tree.map(lambda x: x[None], base.model)
    keys = key[None]
    c_states = _roll(task.engine, base, models, state, action[None, None], keys)
    one = jax.tree.map(lambda x: x[0, 0], c_states)
    final, _, _ = _replay(base, state, action[None], keys, one, task.engine.n_substeps)
    return final


# --- the checks `wrap` makes, by probing the task ----------------------------------------
# What `mjzoo.planning.native` checks when it wraps a task, by probing it: how many
# physics steps a control step takes, which applied inputs its step changes, that those do
# not depend on the physics state, and that its reward and termination read nothing C
# MuJoCo does not return. Each failure is one `ValueError` naming the cause. Two compiles,
# neither of MJX's physics: the task's step with its physics recorded, and its replay.


def _start_state(task: Task) -> State:
    """A start state of `task` without compiling MJX: the structure of its `start`
    (`jax.eval_shape`), its physics from C MuJoCo's `mj_forward` at the reset keyframe
    (qpos0), zeros elsewhere. What the probes run from."""
    shape = jax.eval_shape(task.start, task.model, jax.random.key(0))
    mj_data = mujoco.MjData(task.mj_model)
    mujoco.mj_forward(task.mj_model, mj_data)
    data = mjx.put_data(task.mj_model, mj_data)
    data = jax.tree.map(lambda d, s: np.asarray(d, s.dtype).reshape(s.shape), data, shape.data)
    zeros = lambda s: np.zeros(s.shape, s.dtype)
    state = shape.replace(
        data=data,
        obs=jax.tree.map(zeros, shape.obs),
        info=jax.tree.map(zeros, shape.info),
        layers=jax.tree.map(zeros, shape.layers),
        metrics=jax.tree.map(zeros, shape.metrics),
        reward=np.float32(0),
        terminated=np.bool_(False),
        truncated=np.bool_(False),
    )
    return jax.tree.map(np.asarray, _fill_transition_entries(task, state))


@dataclasses.dataclass(frozen=True)
class _Probe:
    """What the task's step did in two probe control steps (one compile, no physics).

    Attributes:
      n_substeps: physics steps per control step.
      changed: the applied inputs (`APPLIED`) the step changes.
      actions: [2, nu] the probe actions, inside the control ranges.
      applied: {field: [2, size]} what the step applied for them.
      state_dependent: whether those change when only qpos, qvel, act and time do.
      direct: whether the applied ctrl is the action (or the action clamped to the
        control range, as C clamps it) and nothing else changes.
    """

    n_substeps: int
    changed: list[str]
    actions: np.ndarray
    applied: dict[str, np.ndarray]
    state_dependent: bool
    direct: bool


def _probe(task: Task, start: State, present: list[str]) -> _Probe:
    """Runs the task's step with its physics recorded (`_Recorder`), for probe actions,
    from `start` and from `start` with its physics state moved; raises if the step never
    reaches the physics."""
    low, high = np.asarray(task.mj_model.actuator_ctrlrange, np.float32).T
    limited = np.asarray(task.mj_model.actuator_ctrllimited, bool)
    rng = np.random.default_rng(0)
    u = rng.uniform(-1.0, 1.0, (2, task.action_size)).astype(np.float32)
    own = task.action_dim is None  # else the actuator's own actions, in [-1, 1]
    actions = np.where(limited, low + (u + 1) / 2 * (high - low), u) if own else u
    keys = jax.random.split(jax.random.key(2), 2)
    moved = start.replace(
        data=start.data.replace(**_perturbed({k: getattr(start.data, k) for k in ("qpos", "qvel", "act", "time")}, 3))
    )
    recording = task.replace(model=_Recorder(task.model))

    def run(start, moved):
        after = transition(recording, start, jnp.asarray(actions[0]), keys[0])
        return (
            after.data.time,
            _applied(task, present, start, actions, keys),
            _applied(task, present, moved, actions, keys),
            _applied(task, present, start, 2.0 * actions, keys),
        )

    time, applied, applied_moved, applied_wide = jax.device_get(jax.jit(run)(start, moved))
    n_substeps = round(float(time - start.data.time) / float(task.mj_model.opt.timestep))
    if n_substeps < 1:
        raise ValueError(
            "planning.native: the task's step never reached mjzoo.physics.step or substep with the "
            "model it was given (e.g. it replaces model fields per episode, as domain randomization "
            "does); plan with backend='mjx', or randomize with planning.ensemble"
        )
    sizes = [int(np.size(getattr(start.data, f))) for f in present]
    split = lambda x: dict(zip(present, np.split(x, np.cumsum(sizes)[:-1], axis=1)))
    parts, wide = split(applied), split(applied_wide)
    changed = [f for f in present if not np.allclose(parts[f], np.ravel(getattr(start.data, f)))]
    clamped = np.where(limited, np.clip(2.0 * actions, low, high), 2.0 * actions) if own else None
    direct = (
        own
        and set(changed) <= {"ctrl"}
        and "ctrl" in wide
        and any(np.allclose(wide["ctrl"], target, atol=1e-6) for target in (2.0 * actions, clamped))
    )
    state_dependent = not np.allclose(applied, applied_moved, atol=1e-6)
    return _Probe(n_substeps, changed, actions, parts, state_dependent, bool(direct))


def _perturbed(tree: Any, seed: int) -> Any:
    """Every float leaf x moved by N(0, 0.1 (1 + |x|)) (a change even of MuJoCo's 1e10
    "no contact" distances), every integer leaf by one; dtypes kept."""
    rng = np.random.default_rng(seed)

    def move(leaf):
        leaf = np.asarray(leaf)
        if np.issubdtype(leaf.dtype, np.floating):
            return (leaf + 0.1 * (1 + np.abs(leaf)) * rng.standard_normal(leaf.shape)).astype(leaf.dtype)
        return leaf + np.ones((), leaf.dtype) if np.issubdtype(leaf.dtype, np.integer) else leaf

    return jax.tree.map(move, tree)


def _reads(task: Native, start: State, probed: _Probe) -> None:
    """Raises, naming the fields, if the task's reward or termination reads any part of
    `data` that C MuJoCo does not return and the replay does not recompute: each such
    field is moved in turn and the rewards and terminations of two replayed steps
    compared (one compile)."""
    base = task.task.task if isinstance(task.task, Ensemble) else task.task
    engine = task.engine
    keys = jax.random.split(jax.random.key(2), 2)
    d = start.data
    steps = 2 * engine.n_substeps
    controls = np.concatenate(
        [np.repeat(probed.applied[f], engine.n_substeps, axis=0) for f in engine.fields],
        axis=1,
    )
    history = d.history if d.history is not None else np.zeros((0,))
    out = engine(
        d.time,
        d.qpos,
        d.qvel,
        d.act,
        history,
        d.qacc_warmstart,
        [getattr(d, f) for f in engine.held],
        controls.reshape(1, 1, steps, -1),
    )
    one = {k: v[0, 0] for k, v in _from_c(engine, *out).items()}
    outcome = jax.jit(lambda s: _replay(base, s, jnp.asarray(probed.actions), keys, one, engine.n_substeps)[1:])
    reference = outcome(start)
    fields = [f.name for f in dataclasses.fields(d) if f.name not in FROM_C + APPLIED]
    fields += [f"_impl.{f.name}" for f in dataclasses.fields(d._impl)] if hasattr(d, "_impl") else []
    read = []
    for i, name in enumerate(fields):
        owner, attr = (d._impl, name[6:]) if name.startswith("_impl.") else (d, name)
        value = getattr(owner, attr)
        if name == "_impl" or not any(isinstance(leaf, np.ndarray) for leaf in jax.tree.leaves(value)):
            continue  # a static field (sizes), not data
        moved_owner = owner.replace(**{attr: _perturbed(value, 10 + i)})
        data = d.replace(_impl=moved_owner) if owner is not d else moved_owner
        got = outcome(start.replace(data=data))
        if not all(
            np.array_equal(a, b, equal_nan=True) for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(reference))
        ):
            read.append(name.removeprefix("_impl."))
    if read:
        hints = sorted({hint for name in read for key, hint in _HINTS.items() if name.startswith(key)})
        raise ValueError(
            f"planning.native: this task's reward or termination reads data.{', data.'.join(read)}, which "
            "exists only inside C MuJoCo's step (mujoco.rollout returns states and sensors)"
            + (f"; read {' or '.join(hints)} from data.sensordata instead" if hints else "")
            + ", or plan with backend='mjx'"
        )
