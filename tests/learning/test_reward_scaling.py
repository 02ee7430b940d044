"""`mjzoo.learning.reward_scaling`: the running discounted return by hand (and its reset
after a done), the statistics of those returns against numpy, halves of a batch equal
to the whole, the scaling, under jit and vmap."""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.learning.reward_scaling import init_reward_scaling
from mjzoo.learning.reward_scaling import scale_rewards
from mjzoo.learning.reward_scaling import update_reward_scaling

# Two envs, three steps, discount 0.5; env 0's episode ends at t = 1.
REWARDS = jnp.array([[1.0, 2.0], [2.0, 0.0], [4.0, 4.0]])
DONES = jnp.array([[False, False], [True, False], [False, False]])
# env 0: G_0 = 1;  G_1 = 0.5 * 1 + 2 = 2.5, then reset to 0;  G_2 = 0.5 * 0 + 4 = 4.
# env 1: G_0 = 2;  G_1 = 0.5 * 2 + 0 = 1;  G_2 = 0.5 * 1 + 4 = 4.5.
RETURNS = np.array([1.0, 2.5, 4.0, 2.0, 1.0, 4.5])


def test_running_return_resets_after_a_done():
    state = update_reward_scaling(init_reward_scaling(2), REWARDS, DONES, 0.5)
    np.testing.assert_allclose(state.discounted_return, [4.0, 4.5])
    stats = state.return_stats
    np.testing.assert_allclose([stats.mean, stats.var, stats.count], [RETURNS.mean(), RETURNS.var(), 6.0], rtol=1e-6)
    # Without the done, env 0 would go on from 2.5: G_2 = 1.25 + 4 = 5.25.
    no_done = update_reward_scaling(init_reward_scaling(2), REWARDS, jnp.zeros_like(DONES), 0.5)
    np.testing.assert_allclose(no_done.discounted_return, [5.25, 4.5])


def test_a_done_at_the_last_step_resets_the_carried_return():
    dones = DONES.at[2, 1].set(True)
    state = update_reward_scaling(init_reward_scaling(2), REWARDS, dones, 0.5)
    np.testing.assert_allclose(state.discounted_return, [4.0, 0.0])
    # The return of that step (4.5) is still counted before its reset.
    np.testing.assert_allclose(state.return_stats.mean, RETURNS.mean(), rtol=1e-6)


def test_halves_of_a_batch_equal_the_whole():
    rng = np.random.default_rng(0)
    rewards = jnp.asarray(rng.normal(1.0, 2.0, size=(8, 4)), jnp.float32)
    dones = jnp.asarray(rng.uniform(size=(8, 4)) < 0.2)
    start = update_reward_scaling(init_reward_scaling(4), rewards[:3], dones[:3], 0.9)  # not the initial state
    whole = update_reward_scaling(start, rewards, dones, 0.9)
    halves = update_reward_scaling(
        update_reward_scaling(start, rewards[:5], dones[:5], 0.9), rewards[5:], dones[5:], 0.9
    )
    chex.assert_trees_all_close(whole, halves, rtol=1e-5)
    assert whole.return_stats.count == 3 * 4 + 8 * 4


def test_scale_rewards_hand_computed():
    state = update_reward_scaling(init_reward_scaling(2), REWARDS, DONES, 0.5)
    std = RETURNS.std()  # var = 1.9583..., no mean subtracted from the rewards
    np.testing.assert_allclose(scale_rewards(state, REWARDS), np.asarray(REWARDS) / std, rtol=1e-5)
    # Clipping: 4 / 1.399 = 2.86 -> 2.
    np.testing.assert_allclose(
        scale_rewards(state, jnp.array([4.0, -4.0, 1.0]), clip=2.0), [2.0, -2.0, 1 / std], rtol=1e-5
    )
    # Before any update the variance is 1: the identity.
    np.testing.assert_allclose(scale_rewards(init_reward_scaling(2), REWARDS), REWARDS, rtol=1e-6)


def test_jit_and_vmap_over_discounts():
    """Three discounts at once: each env 0 return hand-computed as in the first test."""
    discounts = jnp.array([0.0, 0.5, 1.0])
    run = jax.jit(jax.vmap(lambda d: update_reward_scaling(init_reward_scaling(2), REWARDS, DONES, d)))
    states = run(discounts)
    # discount 0: G = r -> [4, 4];  0.5: [4, 4.5];  1: env 0 resets -> 4, env 1: 2 + 0 + 4 = 6.
    np.testing.assert_allclose(states.discounted_return, [[4.0, 4.0], [4.0, 4.5], [4.0, 6.0]])
    # discount 0: the returns are the rewards [1, 2, 4, 2, 0, 4]: mean 13 / 6.
    np.testing.assert_allclose(states.return_stats.mean[0], 13 / 6, rtol=1e-6)
    scaled = jax.jit(jax.vmap(scale_rewards, (0, None)))(states, jnp.float32(1.0))
    np.testing.assert_allclose(scaled[1], 1 / RETURNS.std(), rtol=1e-5)
    rewards = np.array([1.0, 2.0, 4.0, 2.0, 0.0, 4.0])
    np.testing.assert_allclose(scaled[0], 1 / rewards.std(), rtol=1e-5)


def test_bad_shapes_and_sizes_raise():
    with pytest.raises(ValueError, match="init_reward_scaling: num_envs=0 must be an integer >= 1"):
        init_reward_scaling(0)
    with pytest.raises(ValueError, match=r"update_reward_scaling: rewards \(3, 3\) and dones \(3, 3\) must both be"):
        update_reward_scaling(init_reward_scaling(2), jnp.zeros((3, 3)), jnp.zeros((3, 3), bool), 0.9)
    with pytest.raises(ValueError, match="update_reward_scaling: the batch is empty"):
        update_reward_scaling(init_reward_scaling(2), jnp.zeros((0, 2)), jnp.zeros((0, 2), bool), 0.9)
