"""Hand-checked behaviour of the physics randomizers (`mjzoo.catalog.randomizers`).

One small model holds every field they edit. Gravity -9.81 along z, Euler with dt = 0.01.
  block  slide joint along x (gravity has no component along it), mass m = 1.5 kg,
         armature a = 0.5, damping b = 2. MuJoCo's Euler integrates damping implicitly:
             (m + a + dt b) qacc = -b v   =>   v_1 = v_0 (m + a) / (m + a + dt b).
  ball   free joint, 2 kg, no contacts: v_z after one step is -g dt, whatever its mass.
  arm    hinge about y through the body origin, 1 kg, inertia I = 0.2 about its centre of
         mass, which sits on the hinge. A position servo (kp = 4, kv = 0.5) pulls it to ctrl:
             from q_0 at rest:  v_1 = dt kp (ctrl - q_0) / I.
         Moving the centre of mass by d along x adds the gravity torque m g d about +y:
             from q_0 = 0 at rest, ctrl = 0:  v_1 = dt m g d / (I + m d^2).
  floor  a plane (friction 0.8); no geom collides here.
A zero-width range draws a known value, which the dynamics tests use.
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
from mjzoo.catalog import randomizers
from mjzoo.types import State
from mjzoo.types import Task

DT, G = 0.01, 9.81
XML = """
<mujoco model="randomized">
  <option timestep="0.01" integrator="Euler"/>
  <default><geom contype="0" conaffinity="0"/></default>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 .1" friction="0.8 0.01 0.001"/>
    <body name="block" pos="0 0 1">
      <joint name="slide" type="slide" axis="1 0 0" damping="2" armature="0.5"/>
      <inertial pos="0 0 0" mass="1.5" diaginertia="0.1 0.1 0.1"/>
    </body>
    <body name="ball" pos="0 2 1">
      <freejoint name="free"/>
      <geom name="ball" size="0.1" mass="2"/>
    </body>
    <body name="arm" pos="0 -2 1">
      <joint name="hinge" type="hinge" axis="0 1 0"/>
      <inertial pos="0 0 0" mass="1" diaginertia="0.2 0.2 0.2"/>
    </body>
  </worldbody>
  <actuator><position name="servo" joint="hinge" kp="4" kv="0.5"/></actuator>
