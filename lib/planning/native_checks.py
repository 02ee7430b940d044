"""What `mjzoo.planning.native` checks when it wraps a task, by probing it: how many
physics steps a control step takes, which applied inputs its step changes, that those do
not depend on the physics state, and that its reward and termination read nothing C
MuJoCo does not return. Each failure is one `ValueError` naming the cause."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from mjzoo.planning.native import (
    _HINTS,
    APPLIED,
    FROM_C,
    Native,
    _applied,
    _Recorder,
    _replay,
    _roll,
)
from mjzoo.planning.rollouts import Ensemble
from mjzoo.running import transition
from mjzoo.types import State, Task

__all__ = ["applied_without_state", "changed", "reads", "substeps"]

Array = jax.Array


def substeps(task: Task, start: State) -> int:
    """Physics steps per control step, counted by recording one transition."""
    recording = task.replace(model=_Recorder(task.model))
    after = jax.jit(lambda s: transition(recording, s, jnp.zeros(task.action_size), jax.random.key(0)))(start)
    count = round(float(after.data.time - start.data.time) / float(task.mj_model.opt.timestep))
    if count < 1:
        raise ValueError("planning.native: the task's step never reached mjzoo.physics.step or substep with the "
                         "model it was given (e.g. it replaces model fields per episode, as domain randomization "
                         "does); plan with backend='mjx', or randomize with planning.ensemble")  # fmt: skip
    return count


def _perturbed(tree: Any, seed: int) -> Any:
    """Every float leaf moved by N(0, 0.1), every integer leaf by one (dtypes kept)."""
    rng = np.random.default_rng(seed)

    def move(leaf):
        leaf = np.asarray(leaf)
        if np.issubdtype(leaf.dtype, np.floating):
            return (leaf + 0.1 * rng.standard_normal(leaf.shape)).astype(leaf.dtype)
        return leaf + np.ones((), leaf.dtype) if np.issubdtype(leaf.dtype, np.integer) else leaf

    return jax.tree.map(move, tree)


def _probe_controls(task: Native, key: Array) -> Array:
    base = task.task.task if isinstance(task.task, Ensemble) else task.task
    low, high = np.asarray(base.mj_model.actuator_ctrlrange, np.float32).T
    limited = np.asarray(base.mj_model.actuator_ctrllimited, bool)
    u = jax.random.uniform(key, (2, base.action_size), minval=-1.0, maxval=1.0)
    if base.action_size == base.mj_model.nu:
        u = jnp.where(limited, low + (u + 1) / 2 * (high - low), u)
    return u


def changed(task: Native, start: State) -> list[str]:
    """The applied inputs (`APPLIED`) the task's step changes, for probe actions."""
    base = task.task.task if isinstance(task.task, Ensemble) else task.task
    actions, keys = _probe_controls(task, jax.random.key(1)), jax.random.split(jax.random.key(2), 2)
    present = task.engine.present
    applied = np.asarray(jax.jit(lambda s: _applied(base, present, s, actions, keys))(start))
    sizes = [np.size(getattr(start.data, f)) for f in present]
    parts = np.split(applied, np.cumsum(sizes)[:-1], axis=1)
    return [f for f, part in zip(present, parts) if not np.allclose(part, np.ravel(getattr(start.data, f)))]


def applied_without_state(task: Native, start: State) -> None:
    """Raises if what the task's step applies changes with the physics state alone."""
    base = task.task.task if isinstance(task.task, Ensemble) else task.task
    actions, keys = _probe_controls(task, jax.random.key(1)), jax.random.split(jax.random.key(2), 2)
    applied = jax.jit(lambda s: _applied(base, task.engine.fields, s, actions, keys))
    moved = start.replace(data=start.data.replace(**_perturbed({k: getattr(start.data, k) for k in ("qpos", "qvel", "act", "time")}, 3)))  # fmt: skip
    if not np.allclose(applied(start), applied(moved), atol=1e-6):
        raise ValueError("planning.native: the controls this task applies depend on the physics state (e.g. a PD "
                         "actuator evaluated every physics step, or an action latency read from qpos); native "
                         "rollouts need every control before the rollout starts: plan with backend='mjx'")  # fmt: skip


def reads(task: Native, start: State) -> None:
    """Raises, naming the fields, if the task's reward or termination reads any part of
    `data` that C MuJoCo does not return and the replay does not recompute."""
    base = task.task.task if isinstance(task.task, Ensemble) else task.task
    engine = task.engine
    actions, keys = _probe_controls(task, jax.random.key(1)), jax.random.split(jax.random.key(2), 2)
    models = jax.tree.map(lambda x: x[None], base.model)
    c_states = jax.jit(lambda s: _roll(engine, base, models, s, actions[None], keys))(start)
    one = jax.tree.map(lambda x: x[0, 0], c_states)
    outcome = jax.jit(lambda s: _replay(base, s, actions, keys, one, engine.n_substeps)[1:])
    start = jax.tree.map(np.asarray, start)  # numpy leaves: perturbed copies share one trace
    reference = outcome(start)
    fields = [f.name for f in dataclasses.fields(start.data) if f.name not in FROM_C + APPLIED]
    fields += [f"_impl.{f.name}" for f in dataclasses.fields(start.data._impl)] if hasattr(start.data, "_impl") else []
    read = []
    for i, name in enumerate(fields):
        if name == "_impl":
            continue
        owner, attr = (start.data._impl, name[6:]) if name.startswith("_impl.") else (start.data, name)
        value = getattr(owner, attr)
        if not any(isinstance(leaf, np.ndarray) for leaf in jax.tree.leaves(value)):
            continue  # a static field (sizes), not data
        moved_owner = owner.replace(**{attr: _perturbed(value, 10 + i)})
        data = start.data.replace(_impl=moved_owner) if owner is not start.data else moved_owner
        got = outcome(start.replace(data=data))
        if not all(np.array_equal(a, b, equal_nan=True) for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(reference))):
            read.append(name.removeprefix("_impl."))
    if read:
        hints = sorted({hint for name in read for key, hint in _HINTS.items() if name.startswith(key)})
        raise ValueError(f"planning.native: this task's reward or termination reads data.{', data.'.join(read)}, which "
                         "exists only inside C MuJoCo's step (mujoco.rollout returns states and sensors)"
                         + (f"; read {' or '.join(hints)} from data.sensordata instead" if hints else "")
                         + ", or plan with backend='mjx'")  # fmt: skip


def direct(task: Native, start: State) -> bool:
    """Whether the task's step applies its action as ctrl and nothing else per step (its
    ctrl is the action, clipped to ctrlrange where C clamps it anyway): then a rollout's
    controls are its actions, with no step of the task to compute them."""
    base = task.task.task if isinstance(task.task, Ensemble) else task.task
    if task.engine.fields != ["ctrl"] or base.action_size != base.mj_model.nu:
        return False
    low, high = np.asarray(base.mj_model.actuator_ctrlrange, np.float32).T
    limited = np.asarray(base.mj_model.actuator_ctrllimited, bool)
    actions = 2.0 * _probe_controls(task, jax.random.key(4))  # beyond the range too
    applied = jax.jit(lambda s: _applied(base, ["ctrl"], s, actions, jax.random.split(jax.random.key(5), 2)))(start)
    clamped = np.where(limited, np.clip(actions, low, high), actions)
    return bool(np.allclose(applied, actions, atol=1e-6) or np.allclose(applied, clamped, atol=1e-6))
