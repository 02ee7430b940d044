"""Hand-checked behaviour of the shared trackers (`mjzoo.catalog.trackers`).

The test task is kinematic, so every contact and velocity can be worked out on paper:
two sphere feet (radius 5 cm) on slide joints over a floor plane; the action is the new
qpos [ax, az, bz, byaw], and a step sets qpos = action, qvel = (action - qpos) / DT,
advances time by DT = 0.02 s and recomputes poses, velocities and contacts.

  foot_a  at (-0.5 + ax, 0, az): touches the floor while az < 0.05 (no margin).
  foot_b  at (0.5 + 0.1 cos byaw, 0.1 sin byaw, bz), 0.1 m off a vertical hinge axis:
          margin 1 cm, so it counts as touching while bz < 0.06. A ball of
          radius 0.1 sits at (0.6, 0, 0.5): at bz = 0.5 foot_b is inside it, touching it,
          not the floor. Its velocity is byaw' * z x (offset) + (0, 0, bz').
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo import physics as physics_lib
from mjzoo.catalog import contacts
from mjzoo.catalog import rewards
from mjzoo.catalog import trackers
from mjzoo.layers import find
from mjzoo.types import State
from mjzoo.types import Task

DT = 0.02
XML = """
<mujoco model="feet">
  <worldbody>
    <geom name="floor" type="plane" size="5 5 .1"/>
    <geom name="ball" type="sphere" size=".1" pos=".6 0 .5"/>
    <body name="a" pos="-.5 0 0">
      <joint name="ax" type="slide" axis="1 0 0"/>
      <joint name="az" type="slide" axis="0 0 1"/>
      <geom name="foot_a" type="sphere" size=".05"/>
    </body>
    <body name="b" pos=".5 0 0">
      <joint name="bz" type="slide" axis="0 0 1"/>
      <joint name="byaw" type="hinge" axis="0 0 1"/>
      <geom name="foot_b" type="sphere" size=".05" pos=".1 0 0" margin=".01"/>
      <geom name="weight" type="sphere" size=".05" pos="-.1 0 0" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="ax"/><motor joint="az"/><motor joint="bz"/><motor joint="byaw"/>
  </actuator>
