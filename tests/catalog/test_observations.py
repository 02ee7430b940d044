"""Hand-checked values of the observation items and combinators (`mjzoo.catalog.observations`).

Items run on a small quadruped-like model: a free-floating "base" (a 1.4 kg box, 0.2 m
square, 0.1 m tall) standing on four 0.1 kg sphere feet at (+-0.1, +-0.1, -0.08), with a
0.2 kg "turret" on a vertical hinge "yaw" 0.07 m above the base origin (a motor, gear 2),
a site "nose" at (0.1, 0, 0) and two sensors. Total mass 2 kg. States are set by hand
and completed with one `mjx.forward`, so every expected value is worked out on paper.

Combinators run on a 1 kg block on a frictionless slide joint without gravity, pushed by
1 N, with MuJoCo's semi-implicit Euler at dt = 0.1 s, starting at qpos 0.5 at rest:
    qvel_n = 0.1 n,   qpos_n = 0.5 + 0.01 n (n + 1) / 2;   obs = [qpos, qvel].
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from catalog_tasks import BLOCK
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo import physics as physics_lib
from mjzoo.catalog import observations as obs
from mjzoo.catalog import trackers
from mjzoo.layers import find
from mjzoo.types import State
from mjzoo.types import Task

XML = """
<mujoco>
  <option timestep="0.005" cone="pyramidal"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="base" pos="0 0 0.1">
      <freejoint name="root"/>
      <geom name="torso" type="box" size="0.1 0.1 0.05" mass="1.4"/>
      <geom name="foot_fl" type="sphere" size="0.02" pos="0.1 0.1 -0.08" mass="0.1"/>
      <geom name="foot_fr" type="sphere" size="0.02" pos="0.1 -0.1 -0.08" mass="0.1"/>
      <geom name="foot_hl" type="sphere" size="0.02" pos="-0.1 0.1 -0.08" mass="0.1"/>
      <geom name="foot_hr" type="sphere" size="0.02" pos="-0.1 -0.1 -0.08" mass="0.1"/>
      <site name="nose" pos="0.1 0 0"/>
      <body name="turret" pos="0 0 0.07">
        <joint name="yaw" type="hinge" axis="0 0 1"/>
        <geom name="turret" type="sphere" size="0.02" mass="0.2" contype="0" conaffinity="0"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor name="yaw" joint="yaw" gear="2"/></actuator>
  <sensor>
    <framepos name="base_pos" objtype="xbody" objname="base"/>
    <jointpos name="yaw_pos" joint="yaw"/>
  </sensor>
