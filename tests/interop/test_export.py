"""Exported policies (`mjzoo.interop.export`): ONNX under onnxruntime and the jax.export
artifact against the JAX policy; the contract's observation vocabulary against hand
computations and against MJX; a hand-built cart-pole policy driving plain C MuJoCo from
the contract alone, to the return of mjzoo's JAX evaluation; `mjzoo export`.

Tolerances, from measurements (a trained cart-pole run, 4096 random observations at
scales 1 to 10): ONNX vs JAX 1e-5 absolute on actions in [-1, 1], measured <= 1.2e-6
(float32 kernels differ in summation order and transcendental approximations); the
jax.export artifact equals the jitted policy exactly (measured 0). C MuJoCo (float64) vs
MJX (float32) on cart-pole: returns within 1e-4 relative per episode, measured <= 1.2e-7
(a balancing closed loop damps the two simulators' rounding differences: their
observations stay within 6e-8 over 500 steps).
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo import learning
from mjzoo.algorithms import ppo
from mjzoo.catalog import observations
from mjzoo.envs import base
from mjzoo.envs import locomotion
from mjzoo.harness import checkpoints
from mjzoo.harness import cli
from mjzoo.harness import training
from mjzoo.harness.cli import exporting
from mjzoo.interop import deployment
from mjzoo.interop import export
from mjzoo.interop import sim2sim
from mjzoo.learning import networks
from mjzoo.learning import normalization
from mjzoo.running import reset

ONNX_ATOL = 1e-5
K = np.array([0.5, 0.0, 20.0, 1.0, 2.0])  # u = tanh(K . obs) balances the cart-pole (found by a search in C)
EPS = 0.05  # the hidden tanh unit works in its linear range: tanh(EPS z) / EPS ~ z


@pytest.fixture(scope="module")
def task():
    return mjzoo.envs.make("cartpole_balance")


def mlp_config(**changes) -> ppo.Config:
    return ppo.Config(
        num_envs=4,
        unroll_length=8,
        num_minibatches=4,
        policy_hidden_sizes=(4,),
        activation="tanh",
        total_steps=32,
        **changes,
    )


def balancing_params() -> dict:
    """MLP params computing loc ~ K . obs: one hidden tanh unit, small input weights."""
    w1 = np.zeros((5, 4), np.float32)
    w1[:, 0] = EPS * K
    w2 = np.zeros((4, 2), np.float32)
    w2[0, 0] = 1.0 / EPS
    policy = [{"kernel": jnp.asarray(w1), "bias": jnp.zeros(4)}, {"kernel": jnp.asarray(w2), "bias": jnp.zeros(2)}]
    return {"policy": policy, "obs_stats": normalization.init_stats(jnp.zeros(5))}


def random_params(recurrent: bool, seed: int = 0) -> dict:
    """Params large enough that actions spread over (-1, 1), and non-trivial observation statistics."""
    key_net, key_scale, key_mean, key_var = jax.random.split(jax.random.key(seed), 4)
    net = networks.gru_mlp(2, 8, (4,), jnp.tanh) if recurrent else networks.mlp(2, (4,), jnp.tanh)
    params = net.init(key_net, jnp.zeros(5))
    leaves, treedef = jax.tree.flatten(params)
    keys = jax.random.split(key_scale, len(leaves))
    params = jax.tree.unflatten(treedef, [x + 0.5 * jax.random.normal(k, x.shape) for x, k in zip(leaves, keys)])
    stats = normalization.RunningStats(
        mean=jax.random.normal(key_mean, (5,)),
        var=jax.random.uniform(key_var, (5,), minval=0.25, maxval=4.0),
        count=jnp.float32(100),
    )
    return {"policy": params, "obs_stats": stats}


def numpy_mlp(params: dict, obs: np.ndarray) -> np.ndarray:
    """PPO's deterministic action by hand: normalize, clip, MLP (tanh), tanh of the loc."""
    stats = params["obs_stats"]
    z = np.clip((obs - np.asarray(stats.mean)) / np.sqrt(np.asarray(stats.var) + 1e-8), -5, 5)
    (l1, l2) = params["policy"]
    hidden = np.tanh(z @ np.asarray(l1["kernel"]) + np.asarray(l1["bias"]))
    out = hidden @ np.asarray(l2["kernel"]) + np.asarray(l2["bias"])
    return np.tanh(out[:, :1])


