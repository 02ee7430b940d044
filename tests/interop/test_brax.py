"""mjzoo tasks as Brax envs (`mjzoo.interop.brax`): exact agreement with `mjzoo.reset` /
`mjzoo.transition`, flags at episode ends, Brax's training wrappers under jit and vmap,
and a short run of Brax's own PPO; and the reverse, Brax envs as mjzoo tasks
(`adapter.task`): the contract on Brax's ant and double pendulum, agreement with Brax's
own steps, and a round trip.

Compiles dominate the cost of this file; each test compiles one function, taking the
task as an argument so tasks that differ only in numbers share it.
"""

from __future__ import annotations

import foreign_envs
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from brax.envs import base as brax_base
from brax.envs.wrappers import training as brax_training

import mjzoo
import mjzoo.envs
from mjzoo.interop import brax as adapter

L = 6  # the task's episode length in these tests (mjzoo's own time limit)


# --- the bare env against mjzoo.reset / mjzoo.transition ------------------------------


@jax.jit
def _both(task: mjzoo.Task, rng: jax.Array, actions: jax.Array):
    """The adapter and mjzoo side by side, from one uint32 key, over `actions` [T, nu]."""
    env = adapter.to_brax_env(task)

    def brax_body(state, action):
        state = env.step(state, action)
        return state, state

    first = env.reset(rng)
    _, brax_states = jax.lax.scan(brax_body, first, actions)

    # The key discipline the adapter documents: reset with split(rng)[1], then each step
    # splits the carried key into (next carried key, transition key).
    rng, reset_key = jax.random.split(rng)
    state = mjzoo.reset(task, jax.random.wrap_key_data(reset_key))

    def mjzoo_body(carry, action):
        state, rng = carry
        rng, key = jax.random.split(rng)
        state = mjzoo.transition(task, state, action, jax.random.wrap_key_data(key))
        return (state, rng), state

    _, mjzoo_states = jax.lax.scan(mjzoo_body, (state, rng), actions)
    return first, state, brax_states, mjzoo_states


def _actions(seed: int, steps: int = L) -> jax.Array:
    return jax.random.uniform(jax.random.PRNGKey(seed), (steps, 1), minval=-1.0, maxval=1.0)


