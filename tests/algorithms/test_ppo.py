"""PPO: config and hyperparameter validation, one-jit updates without retracing, exact
resume (hyperparameters included), multi-device equivalence, vmapped seeds, user
networks and optimizers, an import that loads no harness."""

from __future__ import annotations

import dataclasses
import functools
import json
import subprocess
import sys
import textwrap

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import mjzoo
import mjzoo.envs
from mjzoo.algorithms import ppo
from mjzoo.harness import checkpoints
from mjzoo.harness import training
from mjzoo.learning import networks
from tests.harness.test_distributed import block_task

SMALL = ppo.Config(num_envs=8, unroll_length=8, num_minibatches=2, num_epochs=1, total_steps=8 * 8 * 4)
BF16 = dataclasses.replace(SMALL, compute_dtype="bfloat16")
HP = ppo.Hyperparams()


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("num_envs", 0, "num_envs=0 is invalid; expected an integer >= 1"),
        ("num_minibatches", 3, "num_minibatches=3 is invalid; expected a divisor of num_envs \\* unroll_length = 64"),
        ("activation", "gelu", "activation='gelu' is invalid"),
        ("lr_schedule", "step", "lr_schedule='step' is invalid"),
        ("compute_dtype", "float16", "compute_dtype='float16' is invalid; expected float32 or bfloat16"),
    ],
)
def test_config_errors_name_the_field(field, value, message):
    fields = dict(num_envs=8, unroll_length=8, num_minibatches=2)
    with pytest.raises(ValueError, match=message):
        ppo.Config(**{**fields, field: value})


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("discount", 1.5, "discount=1.5 is invalid; expected in \\[0.0, 1.0\\]"),
        ("learning_rate", 0.0, "learning_rate=0.0 is invalid; expected in \\(0.0, inf\\)"),
        ("clip_epsilon", -0.1, "clip_epsilon=-0.1 is invalid"),
        ("entropy_coef", "big", "entropy_coef='big' is invalid; expected a number"),
        ("learning_rate", np.array([1e-3, -1.0]), "learning_rate=\\[0.001, -1.0\\] is invalid"),  # every element
    ],
)
def test_hyperparameter_errors_name_the_field(field, value, message):
    with pytest.raises(ValueError, match="^ppo.Hyperparams: " + message):
        ppo.Hyperparams(**{field: value})


def test_configure_splits_one_flat_dict_and_names_unknown_fields():
    config, hp = ppo.configure(num_envs=8, unroll_length=8, num_minibatches=2, learning_rate=1e-3, max_grad_norm=None)
    assert config == ppo.Config(num_envs=8, unroll_length=8, num_minibatches=2)
    assert hp == ppo.Hyperparams(learning_rate=1e-3, max_grad_norm=float("inf"))  # None: off, as before
    with pytest.raises(
        ValueError,
        match=r"ppo.configure: unknown field\(s\) \['lerning_rate'\] \(did you mean 'learning_rate'\?\); fields: \[.*'learning_rate'",
    ):
        ppo.configure(lerning_rate=1e-3)
    with pytest.raises(ValueError, match="ppo.Hyperparams: gae_lambda=2.0 is invalid"):
        ppo.configure(gae_lambda=2.0)


def test_importing_ppo_loads_no_harness():
    code = "import sys, mjzoo.algorithms.ppo, mjzoo.algorithms.amp; print(sorted({'rich', 'imageio', 'mjzoo.harness'} & set(sys.modules)))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert result.stdout.strip() == "[]"


@pytest.fixture(scope="module")
def pendulum():
    return mjzoo.envs.make("pendulum_swingup")


@pytest.fixture(scope="module")
def small_update():
    traces = []

    def update(task, state):
        traces.append(None)
        return ppo.update(SMALL, task, state)

    return jax.jit(update), traces


def test_hyperparameters_live_in_the_state_and_change_without_a_retrace(pendulum, small_update):
    """Another learning rate is another state, not another program: the update reads it."""
    update, traces = small_update
    before = len(traces)
    steps = {}
    for rate in (1e-4, 1e-2):
        state = ppo.init(SMALL, pendulum, HP.replace(learning_rate=rate), jax.random.key(5))
        assert float(state.hyperparams.learning_rate) == np.float32(rate)
        new, _ = update(pendulum, state)
        steps[rate] = max(
            jax.tree.leaves(
                jax.tree.map(lambda a, b: float(jnp.max(jnp.abs(a - b))), state.params["policy"], new.params["policy"])
            )
        )
    assert len(traces) - before <= 1  # at most this fixture's first compile
    # Adam's steps scale with the rate (the policy's: PopArt rescales the value head whatever the rate).
    assert steps[1e-2] > 10 * steps[1e-4]