def test_onnx_and_jax_artifacts_match_the_jax_policy(task, tmp_path):
    params = random_params(recurrent=False)
    policy = exporting.policy(ppo, mlp_config(), task, params)
    described = export.describe(task, policy)  # the first test compiles its check; later ones reuse it
    onnx_path = export.write_onnx(policy, described, tmp_path / "p.onnx")
    jax_path = export.write_jax(policy, described, tmp_path / "p.jaxexport")
    onnx_act, onnx_contract = export.load(onnx_path)[:2]
    jax_act, jax_contract = export.load(jax_path)[:2]
    assert onnx_contract == json.loads(json.dumps(described)) == jax_contract
    jitted = jax.jit(jax.vmap(lambda o: policy.apply(o, None)[0]))
    for batch in (7, 1):  # the batch size is dynamic in both artifacts
        obs = np.random.default_rng(batch).normal(0.0, 3.0, (batch, 5)).astype(np.float32)  # some clip at 5
        reference = np.asarray(jitted(obs))
        np.testing.assert_allclose(reference, numpy_mlp(params, obs), atol=1e-5)  # normalization inside
        if batch > 1:
            assert np.ptp(reference) > 0.3  # actions spread: the comparison is not of near-zeros
        onnx_error = np.max(np.abs(onnx_act(obs) - reference))
        print(f"batch {batch}: max |ONNX - JAX| = {onnx_error:.2e}")
        assert onnx_error <= ONNX_ATOL
        np.testing.assert_array_equal(jax_act(obs), reference)
    np.testing.assert_allclose(onnx_act(obs[0]), reference[0], atol=ONNX_ATOL)  # one unbatched observation


def test_recurrent_carry_round_trips(task, tmp_path):
    """Feeding each step's next carry back reproduces PPO's own recurrent acting, whose
    carry restarts at zeros where an episode starts."""
    config = mlp_config(recurrent=True, gru_hidden_size=8)
    params = random_params(recurrent=True)
    policy = exporting.policy(ppo, config, task, params)
    described = export.describe(task, policy)
    assert described["policy"]["recurrent"] and described["policy"]["inputs"][1]["shape"] == ["B", 8]
    onnx_act = export.load(export.write_onnx(policy, described, tmp_path / "r.onnx")).act
    jax_act = export.load(export.write_jax(policy, described, tmp_path / "r.jaxexport")).act
    act = ppo.acting(config, task.replace(action_dim=1), params, deterministic=True)
    step = jax.jit(jax.vmap(lambda c, o, s: act(c, o, s, None)[:2]))
    obs = np.random.default_rng(0).normal(0.0, 2.0, (6, 3, 5)).astype(np.float32)  # [T, B, obs]
    carry_ref = jnp.ones((3, 8))  # overwritten by the episode start
    carry_onnx = carry_jax = np.zeros((3, 8), np.float32)
    for t in range(6):
        carry_ref, action_ref = step(carry_ref, obs[t], jnp.full(3, t == 0))
        action_onnx, carry_onnx = onnx_act(obs[t], carry_onnx)
        action_jax, carry_jax = jax_act(obs[t], carry_jax)
        np.testing.assert_allclose(action_onnx, action_ref, atol=ONNX_ATOL)
        np.testing.assert_allclose(carry_onnx, carry_ref, atol=ONNX_ATOL)
        np.testing.assert_array_equal(action_jax, action_ref)
        np.testing.assert_array_equal(carry_jax, carry_ref)
    assert np.ptp(np.asarray(carry_ref)) > 0.3  # the carry moved: the round trip mattered
    with pytest.raises(ValueError, match="recurrent"):
        onnx_act(obs[0])


