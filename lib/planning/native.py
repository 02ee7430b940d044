"""Native rollouts: a planning task's physics in C MuJoCo (`mujoco.rollout`), its costs
from the task's own reward terms, evaluated in JAX on the states C returns.

On a CPU, MJX is 14-40x slower than C MuJoCo; on a GPU MJX is the right engine. Wrap the
planning task (or an `Ensemble`: one C model per member) once, and plan with it where a
task goes:

    plan_task = planning.native(task)      # C models, a thread pool, checks of the task
    state, controls = jax.jit(mppi.plan, static_argnums=0)(config, plan_task, state, env_state, key)

A replan stays one jit. The controls a rollout applies are computed in JAX from its
actions (the task's own step, its physics recorded, not run), C MuJoCo rolls them out
through `jax.pure_callback`, and the returned states are replayed through the task's own
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
inside C's step: `native` raises at construction if the task's reward or termination
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
import os
import time as time_lib
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mjzoo import physics
from mjzoo.planning.learned import TerminalValue, as_terminal_value
from mjzoo.planning.rollouts import Ensemble
from mjzoo.running import complete, transition
from mjzoo.types import State, Task
from mujoco import mjx
from mujoco import rollout as mj_rollout

__all__ = [
    "Engine",
    "Native",
    "native",
    "physical_cores",
    "rollout_costs",
    "transition_native",
]

Array = jax.Array
APPLIED = (
    "ctrl",
    "qfrc_applied",
    "xfrc_applied",
    "mocap_pos",
    "mocap_quat",
)  # in mjtState order
_SPEC = {
    "ctrl": mujoco.mjtState.mjSTATE_CTRL, "qfrc_applied": mujoco.mjtState.mjSTATE_QFRC_APPLIED,
    "xfrc_applied": mujoco.mjtState.mjSTATE_XFRC_APPLIED, "mocap_pos": mujoco.mjtState.mjSTATE_MOCAP_POS,
    "mocap_quat": mujoco.mjtState.mjSTATE_MOCAP_QUAT,
}  # fmt: skip
FROM_C = ("time", "qpos", "qvel", "act", "sensordata")
C_OUTPUTS = FROM_C
_HINTS = {
    "contact": "a touch or contact sensor", "efc": "a touch or force sensor", "cfrc": "a force or torque sensor",
    "qacc": "an accelerometer or framelinacc sensor", "actuator_force": "an actuatorfrc sensor",
    "qfrc": "a jointactuatorfrc sensor",
}  # fmt: skip


def physical_cores() -> int:
    """CPU cores this process may run on, counting hyperthread siblings once."""
    cpus = sorted(os.sched_getaffinity(0))
    seen, cores = set(), 0
    for cpu in cpus:
        try:
            with open(
                f"/sys/devices/system/cpu/cpu{cpu}/topology/thread_siblings_list"
            ) as f:
                siblings = f.read().strip()
        except OSError:
            return len(cpus)
        cores += siblings not in seen
        seen.add(siblings)
    return max(1, cores)


class Engine:
    """C MuJoCo's side: one host model per ensemble member, a persistent `mujoco.rollout`
    thread pool with its per-thread `MjData`, and the layout of states and controls.
    Compared by identity: a jitted planner compiles once per engine."""

    def __init__(
        self,
        models: list[mujoco.MjModel],
        n_substeps: int,
        num_threads: int,
        chunk_size: int | None,
    ):
        first = models[0]
        self.models, self.n_substeps, self.chunk_size = models, n_substeps, chunk_size
        self.dt = float(first.opt.timestep)
        self.present = [f for f in APPLIED if getattr(mujoco.MjData(first), f).size > 0]
        self.vary(self.present)
        self.direct = False  # True: ctrl is the action itself, no other input varies (set by `native`)
        self.sizes = {
            f: int(getattr(mujoco.MjData(first), f).size)
            for f in ("qpos", "qvel", "act", "sensordata")
        }
        self.full = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
        self.num_threads = num_threads
        self._scratch = mujoco.MjData(first)
        self._datas = [mujoco.MjData(first) for _ in range(max(1, num_threads))]
        self._pool = mj_rollout.Rollout(nthread=num_threads)  # 0: on the calling thread
        self._batches: dict[
            tuple[int, int, int], dict[str, Any]
        ] = {}  # preallocated per batch shape
        self.seconds: list[
            float
        ] = []  # wall time of each call's C rollouts (a real-time runner reads it)

    def vary(self, fields: list[str]) -> None:
        """Sends `fields` (and ctrl) to C as controls at every physics step; the other
        applied inputs are held at the start state's values."""
        self.fields = [f for f in self.present if f in fields or f == "ctrl"]
        self.held = [f for f in self.present if f not in self.fields]
        self.spec = int(sum(_SPEC[f] for f in self.fields))

    def __call__(
        self, time, qpos, qvel, act, history, warmstart, held, controls
    ) -> tuple[np.ndarray, ...]:
        """Rolls out [M, N, T, ncontrol] controls from one state (whose `held` inputs stay
        fixed); returns float32 time [M, N, T], qpos, qvel, act and sensordata
        [M, N, T, size], NaN after a reset."""
        num_models, num_samples, steps, _ = controls.shape
        for data in self._datas:
            for name, value in zip(self.held, held):
                getattr(data, name)[...] = value
        d = self._scratch
        d.time, d.qpos[:], d.qvel[:], d.act[:] = time, qpos, qvel, act
        if d.history.size:
            d.history[:] = history
        batch = num_models * num_samples
        buffers = self._buffers(num_models, num_samples, steps)
        mujoco.mj_getState(self.models[0], d, buffers["start"][0], self.full)
        buffers["start"][1:] = buffers["start"][0]
        buffers["warmstart"][:] = warmstart
        buffers["controls"][:] = controls.reshape(batch, steps, -1)
        tick = time_lib.perf_counter()
        # Every array already has rollout's exact shape and dtype: its Python checks are skipped.
        self._pool.rollout(
            buffers["models"], self._datas, buffers["start"], buffers["controls"], control_spec=self.spec,
            skip_checks=True, nstep=steps, initial_warmstart=buffers["warmstart"], state=buffers["states"],
            sensordata=buffers["sensors"], chunk_size=self.chunk_size or max(1, -(-batch // max(1, self.num_threads))),
        )  # fmt: skip
        self.seconds.append(time_lib.perf_counter() - tick)
        states, nq, nv, na = (
            buffers["states"],
            self.sizes["qpos"],
            self.sizes["qvel"],
            self.sizes["act"],
        )
        times = states[..., 0]
        # C resets a diverging simulation (time back to 0): NaN from there on, as MJX's would be.
        earlier = np.concatenate(
            [np.full((batch, 1), float(time)), times[:, :-1]], axis=1
        )
        reset_ = np.maximum.accumulate(times < earlier - 0.5 * self.dt, axis=1)[
            ..., None
        ]
        qpos_, qvel_ = (
            np.where(reset_, np.nan, x)
            for x in (states[..., 1 : 1 + nq], states[..., 1 + nq : 1 + nq + nv])
        )
        parts = (
            times,
            qpos_,
            qvel_,
            states[..., 1 + nq + nv : 1 + nq + nv + na],
            buffers["sensors"],
        )
        shape = (num_models, num_samples, steps)
        return tuple(
            x.astype(np.float32).reshape(shape + x.shape[2:]) for x in parts
        )  # copies: buffers are reused

    def _buffers(self, num_models: int, num_samples: int, steps: int) -> dict[str, Any]:
        key = (num_models, num_samples, steps)
        if key not in self._batches:
            batch, first = num_models * num_samples, self.models[0]
            ncontrol = mujoco.mj_stateSize(first, self.spec)
            self._batches[key] = {
                "models": [m for m in self.models[:num_models] for _ in range(num_samples)],
                "start": np.zeros((batch, mujoco.mj_stateSize(first, self.full))),
                "warmstart": np.zeros((batch, first.nv)), "controls": np.zeros((batch, steps, ncontrol)),
                "states": np.zeros((batch, steps, mujoco.mj_stateSize(first, self.full))),
                "sensors": np.zeros((batch, steps, first.nsensordata)),
            }  # fmt: skip
        return self._batches[key]

    def close(self) -> None:
        self._pool.close()


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Native:
    """A planning task (or an `Ensemble`) whose rollouts run in C MuJoCo; make it with
    `native`. Its numbers stay leaves (reward weights, targets: no recompile); the C
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
        pre = mjx.com_vel(
            self.model, mjx.com_pos(self.model, mjx.kinematics(self.model, pre))
        )
        return pre.replace(
            **{k: v.astype(getattr(data, k).dtype) for k, v in self.after.items()}
        )


def native(
    task: Task | Ensemble,
    *,
    num_threads: int | None = None,
    chunk_size: int | None = None,
) -> Native:
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
        raise ValueError("planning.native: the task's physics is MuJoCo Warp; native rollouts replay C MuJoCo's "
                         "states through MJX's JAX implementation: load the planning task with impl='jax'")  # fmt: skip
    from mjzoo.planning import native_checks as checks  # built on this module

    start = checks.start_state(base)
    models = _host_models(base.mj_model, variants.fields)
    present = [f for f in APPLIED if getattr(mujoco.MjData(models[0]), f).size > 0]
    probed = checks.probe(base, start, present)
    if probed.state_dependent:
        raise ValueError("planning.native: the controls this task applies depend on the physics state (e.g. a PD "
                         "actuator evaluated every physics step, or an action latency read from qpos); native "
                         "rollouts need every control before the rollout starts: plan with backend='mjx'")  # fmt: skip
    threads = physical_cores() if num_threads is None else num_threads
    engine = Engine(models, probed.n_substeps, threads, chunk_size)
    engine.vary(probed.changed)
    engine.direct = probed.direct
    result = Native(task, engine)
    checks.reads(result, start, probed)
    return result


def _host_models(
    mj_model: mujoco.MjModel, fields: dict[str, Array]
) -> list[mujoco.MjModel]:
    """One C model per ensemble member, its fields set from the ensemble's [M] values."""
    count = max((len(v) for v in fields.values()), default=1)
    models = []
    for m in range(count):
        model = copy.deepcopy(mj_model) if fields else mj_model
        for name, values in fields.items():
            if not hasattr(model, name):
                raise ValueError(
                    f"planning.native: the ensemble varies {name!r}, which the C model has no field for"
                )
            getattr(model, name)[...] = np.asarray(values[m]).reshape(
                getattr(model, name).shape
            )
        models.append(model)
    return models


def _complete(task: Task, state: State) -> State:
    """`mjzoo.complete` for a native task: the structure of a transition, found without
    tracing MJX's physics (the same structure: a stand-in returns the same `Data`)."""
    return complete(task.replace(model=_Recorder(task.model)), state)


def _applied(
    task: Task, fields: list[str], start: State, actions: Array, keys: Array
) -> Array:
    """[H, ncontrol] what the task's step applies in each of H control steps, in C's order."""
    recording = task.replace(model=_Recorder(task.model))

    def body(state: State, inputs) -> tuple[State, Array]:
        state = transition(recording, state, *inputs)
        return state, jnp.concatenate(
            [jnp.ravel(getattr(state.data, f)).astype(jnp.float32) for f in fields]
        )

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
    with_start = {k: jnp.concatenate([getattr(start.data, k)[None].astype(jnp.float32), c_states[k]])
                  for k in ("time", "qpos", "qvel", "act")}  # fmt: skip
    after = {k: v[n_substeps::n_substeps] for k, v in with_start.items()}
    after["sensordata"] = c_states["sensordata"][n_substeps - 1 :: n_substeps]
    before = {
        k: with_start[k][n_substeps - 1 :: n_substeps][:horizon]
        for k in ("qpos", "qvel")
    }

    def body(state: State, inputs) -> tuple[State, tuple[Array, Array]]:
        action, key, a, b = inputs
        state = transition(
            task.replace(model=_Replay(task.model, a, b)), state, action, key
        )
        return state, (state.reward, state.terminated)

    final, (rewards, terminated) = jax.lax.scan(
        body, start, (actions, keys, after, before), unroll=unroll
    )
    return final, rewards, terminated


def _roll(
    engine: Engine, base: Task, models: Any, start: State, controls: Array, keys: Array
) -> dict[str, Array]:
    """C rollouts of controls [N, H, nu] under each of M models ([M] leading axis of
    `models`, an `mjx.Model` batch): {field: [M, N, H x n_substeps, ...]}."""
    applied_one = lambda model, c: _applied(
        base.replace(model=model), engine.fields, start, c, keys
    )
    applied = jax.vmap(
        lambda model: jax.vmap(lambda c: applied_one(model, c))(controls)
    )(models)
    applied = jnp.repeat(
        applied, engine.n_substeps, axis=2
    )  # the same inputs every physics step
    num_models, num_samples, steps = applied.shape[:3]
    shape = (num_models, num_samples, steps)
    sizes = engine.sizes
    out_shapes = (jax.ShapeDtypeStruct(shape, jnp.float32),) + tuple(
        jax.ShapeDtypeStruct(shape + (sizes[k],), jnp.float32)
        for k in ("qpos", "qvel", "act", "sensordata")
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
    if isinstance(host, list):  # `split`'s first pass: hand C's inputs out instead
        host.append((engine, args))
        out = tuple(jnp.zeros(s.shape, s.dtype) for s in out_shapes)
    elif host is not None:  # `split`'s second pass: C's outputs come in
        out = tuple(host)
    else:
        out = jax.pure_callback(engine, out_shapes, *args, vmap_method="sequential")
    return dict(zip(C_OUTPUTS, out))


_HOST: contextvars.ContextVar = contextvars.ContextVar(
    "mjzoo_native_host", default=None
)


def split(fn: Callable) -> Callable:
    """`jax.jit(fn)` for a function that runs C MuJoCo once (a replan or a simulation
    step on `Native` tasks), as two jits around a call of C MuJoCo from the host.

    One jit reaches C through `jax.pure_callback`, which costs ~0.3 ms a call on a CPU:
    more than a whole replan's work besides physics. The first jit computes C's inputs
    (its trace of `fn` hands them out; XLA drops the rest), the host runs C, and the
    second jit computes `fn` with C's outputs passed in. Same result, same key use.
    Raises if `fn` runs C more than once (a planner that costs samples iteratively).
    """
    engines: list[Engine] = []

    def inputs(*args):
        calls: list = []
        token = _HOST.set(calls)
        try:
            fn(*args)
        finally:
            _HOST.reset(token)
        if len(calls) != 1:
            raise NotImplementedError(f"native.split: the function ran C MuJoCo {len(calls)} times; it must run it "
                                      "once (jit it whole instead: C is then called through jax.pure_callback)")  # fmt: skip
        engines[:] = [calls[0][0]]
        return calls[0][1]

    def outputs(c_states, *args):
        token = _HOST.set(c_states)
        try:
            return fn(*args)
        finally:
            _HOST.reset(token)

    first, second = jax.jit(inputs), jax.jit(outputs)

    def run(*args):
        c_inputs = first(*args)
        c_states = engines[0](*jax.tree.map(np.asarray, c_inputs))
        return second(c_states, *args)

    return run


def rollout_costs(
    task: Native,
    state: State,
    controls: Array,
    key: Array,
    terminal_value: TerminalValue | None = None,
    unroll: int = 1,
) -> tuple[Array, Array]:
    """`mjzoo.planning.rollout_costs` with the physics in C MuJoCo: ([M, N] costs,
    [] control step dt) of controls [N, H, nu] from `state`."""
    terminal_value = as_terminal_value(terminal_value)
    variants = task.task if isinstance(task.task, Ensemble) else Ensemble(task.task, {})
    base, engine = variants.task, task.engine
    start = _complete(base, state)
    keys = jax.random.split(key, controls.shape[1])
    if variants.fields:
        models = jax.vmap(lambda f: base.model.replace(**f))(variants.fields)
    else:
        models = jax.tree.map(lambda x: x[None], base.model)
    c_states = _roll(engine, base, models, start, controls, keys)

    def cost(model, actions: Array, sample: dict) -> Array:
        final, rewards, _ = _replay(
            base.replace(model=model),
            start,
            actions,
            keys,
            sample,
            engine.n_substeps,
            unroll,
        )
        value = terminal_value(model, final) if terminal_value is not None else 0.0
        return -(jnp.sum(rewards) + value)

    per_model = lambda model, states: jax.vmap(cost, in_axes=(None, 0, 0))(
        model, controls, states
    )
    costs = jax.vmap(per_model)(models, c_states)
    return costs, jnp.float32(engine.n_substeps * engine.dt)


def transition_native(task: Native, state: State, action: Array, key: Array) -> State:
    """`mjzoo.transition` with the physics of the step in C MuJoCo: a simulation that
    steps in C (one control step: one C rollout of its physics steps)."""
    if isinstance(task.task, Ensemble):
        raise TypeError(
            "planning.native: a simulation steps one model, not an Ensemble"
        )
    base = task.task
    models = jax.tree.map(lambda x: x[None], base.model)
    keys = key[None]
    c_states = _roll(task.engine, base, models, state, action[None, None], keys)
    one = jax.tree.map(lambda x: x[0, 0], c_states)
    final, _, _ = _replay(base, state, action[None], keys, one, task.engine.n_substeps)
    return final