</mujoco>
"""
MJ = mujoco.MjModel.from_xml_string(XML)
MODEL = mjx.put_model(MJ)
KEY = jax.random.key(0)
# qpos: slide (0), free (1..7), hinge (8); qvel: slide (0), free (1..6), hinge (7).
SLIDE_V, BALL_VZ, ARM_V = 0, 3, 7


@jax.jit
def one_step(model: mjx.Model, v_slide, q_arm, ctrl) -> jax.Array:
    """qvel after one step from rest, with the block moving at v_slide and the arm at q_arm."""
    data = mjx.make_data(model)
    data = data.replace(
        qpos=data.qpos.at[8].set(q_arm), qvel=data.qvel.at[SLIDE_V].set(v_slide), ctrl=jnp.full((1,), ctrl)
    )
    return mjx.step(model, data).qvel


def drawn(randomizer, key=KEY) -> mjx.Model:
    return MODEL.replace(**jax.jit(randomizer)(MODEL, key))


def block_v1(m=1.5, a=0.5, b=2.0, v0=1.0):
    return v0 * (m + a) / (m + a + DT * b)


def test_the_model_follows_the_hand_computed_dynamics():
    qvel = one_step(MODEL, 1.0, 0.1, 0.0)
    np.testing.assert_allclose(qvel[SLIDE_V], block_v1(), rtol=1e-5)
    np.testing.assert_allclose(qvel[BALL_VZ], -G * DT, rtol=1e-5)
    np.testing.assert_allclose(qvel[ARM_V], DT * 4 * (0.0 - 0.1) / 0.2, rtol=1e-5)


# --- the nominal model is the zero-width identity ---------------------------------------

IDENTITIES = {
    "friction": lambda: randomizers.scale_friction(MJ, 1.0, 1.0),
    "armature": lambda: randomizers.scale_armature(MJ, 1.0, 1.0),
    "damping": lambda: randomizers.scale_damping(MJ, 1.0, 1.0),
    "scale_masses": lambda: randomizers.scale_masses(MJ, 1.0, 1.0),
    "add_masses": lambda: randomizers.add_masses(MJ, 0.0, 0.0),
    "shift_com": lambda: randomizers.shift_com(MJ, 0.0, 0.0),
    "gains": lambda: randomizers.scale_position_gains(MJ, 1.0, 1.0),
}


def test_zero_range_gives_the_nominal_model():
    combined = randomizers.combine(*(make() for make in IDENTITIES.values()))
    fields = jax.jit(combined)(MODEL, KEY)
    assert set(fields) == {
        "geom_friction",
        "dof_armature",
        "dof_damping",
        "body_mass",
        "body_inertia",
        "body_ipos",
        "actuator_gainprm",
        "actuator_biasprm",
    }
    for name, value in fields.items():
        np.testing.assert_array_equal(value, getattr(MODEL, name), err_msg=name)
        assert value.dtype == getattr(MODEL, name).dtype


# --- hand-checked fields ----------------------------------------------------------------


def test_scale_friction_scales_whole_rows_of_the_named_geoms_only():
    f = drawn(randomizers.scale_friction(MJ, 2.0, 2.0, geoms=["floor"])).geom_friction
    np.testing.assert_allclose(f[0], [1.6, 0.02, 0.002], rtol=1e-6)
    np.testing.assert_array_equal(f[1], MODEL.geom_friction[1])


def test_armature_and_damping_select_the_dofs_of_named_joints():
    # The slide joint owns dof 0, the free joint dofs 1..6, the hinge dof 7.
    armature = drawn(randomizers.scale_armature(MJ, 3.0, 3.0, joints=["slide"])).dof_armature
    np.testing.assert_allclose(armature, [1.5] + [0.0] * 7)
    ids = randomizers.scale_damping(MJ, 2.0, 2.0, joints=["free", "hinge"]).args[1]
    np.testing.assert_array_equal(ids, [1, 2, 3, 4, 5, 6, 7])


def test_scale_masses_scales_mass_and_inertia_together():
    model = drawn(randomizers.scale_masses(MJ, 2.0, 2.0, bodies=["ball"]))
    np.testing.assert_allclose(model.body_mass, [0.0, 1.5, 4.0, 1.0])
    np.testing.assert_allclose(model.body_inertia[2], 2.0 * MODEL.body_inertia[2], rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(model.body_inertia)[[0, 1, 3]], np.asarray(MODEL.body_inertia)[[0, 1, 3]])
    # None: every body but the world.
    model = drawn(randomizers.scale_masses(MJ, 2.0, 2.0))
    np.testing.assert_allclose(model.body_mass, [0.0, 3.0, 4.0, 2.0])


def test_add_masses_and_shift_com():
    model = drawn(randomizers.add_masses(MJ, 0.5, 0.5, bodies=["block", "arm"]))
    np.testing.assert_allclose(model.body_mass, [0.0, 2.0, 2.0, 1.5])
    np.testing.assert_array_equal(model.body_inertia, MODEL.body_inertia)  # a point mass at the COM
    model = drawn(randomizers.shift_com(MJ, [0.1, -0.2, 0.0], [0.1, -0.2, 0.0], bodies=["arm"]))
    np.testing.assert_allclose(model.body_ipos[3], [0.1, -0.2, 0.0], rtol=1e-6)
    np.testing.assert_array_equal(model.body_ipos[:3], MODEL.body_ipos[:3])


def test_scale_position_gains_keeps_the_bias_consistent():
    model = drawn(randomizers.scale_position_gains(MJ, 2.0, 2.0, actuators=["servo"]))
    np.testing.assert_allclose(model.actuator_gainprm[0, :3], [8.0, 0.0, 0.0])
    np.testing.assert_allclose(model.actuator_biasprm[0, :3], [0.0, -8.0, -0.5])  # kv kept


def test_combine_composes_edits_of_one_field_in_order():
    scale, add = randomizers.scale_masses(MJ, 2.0, 2.0, ["block"]), randomizers.add_masses(MJ, 1.0, 1.0, ["block"])
    np.testing.assert_allclose(drawn(randomizers.combine(scale, add)).body_mass[1], 1.5 * 2 + 1)
    np.testing.assert_allclose(drawn(randomizers.combine(add, scale)).body_mass[1], (1.5 + 1) * 2)


# --- draws: ranges, independence, jit and vmap, no retracing ------------------------------


@jax.jit
@chex.assert_max_traces(n=1)
def draw_many(randomizer, keys):
    return jax.vmap(randomizer, in_axes=(None, 0))(MODEL, keys)


def test_draws_are_in_range_independent_and_ranges_are_leaves():
    keys = jax.random.split(KEY, 512)
    for low, high in [(0.5, 1.5), (2.0, 3.0)]:  # one trace for both ranges
        mass = np.asarray(draw_many(randomizers.scale_masses(MJ, low, high), keys)["body_mass"])
        factors = mass[:, 1:] / np.asarray(MODEL.body_mass[1:])
        assert factors.shape == (512, 3) and np.all(mass[:, 0] == 0.0)
        assert np.all((factors >= low) & (factors <= high))
        np.testing.assert_allclose(factors.mean(axis=0), (low + high) / 2, atol=0.05 * (high - low))
        assert abs(np.corrcoef(factors[:, 0], factors[:, 1])[0, 1]) < 0.15  # independent per body
        assert len(np.unique(factors[:, 0])) > 500  # new draw per key


# --- the randomized model changes the dynamics --------------------------------------------


def test_heavier_bodies_fall_the_same_but_accelerate_less_under_damping():
    model = drawn(
        randomizers.combine(
            randomizers.scale_masses(MJ, 3.0, 3.0, ["ball", "block"]), randomizers.add_masses(MJ, 2.0, 2.0, ["ball"])
        )
    )
    qvel = one_step(model, 1.0, 0.0, 0.0)
    np.testing.assert_allclose(qvel[BALL_VZ], -G * DT, rtol=1e-5)  # 8 kg falls like 2 kg
    np.testing.assert_allclose(qvel[SLIDE_V], block_v1(m=4.5), rtol=1e-5)  # damping slows 4.5 kg less


def test_damping_and_armature_change_the_block():
    qvel = one_step(drawn(randomizers.scale_damping(MJ, 5.0, 5.0, ["slide"])), 1.0, 0.0, 0.0)
    np.testing.assert_allclose(qvel[SLIDE_V], block_v1(b=10.0), rtol=1e-5)
    qvel = one_step(drawn(randomizers.scale_armature(MJ, 4.0, 4.0, ["slide"])), 1.0, 0.0, 0.0)
    np.testing.assert_allclose(qvel[SLIDE_V], block_v1(a=2.0), rtol=1e-5)


def test_shifted_com_makes_gravity_turn_the_arm():
    d = 0.1
    qvel = one_step(drawn(randomizers.shift_com(MJ, [d, 0, 0], [d, 0, 0], ["arm"])), 0.0, 0.0, 0.0)
    np.testing.assert_allclose(qvel[ARM_V], DT * G * d / (0.2 + d**2), rtol=1e-5)


def test_scaled_gains_pull_harder_and_hold_the_same_target():
    model = drawn(randomizers.scale_position_gains(MJ, 2.5, 2.5))
    np.testing.assert_allclose(one_step(model, 0.0, 0.1, 0.0)[ARM_V], DT * 10 * (0.0 - 0.1) / 0.2, rtol=1e-5)
    np.testing.assert_allclose(one_step(model, 0.0, 0.1, 0.1)[ARM_V], 0.0, atol=1e-7)  # at its target


# --- through with_domain_randomization ------------------------------------------------------


def _reset(model, key):
    data = mjx.make_data(model).replace(qvel=jnp.zeros(MJ.nv).at[SLIDE_V].set(1.0))
    return State.create(data, data.qvel)


def _step(model, state, action, key):
    data = mjx.step(model, state.data)
    return state.replace(data=data, obs=data.qvel)


def _reward(model, state, action, next_state):
    return {"v": next_state.data.qvel[SLIDE_V]}


def _terminate(model, state):
    return jnp.zeros((), bool), jnp.zeros((), bool)


def test_with_domain_randomization_draws_each_episode_and_steps_with_it():
    task = Task(MODEL, Partial(_reset), Partial(_step), Partial(_reward), Partial(_terminate), MJ)
    task = mjzoo.with_domain_randomization(
        task,
        randomizers.combine(
            randomizers.scale_damping(MJ, 0.0, 10.0, ["slide"]), randomizers.add_masses(MJ, 0.0, 3.0, ["block"])
        ),
    )

    @jax.jit
    def episode(key):
        state = mjzoo.reset(task, key)
        return mjzoo.transition(task, state, jnp.zeros(1), key)

    s = jax.vmap(episode)(jax.random.split(KEY, 64))
    b = np.asarray(mjzoo.find(s, mjzoo.DomainRandomizationState).fields["dof_damping"][:, SLIDE_V])
    m = np.asarray(mjzoo.find(s, mjzoo.DomainRandomizationState).fields["body_mass"][:, 1])
    assert np.all((b >= 0) & (b <= 20)) and np.all((m >= 1.5) & (m <= 4.5)) and len(np.unique(b)) == 64
    np.testing.assert_allclose(s.reward, block_v1(m=m, b=b), rtol=1e-5)


# --- friction on a sliding contact ------------------------------------------------------------

PUCK_XML = """
<mujoco model="puck">
  <option timestep="0.002"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 .1" friction="0.5"/>
    <body name="puck" pos="0 0 0.1">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="z" type="slide" axis="0 0 1"/>
      <geom name="puck" size="0.1" mass="1" friction="0.1"/>
    </body>
  </worldbody>
