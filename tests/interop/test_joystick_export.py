"""A joystick's deployment contract (`mjzoo.interop.deployment`), on a two-legged box
small enough to compile in seconds but built like the robot joysticks
(`envs/robot_joystick.py`): <position> servos driven by `actuators.position_targets`,
IMU and encoder observations with noise, the last action and the velocity command
appended by their combinators, a critic's privileged view beside the policy's. The
contract describes the policy's entry term by term (checked against MJX), maps actions
to servo targets with the model's gains, and C MuJoCo runs it from the contract alone,
command, latency and another timestep included; `tracking` measures both simulators."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import mjzoo
from mjzoo import physics
from mjzoo.catalog import actuators
from mjzoo.catalog import commands
from mjzoo.catalog import gait
from mjzoo.catalog import observations
from mjzoo.catalog import trackers
from mjzoo.harness import cli
from mjzoo.interop import deployment
from mjzoo.interop import export
from mjzoo.interop import sim2sim
from mjzoo.interop import tracking

BIPED = """
<mujoco>
  <option timestep="0.005"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="torso" pos="0 0 0.5">
      <freejoint/>
      <geom type="box" size="0.15 0.1 0.05" mass="2"/>
      <body name="left" pos="0 0.08 -0.05">
        <joint name="left_hip" type="hinge" axis="0 1 0" range="-1 1"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.03" mass="0.3"/>
        <geom name="left_foot" type="box" pos="0 0 -0.42" size="0.12 0.04 0.02" mass="0.1"/>
      </body>
      <body name="right" pos="0 -0.08 -0.05">
        <joint name="right_hip" type="hinge" axis="0 1 0" range="-1 1"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.4" size="0.03" mass="0.3"/>
        <geom name="right_foot" type="box" pos="0 0 -0.42" size="0.12 0.04 0.02" mass="0.1"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="left" joint="left_hip" kp="20" kv="0.5" ctrlrange="-1 1" forcerange="-8 8"/>
    <position name="right" joint="right_hip" kp="20" ctrlrange="-1 1"/>
  </actuator>
