"""Hand-checked behaviour of the actuator models and the action combinators
(`mjzoo.catalog.actuators`).

Two tiny models, no gravity, Euler with dt = 0.1 s:
  JOINTS  a hinge j1 (qpos0 = ref = 0.2 rad) with a motor of gear 1 and ctrlrange +-10,
          and a slide j2 with a motor of gear 2 and ctrlrange [-3, 5]: torque limits
          10 N m and min(3, 5) * 2 = 6 N. Only the actuator functions run on it (no physics).
  BLOCK   a 1 kg block on a frictionless slide joint, a motor of gear 1, ctrlrange +-10:
              v' = v + dt * force / m,   q' = q + dt * v'.
          The tiny task drives it through `actuators.step` with the `torque` actuator:
          force = 10 * action, so each step adds exactly the applied action to the
          velocity: applied_t = qvel_t - qvel_{t-1}. obs = qvel, reward term "v" = qvel.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo.catalog import actuators
from mjzoo.layers import find
from mjzoo.types import State
from mjzoo.types import Task

JOINTS_XML = """
<mujoco model="joints">
  <compiler angle="radian"/>
  <worldbody>
    <body name="a"><joint name="j1" type="hinge" axis="0 0 1" ref="0.2"/>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/></body>
    <body name="b"><joint name="j2" type="slide" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/></body>
  </worldbody>
  <actuator>
    <motor name="m1" joint="j1" gear="1" ctrlrange="-10 10"/>
    <motor name="m2" joint="j2" gear="2" ctrlrange="-3 5"/>
  </actuator>
</mujoco>
"""
BLOCK_XML = """
<mujoco model="block">
  <option timestep="0.1" integrator="Euler" gravity="0 0 0"/>
  <worldbody>
    <body name="block"><joint name="x" type="slide" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/></body>
  </worldbody>
  <actuator><motor name="push" joint="x" gear="1" ctrlrange="-10 10"/></actuator>
