"""Batched rollouts of a task's own `transition`, and the risk measures that turn costs
over a model ensemble into one cost per sample: the physics side of a sampling planner.

Cost of a control sequence (`masked_cost`): -(the task's summed reward terms up to and
including the first step whose `terminate` says terminated) - terminal_value(final
state) if the rollout never terminated, + a `termination_cost` if it did. Physics runs
on past a termination (a scan has a fixed length), but what comes after it is masked: a
fall earns nothing after it, as an episode would (truncation ends nothing here).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any
from typing import Callable

import chex
import jax
import jax.numpy as jnp

from mjzoo import batching
from mjzoo.planning.learned import TerminalValue
from mjzoo.planning.learned import as_terminal_value
from mjzoo.running import fill_transition_entries
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Ensemble", "ensemble", "base_task", "with_base", "masked_cost", "rollout_costs", "aggregate", "RISKS"]

Array = jax.Array
RISKS = ("mean", "worst", "cvar")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Ensemble:
    """A planning task with M variants of its physics: `fields` holds replacements for
    `mjx.Model` fields, each with a leading [M] axis. Plan with it where a `Task` goes."""

    task: Task
    fields: dict[str, Array]


def ensemble(task: Task, randomize: Callable, num_models: int, key: Array) -> Ensemble:
    """M models drawn by `randomize(model, key) -> {field: value}` (the same randomizers
    `mjzoo.with_domain_randomization` takes), for robust planning."""
    if num_models < 1:
        raise ValueError(f"planning.ensemble: num_models must be >= 1, got {num_models}")
    fields = jax.vmap(randomize, in_axes=(None, 0))(task.model, jax.random.split(key, num_models))
    return Ensemble(task, {k: jnp.asarray(v, getattr(task.model, k).dtype) for k, v in fields.items()})


def masked_cost(
    rewards: Array, terminated: Array, final_value: float | Array = 0.0, termination_cost: float | Array = 0.0
) -> Array:
    """[] cost of one rollout that stops counting at its first termination.

    cost = -sum_t alive_t r_t - alive_H V + termination_cost (1 - alive_H),
    alive_t = 1 if no step before t terminated (step t's own reward counts), and alive_H
    = 1 if none of the H steps did: a terminated rollout has no future to value, and
    pays the termination cost once. Masked by `jnp.where`, so NaN physics after a
    termination (a divergence guard's) stays out of the cost.

    Args:
      rewards: [H] each step's summed reward (`State.reward` after the step).
      terminated: [H] bool, `State.terminated` after each step.
      final_value: [] value of the final state (a terminal value), 0 for none.
      termination_cost: [] cost added if any step terminated.
    """
    chex.assert_rank([rewards, terminated], 1)
    ended = jnp.cumsum(terminated.astype(jnp.int32))  # terminations up to and including t
    counted = ended - terminated.astype(jnp.int32) == 0
    alive = ended[-1] == 0
    total = jnp.sum(jnp.where(counted, rewards, 0.0)) + jnp.where(alive, final_value, 0.0)
    return -total + jnp.where(alive, 0.0, termination_cost)


def rollout_costs(
    task: Task | Ensemble,
    state: State,
    controls: Array,
    key: Array,
    terminal_value: TerminalValue | None = None,
    unroll: int = 1,
    termination_cost: float | Array = 0.0,
) -> tuple[Array, Array]:
    """Costs of open-loop control sequences from `state`, by `lax.scan` over the horizon
    of the task's `transition`, vmapped over samples (and over an ensemble's models).

    Args:
      task: the planning task, or an `Ensemble` of M models of it.
      state: the start state (one environment).
      controls: [N, H, nu].
      key: step keys are drawn from it and shared by all samples (common random numbers).
      terminal_value: optional `(model, state) -> []` value of a rollout's final state,
        added to its return (`mjzoo.planning.learned`; a TypeError if not callable).
      unroll: `lax.scan` unroll of the horizon loop.
      termination_cost: [] cost added once to a rollout that terminates (`masked_cost`:
        rewards after its first termination are not counted).

    Returns:
      ([M, N] costs, M = 1 for a plain task; [] control step dt of the planning task, s).
    """
    terminal_value = as_terminal_value(terminal_value)
    variants = task if isinstance(task, Ensemble) else Ensemble(task, {})
    base = variants.task
    num_models = max(1, *(len(v) for v in variants.fields.values())) if variants.fields else 1
    start = batching.sized(fill_transition_entries(base, state), num_models * controls.shape[0])  # Warp: a pool for all
    step_keys = jax.random.split(key, controls.shape[1])

    def cost(model, sample_controls: Array) -> tuple[Array, Array]:
        planning_task = base.replace(model=model)

        def body(s: State, inputs) -> tuple[State, tuple[Array, Array]]:
            action, step_key = inputs
            s = transition(planning_task, s, action, step_key)
            return s, (s.reward, s.terminated)

        final, (rewards, terminated) = jax.lax.scan(body, start, (sample_controls, step_keys), unroll=unroll)
        value = terminal_value(model, final) if terminal_value is not None else 0.0
        return masked_cost(rewards, terminated, value, termination_cost), final.data.time

    per_sample = jax.vmap(cost, in_axes=(None, 0))
    if variants.fields:
        costs, times = jax.vmap(lambda f: per_sample(base.model.replace(**f), controls))(variants.fields)
    else:
        costs, times = jax.tree.map(lambda x: x[None], per_sample(base.model, controls))
    dt = (times[0, 0] - start.data.time) / controls.shape[1]
    return costs, dt.astype(jnp.float32)


def aggregate(costs: Array, risk: str = "mean", alpha: float | Array = 0.25) -> Array:
    """[N] one cost per sample from [M, N] costs over models.

    mean:  (1/M) sum_m c_m
    worst: max_m c_m
    cvar:  mean of the ceil(alpha M) largest c_m (the expected cost in the worst alpha tail)

    `alpha` may be traced ([]: a swept hyperparameter); the tail is then a mask over the
    models sorted worst first, so its size need not be known when tracing.
    """
    if risk == "mean":
        return jnp.mean(costs, axis=0)
    if risk == "worst":
        return jnp.max(costs, axis=0)
    if risk == "cvar":
        num_models = costs.shape[0]
        if isinstance(alpha, numbers.Real):
            tail = max(1, math.ceil(alpha * num_models - 1e-9))  # 0.28 * 25 is 7.000000000000001
            return jnp.mean(jax.lax.top_k(costs.T, tail)[0], axis=-1)
        # float32: 0.28 * 25 may land just above 7, hence the larger slack.
        tail = jnp.maximum(1.0, jnp.ceil(jnp.asarray(alpha, jnp.float32) * num_models - 1e-4))
        worst_first = -jnp.sort(-costs, axis=0)
        in_tail = jnp.arange(num_models)[:, None] < tail
        return jnp.sum(jnp.where(in_tail, worst_first, 0.0), axis=0) / tail
    raise ValueError(f"planning.aggregate: unknown risk {risk!r}; choose one of {RISKS}")


def base_task(task: Task | Ensemble | Any) -> Task:
    """The task itself, or the task inside an `Ensemble` or `mjzoo.planning.native.Native`."""
    while not isinstance(task, Task):
        task = task.task
    return task


def with_base(task: Task | Ensemble | Any, fn: Callable[[Task], Task]) -> Task | Ensemble | Any:
    """`fn` applied to the task inside any wrappers (`Ensemble`, `Native`), which are kept:
    a planner hook that changes the planning task's reward works on each of them."""
    if isinstance(task, Task):
        return fn(task)
    return dataclasses.replace(task, task=with_base(task.task, fn))
