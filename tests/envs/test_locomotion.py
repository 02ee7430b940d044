"""The locomotion tasks (envs/locomotion.py, envs/joystick.py) and the catalog items they
added: progress rewards, the base-height observation, and an auto-reset that a curriculum
keeps.

Hand-checked numbers use `catalog_tasks.BASE_AND_ARM` (zero gravity, no contacts, Euler
at dt = 0.02 s): a free 2 kg base moving at constant velocity, whose body poses lag its
qpos by one physics step (MuJoCo computes them before integrating)."""

from __future__ import annotations

import functools

import catalog_tasks as ct
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from mujoco import mjx

import mjzoo
import mjzoo.envs
from mjzoo.catalog import actuators
from mjzoo.catalog import curriculum
from mjzoo.catalog import observations
from mjzoo.catalog import rewards
from mjzoo.envs import joystick
from mjzoo.envs import locomotion
from mjzoo.envs import pendulum
from mjzoo.types import State


@jax.jit
def _rollout(task, key):
    """Zero-action rollout of 6 steps: (reset state, next states [6])."""
    state = mjzoo.reset(task, key)
    return state, mjzoo.rollout(task, lambda obs, k: jnp.zeros((task.action_size,)), state, key, 6)[1].next_state


# --- catalog items ------------------------------------------------------------------


def test_forward_velocity_is_the_com_speed_capped_and_body_height_the_lagged_z():
    qvel = np.zeros(9)
    qvel[0], qvel[2] = 1.5, 1.0  # vx 1.5 m/s, vz 1 m/s
    task = rewards.terms(
        ct.make_task(qvel=qvel),
        {
            "forward": (rewards.forward_velocity(ct.MJ), 1.0),
            "capped": (rewards.forward_velocity(ct.MJ, "base", max_speed=1.0), 2.0),
            "height": (rewards.body_height(ct.MJ, "base"), 1.0),
        },
    )
    _, states = ct.run(task, jax.random.key(0))
    terms = mjzoo.reward_terms(states)
    # The reset state is not forwarded (its com is 0), so from the second step on:
    np.testing.assert_allclose(terms["forward"][:, 1:], 1.5, rtol=1e-4)
    np.testing.assert_allclose(terms["capped"][:, 1:], 2.0 * 1.0, rtol=1e-6)
    # xpos after step k is the pose before its integration: z = 0.5 + (k - 1) 0.02.
    np.testing.assert_allclose(terms["height"][0], 0.5 + 0.02 * np.arange(ct.T), atol=1e-5)


def test_effort_is_the_sum_of_squared_actions():
    assert float(rewards.effort(None, None, jnp.array([0.5, -2.0]), None)) == pytest.approx(4.25)


def test_base_height_observes_z_only():
    data = mjx.make_data(ct.BASE_AND_ARM.model).replace(qpos=jnp.asarray(ct.QPOS0))
    data = jax.jit(mjx.forward)(ct.BASE_AND_ARM.model, data)  # one compile, not an eager op's each
    item = observations.base_height(ct.MJ)
    np.testing.assert_allclose(jax.jit(item)(ct.BASE_AND_ARM.model, State.create(data, None)), [0.5])


def test_a_curriculum_keeps_its_level_under_a_second_auto_reset():
    """PPO wraps every task in `with_auto_reset`; a curriculum's task resets itself inside,
    so the wrap must leave it alone or each episode end would reset the level."""
    base = pendulum.swingup()

    def at(level: float) -> mjzoo.Task:
        return mjzoo.with_auto_reset(mjzoo.with_time_limit(mjzoo.with_reward(base, "bonus", _one, level), 2))

    task = curriculum.with_curriculum(at, curriculum.by_steps(4))
    assert mjzoo.combinators.resets_itself(task) and not mjzoo.combinators.resets_itself(base)
    assert mjzoo.with_auto_reset(task) is task
    _, states = _rollout(mjzoo.with_auto_reset(task), jax.random.key(0))
    np.testing.assert_allclose(mjzoo.find(states, curriculum.CurriculumState).level, [0.25, 0.5, 0.75, 1.0, 1.0, 1.0])
    assert states.truncated[1] and states.truncated[3]  # episodes of 2 steps ended meanwhile


def _one(model, state, action, next_state):
    return jnp.float32(1.0)


# --- the tasks ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "name,obs_size,nu",
    [
        ("hopper", 11, 3),
        ("walker", 17, 6),
        ("cheetah", 17, 6),
        ("ant", 27, 8),
        ("humanoid_walk", 45, 17),
        ("humanoid_run", 45, 17),
        ("humanoid_standup", 45, 17),
        ("ant_joystick", 29, 8),
    ],
)
def test_documented_sizes(name, obs_size, nu):
    task = mjzoo.envs.make(name)
    state = jax.eval_shape(mjzoo.reset, task, jax.random.key(0))
    assert state.obs.shape == (obs_size,) and task.action_size == nu


