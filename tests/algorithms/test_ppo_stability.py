"""PPO's stability switches, wired: the KL-adaptive rate and the KL early stop, PopArt's
value normalization, reward normalization, the entropy schedule and the non-finite step
guard, each seen in what an update does (the pieces' own numbers are tested in
tests/learning/). A block on a rail is the task: its programs compile in seconds."""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
from mjzoo import learning
from mjzoo.algorithms import ppo
from mjzoo.learning import value_normalization

XML = """
<mujoco model="block">
  <option timestep="0.05"/>
  <worldbody><body><joint name="x" type="slide" axis="1 0 0"/><geom type="box" size="0.1 0.1 0.1" mass="1"/></body></worldbody>
  <actuator><motor joint="x" ctrlrange="-1 1"/></actuator>
</mujoco>
"""


def _distance(p, model, state, action, next_state):
    return -100.0 * (next_state.data.qpos[0] - 0.5) ** 2 - 10.0  # about -35 a step at first


def _nan(model, state, action, next_state):
    return jnp.float32(jnp.nan)


BLOCK = mjzoo.task(XML, rewards={"distance": _distance}, time_limit=5)  # episodes end inside an unroll
# Every switch on, and no observation normalization: the policy a step starts from then
# gives the collected log-probabilities exactly, so the first step measures a KL of 0.
ALL_ON = ppo.Config(
    num_envs=8,
    unroll_length=8,
    num_minibatches=2,
    num_epochs=2,
    total_steps=8 * 8 * 4,
    lr_schedule="adaptive",
    entropy_schedule="linear",
    value_normalization="popart",
    reward_normalization=True,
    normalize_observations=False,
)
STEPS = ALL_ON.num_epochs * ALL_ON.num_minibatches
update = jax.jit(ppo.update, static_argnums=0)


def _max_change(a, b) -> float:
    return max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("lr_schedule", "step", "lr_schedule='step' is invalid; expected constant, linear, cosine, adaptive"),
        ("entropy_schedule", "exp", "entropy_schedule='exp' is invalid; expected constant, linear, cosine"),
        ("value_normalization", "batch", "value_normalization='batch' is invalid; expected none, running, popart"),
        ("reward_normalization", "false", "reward_normalization='false' is invalid; expected True or False"),
    ],
)
def test_config_errors_name_the_switch(field, value, message):
    with pytest.raises(ValueError, match=message):
        dataclasses.replace(ALL_ON, **{field: value})


@pytest.mark.parametrize(
    "field,value", [("target_kl", 0.0), ("max_kl", -1.0), ("final_entropy_coef", -0.1), ("max_learning_rate", 0.0)]
)
def test_hyperparameter_errors_name_the_number(field, value):
    with pytest.raises(ValueError, match=f"^ppo.Hyperparams: {field}={value} is invalid"):
        ppo.Hyperparams(**{field: value})


@pytest.mark.parametrize(
    "rate,target_kl,factor",
    [(1e-3, 1e3, 1.5), (1e-2, 1e-12, 1 / 1.5)],  # every KL far below the target / far above it
)
def test_the_adaptive_rate_follows_the_kl_step_by_step_and_carries_over(rate, target_kl, factor):
    """Each step whose KL is > 0 multiplies the rate by 1.5 (KL < target / 2) or divides
    it (KL > 2 target); a KL of 0 leaves it (an update's first step starts from the
    collecting policy: 0 up to rounding). So an update of STEPS steps moves the rate by
    factor^k, 1 <= k <= STEPS, within [1e-5, 1e-2]; the next update starts from there."""

    def steered(rate: float) -> list[float]:
        return [min(rate * factor**k, 1e-2) for k in range(1, STEPS + 1)]

    state = ppo.init(ALL_ON, BLOCK, ppo.Hyperparams(learning_rate=rate, target_kl=target_kl), jax.random.key(0))
    state, metrics = update(ALL_ON, BLOCK, state)
    once = float(state.learning_rate)
    assert np.isclose(once, steered(rate), rtol=1e-5).any(), once
    assert float(metrics["learning_rate"]) == once
    state, _ = update(ALL_ON, BLOCK, state)
    assert np.isclose(float(state.learning_rate), steered(once), rtol=1e-5).any(), float(state.learning_rate)