def test_contract_of_cartpole(task):
    c = export.describe(task, export.Deployable(lambda o, c: (o, c), 5, 1))
    terms = c["observation"]["terms"]
    assert [(t["source"], t["index"]) for t in terms] == [
        ("qpos", [0]),
        ("cos_qpos", [1]),
        ("sin_qpos", [1]),
        ("qvel", [0]),
        ("qvel", [1]),
    ]
    assert c["observation"]["size"] == 5 and c["observation"]["history"] == 1
    assert c["observation"]["checked"]["max_abs_error"] <= 1e-4
    assert c["model"]["joint_names"] == ["slider", "hinge"] and c["model"]["actuator_names"] == ["slide"]
    assert c["action"]["to_task"] == dict(
        type="ctrlrange_affine", formula=c["action"]["to_task"]["formula"], low=[-1.0], high=[1.0], limited=[True]
    )
    assert c["action"]["to_ctrl"]["type"] == "direct"
    assert c["physics"]["physics_dt"] == 0.01 and c["physics"]["substeps"] == 2
    assert c["physics"]["control_dt"] == pytest.approx(0.02, abs=1e-6)


def test_humanoid_terms_by_hand():
    """The humanoid's observation in the vocabulary, and `frame` on a C state whose values
    are known: torso yawed 90 degrees, moving +x in the world at 1 m/s."""
    physics = base.brax_asset("humanoid.xml", **locomotion.MJX_OPTIONS)  # humanoid_walk's, without its checks' cost
    m = physics.mj_model
    walk = locomotion.bare(physics, locomotion.free_base_observation(m))
    terms = deployment.observation_terms(walk)
    assert [t["source"] for t in terms] == [
        "body_position",
        "body_orientation",
        "qpos",
        "body_linear_velocity_local",
        "body_angular_velocity_local",
        "qvel",
    ]
    assert deployment.frame_size(terms) == 45 and terms[0]["bodies"] == ["torso"] and terms[0]["components"] == [2]
    assert terms[2]["index"] == list(range(7, m.nq)) and terms[5]["index"] == list(range(6, m.nv))
    d = mujoco.MjData(m)
    d.qpos[2] = 1.3
    d.qpos[3:7] = [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]  # yaw +90 degrees
    d.qvel[:6] = [1.0, 0.0, 0.0, 0.1, 0.2, 0.3]  # world linear, local angular
    mujoco.mj_forward(m, d)
    obs = deployment.frame(terms, m, d, np.zeros(m.nu))
    np.testing.assert_allclose(obs[0], 1.3, atol=1e-6)
    np.testing.assert_allclose(obs[1:5], d.qpos[3:7], atol=1e-6)
    np.testing.assert_allclose(obs[22:25], [0.0, -1.0, 0.0], atol=1e-6)  # +x seen from a frame yawed by 90 degrees
    np.testing.assert_allclose(obs[25:28], [0.1, 0.2, 0.3], atol=1e-6)


def test_observation_noise_is_off_for_the_contract(task):
    """The check and sim-to-sim compare noiseless observations: the noise combinators'
    scales become 0 and the observation is the bare task's again (same structure)."""
    noisy = observations.with_observation_bias(mjzoo.with_observation_noise(task, 0.3), 0.2)
    clean = deployment.without_observation_noise(noisy)
    assert jax.tree.structure(clean) == jax.tree.structure(noisy)
    key = jax.random.key(1)
    bare, clean_obs = reset(task, key).obs, reset(clean, key).obs
    assert np.max(np.abs(reset(noisy, key).obs - bare)) > 0.05
    np.testing.assert_array_equal(clean_obs, bare)


def first_three(obs):
    return obs[:3]