@functools.cache
def _humanoids():
    """The walk and run tasks' first transition from a standing start pushed at 3 m/s."""

    @jax.jit
    def pushed(task):
        state = mjzoo.reset(task, jax.random.key(0))
        state = state.replace(data=state.data.replace(qvel=state.data.qvel.at[0].set(3.0)))
        return mjzoo.transition(task, state, jnp.zeros((task.action_size,)), jax.random.key(1))

    return pushed(mjzoo.envs.make("humanoid_walk")), pushed(mjzoo.envs.make("humanoid_run"))


def test_humanoid_walk_caps_the_forward_reward_and_run_does_not():
    walk, run = (mjzoo.reward_terms(s) for s in _humanoids())
    assert float(walk["forward"]) == pytest.approx(1.25 * 1.5)  # the com moves at ~3 m/s > 1.5
    # Body poses lag one of the 5 substeps: the first transition sees 4 substeps of motion
    # over the whole control step, 3 m/s x 4/5 (afterwards both ends lag alike).
    assert float(run["forward"]) == pytest.approx(1.25 * 3.0 * 4 / 5, rel=1e-3)
    assert float(walk["alive"]) == 5.0 and float(walk["effort"]) == 0.0


def test_hopper_ends_when_the_torso_drops_or_tilts():
    task = mjzoo.envs.make("hopper")

    @jax.jit
    def from_pose(qpos):
        state = mjzoo.reset(task, jax.random.key(0))
        state = state.replace(data=state.data.replace(qpos=qpos, qvel=jnp.zeros_like(state.data.qvel)))
        return mjzoo.transition(task, state, jnp.zeros(3), jax.random.key(1))

    upright, low, tilted = (
        from_pose(jnp.array(q, jnp.float32)) for q in ([0, 0, 0, 0, 0, 0], [0, -0.6, 0, 0, 0, 0], [0, 0, 0.4, 0, 0, 0])
    )
    assert not upright.terminated and float(mjzoo.reward_terms(upright)["alive"]) == 1.0
    assert low.terminated and low.metrics["termination/too_low"] == 1.0
    assert tilted.terminated and tilted.metrics["termination/tilted"] == 1.0
    assert float(mjzoo.reward_terms(low)["alive"]) == 0.0


def test_standup_starts_lying_and_rewards_the_torso_height():
    state, states = _rollout(mjzoo.envs.make("humanoid_standup"), jax.random.key(0))
    height = mjzoo.reward_terms(states)["height"]
    assert float(state.data.xpos[1, 2]) < 0.3 and not states.terminated.any()
    np.testing.assert_allclose(height, states.data.xpos[:, 1, 2], rtol=1e-6)


def test_only_noise_and_pushes_follow_the_joystick_level():
    easy, hard = joystick.joystick(level=0.0), joystick.joystick(level=1.0)
    moved = {
        (np.asarray(a).tobytes(), np.asarray(b).tobytes()): (np.asarray(a), np.asarray(b))
        for a, b in zip(jax.tree.leaves(easy), jax.tree.leaves(hard))
        if not np.array_equal(a, b)
    }
    assert len(moved) == 2  # the noise scale and the push limits (each bound where used), nothing else
    (noise_0, noise_1), (push_0, push_1) = sorted(moved.values(), key=lambda pair: pair[0].size)
    assert float(noise_0) == 0.0 and float(noise_1) == pytest.approx(0.05)
    np.testing.assert_allclose(push_0, 0.0)
    np.testing.assert_allclose(push_1, [0.5, 0.5, 0.0, 0.0, 0.0, 0.0])


def test_joystick_curriculum_resets_itself_and_observes_the_command():
    """One compile of the whole joystick stack (a minute of CPU), so one rollout."""
    task = joystick.joystick_curriculum(episode_steps=3)
    assert mjzoo.with_auto_reset(task) is task
    _, states = _rollout(task, jax.random.key(0))
    assert "curriculum/level" in states.metrics and states.truncated[2]
    command = mjzoo.find(states, mjzoo.catalog.commands.VelocityCommandState).target
    np.testing.assert_allclose(states.obs[:3, -3:], command[:3])  # level 0 until the first episode ends: no noise
    np.testing.assert_allclose(states.obs[3:, -3:], command[3:], atol=0.3)  # then N(0, (0.05 level)^2) noise
    assert (np.abs(command) <= 1.0).all() and np.abs(command).max() > 0.0
    assert {"reward/tracking", "reward/progress", "reward/yaw_tracking"} <= set(states.metrics)


def test_bare_runs_a_catalog_actuator():
    """Ant motors have gear 150: a 75 N m torque limit turns action 1 into ctrl 0.5."""
    physics = mjzoo.envs.base.brax_asset("ant.xml", ctrl_dt=0.05)
    task = locomotion.bare(physics, observations.joint_positions, actuators.torque(physics.mj_model, 75.0))
    state = jax.jit(mjzoo.reset)(task, jax.random.key(0))  # eager, each of its ops compiles alone
    next_state = jax.jit(mjzoo.transition)(task, state, jnp.ones(8), jax.random.key(1))
    np.testing.assert_allclose(next_state.data.ctrl, 0.5)
    assert next_state.obs.shape == (8,) and np.isfinite(next_state.obs).all()