def test_the_adaptive_rate_stops_at_its_ceiling():
    """Every KL far below the target raises the rate by 1.5 a step; from 1e-3 under a
    ceiling of 1.2e-3 one step reaches it and the rest stay there (the default ceiling,
    rsl_rl's 1e-2, let the learning-quality runs' rates climb to 1e-2 and their KL spike
    to 10-800 in the update after)."""
    hp = ppo.Hyperparams(learning_rate=1e-3, target_kl=1e3, max_learning_rate=1.2e-3)
    state, metrics = update(ALL_ON, BLOCK, ppo.init(ALL_ON, BLOCK, hp, jax.random.key(0)))
    np.testing.assert_allclose(float(state.learning_rate), 1.2e-3, rtol=1e-6)
    np.testing.assert_allclose(float(metrics["learning_rate"]), 1.2e-3, rtol=1e-6)


@pytest.mark.parametrize("target_kl,factor", [(1e3, 1.5), (1e-12, 1 / 1.5)])
def test_the_per_update_adaptive_rate_holds_within_an_update_and_moves_once(target_kl, factor):
    """lr_schedule="adaptive_update": every step of an update runs at the rate it started
    with (the same parameters as a constant schedule at that rate), and the update's
    mean KL then moves it by exactly one factor of 1.5, for the next update."""
    per_update = dataclasses.replace(ALL_ON, lr_schedule="adaptive_update")
    constant = dataclasses.replace(ALL_ON, lr_schedule="constant")
    hp = ppo.Hyperparams(learning_rate=1e-3, target_kl=target_kl)
    start = ppo.init(per_update, BLOCK, hp, jax.random.key(3))
    moved, metrics = update(per_update, BLOCK, start)
    held, _ = update(constant, BLOCK, start)
    chex.assert_trees_all_close(moved.params, held.params, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(float(moved.learning_rate), 1e-3 * factor, rtol=1e-6)
    assert float(metrics["learning_rate"]) == float(moved.learning_rate)
    again, _ = update(per_update, BLOCK, moved)
    np.testing.assert_allclose(float(again.learning_rate), 1e-3 * factor**2, rtol=1e-6)


def test_max_kl_stops_the_update_after_the_step_that_moved_the_policy():
    """The first step measures a KL of 0 and is applied; the second measures the policy
    it moved, above the bound, and it and every later step are dropped."""
    hp = ppo.Hyperparams(learning_rate=1e-2, max_kl=1e-9)
    start = ppo.init(ALL_ON, BLOCK, hp, jax.random.key(1))
    stopped, metrics = update(ALL_ON, BLOCK, start)
    assert float(metrics["loss/kl_stopped"]) == (STEPS - 1) / STEPS
    free, free_metrics = update(ALL_ON, BLOCK, start.replace(hyperparams=start.hyperparams.replace(max_kl=jnp.inf)))
    assert float(free_metrics["loss/kl_stopped"]) == 0.0
    assert _max_change(start.params, stopped.params) > 0  # the first step
    assert _max_change(stopped.params, free.params) > 0  # and not the others


def test_a_non_finite_reward_drops_every_step_and_leaves_the_statistics():
    nan_task = mjzoo.with_reward(BLOCK, "nan", _nan, 1.0)  # outside the task's divergence guard
    start = ppo.init(ALL_ON, nan_task, ppo.Hyperparams(), jax.random.key(2))
    state, metrics = update(ALL_ON, nan_task, start)
    assert float(metrics["loss/skipped_steps"]) == 1.0
    assert _max_change(start.params, state.params) == 0.0
    assert _max_change(start.opt_state, state.opt_state) == 0.0
    kept = (state.value_stats, state.reward_scaling.return_stats)
    assert _max_change((start.value_stats, start.reward_scaling.return_stats), kept) == 0.0
    assert int(state.updates) == 1  # the run goes on


def test_popart_keeps_the_value_functions_outputs_while_its_statistics_move():
    """With a rate too small to learn anything, PopArt's rescaling is all that changes the
    value head: its outputs in return units stay, though the targets' mean moved from 0
    to below -10 (returns of the raw reward)."""
    config = dataclasses.replace(ALL_ON, lr_schedule="constant", reward_normalization=False)
    start = ppo.init(config, BLOCK, ppo.Hyperparams(learning_rate=1e-30), jax.random.key(3))
    state, _ = update(config, BLOCK, start)
    assert float(state.value_stats.count) == config.steps_per_update
    assert float(state.value_stats.mean) < -10.0

    def values(s):
        obs = s.collector.env_state.obs
        out = ppo._networks(config, BLOCK)[1].apply(s.params["value"], obs)[..., 0]
        return value_normalization.denormalize_values(s.value_stats, out)

    np.testing.assert_allclose(values(state), values(start.replace(collector=state.collector)), rtol=1e-4, atol=1e-4)


def test_reward_normalization_tracks_each_envs_discounted_return():
    """The statistics after one update are the moments of every G_t = 0.99 G_(t-1) + r_t
    of the collected rewards (G reset after an episode ends), computed here by hand."""
    start = ppo.init(ALL_ON, BLOCK, ppo.Hyperparams(), jax.random.key(4))
    collect_key, learn_key = jax.random.split(jax.random.key(6))
    collector, data, _ = jax.jit(ppo.collect, static_argnums=0)(ALL_ON, BLOCK, start, collect_key)
    state, _ = jax.jit(ppo.improve, static_argnums=0)(
        ALL_ON, BLOCK, start.replace(collector=collector), data, learn_key
    )
    rewards, ended = np.asarray(data.reward), np.asarray(data.terminated | data.truncated)
    g, returns = np.zeros(ALL_ON.num_envs), []
    for reward, end in zip(rewards, ended):
        g = 0.99 * g + reward
        returns.append(g)
        g = np.where(end, 0.0, g)
    assert ended[4].all() and not ended[5:].any()  # 5-step episodes: G restarts at step 5
    stats = state.reward_scaling.return_stats
    np.testing.assert_allclose(float(stats.mean), np.mean(returns), rtol=1e-5)
    np.testing.assert_allclose(float(stats.var), np.var(returns), rtol=1e-4)
    np.testing.assert_allclose(state.reward_scaling.discounted_return, g, rtol=1e-5)


def test_the_entropy_coefficient_decays_linearly_over_the_run():
    hp = ppo.Hyperparams(entropy_coef=0.04, final_entropy_coef=0.0)
    _, metrics = jax.jit(ppo.train, static_argnums=0)(ALL_ON, BLOCK, hp, jax.random.key(5))
    n = ALL_ON.num_updates
    np.testing.assert_allclose(metrics["loss/entropy_coef"], 0.04 * (1 - np.arange(n) / n), rtol=1e-6)


def _linear_init(key, x):
    return {"w": jnp.zeros((x.shape[-1], 1))}


def _linear_apply(params, x):
    return x @ params["w"]


def test_popart_refuses_a_value_network_it_cannot_rescale_and_running_takes_it():
    """PopArt (on by default) rescales an mlp's output layer: a value network of another
    shape is refused at init, naming the way out, and "running" takes it."""
    own = ppo.Components(value_network=learning.Network(_linear_init, _linear_apply))
    plain = ppo.Config(num_envs=8, unroll_length=8, num_minibatches=2, num_epochs=1, total_steps=64)
    assert plain.value_normalization == "popart"
    with pytest.raises(
        ValueError, match=r"value_normalization='popart' \(the default\).*set value_normalization='running'"
    ):
        ppo.init(plain, BLOCK, ppo.Hyperparams(), jax.random.key(0), components=own)
    state = ppo.init(
        dataclasses.replace(plain, value_normalization="running"),
        BLOCK,
        ppo.Hyperparams(),
        jax.random.key(0),
        components=own,
    )
    assert state.params["value"]["w"].shape == (2, 1)  # the block's observation: position and velocity