</mujoco>"""
PUCK = mujoco.MjModel.from_xml_string(PUCK_XML)
# The same puck touching the floor only through an explicit pair, whose friction (0.5) rules.
PAIR = '<contact><pair geom1="floor" geom2="puck" friction="0.5 0.5 0.005 1e-4 1e-4"/></contact>'
PAIRED_PUCK = mujoco.MjModel.from_xml_string(
    PUCK_XML.replace('friction="0.1"', 'friction="0.1" contype="0" conaffinity="0"').replace(
        "</mujoco>", PAIR + "</mujoco>"
    )
)


@jax.jit
def slide(model: mjx.Model) -> jax.Array:
    """x velocity of the puck (sliding, it cannot roll) 0.2 s after a 3 m/s kick, once settled."""
    data = jax.lax.fori_loop(0, 100, lambda _, d: mjx.step(model, d), mjx.make_data(model))
    data = data.replace(qvel=jnp.array([3.0, 0.0]))
    return jax.lax.fori_loop(0, 100, lambda _, d: mjx.step(model, d), data).qvel[0]


def test_floor_friction_sets_the_sliding_deceleration():
    # Coulomb friction decelerates at mu g: after 0.2 s, v = 3 - mu g 0.2 (soft contacts: ~5%).
    # The contact takes the larger friction, the floor's 0.5 s against the puck's 0.1.
    model = mjx.put_model(PUCK)
    for s in (0.5, 2.0):
        fields = randomizers.scale_friction(PUCK, s, s, geoms=["floor"])(model, KEY)
        v = slide(model.replace(**fields))
        np.testing.assert_allclose(3.0 - v, 0.5 * s * G * 0.2, rtol=0.1)


def test_a_pair_contact_takes_the_friction_of_its_pair():
    # Geoms' friction does not reach a <pair> contact (the puck's own is 0.1): its pair's does.
    model = mjx.put_model(PAIRED_PUCK)
    np.testing.assert_allclose(3.0 - slide(model), 0.5 * G * 0.2, rtol=0.1)
    fields = randomizers.scale_friction(PAIRED_PUCK, 2.0, 2.0, geoms=["puck"])(model, KEY)
    np.testing.assert_allclose(fields["pair_friction"][0], [1.0, 1.0, 0.01, 2e-4, 2e-4], rtol=1e-6)
    np.testing.assert_allclose(3.0 - slide(model.replace(**fields)), 1.0 * G * 0.2, rtol=0.1)
    # A model without pairs gets no pair field.
    assert "pair_friction" not in randomizers.scale_friction(PUCK, 2.0, 2.0)(mjx.put_model(PUCK), KEY)


# --- construction errors ---------------------------------------------------------------------


def test_unknown_names_are_reported_with_what_exists():
    with pytest.raises(ValueError, match=r"no body named 'torso'.*\['world', 'block', 'ball', 'arm'\]"):
        randomizers.scale_masses(MJ, bodies=["torso"])
    with pytest.raises(ValueError, match=r"body 'world' is the world"):
        randomizers.add_masses(MJ, bodies=["world"])
    with pytest.raises(ValueError, match=r"no geom named 'ground'.*'floor'"):
        randomizers.scale_friction(MJ, geoms=["ground"])
    with pytest.raises(ValueError, match=r"no joint named 'knee'.*'slide', 'free', 'hinge'"):
        randomizers.scale_damping(MJ, joints=["knee"])
    with pytest.raises(ValueError, match="body names repeat"):
        randomizers.shift_com(MJ, bodies=["arm", "arm"])


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: randomizers.scale_friction(MJ, 1.5, 0.5), "low <= high"),
        (lambda: randomizers.scale_damping(MJ, -0.1, 1.0), ">= 0"),
        (lambda: randomizers.scale_masses(MJ, 0.0, 1.0), "> 0"),
        (lambda: randomizers.scale_armature(MJ, float("nan"), 1.0), "finite"),
        (lambda: randomizers.add_masses(MJ, -1.0, 0.0), "'arm'.*positive mass"),
        (lambda: randomizers.shift_com(MJ, [0.0, 0.0], 0.1), "range"),
        (lambda: randomizers.scale_position_gains(PUCK), "actuator"),
    ],
)
def test_bad_ranges_are_reported(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_gains_need_position_actuators_and_combine_needs_callables():
    motor = mujoco.MjModel.from_xml_string(
        XML.replace('<position name="servo" joint="hinge" kp="4" kv="0.5"/>', '<motor name="servo" joint="hinge"/>')
    )
    with pytest.raises(ValueError, match="'servo' is not a position actuator"):
        randomizers.scale_position_gains(motor)
    with pytest.raises(ValueError, match="at least one"):
        randomizers.combine()
    with pytest.raises(TypeError, match="randomizer 1"):
        randomizers.combine(IDENTITIES["friction"](), {"body_mass": 1.0})
