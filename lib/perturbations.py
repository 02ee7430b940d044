"""Perturbation combinators, `Task -> Task`: sensor noise, actuator noise and domain
randomization (new physics drawn at every reset).

Noise scales are pytree leaves, so a sweep over them runs under one trace.
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo.layers import layered
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "with_observation_noise",
    "with_action_noise",
    "with_domain_randomization",
    "add_noise",
    "DomainRandomizationState",
]

Array = jax.Array
NOISE_STREAM, DRAW_STREAM = 0x0B5, 0xD4A  # fold_in tags: the inner task keeps its own key,
# so a perturbed task with zero noise replays the clean task's episodes exactly
Randomizer = Callable[[mjx.Model, Array], dict[str, Array]]


def _check_scale(name: str, scale: float) -> Array:
    if not scale >= 0:
        raise ValueError(f"{name}: scale={scale!r} must be >= 0")
    return jnp.float32(scale)


def add_noise(tree, scale: Array, key: Array):
    """`tree` plus N(0, scale^2) on every entry of every inexact leaf (one key per leaf,
    split from `key`); integer and bool leaves are returned unchanged."""
    leaves, treedef = jax.tree.flatten(tree)
    keys = jax.random.split(key, max(len(leaves), 1))
    noisy = [
        leaf + scale * jax.random.normal(k, jnp.shape(leaf), leaf.dtype)
        if jnp.issubdtype(leaf.dtype, jnp.inexact)
        else leaf
        for leaf, k in zip(leaves, keys)
    ]
    return jax.tree.unflatten(treedef, noisy)


# --- observation noise --------------------------------------------------------------


def with_observation_noise(task: Task, scale: float) -> Task:
    """Adds independent Gaussian noise N(0, scale^2) to every observation leaf.

    Applied after reset and after every step; the physics never sees it. Keeps no
    record; applied twice, the two noises add up.
    """
    scale = _check_scale("with_observation_noise", scale)
    return task.replace(start=Partial(_noisy_reset, task.start, scale), step=Partial(_noisy_obs_step, task.step, scale))


def _noisy_reset(reset_fn, scale, model, key) -> State:
    state = reset_fn(model, key)
    return state.replace(obs=add_noise(state.obs, scale, jax.random.fold_in(key, NOISE_STREAM)))


def _noisy_obs_step(step_fn, scale, model, state, action, key) -> State:
    next_state = step_fn(model, state, action, key)
    return next_state.replace(obs=add_noise(next_state.obs, scale, jax.random.fold_in(key, NOISE_STREAM)))


# --- action noise -------------------------------------------------------------------


def with_action_noise(task: Task, scale: float) -> Task:
    """Adds Gaussian noise N(0, scale^2) to the action before the inner step.

    The reward still sees the commanded action. Keeps no record.
    """
    return task.replace(step=Partial(_noisy_action_step, task.step, _check_scale("with_action_noise", scale)))


def _noisy_action_step(step_fn, scale, model, state, action, key) -> State:
    noisy = add_noise(action, scale, jax.random.fold_in(key, NOISE_STREAM))
    return step_fn(model, state, noisy, key)


# --- domain randomization -----------------------------------------------------------


class DomainRandomizationState(NamedTuple):
    """`with_domain_randomization`'s record: ``fields``, the episode's physics, the
    `mjx.Model` fields it replaces ``{name: value}``."""

    fields: dict[str, Array]
    inner: Any = ()


def with_domain_randomization(task: Task, randomize: Randomizer) -> Task:
    """Draws new physics for every episode: ``randomize(model, key) -> {field: value}``.

    `randomize` returns replacements for top-level `mjx.Model` fields (e.g.
    ``{"geom_friction": ..., "body_mass": ...}``), each with the field's shape. It may
    be a `jax.tree_util.Partial` holding its ranges as leaves. The draw happens in
    `reset`; the episode's physics is kept in a `DomainRandomizationState` (the
    returned dict) and every call of reset, step, reward and terminate sees the model
    with those fields replaced.
    """
    if not callable(randomize):
        raise TypeError(f"with_domain_randomization: randomize must be callable, got {type(randomize).__name__}")
    if not isinstance(randomize, jax.tree_util.Partial):
        randomize = jax.tree_util.Partial(randomize)
    _check_fields(task.model, randomize)
    return layered(
        task,
        DomainRandomizationState,
        start=Partial(_randomized_reset, task.start, randomize),
        step=Partial(_randomized_step, task.step),
        reward=Partial(_randomized_reward, task.reward),
        terminate=Partial(_randomized_terminate, task.terminate),
    )


def _check_fields(model: mjx.Model, randomize) -> None:
    """Fails at construction if `randomize` names unknown fields or changes shapes."""
    drawn = jax.eval_shape(randomize, model, jax.random.key(0))
    if not isinstance(drawn, dict):
        raise TypeError(
            f"with_domain_randomization: randomize must return a dict of model fields, got {type(drawn).__name__}"
        )
    fields = {f.name for f in dataclasses.fields(model)}
    for name, value in drawn.items():
        if name not in fields:
            raise KeyError(f"with_domain_randomization: mjx.Model has no field {name!r}")
        expected = jnp.shape(getattr(model, name))
        if value.shape != expected:
            raise ValueError(f"with_domain_randomization: field {name!r} must keep shape {expected}, got {value.shape}")


def _randomized(model: mjx.Model, state: State) -> tuple[mjx.Model, State]:
    """The episode's model and the state the wrapped task sees."""
    own, inner = peel(state, DomainRandomizationState)
    return model.replace(**own.fields), inner


def _randomized_reset(reset_fn, randomize, model, key) -> State:
    drawn = randomize(model, jax.random.fold_in(key, DRAW_STREAM))
    fields = {k: jnp.asarray(v, getattr(model, k).dtype) for k, v in drawn.items()}
    return wrap(reset_fn(model.replace(**fields), key), DomainRandomizationState(fields=fields))


def _randomized_step(step_fn, model, state, action, key) -> State:
    randomized, inner = _randomized(model, state)
    return wrap(step_fn(randomized, inner, action, key), peel(state, DomainRandomizationState)[0])


def _randomized_reward(reward_fn, model, state, action, next_state):
    randomized, inner = _randomized(model, state)
    return reward_fn(randomized, inner, action, peel(next_state, DomainRandomizationState)[1])


def _randomized_terminate(terminate_fn, model, state):
    return terminate_fn(*_randomized(model, state))