def test_update_is_one_jit_that_does_not_retrace(pendulum, small_update):
    update, traces = small_update
    state = ppo.init(SMALL, pendulum, HP, jax.random.key(0))
    state, metrics = update(pendulum, state)
    other = mjzoo.envs.make("pendulum_swingup", upright_weight=2.0, effort_weight=0.5)
    state, metrics = update(other, state)
    assert len(traces) == 1
    assert int(state.updates) == 2
    for name in ("loss/policy", "loss/value", "loss/entropy", "loss/approx_kl", "env/reward/upright"):
        assert np.isfinite(metrics[name]), name
    chex.assert_shape(state.collector.episode_return, (SMALL.num_envs,))


def test_update_changes_parameters_and_normalizer(pendulum, small_update):
    update, _ = small_update
    state = ppo.init(SMALL, pendulum, HP, jax.random.key(1))
    new, _ = update(pendulum, state)
    moved = jax.tree.map(lambda a, b: float(jnp.max(jnp.abs(a - b))), state.params, new.params)
    assert max(jax.tree.leaves(moved)) > 0
    assert float(new.obs_stats.count) == SMALL.num_envs * SMALL.unroll_length


def test_a_bfloat16_update_keeps_float32_state_and_moves_like_float32(pendulum, small_update):
    """Mixed precision: the train state stays float32, and one update's step on the
    params is the float32 update's to within bfloat16's rounding."""
    assert SMALL.compute_dtype == "float32"  # so the float32 arm is the module's compiled update
    updates = {"float32": small_update[0], "bfloat16": jax.jit(functools.partial(ppo.update, BF16))}
    states = {}
    for dtype, update in updates.items():
        state = ppo.init(dataclasses.replace(SMALL, compute_dtype=dtype), pendulum, HP, jax.random.key(2))
        states[dtype] = (state, update(pendulum, state)[0])
    (before, f32), (_, bf16) = states["float32"], states["bfloat16"]
    assert all(x.dtype == jnp.float32 for x in jax.tree.leaves(bf16.params))
    steps = [jax.tree.leaves(jax.tree.map(jnp.subtract, s.params, before.params)) for s in (f32, bf16)]
    cosine = [float(jnp.vdot(a, b) / (jnp.linalg.norm(a) * jnp.linalg.norm(b) + 1e-12)) for a, b in zip(*steps)]
    assert min(cosine) > 0.9, cosine


def test_deployable_policy_acts_within_ctrlrange(pendulum):
    state = ppo.init(SMALL, pendulum, HP, jax.random.key(2))
    act = jax.jit(ppo.policy(SMALL, pendulum))
    obs = jnp.array([-1.0, 0.0, 0.3])
    action = act(ppo.policy_params(state), obs, jax.random.key(0))
    chex.assert_shape(action, (1,))
    assert -1.0 <= float(action[0]) <= 1.0
    np.testing.assert_array_equal(action, act(ppo.policy_params(state), obs, jax.random.key(1)))  # deterministic
    sampled = ppo.policy(SMALL, pendulum, deterministic=False)
    draws = jnp.stack([sampled(ppo.policy_params(state), obs, k) for k in jax.random.split(jax.random.key(0), 8)])
    assert float(jnp.std(draws)) > 0.05


def test_vmapped_seeds_equal_separate_runs(pendulum, small_update):
    keys = jax.random.split(jax.random.key(3), 2)
    update, _ = small_update  # the lone runs: the module's compiled update, not a copy compiled again
    batched = jax.jit(jax.vmap(lambda s: ppo.update(SMALL, pendulum, s)))
    states, _ = batched(jax.vmap(lambda k: ppo.init(SMALL, pendulum, HP, k))(keys))
    for i, key in enumerate(keys):
        single, _ = update(pendulum, ppo.init(SMALL, pendulum, HP, key))
        chex.assert_trees_all_close(
            jax.tree.map(lambda x, i=i: x[i], states.params), single.params, rtol=1e-5, atol=1e-6
        )
    assert not np.allclose(states.params["value"][0]["kernel"][0], states.params["value"][0]["kernel"][1])


