"""The real robots' joysticks (envs/robot_joystick.py) and the catalog items they brought:
the Task contract on the Go1 (its scene from EnvPool's wheel, servos, randomized physics,
pushes and the asymmetric observation in one compile: minutes of the suite's CPU), and the
servo actuator and the stand-still cost by hand. The terrain's pieces are tested in
tests/robots/test_terrain.py."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo import physics
from mjzoo.catalog import actuators
from mjzoo.catalog import commands
from mjzoo.catalog import rewards
from mjzoo.envs import robot_joystick

SERVOS = """
<mujoco>
  <worldbody>
    <body><joint name="a" type="hinge" range="-1 1"/><geom size=".1" mass="1"/>
      <body><joint name="b" type="hinge"/><geom size=".1" mass="1"/></body></body>
  </worldbody>
  <actuator>
    <position joint="a" kp="20" ctrlrange="-0.5 0.5"/>
    <position joint="b" kp="10"/>
  </actuator>
  <keyframe><key qpos="0.2 -0.3" ctrl="0.2 -0.3"/></keyframe>
</mujoco>
"""


def test_position_targets_by_hand():
    mj = physics.load(SERVOS).mj_model
    act = actuators.position_targets(mj, action_scale=(0.5, 2.0))  # around the keyframe's ctrl
    ctrl = jax.jit(lambda a: act(None, None, a, None))
    # a: 0.2 + 0.5 * 0.4 = 0.4; b: -0.3 + 2 * clip(-3) = -2.3 (b has no ctrlrange).
    np.testing.assert_allclose(ctrl(jnp.array([0.4, -3.0])), [0.4, -2.3], rtol=1e-6)
    np.testing.assert_allclose(ctrl(jnp.array([1.0, 0.0])), [0.5, -0.3], rtol=1e-6)  # a clipped to its ctrlrange
    with pytest.raises(ValueError, match=r"<position> servo .* not: \['m'\]"):
        actuators.position_targets(
            physics.load(SERVOS.replace('<position joint="b" kp="10"/>', '<motor name="m" joint="b"/>')).mj_model
        )


def test_stand_still_counts_only_at_a_zero_command():
    xml = SERVOS.replace("<worldbody>", '<worldbody><body name="base"><freejoint/><geom size=".1"/></body>')
    p = physics.load(xml.replace('qpos="0.2 -0.3"', 'qpos="0 0 0 1 0 0 0 0.2 -0.3"'))
    mj = p.mj_model
    cost = rewards.stand_still(mj, max_command=0.1)
    data = mujoco.MjData(mj)
    data.qpos[7:] = [0.5, 0.1]  # the keyframe's joints: 0.2, -0.3 -> deviation 0.3^2 + 0.4^2 = 0.25
    state = mjzoo.State.create(mujoco.mjx.put_data(mj, data), jnp.zeros(1))
    for command, expected in (((0.05, 0.0, 0.05), 0.25), ((0.2, 0.0, 0.0), 0.0)):
        command = jnp.asarray(command, jnp.float32)
        commanded = mjzoo.layers.wrap(state, commands.VelocityCommandState(jnp.float32(1), command, command))
        assert float(cost(p.model, commanded, jnp.zeros(2), state)) == pytest.approx(expected, rel=1e-5)


def test_go1_keeps_the_task_contract():
    task = mjzoo.envs.make("go1_joystick")
    obs = jax.eval_shape(lambda k: mjzoo.reset(task, k), jax.random.key(0)).obs
    # The policy: gyro, gravity, 12 joint positions and velocities, its last action, the
    # command; the critic adds base velocity and height and 4 foot contacts.
    assert obs["state"].shape == (3 + 3 + 12 + 12 + 12 + 3,) and obs["privileged_state"].shape == (45 + 3 + 1 + 4,)
    report = mjzoo.testing.check_task(task, num_steps=8)  # raises on any failed property
    assert set(report.skipped) <= {"time_limit"}  # 1000 steps: longer than the rollout


def test_unknown_robot_and_terrain():
    with pytest.raises(ValueError, match="robot='h2' is unknown"):
        robot_joystick.robot_joystick("h2")
    with pytest.raises(ValueError, match="terrain='lava' is unknown"):
        robot_joystick.robot_joystick("go1", terrain="lava")


def test_a_humanoid_is_paid_for_staying_up():
    """Under PPO's first exploration noise (actions tanh(N(0, 0.69^2)): a zero-initialised
    log std through softplus) the G1 falls within ~1 s; while it is up, its reward must
    be positive, or falling early is what the return pays for (it was -2.15 a step, with
    a torque cost and alive at 1, and every G1 evaluation episode fell after 70M steps)."""
    task = mjzoo.envs.make("g1_joystick")
    n = 8
    keys = jax.random.split(jax.random.key(0), n)

    def body(states, key):
        noise, step = jax.random.split(key)
        actions = jnp.tanh(0.69 * jax.random.normal(noise, (n, task.action_size)))
        after = jax.vmap(lambda s, a, k: mjzoo.running.transition(task, s, a, k))(
            states, actions, jax.random.split(step, n)
        )
        return after, (after.reward, after.terminated, after.metrics["reward/alive"])

    states = jax.vmap(lambda k: mjzoo.reset(task, k))(keys)
    rewards_, ended, alive = jax.jit(lambda s: jax.lax.scan(body, s, jax.random.split(jax.random.key(1), 100))[1])(
        states
    )
    up = np.cumsum(np.asarray(ended), 0) == 0  # [T, n] steps before each episode's fall
    assert np.asarray(ended).any(0).all()  # each falls within the 2 s
    np.testing.assert_array_equal(np.asarray(alive)[up], 2.0)  # the term: 2 a step survived
    assert float(np.asarray(rewards_)[up].mean()) > 0.0


@pytest.mark.parametrize("robot, feet", [("g1", 2), ("go1", 4)])
def test_a_gait_clock_is_observed_and_paid(robot, feet):
    plain, clocked = (mjzoo.envs.make(f"{robot}_joystick", gait_frequency=f) for f in (None, 1.375))
    shapes = [
        jax.eval_shape(lambda k, t=t: mjzoo.reset(t, k), jax.random.key(0)).obs["state"].shape for t in (plain, clocked)
    ]
    assert shapes[1][0] == shapes[0][0] + 2 * feet  # cos and sin of each foot's phase
    state = jax.eval_shape(lambda k: mjzoo.reset(clocked, k), jax.random.key(0))
    after = jax.eval_shape(
        lambda s, k: mjzoo.running.transition(clocked, s, jnp.zeros(clocked.action_size), k), state, jax.random.key(1)
    )
    assert "reward/feet_phase" in after.metrics