def test_export_names_what_it_cannot_describe(task):
    physics = base.load("cartpole.xml", ctrl_dt=0.02)
    touching = locomotion.bare(physics, observations.concat(observations.joint_positions, observations.foot_contacts))
    with pytest.raises(deployment.ContractError, match="foot_contacts"):
        deployment.observation_terms(touching)

    def own(model, state):
        return state.data.qpos

    with pytest.raises(deployment.ContractError, match="own"):
        deployment.observation_terms(locomotion.bare(physics, own))
    hidden = mjzoo.with_observation(task, first_three)
    with pytest.raises(deployment.ContractError, match="with_observation"):
        deployment.observation_terms(hidden)


def test_cartpole_policy_drives_c_mujoco_to_the_jax_return(task, tmp_path):
    """The hand-built policy, exported, balances plain C MuJoCo from the states mjzoo's JAX
    evaluation starts from, its observations built from the ONNX metadata alone; the
    task's reward on C's states gives the JAX evaluation's returns."""
    params, config, num = balancing_params(), mlp_config(), 4
    policy = exporting.policy(ppo, config, task, params)
    path = export.write_onnx(policy, export.describe(task, policy), tmp_path / "balance.onnx")
    key, steps = jax.random.key(3), int(task.time_limit)
    act = ppo.acting(config, task, params, deterministic=True)
    jax_returns = np.asarray(learning.evaluate(task, act, key, num, steps).returns)
    starts = sim2sim.starts(task, key, num)
    c_returns, errors = [], []
    for i in range(num):
        start = jax.tree.map(lambda x, i=i: x[i], starts)
        rollout = sim2sim.run_in_mujoco(
            path, task.mj_model, steps, qpos=np.asarray(start.data.qpos), qvel=np.asarray(start.data.qvel)
        )
        scored = sim2sim.replay(task, start, rollout)
        c_returns.append(scored.episode_return)
        errors.append(scored.obs_error)
    c_returns = np.asarray(c_returns)
    print(
        f"JAX returns {np.round(jax_returns, 3)}, C MuJoCo {np.round(c_returns, 3)}, "
        f"max relative difference {np.max(np.abs(c_returns / jax_returns - 1)):.2e}, obs error {max(errors):.1e}"
    )
    assert np.all(jax_returns > 450)  # balanced the whole episode (500 steps, ~1 per step)
    np.testing.assert_allclose(c_returns, jax_returns, rtol=1e-4)
    assert max(errors) <= 1e-4  # the contract's observation is the task's own, on C's states too


def test_cli_export(task, tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    config = mlp_config()
    (run / "task.json").write_text(json.dumps({"env": "cartpole_balance", "overrides": {}}))
    (run / "config.json").write_text(
        json.dumps({"algorithm": "ppo", "config": training.config_dict(config), "settings": {}})
    )
    state = ppo.init(config, task, ppo.Hyperparams(), jax.random.key(0))
    state = state.replace(params={**state.params, "policy": balancing_params()["policy"]})
    checkpoints.save(run / "checkpoints", 1, state)

    cli.main(["export", str(run)])
    act, described = export.load(run / "policy.onnx")[:2]
    assert described["source"]["env"] == "cartpole_balance" and described["source"]["step"] == 0
    np.testing.assert_allclose(act(np.array([0.0, 1.0, 0.1, 0.0, 0.0], np.float32)), np.tanh([K[2] * 0.1]), atol=0.02)
    cli.main(["export", str(run), "--format", "jax"])
    assert export.sidecar(run / "policy.jaxexport").is_file()
    capsys.readouterr()
    for argv, words in (
        ([str(run)], ("already exists", "--overwrite")),
        ([str(tmp_path / "nowhere")], ("no such run directory",)),
        ([str(run), "--out", str(tmp_path)], ("is a directory",)),
    ):
        with pytest.raises(SystemExit) as exit_info:
            cli.main(["export", *argv])
        err = capsys.readouterr().err
        assert exit_info.value.code == 2 and len(err.splitlines()) == 1, err
        assert all(w in err for w in words), err
