"""`mjzoo.learning.collection`, `evaluation` and `actions` on a block that one
newton pushes along a frictionless slide (1 kg, dt = 0.1 s, semi-implicit Euler): from
rest, qvel after k steps is 0.1 k m/s and qpos 0.005 k (k + 1) m. The reward is the
action, episodes are truncated after 3 steps, so every number below is hand-computed."""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
from mjzoo import learning

XML = """
<mujoco model="block">
  <option timestep="0.1" integrator="Euler" gravity="0 0 0"/>
  <worldbody>
    <body name="block">
      <joint name="x" type="slide" axis="1 0 0"/>
      <geom type="box" size="0.1 0.1 0.1" mass="1"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="x"/>
    <motor joint="x" ctrllimited="true" ctrlrange="-2 4"/>
  </actuator>
</mujoco>
"""


def push(p, model, state, action, next_state):
    return action[0] + action[1]


TASK = mjzoo.task(XML, rewards={"push": push}, time_limit=3)  # obs: qpos, qvel [2]
NUM_ENVS, NUM_STEPS = 2, 7


def counting(carry, obs, start, key):
    """Pushes with 1 N (half on each motor); its carry counts the steps of the episode."""
    count = jnp.where(start, 0, carry) + 1
    return count, jnp.array([0.5, 0.5]), {"count_before": carry, "qpos": obs[0]}


@jax.jit
def collect(task, collector, key):
    return learning.collect(task, counting, collector, key, NUM_STEPS)


@pytest.fixture(scope="module")
def collected():
    collector = learning.Collector.create(TASK, jax.random.key(0), NUM_ENVS, carry=jnp.int32(0))
    return collector, *collect(TASK, collector, jax.random.key(1))


def test_transitions_are_time_major_with_the_policy_s_extras(collected):
    _, _, data, _ = collected
    chex.assert_shape([data.reward, data.start, data.terminated, data.truncated], (NUM_STEPS, NUM_ENVS))
    chex.assert_shape([data.obs, data.next_obs, data.action], (NUM_STEPS, NUM_ENVS, 2))
    np.testing.assert_allclose(data.reward, 1.0)
    np.testing.assert_array_equal(data.extras["count_before"][:, 0], [0, 1, 2, 3, 1, 2, 3])
    np.testing.assert_array_equal(data.extras["qpos"], data.obs[..., 0])


def test_episodes_restart_and_next_obs_is_the_true_final_one(collected):
    _, _, data, _ = collected
    expected_start = [True, False, False, True, False, False, True]
    np.testing.assert_array_equal(data.start[:, 0], expected_start)
    np.testing.assert_array_equal(data.truncated[:, 0], [False, False, True] * 2 + [False])
    assert not np.any(data.terminated)
    final = np.array([0.06, 0.3])  # after 3 pushes: qpos 0.005 * 3 * 4, qvel 0.3
    np.testing.assert_allclose(data.next_obs[2, 0], final, atol=1e-6)
    np.testing.assert_allclose(data.obs[3, 0], [0.0, 0.0], atol=1e-6)  # the new episode's first
    np.testing.assert_allclose(
        data.next_obs[:-1], np.where(data.truncated[:-1, :, None], data.next_obs[:-1], data.obs[1:]), atol=1e-6
    )


def test_the_collector_continues_and_metrics_count_ended_episodes(collected):
    _, collector, _, metrics = collected
    np.testing.assert_array_equal(collector.carry, [1, 1])  # one step into the third episode
    np.testing.assert_array_equal(collector.episode_return, [1.0, 1.0])
    np.testing.assert_array_equal(collector.start, [False, False])
    assert float(metrics["train/episodes"]) == 4  # two per env
    assert float(metrics["train/episode_return"]) == pytest.approx(3.0)
    assert float(metrics["train/episode_length"]) == pytest.approx(3.0)
    assert float(metrics["env/reward/push"]) == pytest.approx(1.0)


def test_no_ended_episode_reports_nan():
    collector = learning.Collector.create(TASK, jax.random.key(0), NUM_ENVS, carry=jnp.int32(0))
    _, _, metrics = jax.jit(lambda c: learning.collect(TASK, counting, c, jax.random.key(0), 2))(collector)
    assert np.isnan(metrics["train/episode_return"]) and float(metrics["train/episodes"]) == 0


def test_vmapped_collections_equal_separate_ones(collected):
    collector, *_ = collected
    keys = jax.random.split(jax.random.key(2), 2)
    stacked = jax.tree.map(lambda x: jnp.stack([x, x]), collector)
    _, batched, _ = jax.vmap(lambda c, k: collect(TASK, c, k))(stacked, keys)
    _, single, _ = collect(TASK, collector, keys[1])
    chex.assert_trees_all_close(jax.tree.map(lambda x: x[1], batched), single)


def test_feed_forward_keeps_an_empty_carry():
    policy = learning.feed_forward(lambda obs, key: (obs, {"seen": obs}))
    carry, _, extras = policy((), jnp.ones(2), jnp.bool_(True), jax.random.key(0))
    assert carry == () and extras["seen"].shape == (2,)


# --- evaluation ---------------------------------------------------------------------


@jax.jit
def evaluate(task, key):
    return learning.evaluate(task, counting, key, 3, 5, carry=jnp.int32(0))


def test_evaluation_scores_the_first_episode():
    result = evaluate(TASK, jax.random.key(0))
    np.testing.assert_allclose(result.returns, [3.0, 3.0, 3.0])  # 5 steps run, the episode is 3
    np.testing.assert_array_equal(result.lengths, [3, 3, 3])
    chex.assert_shape(result.trajectory.action, (5, 2))
    np.testing.assert_allclose(result.trajectory.next_state.data.qvel[:3, 0], [0.1, 0.2, 0.3], atol=1e-6)


def test_evaluation_reads_the_task_s_own_episode_length_on_the_host():
    result = learning.evaluate(
        TASK.replace(time_limit=jnp.int32(2)), counting, jax.random.key(0), 1, carry=jnp.int32(0)
    )
    chex.assert_shape(result.trajectory.action, (2, 2))
    assert mjzoo.episode_steps(TASK) == 3
    with pytest.raises(ValueError, match="the task has no time limit"):
        learning.evaluate(TASK.replace(time_limit=None), counting, jax.random.key(0), 1)
    with pytest.raises(TypeError, match="time limit is traced"):
        jax.jit(lambda task: learning.evaluate(task, counting, jax.random.key(0), 1, carry=jnp.int32(0)))(TASK)


# --- actions ------------------------------------------------------------------------


def test_to_controls_maps_limited_actuators_onto_their_ctrlrange():
    actions = jnp.array([[-1.0, -1.0], [0.0, 0.0], [3.0, 1.0]])
    controls = jax.jit(jax.vmap(lambda a: learning.to_controls(TASK, a)))(actions)
    np.testing.assert_allclose(controls, [[-1.0, -2.0], [0.0, 1.0], [3.0, 4.0]])  # the first is unlimited
    np.testing.assert_array_equal(learning.to_controls(TASK.replace(action_dim=2), actions), actions)
    with pytest.raises(ValueError, match=r"the action has shape \(3,\); the task takes \[..., 2\]"):
        learning.to_controls(TASK, jnp.zeros(3))