</mujoco>
"""
SCALE = 0.4


def make_biped(**command) -> mjzoo.Task:
    p = physics.load(BIPED, ctrl_dt=0.02)
    m = p.mj_model
    layers = (
        functools.partial(actuators.with_action_latency, max_latency=1),
        functools.partial(mjzoo.with_observation_noise, scale=0.05),
        functools.partial(trackers.with_action_history, length=2, observe=True),
        functools.partial(commands.with_velocity_command, **command),
        functools.partial(
            observations.with_privileged_observation,
            observe=observations.concat(observations.base_linear_velocity(m), observations.base_height(m)),
        ),
    )
    sensed = observations.concat(
        observations.base_angular_velocity(m),
        observations.projected_gravity(m),
        observations.joint_positions,
        observations.joint_velocities,
    )
    return mjzoo.task(
        p, observe=sensed, actuator=actuators.position_targets(m, SCALE), combinators=layers, time_limit=50
    )


@pytest.fixture(scope="module")
def biped() -> mjzoo.Task:
    return make_biped()


def test_the_policy_sees_its_last_action_and_the_command_the_critic_more(biped):
    state = mjzoo.reset(biped, jax.random.key(0))
    policy, critic = state.obs["state"], state.obs["privileged_state"]
    assert policy.shape == (3 + 3 + 2 + 2 + 2 + 3,) and critic.shape == (policy.shape[0] + 4,)
    np.testing.assert_array_equal(critic[: policy.shape[0]], policy)  # the policy's view comes first
    np.testing.assert_array_equal(policy[10:12], 0.0)  # no action yet
    command = mjzoo.find(state, commands.VelocityCommandState).command
    np.testing.assert_array_equal(policy[-3:], command)
    after = mjzoo.transition(biped, state, jnp.array([0.3, -0.7]), jax.random.key(1))
    np.testing.assert_allclose(after.obs["state"][10:12], [0.3, -0.7])  # the last action, exactly
    np.testing.assert_allclose(after.obs["privileged_state"][-1], after.data.xpos[1, 2], atol=1e-6)  # noiseless height
    # The actuator takes the policy's [-1, 1] actions itself: no stretch over the ctrlranges.
    assert biped.action_dim == 2 and float(mjzoo.learning.to_controls(biped, jnp.array([0.5, -1.0]))[0]) == 0.5


def test_contract_of_a_joystick(biped):
    policy = export.Deployable(lambda obs, carry: (jnp.tanh(obs[:2]), None), 15, 2)
    with pytest.raises(deployment.ContractError, match="obs_key"):
        export.describe(biped, policy)  # a dict observation needs the policy's entry named
    contract = export.describe(biped, policy, obs_key="state")
    obs = contract["observation"]
    assert obs["key"] == "state" and obs["checked"]["max_abs_error"] <= 1e-5
    assert [t["source"] for t in obs["terms"]] == [
        "body_angular_velocity_local",
        "projected_gravity",
        "qpos",
        "qvel",
        "previous_action",
        "command",
    ]
    assert (
        obs["terms"][2]["joints"] == ["left_hip", "right_hip"] and obs["terms"][-1]["record"] == "VelocityCommandState"
    )
    to_ctrl = contract["action"]["to_ctrl"]
    assert contract["action"]["to_task"]["type"] == "identity" and to_ctrl["type"] == "position_targets"
    assert to_ctrl["kp"] == [20.0, 20.0] and to_ctrl["kv"] == [0.5, 0.0] and to_ctrl["force_limit"] == [8.0, None]
    assert to_ctrl["action_scale"] == pytest.approx([SCALE, SCALE]) and to_ctrl["joints"] == ["left_hip", "right_hip"]


def test_c_mujoco_runs_the_joystick_from_its_contract(biped, tmp_path):
    """The exported policy in C with a command, one step of latency and half the timestep:
    ctrl is the servo target of the action one step late; the command is observed."""
    w = np.asarray(jax.random.normal(jax.random.key(2), (15, 2)), np.float32) * 0.3
    policy = export.Deployable(lambda obs, carry: (jnp.tanh(obs @ w), None), 15, 2)
    path = export.write_jax(policy, export.describe(biped, policy, obs_key="state"), tmp_path / "biped.jaxexport")
    m = biped.mj_model
    m.opt.timestep = 0.0025
    try:
        with pytest.raises(ValueError, match="pass command="):
            sim2sim.run_in_mujoco(path, m, 3)
        command = np.array([0.5, 0.0, 0.2])
        rollout = sim2sim.run_in_mujoco(path, m, 3, command=command, latency=1)
    finally:
        m.opt.timestep = 0.005
    np.testing.assert_allclose(rollout.obs[:, -3:], np.tile(command, (3, 1)), rtol=1e-7)
    np.testing.assert_allclose(rollout.obs[1:, 10:12], rollout.action[:-1], atol=1e-6)  # its last action
    np.testing.assert_allclose(rollout.ctrl[0], 0.0)  # step 0: nothing has arrived yet (the default pose)
    np.testing.assert_allclose(rollout.ctrl[1:], SCALE * rollout.action[:-1], atol=1e-6)
    np.testing.assert_allclose(rollout.time[-1], 3 * 0.02)  # the control rate kept: 8 substeps of 2.5 ms
    m.opt.timestep = 0.003
    with pytest.raises(ValueError, match="does not divide"):
        sim2sim.run_in_mujoco(path, m, 1, command=command)
    m.opt.timestep = 0.005


def test_base_velocities_in_the_base_frame():
    """A base turned 90 degrees about z moving along world +y moves along its own +x."""
    quarter = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])
    qpos = np.concatenate([[0.0, 0.0, 0.5], quarter])
    qvel = np.array([0.0, 2.0, 0.0, 0.0, 0.0, 0.7])
    v_xy, w_z = tracking.base_velocities(qpos, qvel, (0, 0))
    np.testing.assert_allclose(v_xy, [2.0, 0.0], atol=1e-12)
    assert w_z == 0.7
    jax_v, _ = tracking.base_velocities(jnp.asarray(qpos), jnp.asarray(qvel), (0, 0))
    np.testing.assert_allclose(jax_v, v_xy, atol=1e-6)


def test_windowed_velocity_errors_average_out_a_sway():
    """A base swaying sideways at ±0.2 m/s and yawing at ±0.4 rad/s about a command it
    follows on average (1 m/s ahead, no turn): per step its errors are 0.2 and 0.4;
    over two-step windows (after the first step, a window of one) they vanish."""
    sway = jnp.asarray([1.0, -1.0, 1.0, -1.0])
    v_xy = jnp.stack([jnp.ones(4), 0.2 * sway], -1)
    command = jnp.tile(jnp.asarray([1.0, 0.0, 0.0]), (4, 1))
    linear, yaw = tracking.velocity_errors(v_xy, 0.4 * sway, command)
    np.testing.assert_allclose(linear, [0.2] * 4, atol=1e-6)
    np.testing.assert_allclose(yaw, [0.4] * 4, atol=1e-6)
    linear, yaw = jax.jit(tracking.velocity_errors, static_argnums=3)(v_xy, 0.4 * sway, command, 2)
    np.testing.assert_allclose(linear, [0.2, 0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(yaw, [0.4, 0, 0, 0], atol=1e-6)
    # A window longer than the episode: the mean so far; [1, 0.5, 1, 1.5] against 0.5
    linear, _ = tracking.velocity_errors(
        jnp.asarray([[1.0, 0], [0, 0], [2, 0], [3, 0]]), jnp.zeros(4), 0.5 * command, 9
    )
    np.testing.assert_allclose(linear, [0.5, 0.0, 0.5, 1.0], atol=1e-6)
    with pytest.raises(ValueError, match="window=0"):
        tracking.velocity_errors(v_xy, sway, command, 0)


def test_tracking_of_a_standing_policy_in_both_simulators(tmp_path):
    """Commanded 0.5 m/s forward and no turn, a policy that holds its stance (its feet
    on the floor) moves by millimetres per second: both simulators measure a linear error
    of 0.5 m/s and a yaw error of 0, over every step of every episode, and no falls."""
    task = make_biped(vx=(0.5, 0.5), vy=(0.0, 0.0), yaw_rate=(0.0, 0.0))
    trained = tracking.in_task(
        task, lambda obs: jnp.zeros(2), jax.random.key(0), num_envs=2, seconds=0.6, obs_key="state"
    )
    policy = export.Deployable(lambda obs, carry: (jnp.zeros(2), None), 15, 2)
    path = export.write_jax(policy, export.describe(task, policy, obs_key="state"), tmp_path / "still.jaxexport")
    deployed = tracking.in_mujoco(path, task, episodes=2, seconds=0.6, timestep=0.0025, latency=1)
    for measured in (trained, deployed):
        assert measured.episodes == 2 and measured.falls == 0 and np.all(measured.per_episode["steps"] == 30)
        assert abs(measured.linear_error - 0.5) < 0.02 and measured.yaw_error < 0.02, measured.summary()


def test_cli_sim2sim_names_what_is_missing(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "sim2sim.json").write_text("{}")
    for argv, words in (
        ([str(run)], ("no exported policy", "mjzoo export")),
        ([str(run), "--policy", str(run / "sim2sim.json")], ("already exists", "--overwrite")),
        ([str(run), "--policy", str(run / "sim2sim.json"), "--overwrite", "--episodes", "0"], ("--episodes 0",)),
    ):
        with pytest.raises(SystemExit) as exit_info:
            cli.main(["sim2sim", *argv])
        err = capsys.readouterr().err
        assert exit_info.value.code == 2 and len(err.splitlines()) == 1, err
        assert all(w in err for w in words), err


def test_contract_of_a_stepping_clock():
    """A gait clock (`catalog.gait.clock`) is a term of its own, read from MjData's time:
    at t = 0.25 s and 1 Hz the biped's feet are a quarter cycle in, half a cycle apart."""
    p = physics.load(BIPED, ctrl_dt=0.02)
    task = mjzoo.task(p, observe=observations.concat(observations.joint_positions, gait.clock(1.0)), time_limit=50)
    terms = deployment.observation_terms(task)
    assert terms[-1] == dict(
        name="gait_clock(1 Hz)", size=4, source="gait_clock", frequency=1.0, offsets=[0.0, pytest.approx(np.pi)]
    )
    check = deployment.check_observation(task, terms, jax.random.key(0), steps=20)  # 0.4 s: past a half cycle
    assert check.max_error <= 1e-4
    m = task.mj_model
    d = mujoco.MjData(m)
    d.time = 0.25
    np.testing.assert_allclose(deployment.frame(terms[-1:], m, d, np.zeros(2)), [0, 0, 1, -1], atol=1e-6)
