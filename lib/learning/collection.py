"""Collecting experience: a batch of auto-resetting environments run by a policy for a
number of steps, time-major.

A policy acts for ONE environment (`collect` vmaps it):

    policy(carry, obs, start, key) -> (carry, action, extras)

`carry` is its recurrent state (``()`` when it has none); `start` (bool scalar) says
`obs` begins an episode, so a recurrent policy resets its carry there; `action` is
what the task takes ([action_size], e.g. `to_controls` of a squashed sample); `extras`
is any pytree the learner needs later (the pre-tanh sample, its log-probability, a
value, the carry the step started from), recorded as it is. `feed_forward` adapts a
plain ``fn(obs, key) -> (action, extras)``.

    collector = Collector.create(task, key, num_envs)
    collector, data, metrics = collect(task, policy, collector, key, num_steps)

`Collector` holds everything that continues from one collection to the next (env
states, policy carries, running episode returns), so a train state keeps it whole.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from mjzoo import batching
from mjzoo import checks
from mjzoo.combinators import AutoResetState
from mjzoo.combinators import with_auto_reset
from mjzoo.layers import find
from mjzoo.running import reset
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Collector", "Actor", "Transitions", "collect", "feed_forward"]

Array = jax.Array
PyTree = Any
# What a learner acts with: (carry, obs, start, key) -> (carry, action, extras), for one env. It
# carries memory and returns what learning needs; `mjzoo.Policy` is the plain (obs, key) -> action.
Actor = Callable[[PyTree, PyTree, Array, Array], tuple[PyTree, Array, PyTree]]


def feed_forward(fn: Callable[[PyTree, Array], tuple[Array, PyTree]]) -> Actor:
    """An `Actor` from ``fn(obs, key) -> (action, extras)``: its carry stays ``()``."""

    def policy(carry, obs, start, key):
        action, extras = fn(obs, key)
        return carry, action, extras

    return policy


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Collector:
    """What one collection hands to the next; every leaf has a leading [num_envs] axis.

    Attributes:
      env_state: `State` of each env, of the auto-resetting task.
      carry: each env's policy carry (``()`` for a feed-forward policy).
      start: bool, the env's observation begins an episode (the policy resets there).
      episode_return: float32, reward summed so far in the running episode.
      episode_length: float32, steps taken so far in the running episode.
    """

    env_state: State
    carry: PyTree
    start: Array
    episode_return: Array
    episode_length: Array

    @classmethod
    def create(cls, task: Task, key: Array, num_envs: int, carry: PyTree = ()) -> Collector:
        """`num_envs` freshly reset envs of `task` (auto-resetting) and each env's copy of
        the policy's initial `carry` (one env's carry, broadcast)."""
        num_envs = checks.integer("Collector.create", "num_envs", num_envs)
        batch = batching.sized(with_auto_reset(task), num_envs)  # Warp: a contact pool for them all
        env_state = jax.vmap(reset, in_axes=(None, 0))(batch, jax.random.split(key, num_envs))
        zeros = jnp.zeros((num_envs,), jnp.float32)
        return cls(
            env_state=env_state,
            carry=jax.tree.map(lambda c: jnp.broadcast_to(c, (num_envs,) + jnp.shape(c)), carry),
            start=jnp.ones((num_envs,), bool),
            episode_return=zeros,
            episode_length=zeros,
        )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Transitions:
    """`num_steps` steps of `num_envs` envs, every leaf [T, num_envs, ...] (time-major).

    Attributes:
      obs: the observation each action was chosen from.
      action: [T, N, action_size] what the task took.
      extras: what the policy returned beside each action.
      reward: [T, N] float32.
      terminated: [T, N] bool, the transition ended its episode in a terminal state.
      truncated: [T, N] bool, the transition cut its episode short (bootstrap from next_obs).
      start: [T, N] bool, obs begins an episode.
      next_obs: the observation each transition reached: where an episode ended, its
        true final observation (not the next episode's first), for bootstrapping.
    """

    obs: PyTree
    action: Array
    extras: PyTree
    reward: Array
    terminated: Array
    truncated: Array
    start: Array
    next_obs: PyTree


def collect(
    task: Task, policy: Actor, collector: Collector, key: Array, num_steps: int
) -> tuple[Collector, Transitions, dict[str, Array]]:
    """Runs `policy` on every env of `collector` for `num_steps` (static) steps, with one
    `lax.scan`; an env whose episode ends starts a new one at once.

    `task` gets `with_auto_reset` unless it resets itself (a curriculum's does).

    Returns:
      (collector, transitions, metrics): the collector to continue from, `Transitions`
      ([num_steps, num_envs, ...]) and scalar metrics: ``train/episode_return`` and
      ``train/episode_length``, the means over the episodes that ended in these steps
      (NaN where none did: average them with `nanmean`), ``train/episodes``, their
      number, and ``env/<name>``, the mean of each of the task's metrics.
    """
    num_steps = checks.integer("collect", "num_steps", num_steps)
    env = with_auto_reset(task)
    act = jax.vmap(policy)

    def body(c: Collector, key: Array):
        act_key, step_key = jax.random.split(key)
        num_envs = c.start.shape[0]
        carry, action, extras = act(c.carry, c.env_state.obs, c.start, jax.random.split(act_key, num_envs))
        next_state = batching.vmap_transition(
            transition, env, c.env_state, action, jax.random.split(step_key, num_envs)
        )
        done = next_state.terminated | next_state.truncated
        episode_return, episode_length = c.episode_return + next_state.reward, c.episode_length + 1.0
        ended = {
            "episodes": jnp.sum(done),
            "return": jnp.sum(jnp.where(done, episode_return, 0.0)),
            "length": jnp.sum(jnp.where(done, episode_length, 0.0)),
            "env": jax.tree.map(jnp.mean, next_state.metrics),
        }
        data = Transitions(
            obs=c.env_state.obs,
            action=action,
            extras=extras,
            reward=next_state.reward,
            terminated=next_state.terminated,
            truncated=next_state.truncated,
            start=c.start,
            next_obs=find(next_state, AutoResetState).final_obs,
        )
        c = Collector(
            env_state=next_state,
            carry=carry,
            start=done,
            episode_return=jnp.where(done, 0.0, episode_return),
            episode_length=jnp.where(done, 0.0, episode_length),
        )
        return c, (data, ended)

    collector, (data, ended) = jax.lax.scan(body, collector, jax.random.split(key, num_steps))
    episodes = jnp.sum(ended["episodes"])
    per_episode = lambda total: jnp.where(episodes > 0, total / jnp.maximum(episodes, 1), jnp.nan)
    metrics = {
        "train/episode_return": per_episode(jnp.sum(ended["return"])),
        "train/episode_length": per_episode(jnp.sum(ended["length"])),
        "train/episodes": episodes.astype(jnp.float32),
        **{f"env/{k}": jnp.mean(v) for k, v in ended["env"].items()},
    }
    return collector, data, metrics