def test_user_network_and_optimizer(pendulum):
    """An (init, apply) pair from another library (here flax.linen) and any optax
    optimizer, given to `ppo.make` (the Config holds no callables)."""
    import flax.linen as nn

    class Tiny(nn.Module):
        @nn.compact
        def __call__(self, x):
            return nn.Dense(2)(jnp.tanh(nn.Dense(16)(x)))

    module = Tiny()
    net = networks.Network(init=lambda key, x: module.init(key, x), apply=module.apply)
    config = ppo.Config(num_envs=8, unroll_length=8, num_minibatches=2, num_epochs=1)
    algo = ppo.make(config, policy_network=net, optimizer=optax.sgd(1e-2))
    state = algo.init(pendulum, HP, jax.random.key(4))
    new, metrics = jax.jit(algo.update)(pendulum, state)
    assert "params" in new.params["policy"]  # flax's own layout, untouched by us
    moved = jax.tree.map(lambda a, b: float(jnp.max(jnp.abs(a - b))), state.params["policy"], new.params["policy"])
    assert max(jax.tree.leaves(moved)) > 0 and np.isfinite(metrics["loss/total"])
    # A function of the learning rate gets the state's (traced) rate: 10x the rate, 10x SGD's one step.
    algo = ppo.make(dataclasses.replace(config, num_minibatches=1, lr_schedule="constant"), optimizer=optax.sgd)
    steps = []
    for rate in (1e-3, 1e-2):
        state = algo.init(pendulum, HP.replace(learning_rate=rate, max_grad_norm=float("inf")), jax.random.key(4))
        new, _ = jax.jit(algo.update)(pendulum, state)
        # The policy's step: PopArt moves the value head whatever the rate.
        steps.append(jax.tree.map(jnp.subtract, new.params["policy"], state.params["policy"]))
    assert max(float(jnp.max(jnp.abs(x))) for x in jax.tree.leaves(steps[1])) > 1e-4  # far above the tolerance
    # (new - old rounds to float32 at the params' scale: ~1e-7, 10x in the first step)
    chex.assert_trees_all_close(jax.tree.map(lambda x: 10 * x, steps[0]), steps[1], rtol=1e-3, atol=3e-6)


CONFIG = ppo.Config(num_envs=8, unroll_length=8, num_minibatches=2, num_epochs=2, total_steps=8 * 8 * 4)
ALGO = ppo.make(CONFIG)  # one value for every run: they share the chunk's compile


def _train(tmp_path, name: str, resume: bool = False, hyperparams: ppo.Hyperparams | None = None):
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
    return training.run(ALGO, block_task(), settings, hyperparams)  # any task resumes alike: the cheapest


def test_a_crashed_run_resumes_to_the_same_result(tmp_path, monkeypatch):
    hp = HP.replace(learning_rate=1e-3, entropy_coef=0.0)
    whole, _ = _train(tmp_path, "whole", hyperparams=hp)
    save = checkpoints.save

    def crash_after_first(directory, step, tree):
        if checkpoints.latest_step(directory) is not None:
            raise KeyboardInterrupt("simulated crash")
        return save(directory, step, tree)

    monkeypatch.setattr(checkpoints, "save", crash_after_first)
    with pytest.raises(KeyboardInterrupt):
        _train(tmp_path, "crashed", hyperparams=hp)  # dies at its second checkpoint, after 4 of 4 updates ran
    monkeypatch.setattr(checkpoints, "save", save)
    assert checkpoints.latest_step(tmp_path / "crashed" / "checkpoints") == 128
    resumed, _ = _train(tmp_path, "crashed", resume=True)  # continues from update 2, with the checkpoint's numbers
    assert int(resumed.updates) == int(whole.updates) == 4
    assert float(resumed.hyperparams.learning_rate) == np.float32(1e-3)
    saved = json.loads((tmp_path / "crashed" / "config.json").read_text())
    assert saved["algorithm"] == "ppo" and saved["config"]["num_epochs"] == 2
    assert saved["hyperparams"]["learning_rate"] == pytest.approx(1e-3) and saved["hyperparams"]["entropy_coef"] == 0.0
    assert saved["config"] == training.config_dict(CONFIG)
    assert saved["hyperparams"] == pytest.approx(training.hyperparams_dict(hp))  # float32, as the state holds them
    chex.assert_trees_all_equal(resumed.params, whole.params)
    chex.assert_trees_all_equal(resumed.collector.env_state.obs, whole.collector.env_state.obs)
    lines = [json.loads(line) for line in (tmp_path / "crashed" / "metrics.jsonl").read_text().splitlines()]
    assert [line["step"] for line in lines] == [128, 256]  # the crashed chunk's line was cut back
    assert all("eval/return" in line for line in lines)
    assert sorted(p.name for p in (tmp_path / "crashed").iterdir()) == [
        "checkpoints",
        "config.json",
        "curves.png",
        "metrics.jsonl",
        "tensorboard",
    ]


