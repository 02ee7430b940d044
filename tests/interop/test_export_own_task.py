"""A task that observes with a function of its own (`mjzoo.task(observe=...)`, as
docs/own-task.md teaches) deploys: `export.end_to_end` exports its policy from the
physics state, its observation inside, which plain `jax.export` runs and C MuJoCo
drives; the contract's formats name the term they cannot describe and say what to do.

Tolerances, from measurements: the deserialized artifact against the in-process PPO
policy on MJX states of a rollout 1e-6 absolute on actions in the ctrlrange (the same
float32 program, lowered once more: measured 0 over 36 states); C MuJoCo's observation against the
one recomputed by hand from its own data 1e-5 (the artifact reads float32 copies of C's
float64 fields).
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo.algorithms import ppo
from mjzoo.harness import checkpoints
from mjzoo.harness import cli
from mjzoo.harness import training
from mjzoo.harness.cli import exporting
from mjzoo.interop import deployment
from mjzoo.interop import export
from mjzoo.interop import sim2sim
from mjzoo.learning import normalization

ARM = """
<mujoco model="arm">
  <compiler angle="radian"/>
  <option timestep="0.01"><flag contact="disable"/></option>
  <default><joint type="hinge" axis="0 0 1" damping="0.01"/><geom type="capsule" size="0.01"/></default>
  <worldbody>
    <body name="upper">
      <joint name="shoulder"/><geom fromto="0 0 0 0.12 0 0"/>
      <body name="lower" pos="0.12 0 0">
        <joint name="elbow"/><geom fromto="0 0 0 0.12 0 0"/><site name="tip" pos="0.12 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor joint="shoulder" gear="0.05" ctrlrange="-1 1"/><motor joint="elbow" gear="0.05" ctrlrange="-1 2"/>
  </actuator>
</mujoco>
"""
INPUTS = {"qpos": [2], "qvel": [2], "site_xpos": [1, 3], "info['goal']": [2]}  # what `observe` reads


def random_arm(p, model, data, key):
    return data.replace(qpos=jax.random.uniform(key, (2,), minval=-3.0, maxval=3.0), qvel=jnp.array([1.0, -2.0]))


def random_goal(p, model, data, key):
    return data, {"goal": jax.random.uniform(key, (2,), minval=-0.2, maxval=0.2)}


def observe(p, model, state):  # [8]: cos, sin of both angles, their velocities, goal - tip
    q = state.data.qpos
    tip = state.data.site_xpos[0, :2]
    return jnp.concatenate([jnp.cos(q), jnp.sin(q), state.data.qvel, state.info["goal"] - tip])


def make_task(**params):
    return mjzoo.task(
        ARM, observe=observe, start=random_arm, resets=(random_goal,), time_limit=50, params=params, ctrl_dt=0.02
    )


def by_hand(qpos, qvel, tip, goal):  # `observe` in NumPy, [..., 8]
    return np.concatenate([np.cos(qpos), np.sin(qpos), qvel, goal - tip[..., :2]], axis=-1)


def config() -> ppo.Config:
    return ppo.Config(
        num_envs=4, unroll_length=8, num_minibatches=4, policy_hidden_sizes=(8,), activation="tanh", total_steps=32
    )


@pytest.fixture(scope="module")
def task():
    return make_task()


@pytest.fixture(scope="module")
def params(task):
    """PPO's policy with weights large enough that actions spread, and non-trivial statistics."""
    state = ppo.init(config(), task, ppo.Hyperparams(), jax.random.key(0))
    leaves, treedef = jax.tree.flatten(state.params["policy"])
    keys = jax.random.split(jax.random.key(1), len(leaves) + 2)
    policy = jax.tree.unflatten(treedef, [x + jax.random.normal(k, x.shape) for x, k in zip(leaves, keys)])
    stats = normalization.RunningStats(
        mean=0.3 * jax.random.normal(keys[-2], (8,)),
        var=jax.random.uniform(keys[-1], (8,), minval=0.25, maxval=4.0),
        count=jnp.float32(100),
    )
    return {"policy": policy, "obs_stats": stats}


@pytest.fixture(scope="module")
def e2e(task, params):
    return export.end_to_end(task, exporting.policy(ppo, config(), task, params))