</mujoco>
"""
MJ = mujoco.MjModel.from_xml_string(XML)
MODEL = mjx.put_model(MJ)
FEET = ["foot_fl", "foot_fr", "foot_hl", "foot_hr"]
C = float(np.sqrt(0.5))
forward = jax.jit(mjx.forward)


def state_at(qpos, qvel=(0.0,) * 7, ctrl=0.0, model=MODEL, layers=()) -> State:
    """A state at the given qpos (base xyz, base quat wxyz, yaw) completed by mjx.forward."""
    data = mjx.make_data(model).replace(
        qpos=jnp.asarray(qpos, jnp.float32), qvel=jnp.asarray(qvel, jnp.float32), ctrl=jnp.asarray([ctrl], jnp.float32)
    )
    return State.create(forward(model, data), jnp.zeros(())).replace(
        layers=layers
    )  # the solver starts cold: fine at rest


def stack(*states):
    return jax.tree.map(lambda *xs: jnp.stack(xs), *states)


# Pose A: base at (1, 2, 0.5) yawed +90 deg (base x axis = world y), turret at 0.3 rad;
# base moving at (1, 2, 3) m/s and turning at 1 rad/s about z, turret at 0.5 rad/s.
POSE_A = dict(qpos=[1, 2, 0.5, C, 0, 0, C, 0.3], qvel=[1, 2, 3, 0, 0, 1, 0.5], ctrl=0.25)
# Pose B: base at (0, 0, 1) rolled +90 deg about x (base y axis = world z, z axis = -y), at rest.
POSE_B = dict(qpos=[0, 0, 1, C, C, 0, 0, 0], ctrl=-1.0)


def kept(action_history, contact):
    """The records of `trackers.with_action_history` around `trackers.with_feet` (only
    the contacts, the rest unused)."""
    unused = {f: None for f in trackers.FeetState._fields if f not in ("contact", "inner")}
    return trackers.ActionHistoryState(action_history, trackers.FeetState(contact=contact, **unused))


INFO_A = dict(layers=kept(jnp.array([[0.7], [0.6]]), jnp.array([True, False])))
INFO_B = dict(layers=kept(jnp.array([[-0.1], [0.2]]), jnp.array([False, True])))

# name: (item, expected in pose A, expected in pose B)
ITEMS = {
    "joint_positions": (obs.joint_positions, [0.3], [0.0]),  # the free joint is left out
    "joint_velocities": (obs.joint_velocities, [0.5], [0.0]),
    "joint_positions_of": (
        obs.joint_positions_of(MJ, ["yaw", "root"]),
        [0.3, 1, 2, 0.5, C, 0, 0, C],
        [0, 0, 0, 1, C, C, 0, 0],
    ),
    "joint_velocities_of": (obs.joint_velocities_of(MJ, "root"), [1, 2, 3, 0, 0, 1], [0] * 6),
    "base_position": (obs.base_position(MJ), [1, 2, 0.5], [0, 0, 1]),
    "base_orientation": (obs.base_orientation(MJ), [C, 0, 0, C], [C, C, 0, 0]),
    # (1, 2, 3) in a frame yawed 90 deg: x_b = (0, 1, 0), y_b = (-1, 0, 0) -> (2, -1, 3)
    "base_linear_velocity": (obs.base_linear_velocity(MJ), [2, -1, 3], [0, 0, 0]),
    "base_angular_velocity": (obs.base_angular_velocity(MJ), [0, 0, 1], [0, 0, 0]),
    # rolled 90 deg about x: (0, 0, -1) . (x_b, y_b, z_b) = (0, -1, 0)
    "projected_gravity": (obs.projected_gravity(MJ), [0, 0, -1], [0, -1, 0]),
    "body_positions": (obs.body_positions(MJ, ["turret", "base"]), [1, 2, 0.57, 1, 2, 0.5], [0, -0.07, 1, 0, 0, 1]),
    # the turret's origin is on the base's spin axis: base velocity, spin 1 + 0.5 rad/s
    "body_velocities": (obs.body_velocities(MJ, "turret"), [1, 2, 3, 0, 0, 1.5], [0] * 6),
    "site_positions": (obs.site_positions(MJ, "nose"), [1, 2.1, 0.5], [0.1, 0, 1]),
    # (1, 2, 3) + (0, 0, 1) x (0, 0.1, 0) = (0.9, 2, 3)
    "site_velocities": (obs.site_velocities(MJ, "nose"), [0.9, 2, 3, 0, 0, 1], [0] * 6),
    "sensors": (obs.sensors(MJ, ["yaw_pos", "base_pos"]), [0.3, 1, 2, 0.5], [0, 0, 0, 1]),
    "actuator_forces": (obs.actuator_forces, [0.25], [-1.0]),  # the control, before the gear
    "geom_contacts": (obs.geom_contacts(MJ, FEET, "floor"), [0] * 4, [0] * 4),  # in the air
    "foot_forces": (obs.foot_forces(MJ, FEET, "floor"), [0] * 4, [0] * 4),
    "foot_contacts": (obs.foot_contacts, [1, 0], [0, 1]),
    "last_action": (obs.last_action, [0.7], [-0.1]),
}


def test_items_hand_checked_under_jit_and_vmap():
    joined = obs.concat(*(item for item, _, _ in ITEMS.values()))
    states = stack(state_at(**POSE_A, **INFO_A), state_at(**POSE_B, **INFO_B))
    out = jax.jit(jax.vmap(joined, in_axes=(None, 0)))(MODEL, states)
    expected = [np.concatenate([np.asarray(e[i], np.float32) for e in ITEMS.values()]) for i in (1, 2)]
    assert out.dtype == jnp.float32 and out.shape == (2, len(expected[0]))
    start = 0
    for name, (_, a, b) in ITEMS.items():
        stop = start + len(a)
        np.testing.assert_allclose(out[:, start:stop], [a, b], atol=1e-5, err_msg=name)
        start = stop


def test_items_are_plain_or_bound_functions_whose_numbers_are_leaves():
    @jax.jit
    @chex.assert_max_traces(n=1)
    def apply(item, state):
        return item(MODEL, state)

    state = state_at(**POSE_A)
    np.testing.assert_allclose(apply(obs.body_positions(MJ, "turret"), state), [1, 2, 0.57], atol=1e-6)
    np.testing.assert_allclose(apply(obs.body_positions(MJ, "base"), state), [1, 2, 0.5], atol=1e-6)  # no retrace
    assert jax.tree.leaves(obs.base_position(MJ))[0].dtype == jnp.int32


def test_geom_contacts_standing_and_upside_down():
    standing = state_at(qpos=[0, 0, 0.099, 1, 0, 0, 0, 0])  # feet 1 mm into the floor
    flipped = state_at(qpos=[0, 0, 0.045, 0, 1, 0, 0, 0])  # on its back, torso 5 mm into the floor
    probe = obs.geom_contacts(MJ, ["foot_fl", "foot_hr", "torso"], "floor")
    anything = obs.geom_contacts(MJ, ["foot_fl", "foot_hr", "torso"])
    np.testing.assert_array_equal(probe(MODEL, standing), [1, 1, 0])
    np.testing.assert_array_equal(probe(MODEL, flipped), [0, 0, 1])
    np.testing.assert_array_equal(anything(MODEL, flipped), [0, 0, 1])


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_foot_forces_carry_the_weight_at_rest(cone):
    # After 1 s standing still, each of the four symmetric feet carries a quarter of the
    # 2 kg weight: 2 * 9.81 / 4 = 4.905 N; the torso, above the floor, carries nothing.
    # (Settled by MuJoCo on the host, then one mjx.forward: MJX's own constraint forces.)
    mj_model = mujoco.MjModel.from_xml_string(XML.replace('cone="pyramidal"', f'cone="{cone}"'))
    mj_data = mujoco.MjData(mj_model)
    mujoco.mj_step(mj_model, mj_data, nstep=200)
    model = mjx.put_model(mj_model)
    state = state_at(mj_data.qpos, mj_data.qvel, model=model)
    forces = obs.foot_forces(mj_model, FEET + ["torso"], "floor")(model, state)
    np.testing.assert_allclose(forces, [4.905] * 4 + [0.0], rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(obs.foot_forces(mj_model, FEET)(model, state), [4.905] * 4, rtol=2e-3)


def test_names_are_checked_at_construction():
    with pytest.raises(ValueError, match="no body named 'tail'.*'base', 'turret'"):
        obs.body_positions(MJ, ["base", "tail"])
    for make, kind in [
        (obs.site_positions, "site"),
        (obs.joint_positions_of, "joint"),
        (obs.sensors, "sensor"),
        (obs.geom_contacts, "geom"),
    ]:
        with pytest.raises(ValueError, match=f"no {kind} named 'nope'"):
            make(MJ, "nope")
    with pytest.raises(ValueError, match="at least one body"):
        obs.body_velocities(MJ, [])
    with pytest.raises(ValueError, match="no geom named 'ground'"):
        obs.foot_forces(MJ, FEET, floor="ground")
    with pytest.raises(ValueError, match="'turret' can never touch"):
        obs.geom_contacts(MJ, "turret", "floor")
    with pytest.raises(ValueError, match="no free joint.*'block'"):
        obs.projected_gravity(BLOCK.mj_model)
    assert obs.projected_gravity(BLOCK.mj_model, body="block") is not None
    with pytest.raises(ValueError, match="at least one"):
        obs.concat()
    with pytest.raises(TypeError, match="item 1 must be callable"):
        obs.concat(obs.joint_positions, 3)


# --- combinators, on the sliding block (catalog_tasks.BLOCK) ------------------------------

QPOS = [0.5 + 0.01 * n * (n + 1) / 2 for n in range(4)]  # 0.5, 0.51, 0.53, 0.56
QVEL = [0.1 * n for n in range(4)]


def _observe(data):
    return jnp.concatenate([data.qpos, data.qvel])


def _reset(model, key):
    data = mjx.make_data(model)
    data = data.replace(qpos=data.qpos.at[0].set(0.5))
    return State.create(data, _observe(data))


def _step(model, state, action, key):
    data = physics_lib.step(model, state.data, action, 1)  # records the last entry of the obs it was given
    return state.replace(data=data, obs=_observe(data), metrics={"given": state.obs[-1]})


def _reward(model, state, action, next_state):
    return {"x": next_state.data.qpos[0]}


def _terminate(model, state):
    return jnp.zeros((), bool), jnp.zeros((), bool)


def block_task() -> Task:
    fns = {
        name: Partial(fn) for name, fn in dict(start=_reset, step=_step, reward=_reward, terminate=_terminate).items()
    }
    return Task(model=BLOCK.model, mj_model=BLOCK.mj_model, **fns)


@jax.jit
def episodes(task: Task, keys: jax.Array):
    """For each key: reset, then three 1 N pushes; the states [4] (reset state first)."""

    def one(key):
        state = mjzoo.reset(task, key)
        _, states = mjzoo.rollout(task, lambda o, k: jnp.ones(1), state, key, 3)
        return jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), state, states.next_state)

    return jax.vmap(one)(keys)


KEYS = jax.random.split(jax.random.key(0), 512)
CLEAN = np.stack([QPOS, QVEL], axis=1)  # [4, 2]: the block's own observations


def test_observation_history_newest_first_filled_at_reset():
    states = episodes(obs.with_observation_history(block_task(), 3), KEYS[:2])
    o0, o1, o2, o3 = CLEAN
    expected = [np.r_[o0, o0, o0], np.r_[o1, o0, o0], np.r_[o2, o1, o0], np.r_[o3, o2, o1]]
    np.testing.assert_allclose(states.obs[0], expected, rtol=1e-5)
    np.testing.assert_allclose(find(states, obs.ObservationHistoryState).frames[0, 3], [o3, o2, o1], rtol=1e-5)
    # The block's step is given its own last observation [qpos, qvel], not the history.
    np.testing.assert_allclose(states.metrics["given"][0, 1:], QVEL[:3], atol=1e-6)
    # Applied twice, each keeps its own record: the outer stacks the inner's stacks.
    twice = episodes(obs.with_observation_history(obs.with_observation_history(block_task(), 2), 2), KEYS[:1])
    nested = [np.r_[o0, o0, o0, o0], np.r_[o1, o0, o0, o0], np.r_[o2, o1, o1, o0], np.r_[o3, o2, o2, o1]]
    np.testing.assert_allclose(twice.obs[0], nested, rtol=1e-5)
    for length in [0, 2.0, True]:
        with pytest.raises(ValueError, match="length"):
            obs.with_observation_history(block_task(), length)


def test_observation_bias_is_constant_per_episode_and_drawn_at_reset():
    states = episodes(obs.with_observation_bias(block_task(), 0.3), KEYS)
    bias = np.asarray(states.obs) - CLEAN  # [512, 4, 2]
    np.testing.assert_allclose(
        bias, np.broadcast_to(find(states, obs.ObservationBiasState).bias[:, :1], bias.shape), atol=1e-6
    )
    np.testing.assert_allclose(bias[:, 0].std(axis=0), [0.3, 0.3], rtol=0.1)  # one draw per episode
    np.testing.assert_allclose(bias[:, 0].mean(axis=0), [0.0, 0.0], atol=0.05)
    states = episodes(obs.with_observation_bias(block_task(), 0.0), KEYS[:2])  # scale is a leaf: no retrace
    np.testing.assert_allclose(states.obs[0], CLEAN, rtol=1e-6)
    with pytest.raises(ValueError, match="scale"):
        obs.with_observation_bias(block_task(), -0.1)


def test_multiplicative_noise_scales_with_the_signal():
    seen = episodes(obs.with_multiplicative_observation_noise(block_task(), 0.2), KEYS).obs
    np.testing.assert_array_equal(np.asarray(seen)[:, 0, 1], 0.0)  # zero velocity at reset stays zero
    relative = np.asarray(seen)[:, 1:] / CLEAN[1:] - 1.0  # [512, 3, 2]
    np.testing.assert_allclose(relative.std(axis=0), np.full((3, 2), 0.2), rtol=0.15)
    assert abs(np.corrcoef(relative[:, 0, 0], relative[:, 1, 0])[0, 1]) < 0.15  # fresh noise every step
    with pytest.raises(ValueError, match="scale"):
        obs.with_multiplicative_observation_noise(block_task(), float("nan"))


def test_privileged_view_and_observed_actions_refuse_what_they_cannot_build():
    """Both append to a 1-D observation: a dict one (say, already split) is refused by
    name, as are two keys that are the same."""
    from catalog_tasks import make_task

    task = make_task()
    split = obs.with_privileged_observation(task, obs.joint_positions)
    assert set(jax.eval_shape(lambda k: mjzoo.reset(split, k), jax.random.key(0)).obs) == {"state", "privileged_state"}
    with pytest.raises(ValueError, match="with_action_history: observe=True appends"):
        trackers.with_action_history(split, observe=True)
    with pytest.raises(ValueError, match="must observe a 1-D array"):
        obs.with_privileged_observation(split, obs.joint_positions)
    with pytest.raises(ValueError, match="two different names"):
        obs.with_privileged_observation(task, obs.joint_positions, keys=("state", "state"))
    with pytest.raises(TypeError, match="observation item"):
        obs.with_privileged_observation(task, 3)