TWO_DEVICES = textwrap.dedent(
    r"""
    import dataclasses, re, jax, jax.numpy as jnp, numpy as np
    import mjzoo
    from mjzoo.harness import devices, training
    from mjzoo.algorithms import ppo
    assert jax.device_count() == 2
    config = ppo.Config(num_envs=8, unroll_length=8, num_minibatches=2, num_epochs=2, total_steps=256)
    task = mjzoo.task(  # a block on a rail, held at x = 0.5: its programs compile in seconds
        '<mujoco><option timestep="0.05"/><worldbody><body><joint name="x" type="slide" axis="1 0 0"/>'
        '<geom type="box" size="0.1 0.1 0.1" mass="1"/></body></worldbody>'
        '<actuator><motor joint="x" ctrlrange="-1 1"/></actuator></mujoco>',
        rewards={"distance": lambda p, m, s, a, n: -((n.data.qpos[0] - 0.5) ** 2)},
        time_limit=10,
    )
    whole = dataclasses.replace(config, split_minibatches=False)  # the default splits

    def update(config, task, state):
        with devices.env_mesh_scope():  # as the harness traces its chunk
            return ppo.update(config, task, state)

    update = jax.jit(update, static_argnums=0)
    results = []
    for config_, placed in ((config, jax.devices()[:1]), (whole, jax.devices()), (config, jax.devices())):
        state = devices.shard_envs(ppo.init(config_, task, ppo.Hyperparams(), jax.random.key(0)), ppo.PER_ENV_FIELDS, placed)
        task_ = devices.replicate(task, placed)
        for _ in range(3):
            state, _ = update(config_, task_, state)
        results.append(state)
    assert len(results[1].collector.env_state.obs.sharding.device_set) == 2
    one, two, three = jax.device_get(results)  # split or not, the result of one device
    for other in (two, three):
        diff = max(jax.tree.leaves(jax.tree.map(lambda a, b: float(np.max(np.abs(a - b))), one.params, other.params)))
        print("max param difference", diff)
        np.testing.assert_allclose(one.collector.env_state.obs, other.collector.env_state.obs, atol=1e-4)
        assert diff < 1e-4

    state, task_ = results[1], devices.replicate(task, jax.devices())
    data = jax.jit(lambda t, s: ppo.collect(config, t, s, jax.random.key(1))[1])(task_, state)  # either config's

    def loop_collectives(config_):  # all-reduces in the minibatch loop's body, the busiest computation
        learn = jax.jit(lambda t, s, d: ppo.improve(config_, t, s, d, jax.random.key(2)))
        with devices.env_mesh_scope():
            hlo = learn.lower(task_, state, data).compile().as_text()
        bodies = re.split(r"\n(?=[%A-Z][^\n]*\{\n)", hlo)
        body = max(bodies, key=lambda c: len(re.findall(r" fusion\(", c)))
        return len(re.findall(r" all-reduce(?:-start)?\(", body))

    assert loop_collectives(whole) == 0  # each device computes every step whole
    assert loop_collectives(config) >= 1  # each its share, the gradients summed every step
    odd = ppo.init(dataclasses.replace(config, num_envs=5, num_minibatches=1), task, ppo.Hyperparams(), jax.random.key(0))
    try:  # an uneven split is refused, naming the fix
        devices.shard_envs(odd, ppo.PER_ENV_FIELDS)
        raise AssertionError("5 envs were split over 2 devices")
    except ValueError as error:
        assert "5 envs do not split evenly over 2 devices; make num_envs a multiple of 2" in str(error), error
    """
)


def test_two_devices_match_one_device(cpu_devices_env):
    result = subprocess.run(
        [sys.executable, "-c", TWO_DEVICES], env=cpu_devices_env(2), capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert "max param difference" in result.stdout