def test_own_observation_exports_end_to_end(task, params, e2e, tmp_path):
    """The artifact, deserialized by plain jax.export (no mjzoo), gives the in-process
    policy's actions on MJX's states of a rollout; it reads what `observe` reads."""
    assert {i["name"]: i["shape"][1:] for i in e2e.contract["inputs"]} == INPUTS
    assert e2e.contract["physics"]["control_dt"] == pytest.approx(0.02) and e2e.contract["physics"]["substeps"] == 2
    path = export.write_end_to_end(e2e, tmp_path / "arm.jaxexport")
    exported = jax.export.deserialize(bytearray(path.read_bytes()))
    act = ppo.acting(config(), task, params, deterministic=True)

    def run(key):  # the in-process policy in MJX: its states and its actions on them
        policy = lambda obs, _: act((), obs, jnp.zeros((), bool), None)[1]  # noqa: E731
        return mjzoo.rollout(task, policy, mjzoo.reset(task, key), key, 12)[1]

    trajectory = jax.jit(jax.vmap(run))(jax.random.split(jax.random.key(2), 3))
    states = jax.tree.map(lambda x: x.reshape(x.shape[0] * x.shape[1], *x.shape[2:]), trajectory.next_state)
    want = np.asarray(jax.jit(jax.vmap(lambda obs: act((), obs, False, None)[1]))(states.obs))
    out = exported.call(export.inputs_of(e2e, states))
    error = float(np.max(np.abs(np.asarray(out["action"]) - want)))
    print(f"max |artifact - in-process policy| = {error:.2e} over {len(want)} states, {path.stat().st_size} bytes")
    assert error <= 1e-6
    np.testing.assert_array_equal(out["obs"], states.obs)  # the task's own observation, inside
    np.testing.assert_array_equal(out["next info['goal']"], states.info["goal"])
    low, high = np.array([-1.0, -1.0]), np.array([1.0, 2.0])
    assert np.all((want >= low) & (want <= high)) and np.ptp(want) > 0.5  # task actions in ctrlrange, spread out


def test_c_mujoco_runs_the_own_task_from_the_artifact(task, e2e, tmp_path):
    """`run_in_mujoco` drives C MuJoCo with the artifact alone: MjData's fields and the
    goal in, the action straight to ctrl, the control step kept."""
    path = export.write_end_to_end(e2e, tmp_path / "arm.jaxexport")
    with pytest.raises(ValueError, match="info\\['goal'\\]"):
        sim2sim.run_in_mujoco(path, task.mj_model, 2)
    goal = np.array([0.1, -0.15])
    qpos = np.array([0.5, -1.0])
    rollout = sim2sim.run_in_mujoco(path, task.mj_model, 6, qpos=qpos, entries={"info['goal']": goal})
    np.testing.assert_allclose(rollout.time[-1], 6 * 0.02)
    np.testing.assert_allclose(rollout.ctrl, rollout.task_action)  # no actuator: the action is ctrl
    assert np.ptp(rollout.qpos[:, 1]) > 0.01  # the policy moved the arm
    np.testing.assert_allclose(rollout.inputs["info['goal']"], np.tile(goal, (6, 1)))  # carried on by the artifact
    tips = rollout.inputs["site_xpos"][:, 0]
    np.testing.assert_allclose(rollout.obs, by_hand(rollout.qpos[:-1], rollout.qvel[:-1], tips, goal), atol=1e-5)


def test_contract_formats_say_what_to_do(task, e2e):
    with pytest.raises(deployment.ContractError) as caught:
        export.describe(task, export.Deployable(lambda o, c: (o[:2], c), 8, 2))
    message = str(caught.value)
    assert "test_export_own_task:observe" in message and "end_to_end" in message and "catalog" in message
    cartpole = export.end_to_end(mjzoo.envs.make("cartpole_balance"), export.Deployable(lambda o, c: (o[:1], c), 5, 1))
    assert [i["name"] for i in cartpole.contract["inputs"]] == ["qpos", "qvel"]  # a catalog task too


def write_run(run, task) -> None:
    run.mkdir()
    (run / "task.json").write_text(json.dumps({"env": "test_export_own_task:make_task", "overrides": {}}))
    (run / "config.json").write_text(
        json.dumps({"algorithm": "ppo", "config": training.config_dict(config()), "settings": {}})
    )
    checkpoints.save(run / "checkpoints", 1, ppo.init(config(), task, ppo.Hyperparams(), jax.random.key(0)))


def test_cli_exports_an_own_task(task, tmp_path, capsys):
    run = tmp_path / "run"
    write_run(run, task)
    cli.main(["export", str(run), "--format", "jax"])
    printed = capsys.readouterr().out
    assert "info['goal']" in printed, printed
    loaded = export.load(run / "policy.jaxexport")
    assert loaded.contract["format"] == export.END_TO_END
    out = loaded.act({"qpos": np.zeros(2), "qvel": np.zeros(2), "site_xpos": np.zeros((1, 3)), "info['goal']": [0, 0]})
    assert out["action"].shape == (2,)
    for argv, words in (
        (["export", str(run), "--format", "onnx"], ("test_export_own_task:observe", "--format jax")),
        (["sim2sim", str(run), "--policy", str(run / "policy.jaxexport")], ("end-to-end", "--format onnx")),
    ):
        with pytest.raises(SystemExit) as exit_info:
            cli.main(argv)
        err = capsys.readouterr().err
        assert exit_info.value.code == 2 and len(err.splitlines()) == 1, err
        assert all(w in err for w in words), err
