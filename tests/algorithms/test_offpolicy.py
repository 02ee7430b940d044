"""SAC and FastTD3: config errors naming the field, one-jit updates without retracing,
the warm-up before learning, exact resume through the harness (the replay buffer
included), a vmapped sweep over seeds and a hyperparameter."""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.algorithms import fast_td3
from mjzoo.algorithms import sac
from mjzoo.harness import checkpoints
from mjzoo.harness import training
from tests.harness.test_distributed import block_task

TINY = dict(num_envs=4, batch_size=16, learning_starts=8, total_steps=4 * 4, buffer_size=64)
SMALL = {
    sac: sac.Config(**TINY, policy_hidden_sizes=(16,), critic_hidden_sizes=(16,), n_steps=2, layer_norm=True),
    fast_td3: fast_td3.Config(**TINY, policy_hidden_sizes=(16,), critic_hidden_sizes=(16,), num_atoms=11),
}
MODULES = pytest.mark.parametrize("module", [sac, fast_td3], ids=["sac", "fast_td3"])


@MODULES
@pytest.mark.parametrize(
    "field,value,message",
    [
        ("num_envs", 0, "num_envs=0 is invalid; expected an integer >= 1"),
        ("n_steps", 0, "n_steps=0 is invalid; expected an integer >= 1"),
        ("learning_starts", -1, "learning_starts=-1 is invalid; expected an integer >= 0"),
        ("activation", "gelu", "activation='gelu' is invalid"),
        ("compute_dtype", "float16", "compute_dtype='float16' is invalid; expected float32 or bfloat16"),
    ],
)
def test_config_errors_name_the_field(module, field, value, message):
    with pytest.raises(ValueError, match=message):
        module.Config(**{field: value})


def test_hyperparameter_errors_name_the_field():
    with pytest.raises(ValueError, match="tau=1.5 is invalid"):
        sac.configure(tau=1.5)
    with pytest.raises(ValueError, match="v_min=5.0 must be below v_max=1.0"):
        fast_td3.configure(v_min=5.0, v_max=1.0)
    with pytest.raises(ValueError, match="unknown field"):
        fast_td3.configure(entropy_coef=0.1)


@MODULES
def test_updates_warm_up_then_learn_in_one_jit(module):
    """Two updates of 4 envs fill the replay with 8 steps (learning_starts): the first
    reports no learning, the second learns (finite losses, new params); no retrace."""
    config, task = SMALL[module], block_task()
    chex.clear_trace_counter()  # the lambda below is one function to chex for both modules
    state = module.init(config, task, module.Hyperparams(), jax.random.key(0))
    update = jax.jit(chex.assert_max_traces(lambda t, s: module.update(config, t, s), n=1))
    first, metrics = update(task, state)
    assert int(first.replay.size) == 1 and np.isnan(metrics["loss/critic"])
    chex.assert_trees_all_equal(first.params, state.params)
    second, metrics = update(task, first)
    assert int(second.replay.size) == 2 and np.isfinite(metrics["loss/critic"])
    moved = jax.tree.map(lambda a, b: float(jnp.max(jnp.abs(a - b))), first.params["critic"], second.params["critic"])
    assert max(jax.tree.leaves(moved)) > 0
    act = module.policy(config, task)
    ctrl = jax.jit(act)(module.policy_params(second), second.collector.env_state.obs[0], jax.random.key(1))
    assert ctrl.shape == (task.action_size,) and -1 <= float(ctrl[0]) <= 1


@MODULES
def test_bfloat16_arithmetic_keeps_float32_params_and_near_float32_outputs(module):
    """Mixed precision: the same params give the critics' outputs of float32 within
    bfloat16's resolution, and an update learns with params (and gradients) in float32."""
    config, task = SMALL[module], block_task()
    mixed = dataclasses.replace(config, compute_dtype="bfloat16")
    state = module.init(mixed, task, module.Hyperparams(), jax.random.key(0))
    inputs = state.params["critic"][0]["kernel"].shape[1]  # [2, in, out]: the twins' first layer
    x = jax.random.normal(jax.random.key(1), (8, inputs))
    exact, rounded = (module._networks(c, task)[1].apply(state.params["critic"], x) for c in (config, mixed))
    assert rounded.dtype == jnp.float32 and exact.shape == rounded.shape
    np.testing.assert_allclose(rounded, exact, atol=0.03 * float(jnp.max(jnp.abs(exact))))
    assert float(jnp.max(jnp.abs(rounded - exact))) > 0  # it did round
    for _ in range(2):
        state, metrics = jax.jit(lambda s: module.update(mixed, task, s))(state)
    assert np.isfinite(metrics["loss/critic"])
    assert {leaf.dtype for leaf in jax.tree.leaves(state.params)} == {jnp.dtype(jnp.float32)}


def _run(module, tmp_path, name: str, resume: bool = False):
    settings = training.Settings(
        out_dir=tmp_path / name,
        updates_per_chunk=2,
        eval_envs=2,
        eval_steps=20,
        eval_every=1,
        checkpoint_every=1,
        video=False,
        resume=resume,
        progress=False,
    )
    return training.run(module.make(SMALL[module]), block_task(), settings)


@MODULES
def test_a_crashed_run_resumes_to_the_same_result_replay_included(module, tmp_path, monkeypatch):
    whole, _ = _run(module, tmp_path, "whole")
    save = checkpoints.save

    def crash_after_first(directory, step, tree):
        if checkpoints.latest_step(directory) is not None:
            raise KeyboardInterrupt("simulated crash")
        return save(directory, step, tree)

    monkeypatch.setattr(checkpoints, "save", crash_after_first)
    with pytest.raises(KeyboardInterrupt):
        _run(module, tmp_path, "crashed")
    monkeypatch.setattr(checkpoints, "save", save)
    resumed, _ = _run(module, tmp_path, "crashed", resume=True)
    assert int(resumed.updates) == int(whole.updates) == 4
    chex.assert_trees_all_equal(resumed.params, whole.params)
    chex.assert_trees_all_equal(resumed.replay, whole.replay)
    chex.assert_trees_all_equal(resumed.collector, whole.collector)


def test_train_vmaps_over_seeds_and_a_hyperparameter():
    config = dataclasses.replace(SMALL[fast_td3], total_steps=12)
    rates = jnp.array([1e-4, 1e-2])
    hps = jax.tree.map(lambda x: jnp.full(2, x, jnp.float32), fast_td3.Hyperparams()).replace(learning_rate=rates)
    run = jax.jit(jax.vmap(lambda hp, key: fast_td3.train(config, block_task(), hp, key)))
    states, metrics = run(hps, jax.random.split(jax.random.key(0), 2))
    assert states.updates.shape == (2,) and metrics["loss/critic"].shape == (2, 3)
    np.testing.assert_allclose(states.hyperparams.learning_rate, rates)
    first = jax.tree.leaves(states.params["policy"])[0]
    assert not np.allclose(first[0], first[1])