</mujoco>
"""
JOINTS, BLOCK = (mujoco.MjModel.from_xml_string(xml) for xml in (JOINTS_XML, BLOCK_XML))
JOINTS_MODEL, BLOCK_MODEL = mjx.put_model(JOINTS), mjx.put_model(BLOCK)
KEY = jax.random.key(0)


def joint_data(q, qd) -> mjx.Data:
    return mjx.make_data(JOINTS_MODEL).replace(qpos=jnp.asarray(q, jnp.float32), qvel=jnp.asarray(qd, jnp.float32))


@jax.jit
def ctrl_batch(actuator, data, actions, keys):
    """ctrl for a batch of actions and keys, under jit and vmap."""
    return jax.vmap(actuator, in_axes=(None, None, 0, 0))(JOINTS_MODEL, data, actions, keys)


def ctrl_of(actuator, data, *actions):
    actions = jnp.asarray(actions, jnp.float32)
    return np.asarray(ctrl_batch(actuator, data, actions, jax.random.split(KEY, len(actions))))


# --- actuator functions -------------------------------------------------------------------


def test_torque_scales_the_clipped_action_to_the_limits():
    # Limits 10 N m and 6 N; gear 2 halves the ctrl of j2.
    ctrl = ctrl_of(actuators.torque(JOINTS), joint_data([0, 0], [0, 0]), [0.5, -2.0], [-0.25, 0.5])
    np.testing.assert_allclose(ctrl, [[5.0, -3.0], [-2.5, 1.5]], rtol=1e-6)
    ctrl = ctrl_of(actuators.torque(JOINTS, torque_limit=[2.0, 4.0]), joint_data([0, 0], [0, 0]), [1.0, 1.0])
    np.testing.assert_allclose(ctrl, [[2.0, 2.0]], rtol=1e-6)


def test_pd_torque_by_hand():
    pd = actuators.pd(JOINTS, kp=[20.0, 10.0], kd=[1.0, 2.0], action_scale=[0.5, 1.0])
    data = joint_data([0.1, -0.3], [2.0, -1.0])
    # action [0.4, 0.2]:  j1 target 0.2 + 0.5 * 0.4 = 0.4, torque 20 * 0.3 - 1 * 2 = 4;
    #                     j2 target 0.2, torque 10 * 0.5 - 2 * (-1) = 7 > 6: 6 N, ctrl 6 / 2 = 3.
    # action [-2, 0]:     j1 clipped to -1: target -0.3, torque 20 * -0.4 - 2 = -10 (the limit);
    #                     j2 target 0, torque 10 * 0.3 + 2 = 5, ctrl 2.5.
    np.testing.assert_allclose(ctrl_of(pd, data, [0.4, 0.2], [-2.0, 0.0]), [[4.0, 3.0], [-10.0, 2.5]], rtol=1e-5)


def test_pd_default_pose_is_qpos0_unless_given():
    data = joint_data([0.2, 0.0], [0.0, 0.0])
    np.testing.assert_allclose(ctrl_of(actuators.pd(JOINTS, 5.0, 0.0), data, [0.0, 0.0]), [[0.0, 0.0]], atol=1e-6)
    pd = actuators.pd(JOINTS, 5.0, 0.0, default_pose=[0.0, 0.4])
    np.testing.assert_allclose(ctrl_of(pd, data, [0.0, 0.0]), [[-1.0, 1.0]], rtol=1e-5)  # j2: 5 * 0.4 / 2


def test_position_velocity_by_hand():
    pv = actuators.position_velocity(
        JOINTS, kp=[20.0, 10.0], kd=[1.0, 2.0], position_scale=[0.5, 1.0], velocity_scale=[2.0, 4.0]
    )
    data = joint_data([0.1, -0.3], [2.0, -1.0])
    # j1: target q 0.4, target qdot 2 * 0.5 = 1: 20 * 0.3 + 1 * (1 - 2) = 5.
    # j2: target q 0.2, target qdot 4 * -0.5 = -2: 10 * 0.5 + 2 * (-2 + 1) = 3, ctrl 1.5.
    np.testing.assert_allclose(ctrl_of(pv, data, [0.4, 0.2, 0.5, -0.5]), [[5.0, 1.5]], rtol=1e-5)
    with pytest.raises(ValueError, match=r"shape \(4,\)"):
        ctrl_of(pv, data, [0.4, 0.2])


def test_torque_noise_is_additive_gaussian_per_key():
    noisy = actuators.pd(JOINTS, 0.0, 0.0, torque_noise=0.5, torque_limit=100.0)
    ctrl = ctrl_of(noisy, joint_data([0, 0], [0, 0]), *[[0.0, 0.0]] * 4000)
    torque = ctrl * np.array([1.0, 2.0])
    np.testing.assert_allclose(torque.std(axis=0), 0.5, rtol=0.05)
    np.testing.assert_allclose(torque.mean(axis=0), 0.0, atol=0.03)
    assert abs(np.corrcoef(torque.T)[0, 1]) < 0.06  # independent per actuator


def test_gain_noise_is_multiplicative_within_its_band():
    noisy = actuators.pd(JOINTS, 10.0, 0.0, gain_noise=0.2, default_pose=[0.0, 0.0])
    ctrl = ctrl_of(noisy, joint_data([-0.1, -0.1], [0, 0]), *[[0.0, 0.0]] * 4000)
    factor = ctrl * np.array([1.0, 2.0]) / (10.0 * 0.1)  # the drawn kp / kp
    assert np.all((factor >= 0.8) & (factor <= 1.2))
    np.testing.assert_allclose(factor.std(axis=0), 0.4 / np.sqrt(12), rtol=0.05)  # uniform on [0.8, 1.2]


def test_new_gains_do_not_retrace():
    traces = []

    @jax.jit
    @chex.assert_max_traces(n=1)
    def ctrl(actuator):
        traces.append(None)
        return actuator(JOINTS_MODEL, joint_data([0.0, 0.0], [0.0, 0.0]), jnp.ones(2), KEY)

    for kp in (1.0, 2.0, 3.0):
        np.testing.assert_allclose(
            ctrl(actuators.pd(JOINTS, kp, 0.5, default_pose=0.0, action_scale=0.1)), [0.1 * kp, 0.1 * kp / 2], rtol=1e-5
        )
    assert len(traces) == 1


# --- step ----------------------------------------------------------------------------------


@jax.jit
def block_step(actuator, action, key):
    data = actuators.step(BLOCK_MODEL, mjx.make_data(BLOCK_MODEL), actuator, action, 3, key)
    return data.qpos[0], data.qvel[0]


def test_step_applies_the_actuator_at_every_substep():
    # PD towards 0.3 m with kp 2, kd 0.5, recomputed from the state before each substep.
    q, v = 0.0, 0.0
    for _ in range(3):
        v += 0.1 * (2.0 * (0.3 - q) - 0.5 * v)
        q += 0.1 * v  # v: 0.06, 0.1158, 0.166494; q: 0.006, 0.01758, 0.0342294
    np.testing.assert_allclose(block_step(actuators.pd(BLOCK, 2.0, 0.5), jnp.array([0.3]), KEY), (q, v), rtol=1e-5)
    # A torque actuator holds its force: v = 3 * 0.1 * 10 * 0.4 = 1.2, q = 0.1 * (0.4 + 0.8 + 1.2).
    np.testing.assert_allclose(block_step(actuators.torque(BLOCK), jnp.array([0.4]), KEY), (0.24, 1.2), rtol=1e-5)


def test_step_noise_depends_on_the_key_only():
    noisy = actuators.pd(BLOCK, 0.0, 0.0, torque_noise=1.0)
    a, b = block_step(noisy, jnp.zeros(1), KEY), block_step(noisy, jnp.zeros(1), jax.random.key(1))
    assert a == block_step(noisy, jnp.zeros(1), KEY) and a[1] != b[1]


# --- the tiny task ------------------------------------------------------------------------


def _reset(actuator, model, key):
    data = mjx.make_data(model)
    return State.create(data, data.qvel)


def _step(actuator, model, state, action, key):
    data = actuators.step(model, state.data, actuator, action, 1, key)
    return state.replace(data=data, obs=data.qvel)


def _reward(actuator, model, state, action, next_state):
    return {"v": next_state.data.qvel[0]}


def _terminate(actuator, model, state):
    return jnp.zeros((), bool), jnp.zeros((), bool)


def block_task() -> Task:
    act = actuators.torque(BLOCK)
    return Task(
        BLOCK_MODEL, Partial(_reset, act), Partial(_step, act), Partial(_reward, act), Partial(_terminate, act), BLOCK
    )


@jax.jit
def episodes(task: Task, actions: jax.Array, keys: jax.Array):
    """One episode per key: actions [T] (the same for every key); states stacked [K, T]."""

    def episode(key):
        def body(state, xs):
            action, key = xs
            state = mjzoo.transition(task, state, action[None], key)
            return state, state

        keys = jax.random.split(key, actions.shape[0] + 1)
        return jax.lax.scan(body, mjzoo.reset(task, keys[0]), (actions, keys[1:]))[1]

    return jax.vmap(episode)(keys)


def applied(states) -> np.ndarray:
    """The action the inner task applied at each step, [K, T]: the velocity increments."""
    v = np.asarray(states.data.qvel[..., 0])
    return np.diff(v, axis=-1, prepend=0.0)


ACTIONS = jnp.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
KEYS = jax.random.split(KEY, 48)


def test_latency_delays_the_action_by_exactly_the_drawn_steps():
    s = episodes(actuators.with_action_latency(block_task(), 2), ACTIONS, KEYS)
    delays = np.asarray(find(s, actuators.ActionLatencyState).delay)
    assert np.all(delays == delays[:, :1]) and set(delays[:, 0]) == {0, 1, 2}  # one draw per episode
    for d, got in zip(delays[:, 0], applied(s)):  # delay 0: the plain task's actions
        np.testing.assert_allclose(got, np.concatenate([np.zeros(d), ACTIONS[: 6 - d]]), atol=1e-6)
    np.testing.assert_allclose(s.metrics["action_latency/delay"], delays)
    np.testing.assert_allclose(find(s, actuators.ActionLatencyState).buffer[0, -1, :, 0], [0.6, 0.5, 0.4], rtol=1e-6)
    np.testing.assert_allclose(s.reward[:, -1], np.asarray(s.data.qvel[:, -1, 0]))  # reward untouched


def test_latency_restarts_with_each_episode_inside_auto_reset():
    task = mjzoo.with_auto_reset(mjzoo.with_time_limit(actuators.with_action_latency(block_task(), 3), 3))
    s = episodes(task, ACTIONS, KEYS[:16])
    buffer = np.asarray(find(s, actuators.ActionLatencyState).buffer[:, 2])  # the state after step 3: a new episode
    np.testing.assert_array_equal(buffer, 0.0)
    delays = np.asarray(find(s, actuators.ActionLatencyState).delay)
    assert np.any(delays[:, 0] != delays[:, 3])  # redrawn


def test_drop_holds_the_previously_applied_action():
    actions = jnp.array([0.5, -0.3, 0.8, 0.1, -0.6, 0.4])
    s = episodes(actuators.with_action_drop(block_task(), 0.5), actions, KEYS)
    dropped = np.asarray(s.metrics["action_drop/dropped"]).astype(bool)
    expected, held = [], np.zeros(len(KEYS))
    for t in range(6):
        held = np.where(dropped[:, t], held, actions[t])
        expected.append(held)
    np.testing.assert_allclose(applied(s), np.stack(expected, axis=1), atol=1e-6)
    np.testing.assert_allclose(
        find(s, actuators.ActionDropState).previous[..., 0], np.stack(expected, axis=1), atol=1e-6
    )
    assert 0.35 < dropped.mean() < 0.65
    # Probability is a leaf (no new compile): 0 passes everything, 1 holds the reset's zeros.
    never = episodes(actuators.with_action_drop(block_task(), 0.0), actions, KEYS)
    np.testing.assert_allclose(applied(never), np.broadcast_to(actions, (len(KEYS), 6)), atol=1e-6)
    np.testing.assert_array_equal(applied(episodes(actuators.with_action_drop(block_task(), 1.0), actions, KEYS)), 0.0)


def test_filter_follows_the_first_order_recurrence():
    s = episodes(actuators.with_action_filter(block_task(), 0.5), jnp.ones(6), KEYS[:1])
    # a_t = 0.5 * 1 + 0.5 * a_{t-1}, a_{-1} = 0: 1 - 2^-(t+1).
    np.testing.assert_allclose(applied(s)[0], [0.5, 0.75, 0.875, 0.9375, 0.96875, 0.984375], rtol=1e-5)
    np.testing.assert_allclose(find(s, actuators.ActionFilterState).previous[0, :, 0], applied(s)[0], rtol=1e-5)
    s = episodes(actuators.with_action_filter(block_task(), 1.0), ACTIONS, KEYS[:1])  # alpha 1: no filter
    np.testing.assert_allclose(applied(s)[0], ACTIONS, atol=1e-6)


# --- construction errors ------------------------------------------------------------------


def test_actuators_must_be_motors():
    servo = mujoco.MjModel.from_xml_string(BLOCK_XML.replace('<motor name="push"', '<position name="push" kp="5"'))
    for make in (actuators.torque, lambda m: actuators.pd(m, 1.0, 0.1), lambda m: actuators.position_velocity(m, 1, 0)):
        with pytest.raises(ValueError, match=r"actuator 'push' must be a <motor>.*\['push'\]"):
            make(servo)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: actuators.pd(JOINTS, [1.0, 2.0, 3.0], 0.1), r"kp=\[1.0, 2.0, 3.0\] must be .* or 2 of them"),
        (lambda: actuators.pd(JOINTS, 1.0, -0.1), "kd=-0.1 must be a finite number >= 0"),
        (lambda: actuators.pd(JOINTS, 1.0, 0.1, gain_noise=1.0), "gain_noise"),
        (lambda: actuators.pd(JOINTS, 1.0, 0.1, torque_noise=-1.0), "torque_noise"),
        (lambda: actuators.torque(JOINTS, torque_limit=0.0), "must be > 0"),
        (
            lambda: actuators.torque(mujoco.MjModel.from_xml_string(JOINTS_XML.replace('ctrlrange="-3 5"', ""))),
            r"\['m2'\] have no ctrlrange or forcerange; pass torque_limit",
        ),
        (lambda: actuators.with_action_latency(block_task(), -1), "max_latency"),
        (lambda: actuators.with_action_latency(block_task(), 1.5), "max_latency"),
        (lambda: actuators.with_action_drop(block_task(), 1.5), "probability"),
        (lambda: actuators.with_action_filter(block_task(), 0.0), "alpha"),
    ],
)
def test_bad_input_is_reported(make, match):
    with pytest.raises(ValueError, match=match):
        make()