def test_reset_and_steps_match_mjzoo_and_truncate_at_the_time_limit():
    task = mjzoo.envs.make("cartpole_balance", episode_steps=L)
    first, state, b, m = _both(task, jax.random.PRNGKey(7), _actions(0))
    np.testing.assert_array_equal(first.obs, state.obs)
    np.testing.assert_array_equal(first.pipeline_state.qpos, state.data.qpos)
    assert float(first.reward) == 0.0 and float(first.done) == 0.0
    np.testing.assert_allclose(b.obs, m.obs, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(b.pipeline_state.qvel, m.data.qvel, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(b.reward, m.reward, rtol=1e-6, atol=1e-6)
    for name in ("upright", "centered", "velocity", "effort"):
        np.testing.assert_allclose(b.metrics[f"reward/{name}"], m.metrics[f"reward/{name}"], rtol=1e-6, atol=1e-6)
    assert b.done.dtype == jnp.float32 and b.reward.dtype == jnp.float32 and b.obs.shape == (L, 5)
    # Balanced for L steps: truncated (not terminated) exactly at the limit, and Brax sees it.
    np.testing.assert_array_equal(m.truncated, [False] * (L - 1) + [True])
    assert not m.terminated.any()
    np.testing.assert_array_equal(b.done, (m.terminated | m.truncated).astype(np.float32))
    np.testing.assert_array_equal(b.info["truncation"], m.truncated.astype(np.float32))
    np.testing.assert_array_equal(mjzoo.find(b.info["mjzoo"]["state"], mjzoo.TimeLimitState).steps, np.arange(1, L + 1))
    # The carried key is split on every step.
    assert len({tuple(np.asarray(k)) for k in b.info["rng"]}) == L


def test_terminated_is_done_without_truncation():
    # fall_angle 0: the pole leans past it at once. Same structure, same compile as above.
    task = mjzoo.envs.make("cartpole_balance", episode_steps=L, fall_angle=0.0)
    _, _, b, m = _both(task, jax.random.PRNGKey(8), _actions(1))
    assert bool(m.terminated[0]) and not bool(m.truncated[0])
    assert float(b.done[0]) == 1.0 and float(b.info["truncation"][0]) == 0.0
    np.testing.assert_allclose(b.reward, m.reward, rtol=1e-6, atol=1e-6)
    # Stepped again without a reset, the bare env treats each step as an episode's first:
    # mjzoo's step counter restarts (Brax's AutoResetWrapper would also put the first
    # physics state back); mjzoo, never reset, keeps counting.
    np.testing.assert_array_equal(mjzoo.find(b.info["mjzoo"]["state"], mjzoo.TimeLimitState).steps, [1] * L)
    np.testing.assert_array_equal(mjzoo.find(m, mjzoo.TimeLimitState).steps, np.arange(1, L + 1))


# --- Brax's training wrappers, jit and vmap ---------------------------------------------

N_ENVS, T, BRAX_LIMIT = 3, 8, 4


@jax.jit
def _wrapped(task: mjzoo.Task, rng: jax.Array):
    """T zero-action steps of N_ENVS envs under Brax's own `wrap` (limit BRAX_LIMIT < L)
    and its `EvalWrapper`, as Brax PPO's evaluator stacks them."""
    env = adapter.to_brax_env(task)
    wrapped = brax_training.EvalWrapper(brax_training.wrap(env, episode_length=BRAX_LIMIT))

    def body(state, _):
        state = wrapped.step(state, jnp.zeros((N_ENVS, env.action_size)))
        record = dict(
            obs=state.obs,
            done=state.done,
            truncation=state.info["truncation"],
            reward=state.reward,
            time_limit=mjzoo.find(state.info["mjzoo"]["state"], mjzoo.TimeLimitState).steps,
        )
        return state, record

    first = wrapped.reset(jax.random.split(rng, N_ENVS))
    final, records = jax.lax.scan(body, first, None, length=T)
    return first, final, records


def test_brax_training_wrappers_under_jit_and_vmap():
    # Brax's limit (4) ends the episodes before the task's (L): the adapter's `done` is 0
    # there, so Brax reports a truncation; the next episode starts from the first state
    # Brax puts back, and mjzoo's per-episode info (its step counter) restarts with it.
    task = mjzoo.envs.make("cartpole_balance", episode_steps=L)
    first, final, r = _wrapped(task, jax.random.PRNGKey(3))
    assert r["obs"].shape == (T, N_ENVS, 5)
    assert len({tuple(np.round(np.asarray(o), 6)) for o in first.obs}) == N_ENVS  # vmapped, distinct
    ends = np.array([0, 0, 0, 1, 0, 0, 0, 1], np.float32)[:, None].repeat(N_ENVS, 1)
    np.testing.assert_array_equal(r["done"], ends)
    np.testing.assert_array_equal(r["truncation"], ends)
    np.testing.assert_array_equal(r["time_limit"], np.array([1, 2, 3, 4, 1, 2, 3, 4])[:, None].repeat(N_ENVS, 1))
    np.testing.assert_array_equal(r["obs"][3], first.obs)  # auto-reset to the first state
    np.testing.assert_array_equal(r["obs"][7], first.obs)
    np.testing.assert_allclose(r["reward"][:4], r["reward"][4:], rtol=1e-6)  # the same episode again
    eval_metrics = final.info["eval_metrics"].episode_metrics
    assert {"reward", "reward/upright", "diverged"} <= set(eval_metrics)
    np.testing.assert_allclose(eval_metrics["reward"], r["reward"][:4].sum(0), rtol=1e-5)
    assert (eval_metrics["reward/upright"] > 0).all()


class _Stub(brax_base.Env):
    """No physics: its own time limit of L steps, flagged like the adapter flags it."""

    observation_size, action_size, backend = 1, 1, "stub"

    def reset(self, rng):
        return self._state(jnp.zeros((), jnp.int32), {})

    def step(self, state, action):
        return self._state(state.info["mjzoo"]["state"].info["t"] + 1, state.info)

    def _state(self, t, info):
        done = t >= L
        rest = mjzoo.State(None, None, jnp.float32(1.0), jnp.bool_(False), done, {"t": t}, {})
        info = {**info, "mjzoo": {"state": rest}, "truncation": done.astype(jnp.float32)}
        return brax_base.State(None, jnp.zeros(1), jnp.float32(1.0), done.astype(jnp.float32), {}, info)


def test_wrap_for_training_keeps_the_task_truncation():
    for wrap, expected in ((brax_training.wrap, 0.0), (adapter.wrap_for_training, 1.0)):
        env = wrap(_Stub(), episode_length=L)

        @jax.jit
        def run(keys, env=env):
            step = lambda s, _: (env.step(s, jnp.zeros((2, 1))), None)
            return jax.lax.scan(step, env.reset(keys), None, length=L)[0]

        state = run(jax.random.split(jax.random.PRNGKey(0), 2))
        np.testing.assert_array_equal(state.done, [1.0, 1.0])
        # Brax's EpisodeWrapper reports an episode that `done` ended at its limit as not
        # truncated; wrap_for_training puts the task's flag back.
        np.testing.assert_array_equal(state.info["truncation"], [expected] * 2)


# --- interface, checks and the jax shim (no compiles) -----------------------------------


def test_interface_and_errors():
    task = mjzoo.envs.make("cartpole_balance")
    env = adapter.to_brax_env(task)
    assert (env.observation_size, env.action_size, env.backend) == (5, 1, "mjx")
    assert env.unwrapped is env and env.sys is task.model
    wrapped = adapter.wrap_for_training(env, episode_length=500)
    assert wrapped.unwrapped is env and wrapped.observation_size == 5
    with pytest.raises(TypeError, match="expected an mjzoo.Task"):
        adapter.to_brax_env("cartpole_balance")
    with pytest.raises(ValueError, match="action_repeat=2 must be 1"):
        adapter.wrap_for_training(env, episode_length=500, action_repeat=2)
    # Pytree observations travel flat and come back with their structure.
    obs = {"a": jnp.arange(3.0).reshape(3, 1), "b": jnp.float32(7.0)}
    env._obs_tree, env._obs_shapes = jax.tree.structure(obs), [(3, 1), ()]
    flat = env._flatten(obs)
    np.testing.assert_array_equal(flat, [0.0, 1.0, 2.0, 7.0])
    back = env._unflatten(flat)
    assert back["a"].shape == (3, 1) and float(back["b"]) == 7.0


def test_patch_installs_device_put_replicated_only_if_missing(monkeypatch):
    sentinel = object()
    monkeypatch.setattr(jax, "device_put_replicated", sentinel, raising=False)
    adapter.patch_brax_for_current_jax()
    assert jax.device_put_replicated is sentinel  # present: left alone
    monkeypatch.delattr(jax, "device_put_replicated")
    adapter.patch_brax_for_current_jax()
    devices = jax.local_devices()
    out = jax.device_put_replicated({"w": jnp.arange(3.0)}, devices)
    assert out["w"].shape == (len(devices), 3)
    np.testing.assert_array_equal(out["w"][0], [0.0, 1.0, 2.0])


# --- Brax's own PPO through the adapter --------------------------------------------------


@pytest.fixture
def patched_jax():
    """`patch_brax_for_current_jax`, undone after the test."""
    had = "device_put_replicated" in vars(jax)
    adapter.patch_brax_for_current_jax()
    yield
    if not had:
        vars(jax).pop("device_put_replicated", None)


def test_brax_ppo_trains_on_an_adapted_task(patched_jax):
    # Training metrics only: Brax's evaluator compiles its unroll twice on JAX 0.10 (the
    # parameters' sharding changes after the first epoch), doubling this test's cost.
    # The evaluator's wrapper stack is covered above, and benchmarks/brax_peer.py runs it.
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as ppo

    env = adapter.to_brax_env(mjzoo.envs.make("cartpole_balance"))
    progress = []
    _, params, metrics = ppo.train(
        env,
        num_timesteps=2_000,
        episode_length=500,
        num_envs=8,
        batch_size=8,
        num_minibatches=2,
        unroll_length=5,
        num_updates_per_batch=1,
        num_evals=2,
        run_evals=False,
        log_training_metrics=True,
        training_metrics_steps=1_000,
        normalize_observations=True,
        wrap_env_fn=adapter.wrap_for_training,
        network_factory=lambda *a, **k: ppo_networks.make_ppo_networks(
            *a, **k, policy_hidden_layer_sizes=(16,), value_hidden_layer_sizes=(16,)
        ),
        progress_fn=lambda step, m: progress.append((step, m)),
        seed=1,
    )
    assert progress[-1][0] == 2_000
    for key in ("training/total_loss", "training/policy_loss", "training/v_loss"):
        assert np.isfinite(metrics[key]), key
    episodes = [m for _, m in progress if "episode/sum_reward" in m]
    assert episodes, "no episode metrics were logged"
    for key in ("episode/sum_reward", "episode/reward/upright", "episode/length"):
        assert np.isfinite(episodes[-1][key]) and episodes[-1][key] > 0, key
    assert all(np.isfinite(leaf).all() for leaf in jax.tree.leaves(params))


# --- the reverse: Brax envs as mjzoo tasks (`adapter.task`) ---------------------------------


@pytest.mark.parametrize("name", ["ant", "inverted_double_pendulum"])
def test_brax_envs_pass_check_task(name):
    import brax.envs

    env = brax.envs.get_environment(name, backend="mjx")
    foreign_envs.assert_passes_check_task(adapter.task(env, episode_length=8))


def test_rewards_and_done_match_brax_own_steps():
    import brax.envs

    env = brax.envs.get_environment("inverted_double_pendulum", backend="mjx")
    task = adapter.task(env, episode_length=None)
    assert task.time_limit is None and task.action_size == 1
    actions = jnp.ones((40, 1))  # pushed one way: the poles fall
    ours, own = foreign_envs.assert_agrees_with_own(task, env, "brax", jax.random.key(11), actions, tol=1e-5)
    assert own.done.any() and not own.done.all()  # both kinds of steps were compared
    np.testing.assert_array_equal(ours.terminated, own.done == 1)  # done, with no truncation flag: terminated
    assert not np.asarray(ours.truncated).any()


def test_round_trip_gives_the_tasks_own_rewards_and_flags():
    # mjzoo task -> Brax env -> mjzoo task: the same rollout as the task's own under the key
    # discipline the Brax adapter documents (`_both` runs it), truncation included.
    task = mjzoo.envs.make("cartpole_balance", episode_steps=L)
    back = adapter.task(adapter.to_brax_env(task), episode_length=L)
    key, actions = jax.random.key(7), _actions(2)
    first, b = foreign_envs.rollout(back, key, actions)
    _, state, _, m = _both(task, jax.random.key_data(key), actions)
    np.testing.assert_array_equal(first.obs, state.obs)
    np.testing.assert_allclose(b.reward, m.reward, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(b.obs, m.obs, rtol=1e-6, atol=1e-6)
    for name in ("upright", "centered", "velocity", "effort"):  # the inner terms, as the Brax env reported them
        np.testing.assert_allclose(b.metrics[f"brax/reward/{name}"], m.metrics[f"reward/{name}"], rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(b.truncated, m.truncated)  # info["truncation"]: truncated, not terminated
    np.testing.assert_array_equal(b.terminated, m.terminated)
    assert bool(m.truncated[-1]) and not np.asarray(m.terminated).any()
    # The Brax env steps the task's model (its `sys` is swapped in while tracing).
    foreign_envs.assert_model_edits_apply(back, key, actions, b)


def test_brax_envs_that_cannot_be_tasks_are_refused():
    import brax.envs

    with pytest.raises(ValueError, match="backend is 'generalized'"):
        adapter.task(brax.envs.get_environment("inverted_double_pendulum", backend="generalized"))
    env = brax.envs.get_environment("inverted_double_pendulum", backend="mjx")
    with pytest.raises(TypeError, match="inside Brax's AutoResetWrapper"):
        adapter.task(brax_training.wrap(env, episode_length=10))
    with pytest.raises(TypeError, match="expected a brax.envs.Env"):
        adapter.task(mjzoo.envs.make("cartpole_balance"))
    with pytest.raises(ValueError, match="episode_length=0 must be an integer >= 1"):
        adapter.task(env, episode_length=0)