</mujoco>
"""
PHYSICS = physics_lib.load(XML)
INIT = [0.0, 0.0, 0.2, 0.0]  # foot_a on the floor, foot_b 15 cm above it


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Params:
    init: jax.Array  # qpos at reset
    dt: jax.Array


def _positions_and_contacts(model, data):
    """The part of `mjx.forward` the trackers read (poses, com velocities, contacts):
    the constraint solver of a full forward would only cost compile time."""
    data = mjx.com_vel(model, mjx.com_pos(model, mjx.kinematics(model, data)))
    return mjx.collision(model, data)


def _reset(p: Params, model, key) -> State:
    data = mjx.make_data(model).replace(qpos=p.init)
    return State.create(_positions_and_contacts(model, data), p.init)


def _step(p: Params, model, state: State, action, key) -> State:
    data = state.data
    data = data.replace(qpos=action, qvel=(action - data.qpos) / p.dt, time=data.time + p.dt)
    return state.replace(data=_positions_and_contacts(model, data), obs=action)


def _terminate(p: Params, model, state):
    return jnp.zeros((), bool), jnp.zeros((), bool)


def _no_reward(p: Params, model, state, action, next_state):
    return {}


def kinematic_task() -> Task:
    p = Params(jnp.asarray(INIT, jnp.float32), jnp.float32(DT))
    return Task(
        PHYSICS.model,
        Partial(_reset, p),
        Partial(_step, p),
        Partial(_no_reward, p),
        Partial(_terminate, p),
        PHYSICS.mj_model,
    )


def tracked(threshold: float = 0.05) -> Task:
    """The stack under test: trackers inside a 5-step auto-resetting episode, with the
    reward terms that read them."""
    task = trackers.with_feet(
        trackers.with_action_history(kinematic_task(), length=4), feet=["foot_a", "foot_b"], floor="floor"
    )
    task = rewards.terms(
        task,
        {
            "air": (rewards.feet_air_time(threshold), 1.0),
            "slip": (rewards.foot_slip, 1.0),
            "rate": (rewards.action_rate, 1.0),
            "jerk": (rewards.action_jerk, 1.0),
        },
    )
    return mjzoo.with_auto_reset(mjzoo.with_time_limit(task, 5))


# Sequence A: steps 1-5 are one episode (the 5th is truncated and returns the reset
# state), step 6 starts the next one. Sequence B holds the reset pose throughout.
A = np.array(
    [
        [0.0, 0.1, 0.2, 0.0],  # 1: both feet in the air
        [0.0, 0.1, 0.055, 0.0],  # 2: foot_b lands, 5 mm up (within its 1 cm margin)
        [0.01, 0.0, 0.055, 0.0],  # 3: foot_a lands sliding 1 cm in x (0.5 m/s)
        [0.01, 0.0, 0.5, 0.02],  # 4: foot_b up into the ball, yawing at 1 rad/s
        [0.01, 0.0, 0.1, 0.02],  # 5: truncated: the episode restarts
        [0.0, 0.1, 0.2, 0.0],  # 6: as step 1, from the reset pose
    ],
    np.float32,
)
B = np.tile(np.asarray(INIT, np.float32), (6, 1))


@jax.jit
def run(task: Task, actions: jax.Array):
    """vmapped over [N, T, 4] action sequences; returns the [N] reset and [N, T] next states."""

    def one(actions):
        state = mjzoo.reset(task, jax.random.key(0))

        def body(state, action):
            state = mjzoo.transition(task, state, action, jax.random.key(1))
            return state, state

        return state, jax.lax.scan(body, state, actions)[1]

    return jax.vmap(one)(actions)


@pytest.fixture(scope="module")
def runs():
    return run(tracked(), jnp.stack([A, B]))


def test_feet_at_reset(runs):
    first, _ = runs
    feet = find(first, trackers.FeetState)
    np.testing.assert_array_equal(feet.contact, [[True, False]] * 2)
    np.testing.assert_array_equal(feet.first_contact, [[False, False]] * 2)
    np.testing.assert_array_equal(feet.air_time, np.zeros((2, 2)))
    np.testing.assert_array_equal(feet.last_air_time, np.zeros((2, 2)))
    np.testing.assert_allclose(feet.position[0], [[-0.5, 0, 0], [0.6, 0, 0.2]], atol=1e-6)
    np.testing.assert_array_equal(find(first, trackers.ActionHistoryState).actions, np.zeros((2, 4, 4)))


def test_feet_contacts_and_air_times_by_hand(runs):
    feet = find(runs[1], trackers.FeetState)
    # Steps 1-4 of A, then step 5 returns the new episode's reset, step 6 is its first.
    np.testing.assert_array_equal(feet.contact[0], [[0, 0], [0, 1], [1, 1], [1, 0], [1, 0], [0, 0]])
    np.testing.assert_array_equal(feet.first_contact[0], [[0, 0], [0, 1], [1, 0], [0, 0], [0, 0], [0, 0]])
    # foot_a: off at step 1, 0.02 s then 0.04 s up, lands at step 3 after 0.06 s.
    # foot_b: up since reset, lands at step 2 after 0.04 s, leaves again at step 4.
    air = [[0.02, 0.02], [0.04, 0], [0, 0], [0, 0.02], [0, 0], [0.02, 0.02]]
    last = [[0, 0], [0, 0.04], [0.06, 0.04], [0.06, 0.04], [0, 0], [0, 0]]
    np.testing.assert_allclose(feet.air_time[0], air, atol=1e-6)
    np.testing.assert_allclose(feet.last_air_time[0], last, atol=1e-6)
    # B: foot_a stands, foot_b hangs: its air time grows 0.02 s a step, restarting at 5.
    np.testing.assert_array_equal(feet.contact[1], [[1, 0]] * 6)
    assert not feet.first_contact[1].any()
    np.testing.assert_allclose(feet.air_time[1][:, 1], [0.02, 0.04, 0.06, 0.08, 0, 0.02], atol=1e-6)
    np.testing.assert_array_equal(feet.last_air_time[1], np.zeros((6, 2)))


def test_feet_positions_and_velocities_by_hand(runs):
    feet = find(runs[1], trackers.FeetState)
    # Step 3: foot_a moved 1 cm in x and 10 cm down in 0.02 s: (0.5, 0, -5) m/s.
    np.testing.assert_allclose(feet.velocity[0, 2, 0], [0.5, 0, -5], atol=1e-4)
    np.testing.assert_allclose(feet.position[0, 2, 0], [-0.49, 0, 0], atol=1e-6)
    # Step 4: foot_b yaws by 0.02 rad at 1 rad/s, 0.1 m off the axis, and rises 0.445 m.
    c, s = math.cos(0.02), math.sin(0.02)
    np.testing.assert_allclose(feet.velocity[0, 3, 1], [-0.1 * s, 0.1 * c, 0.445 / DT], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(feet.position[0, 3, 1], [0.5 + 0.1 * c, 0.1 * s, 0.5], atol=1e-6)


def test_action_history_most_recent_first_and_cleared_by_reset(runs):
    history = np.asarray(find(runs[1], trackers.ActionHistoryState).actions[0])
    np.testing.assert_array_equal(history[0], [A[0], 0 * A[0], 0 * A[0], 0 * A[0]])
    np.testing.assert_array_equal(history[3], [A[3], A[2], A[1], A[0]])
    np.testing.assert_array_equal(history[4], np.zeros((4, 4)))  # the reset state
    np.testing.assert_array_equal(history[5], [A[5], 0 * A[5], 0 * A[5], 0 * A[5]])


def test_reward_terms_read_the_trackers(runs):
    metrics = runs[1].metrics
    # air: (last air time - 0.05 s) at each touch-down: foot_b at 2 (0.04), foot_a at 3 (0.06).
    np.testing.assert_allclose(metrics["reward/air"][0], [0, -0.01, 0.01, 0, 0, 0], atol=1e-6)
    # slip: only step 3 has a foot in contact moving sideways: 0.5^2.
    np.testing.assert_allclose(metrics["reward/slip"][0], [0, 0, 0.25, 0, 0, 0], atol=1e-5)
    # rate: |a_t - a_{t-1}|^2 with a_0 = 0 and again 0 before step 6 (new episode):
    # 0.1^2+0.2^2, 0.145^2, 0.01^2+0.1^2, 0.445^2+0.02^2, 0.4^2, 0.1^2+0.2^2.
    rate = [0.05, 0.021025, 0.0101, 0.198425, 0.16, 0.05]
    np.testing.assert_allclose(metrics["reward/rate"][0], rate, rtol=1e-4)
    # jerk at step 4: a4 - 3 a3 + 3 a2 - a1 = (-0.02, 0.2, 0.3, 0.02).
    np.testing.assert_allclose(metrics["reward/jerk"][0, 3], 0.1308, rtol=1e-4)
    np.testing.assert_allclose(metrics["reward/jerk"][0, 0], 0.05, rtol=1e-4)  # a1 alone
    # B holds a = INIT (|a|^2 = 0.04) from a zero history, from reset to reset:
    for name in ("air", "slip"):
        np.testing.assert_array_equal(metrics[f"reward/{name}"][1], np.zeros(6))
    np.testing.assert_allclose(metrics["reward/rate"][1], [0.04, 0, 0, 0, 0, 0.04], rtol=1e-5)
    # jerk: a, a - 3a = -2a, a - 3a + 3a = a, then a - 3a + 3a - a = 0.
    np.testing.assert_allclose(metrics["reward/jerk"][1], [0.04, 0.16, 0.04, 0, 0, 0.04], rtol=1e-5, atol=1e-7)


def test_new_threshold_does_not_retrace(runs):
    _, states = run(tracked(threshold=0.0), jnp.stack([A, B]))
    assert run._cache_size() == 1
    np.testing.assert_allclose(states.metrics["reward/air"][0], [0, 0.04, 0.06, 0, 0, 0], atol=1e-6)


@pytest.mark.parametrize(
    "qpos,on_floor,on_ball",
    [
        ([0, 0.01, 0.059, 0], [True, True], [False, False]),  # a 4 cm in; b 9 mm up, within its 1 cm margin
        ([0, 0.049, 0.061, 0], [True, False], [False, False]),  # a 1 mm in; b 11 mm up, past its margin
        ([0, 0.051, 0.5, 0], [False, False], [False, True]),  # a 1 mm up; b inside the ball
    ],
)
def test_foot_contacts_directly(qpos, on_floor, on_ball):
    # Contacts from MuJoCo's own forward pass (put_data pads the unused slots with
    # distance 1e10); only contacts with the given geom count.
    mj_data = mujoco.MjData(PHYSICS.mj_model)
    mj_data.qpos[:] = qpos
    mujoco.mj_forward(PHYSICS.mj_model, mj_data)
    data = mjx.put_data(PHYSICS.mj_model, mj_data)
    geoms = jnp.array([PHYSICS.id("geom", "foot_a"), PHYSICS.id("geom", "foot_b")], jnp.int32)
    for other, expected in (("floor", on_floor), ("ball", on_ball)):
        np.testing.assert_array_equal(contacts.touching(data, geoms, jnp.array([PHYSICS.id("geom", other)])), expected)


def test_bad_input_is_named():
    task = kinematic_task()
    with pytest.raises(ValueError, match="no geom named 'toe'.*'foot_a'"):
        trackers.with_feet(task, feet=["foot_a", "toe"], floor="floor")
    with pytest.raises(ValueError, match="no geom named 'ground'"):
        trackers.with_feet(task, feet=["foot_a"], floor="ground")
    with pytest.raises(ValueError, match="'weight' can never touch 'floor'"):
        trackers.with_feet(task, feet=["weight"], floor="floor")
    with pytest.raises(ValueError, match="repeat"):
        trackers.with_feet(task, feet=["foot_a", "foot_a"], floor="floor")
    with pytest.raises(ValueError, match="'floor' is listed both as watched and as what it touches"):
        trackers.with_feet(task, feet=["floor"], floor="floor")
    for length in (0, 2.0, True):
        with pytest.raises(ValueError, match="length"):
            trackers.with_action_history(task, length=length)
    # A reward that needs a longer history says how to get it, when traced.
    short = rewards.terms(trackers.with_action_history(task, length=2), {"jerk": (rewards.action_jerk, 1.0)})
    with pytest.raises(ValueError, match=r"length >= 4 \(has length 2\).*with_action_history"):
        jax.eval_shape(lambda: mjzoo.reset(short, jax.random.key(0)))
