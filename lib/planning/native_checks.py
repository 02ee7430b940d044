"""What `mjzoo.planning.native` checks when it wraps a task, by probing it: how many
physics steps a control step takes, which applied inputs its step changes, that those do
not depend on the physics state, and that its reward and termination read nothing C
MuJoCo does not return. Each failure is one `ValueError` naming the cause. Two compiles,
neither of MJX's physics: the task's step with its physics recorded, and its replay."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjzoo.planning.ensembles import Ensemble
from mjzoo.planning.native import _HINTS
from mjzoo.planning.native import APPLIED
from mjzoo.planning.native import FROM_C
from mjzoo.planning.native import Native
from mjzoo.planning.native import _applied
from mjzoo.planning.native import _fill_transition_entries
from mjzoo.planning.native import _from_c
from mjzoo.planning.native import _Recorder
from mjzoo.planning.native import _replay
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Probe", "probe", "reads", "start_state"]

Array = jax.Array


def start_state(task: Task) -> State:
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
class Probe:
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


def probe(task: Task, start: State, present: list[str]) -> Probe:
    """Runs the task's step with its physics recorded (`_Recorder`), for probe actions,
    from `start` and from `start` with its physics state moved; raises if the step never
    reaches the physics."""
    low, high = np.asarray(task.mj_model.actuator_ctrlrange, np.float32).T
    limited = np.asarray(task.mj_model.actuator_ctrllimited, bool)
    rng = np.random.default_rng(0)
    u = rng.uniform(-1.0, 1.0, (2, task.action_size)).astype(np.float32)
    own = task.action_size == task.mj_model.nu
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
    return Probe(n_substeps, changed, actions, parts, state_dependent, bool(direct))


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


def reads(task: Native, start: State, probed: Probe) -> None:
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
