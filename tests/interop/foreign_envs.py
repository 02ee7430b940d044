"""Checks shared by the tests of the adapters that run another library's env as an mjzoo
task (`mjzoo.interop.brax.task`, `mjzoo.interop.playground.task`): the contract, agreement
with the env's own reset and steps, and model edits that apply without recompiling.

Each check compiles at most one function per task structure; `rollout` counts its traces
in `TRACES`, so a test can tell a model edit shared the compiled code.
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import numpy as np

import mjzoo

TRACES = [0]  # traces of `rollout`


@jax.jit
def rollout(task: mjzoo.Task, key: jax.Array, actions: jax.Array):
    """mjzoo's reset of `task` from `key`, then a transition per action ([T, nu]):
    (first state, stacked states)."""
    TRACES[0] += 1
    state = mjzoo.reset(task, key)

    def body(state, action):
        state = mjzoo.transition(task, state, action, jax.random.key(99))
        return state, state

    return state, jax.lax.scan(body, state, actions)[1]


@functools.partial(jax.jit, static_argnums=0)
def own_rollout(env: Any, key: jax.Array, actions: jax.Array):
    """The env's own reset (from the key data of `key`, as the adapters pass it) and steps:
    (first state, stacked states). The env is static: equal by identity."""
    first = env.reset(jax.random.key_data(key))

    def body(state, action):
        state = env.step(state, action)
        return state, state

    return first, jax.lax.scan(body, first, actions)[1]


def assert_passes_check_task(task: mjzoo.Task) -> None:
    """`mjzoo.testing.check_task` over 10 steps of a task whose episode is shorter (8): the
    time limit is checked without a second compile."""
    report = mjzoo.testing.check_task(task, num_steps=10)
    assert "time_limit" in report.passed and "no_retrace" in report.passed and report.traces == 1


def assert_agrees_with_own(task: mjzoo.Task, env: Any, name: str, key: jax.Array, actions: jax.Array, tol: float):
    """The task's rollout against the env's own from one key: the same first observation,
    observations, rewards (the one term `name`) and every metric the env reports (under
    ``"<name>/"``). Returns (ours, own): the stacked states, for the checks of flags."""
    first, ours = rollout(task, key, actions)
    own_first, own = own_rollout(env, key, actions)
    np.testing.assert_array_equal(first.obs, own_first.obs)
    np.testing.assert_allclose(ours.obs, own.obs, rtol=tol, atol=tol)
    np.testing.assert_allclose(ours.reward, own.reward, rtol=tol, atol=tol)
    np.testing.assert_allclose(ours.metrics[f"reward/{name}"], own.reward, rtol=tol, atol=tol)
    assert sorted(mjzoo.reward_terms(ours)) == [name]
    for metric, values in own.metrics.items():  # the env's own components, kept apart from mjzoo's terms
        np.testing.assert_allclose(ours.metrics[f"{name}/{metric}"], values, rtol=tol, atol=tol, err_msg=metric)
    return ours, own


def assert_model_edits_apply(task: mjzoo.Task, key: jax.Array, actions: jax.Array, states: mjzoo.State) -> None:
    """`states` (`rollout(task, key, actions)`'s) differ from a rollout of the task with
    heavier bodies, which shares their trace: the env stepped the task's model, a leaf. The
    env's own numbers are trace constants, so `mjzoo.params` finds none."""
    before = TRACES[0]
    heavy = task.replace(model=task.model.replace(body_mass=task.model.body_mass * 3.0))
    _, heavy_states = rollout(heavy, key, actions)
    assert TRACES[0] == before
    assert not np.allclose(states.data.qvel, heavy_states.data.qvel)
    assert mjzoo.params(task) == {}
