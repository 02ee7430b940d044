"""Reward scaling by the running spread of the discounted return, as Stable-Baselines'
`VecNormalize(norm_reward=True)` does it.

Each env keeps its running discounted return G_t = gamma * G_{t-1} + r_t (reset to 0
after the episode ends), and the variance of those returns over every env and step is
tracked with the exact merge of `mjzoo.learning.normalization`. Rewards are divided by
that spread, not shifted: subtracting a mean would change which behaviour the task
rewards (a constant alive bonus would turn into a penalty), while a scale does not.
The value function then sees returns of order 1 whatever the task's reward units.

    state = init_reward_scaling(num_envs)
    state = update_reward_scaling(state, data.reward, done, discount)   # [T, N] each
    rewards = scale_rewards(state, data.reward)                          # for GAE

The state is a pytree (`RewardScaling`) carried through training like the observation
statistics; updating with the two halves of a batch in time order, one after the other,
equals updating with the whole batch (up to float rounding).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp

from mjzoo.learning.normalization import VAR_EPS
from mjzoo.learning.normalization import RunningStats
from mjzoo.learning.normalization import init_stats
from mjzoo.learning.normalization import update_stats

__all__ = ["RewardScaling", "init_reward_scaling", "scale_rewards", "update_reward_scaling"]

Array = jax.Array


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class RewardScaling:
    """Each env's running discounted return, and the statistics of those returns.

    Attributes:
      discounted_return: [num_envs] float32, G after the last step seen (0 right after
        an episode ended).
      return_stats: scalar `RunningStats` of every G_t seen, over envs and steps.
    """

    discounted_return: Array
    return_stats: RunningStats

    def replace(self, **changes: Any) -> "RewardScaling":
        return dataclasses.replace(self, **changes)


def init_reward_scaling(num_envs: int) -> RewardScaling:
    """Returns of 0 for `num_envs` envs, and statistics of no data (var 1, so
    `scale_rewards` is the identity before the first update).

    Args:
      num_envs: static int >= 1.
    """
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"init_reward_scaling: num_envs={num_envs!r} must be an integer >= 1")
    return RewardScaling(
        discounted_return=jnp.zeros((num_envs,), jnp.float32),
        return_stats=init_stats(jnp.zeros((), jnp.float32)),
    )


def update_reward_scaling(state: RewardScaling, rewards: Array, dones: Array, discount: float | Array) -> RewardScaling:
    """Runs each env's discounted return through a time-major batch and merges every
    step's return into the statistics. For t = 0 .. T-1, per env:

      G_t  = discount * G_{t-1} + r_t       (G_{-1} = state.discounted_return)
      G_t <- 0 after it is recorded, where done_t

    then return_stats absorbs all T * num_envs values G_t (before their reset), and the
    new state holds G_{T-1} after its reset.

    Args:
      state: the state after the previous batch.
      rewards: [T, num_envs] rewards as the task gives them.
      dones: [T, num_envs] bool (or 0/1), True where the episode ended at that step
        (terminated or truncated: either way the next reward belongs to a new episode).
      discount: scalar in [0, 1], may be traced.

    Returns:
      The new `RewardScaling`.
    """
    num_envs = jnp.shape(state.discounted_return)[0]
    if jnp.ndim(rewards) != 2 or jnp.shape(rewards)[1] != num_envs or jnp.shape(dones) != jnp.shape(rewards):
        raise ValueError(
            f"update_reward_scaling: rewards {jnp.shape(rewards)} and dones {jnp.shape(dones)} must both be "
            f"[T, num_envs] with num_envs = {num_envs}"
        )
    if math.prod(jnp.shape(rewards)) == 0:
        raise ValueError(f"update_reward_scaling: the batch is empty (rewards {jnp.shape(rewards)})")
    discount = jnp.asarray(discount, jnp.float32)

    def step(g: Array, reward_and_done: tuple[Array, Array]) -> tuple[Array, Array]:
        reward, done = reward_and_done
        g = discount * g + reward
        return jnp.where(done, 0.0, g), g

    rewards = jnp.asarray(rewards, jnp.float32)
    dones = jnp.asarray(dones).astype(jnp.bool_)
    last, returns = jax.lax.scan(step, state.discounted_return, (rewards, dones))
    return RewardScaling(discounted_return=last, return_stats=update_stats(state.return_stats, returns, 2))


def scale_rewards(state: RewardScaling, rewards: Array, clip: float | Array = math.inf) -> Array:
    """rewards / sqrt(var + 1e-8), var the running variance of the discounted returns;
    no mean is subtracted. Clipped to [-clip, clip] (SB3 clips at 10; the default inf
    does not clip).

    Use the state after `update_reward_scaling` has seen these rewards, as SB3 does.

    Args:
      state: the current state.
      rewards: [...] any shape.
      clip: scalar > 0.

    Returns:
      float32 [...], same shape.
    """
    scaled = jnp.asarray(rewards, jnp.float32) / jnp.sqrt(state.return_stats.var + VAR_EPS)
    return jnp.clip(scaled, -clip, clip)
