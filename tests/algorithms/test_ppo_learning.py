"""PPO learns real tasks from scratch: cartpole balance, and a partially observed
cartpole with a GRU policy. A module of its own (minutes of CPU), so xdist runs it
beside the rest of the PPO tests."""

from __future__ import annotations

import jax

import mjzoo
import mjzoo.envs
from mjzoo.algorithms import ppo
from mjzoo.harness import training


def test_learns_cartpole_balance():
    """From a random policy (return ~40 of ~550) to balancing for the whole episode."""
    task = mjzoo.envs.make("cartpole_balance")
    config, hp = ppo.configure(**{**mjzoo.envs.hyperparameters("cartpole_balance", "ppo"), "total_steps": 163_840})
    before = ppo.evaluate(
        config, task, ppo.init(config, task, hp, jax.random.key(0)), jax.random.key(1), 16, 500
    ).returns.mean()
    settings = training.Settings(updates_per_chunk=10, eval_envs=16, eval_steps=500, progress=False)
    state, last = training.run(ppo.make(config), task, settings, hp)
    assert float(before) < 150
    assert last["eval/return"] > 500


def positions_only(obs):
    """Cart position and the pole angle's cos and sin: no velocities."""
    return obs[:3]


def test_recurrent_gru_policy_learns_a_partially_observed_task():
    """Without velocities, balancing needs memory: a GRU policy solves it (an MLP with
    4x this budget reached ~270 of ~550 when this was calibrated; the GRU passed 500 by
    82k steps, and stayed above 400 to 410k). Clipping at 0.1, not 0.2: with 0.2 some
    seeds learned and lost it again (544 then 384 at the end), and which ones changed with
    XLA's rounding; with 0.1, 11 runs (seeds 0-7, two auto-reset forms) all ended >= 527."""
    task = mjzoo.with_observation(mjzoo.envs.make("cartpole_balance"), positions_only)
    config, hp = ppo.configure(
        num_envs=64,
        unroll_length=32,
        num_minibatches=4,
        num_epochs=4,
        learning_rate=1e-3,
        clip_epsilon=0.1,
        entropy_coef=1e-3,
        recurrent=True,
        total_steps=163_840,
    )
    settings = training.Settings(updates_per_chunk=20, eval_envs=16, eval_steps=500, progress=False)
    state, last = training.run(ppo.make(config), task, settings, hp)
    assert jax.tree.leaves(state.collector.carry)[0].shape == (64, config.gru_hidden_size)
    assert last["eval/return"] > 450
