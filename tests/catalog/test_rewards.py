"""Reward shapes and terms (`mjzoo.catalog.rewards`) and reward clipping against hand-computed
values.

`tolerance` notation: d = (distance outside [lower, upper]) / margin, v = value_at_margin. The four
shapes, as defined in the DeepMind Control Suite, are
  gaussian:   exp(-0.5 (d s)^2),  s = sqrt(-2 ln v)   -> exp(ln(v) d^2) = v^(d^2)
  long_tail:  1 / ((d s)^2 + 1),  s = sqrt(1/v - 1)   -> 1 / ((1/v - 1) d^2 + 1)
  linear:     clip(1 - (1 - v) d, 0, 1)
  quadratic:  clip(1 - (1 - v) d^2, 0, 1)
so every shape is 1 at d = 0 and v at d = 1. The numbers below are derived from these
closed forms by hand, not by calling the implementation.
"""

from __future__ import annotations

import dataclasses
import math

import chex
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo.catalog import commands
from mjzoo.catalog import rewards
from mjzoo.catalog import trackers
from mjzoo.catalog.rewards import SIGMOIDS
from mjzoo.catalog.rewards import tolerance
from mjzoo.types import State
from mjzoo.types import Task

# A band [1, 2] with margin 0.5 and value_at_margin 0.1 unless a test says otherwise.
LOWER, UPPER, MARGIN, V = 1.0, 2.0, 0.5, 0.1


def tol(x, sigmoid, margin=MARGIN, value_at_margin=V):
    return tolerance(x, lower=LOWER, upper=UPPER, margin=margin, sigmoid=sigmoid, value_at_margin=value_at_margin)


def test_sigmoids_are_the_four_documented_shapes():
    assert set(SIGMOIDS) == {"gaussian", "long_tail", "linear", "quadratic"}


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_inside_band_is_one(sigmoid):
    # Both edges and the interior of [1, 2] are inside: exactly 1.
    np.testing.assert_array_equal(tol(jnp.array([1.0, 1.3, 1.5, 2.0]), sigmoid), np.ones(4, np.float32))


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
@pytest.mark.parametrize("x", [UPPER + MARGIN, LOWER - MARGIN])
def test_at_margin_is_value_at_margin(sigmoid, x):
    # distance == margin  =>  d = 1  =>  every shape equals v, on either side of the band.
    for v in (0.1, 0.5, 0.9):
        np.testing.assert_allclose(tol(x, sigmoid, value_at_margin=v), v, rtol=1e-5)


# d = 0.5 (half a margin outside the band), v = 0.1:
#   gaussian:  v^(0.5^2) = 0.1^0.25                        = 0.56234...
#   long_tail: 1 / ((1/0.1 - 1) * 0.25 + 1) = 1 / 3.25     = 0.30769...
#   linear:    1 - (1 - 0.1) * 0.5 = 1 - 0.45              = 0.55
#   quadratic: 1 - (1 - 0.1) * 0.25 = 1 - 0.225            = 0.775
HALF_MARGIN = {
    "gaussian": 0.1**0.25,
    "long_tail": 1.0 / 3.25,
    "linear": 0.55,
    "quadratic": 0.775,
}


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_half_margin_hand_values(sigmoid):
    above = tol(UPPER + 0.5 * MARGIN, sigmoid)
    below = tol(LOWER - 0.5 * MARGIN, sigmoid)
    np.testing.assert_allclose(above, HALF_MARGIN[sigmoid], rtol=1e-5)
    np.testing.assert_allclose(below, HALF_MARGIN[sigmoid], rtol=1e-5)


# d = 2 (two margins outside), v = 0.1:
#   gaussian:  0.1^4                          = 1e-4
#   long_tail: 1 / (9 * 4 + 1) = 1 / 37       = 0.027027...
#   linear:    1 - 0.9 * 2 = -0.8 -> clipped  = 0   (reaches 0 at d = 1/0.9)
#   quadratic: 1 - 0.9 * 4 = -2.6 -> clipped  = 0   (reaches 0 at d = 1/sqrt(0.9))
TWO_MARGINS = {"gaussian": 1e-4, "long_tail": 1.0 / 37.0, "linear": 0.0, "quadratic": 0.0}


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_two_margins_hand_values(sigmoid):
    np.testing.assert_allclose(tol(UPPER + 2 * MARGIN, sigmoid), TWO_MARGINS[sigmoid], rtol=1e-4, atol=1e-7)


def test_linear_and_quadratic_reach_zero_where_the_formula_says():
    # linear is 0 from d = 1/(1 - v) = 1/0.9 = 1.111 margins on, positive just before.
    assert float(tol(UPPER + 1.10 * MARGIN, "linear")) > 0.0
    assert float(tol(UPPER + 1.12 * MARGIN, "linear")) == 0.0
    # quadratic is 0 from d = 1/sqrt(0.9) = 1.054 margins on.
    assert float(tol(UPPER + 1.04 * MARGIN, "quadratic")) > 0.0
    assert float(tol(UPPER + 1.06 * MARGIN, "quadratic")) == 0.0


def test_default_band_is_the_point_zero_with_gaussian():
    # Defaults: lower = upper = 0, margin = 0 (indicator), gaussian.
    np.testing.assert_array_equal(tolerance(jnp.array([0.0, 1e-3, -2.0])), [1.0, 0.0, 0.0])
    # With only a margin: gaussian of |x| / margin, 0.1 at |x| = margin.
    np.testing.assert_allclose(tolerance(jnp.array([-0.3, 0.3]), margin=0.3), [0.1, 0.1], rtol=1e-5)


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_zero_margin_is_the_band_indicator(sigmoid):
    x = jnp.array([0.0, 0.999, 1.0, 1.5, 2.0, 2.001, 100.0, -1e6])
    expected = np.array([0, 0, 1, 1, 1, 0, 0, 0], np.float32)
    out = tol(x, sigmoid, margin=0.0)
    np.testing.assert_array_equal(out, expected)


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_decreases_monotonically_with_distance(sigmoid):
    d = jnp.linspace(0.0, 3.0, 61)
    out = np.asarray(tol(UPPER + d * MARGIN, sigmoid))
    assert np.all(np.diff(out) <= 0.0)
    out_below = np.asarray(tol(LOWER - d * MARGIN, sigmoid))
    np.testing.assert_allclose(out_below, out, rtol=1e-5, atol=1e-6)  # symmetric in the distance


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_output_in_unit_interval_float32_same_shape(sigmoid):
    x = jax.random.uniform(jax.random.key(0), (7, 5), minval=-100.0, maxval=100.0)
    for margin, v in [(0.0, 0.1), (0.5, 0.1), (3.0, 0.5), (1e-3, 0.9)]:
        out = tol(x, sigmoid, margin=margin, value_at_margin=v)
        chex.assert_shape(out, (7, 5))
        chex.assert_type(out, jnp.float32)
        assert bool(jnp.all((out >= 0.0) & (out <= 1.0)))
        assert bool(jnp.all(jnp.isfinite(out)))


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_jit_matches_eager(sigmoid):
    fn = jax.jit(lambda x, lower, upper, margin, v: tolerance(x, lower, upper, margin, sigmoid, v))
    x = jnp.array([0.25, 1.5, 2.25, 2.5])
    out = fn(x, LOWER, UPPER, MARGIN, V)
    # 0.25 is 0.75 = 1.5 margins below the band; 2.25 half a margin above; 2.5 one margin above.
    expected_d15 = {
        "gaussian": 0.1**2.25,  # v^(d^2), d^2 = 2.25
        "long_tail": 1.0 / (9.0 * 2.25 + 1.0),
        "linear": 0.0,  # 1 - 0.9 * 1.5 < 0
        "quadratic": 0.0,  # 1 - 0.9 * 2.25 < 0
    }[sigmoid]
    np.testing.assert_allclose(out, [expected_d15, 1.0, HALF_MARGIN[sigmoid], V], rtol=1e-5, atol=1e-7)
    # Band and margin are traced values: a different margin under the same trace.
    np.testing.assert_allclose(fn(jnp.array(2.25), LOWER, UPPER, 0.25, V), V, rtol=1e-5)


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_vmap_over_x_and_over_bounds(sigmoid):
    x = jnp.array([1.5, 2.25, 2.5, 0.5])
    out = jax.vmap(lambda xi: tol(xi, sigmoid))(x)
    np.testing.assert_allclose(out, [1.0, HALF_MARGIN[sigmoid], V, V], rtol=1e-5)
    # vmap over the upper bound: x = 2.5 is inside for upper = 2.5, d = 1 for upper = 2.0,
    # and d = 0.5 for upper = 2.25.
    uppers = jnp.array([2.5, 2.0, 2.25])
    out = jax.vmap(lambda u: tolerance(2.5, LOWER, u, MARGIN, sigmoid, V))(uppers)
    np.testing.assert_allclose(out, [1.0, V, HALF_MARGIN[sigmoid]], rtol=1e-5)


def test_gaussian_closed_form_over_a_grid():
    # v^(d^2) for a few d and v, against math.pow (independent of the implementation).
    for v in (0.01, 0.1, 0.5):
        for d in (0.1, 0.7, 1.3):
            got = float(tolerance(d * MARGIN, 0.0, 0.0, MARGIN, "gaussian", v))
            assert math.isclose(got, math.pow(v, d * d), rel_tol=1e-5)


def test_unknown_sigmoid_raises_naming_it():
    with pytest.raises(ValueError, match="cubic"):
        tolerance(jnp.array(3.0), 0.0, 1.0, 1.0, sigmoid="cubic")


# --- locomotion reward terms ---------------------------------------------------------
#
# A biped-like test model: a free torso with two legs (hip roll hinges limited to
# [-1, 1] rad driven by gear-2 motors, unlimited knee hinges), and a free box as a
# second floating body. qpos: torso 0-6, left_hip 7, left_knee 8, right_hip 9,
# right_knee 10, box 11-17; qvel: torso 0-5 (linear world, angular local), 6-9 joints.
# States are made by MuJoCo's own forward pass (`mjx.put_data`): no MJX compile.

BIPED = mujoco.MjModel.from_xml_string("""
<mujoco model="biped">
  <compiler angle="radian"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 .1"/>
    <body name="torso" pos="0 0 .5">
      <freejoint name="root"/>
      <geom name="chest" type="box" size=".2 .1 .05"/>
      <body name="left" pos="0 .1 0">
        <joint name="left_hip" type="hinge" axis="1 0 0" range="-1 1"/>
        <joint name="left_knee" type="hinge" axis="0 1 0"/>
        <geom name="left_foot" type="sphere" size=".03" pos="0 0 -.3"/>
      </body>
      <body name="right" pos="0 -.1 0">
        <joint name="right_hip" type="hinge" axis="1 0 0" range="-1 1"/>
        <joint name="right_knee" type="hinge" axis="0 1 0"/>
        <geom name="right_foot" type="sphere" size=".03" pos="0 0 -.3"/>
      </body>
    </body>
    <body name="box" pos="1 0 .1"><freejoint/><geom type="box" size=".1 .1 .1"/></body>
  </worldbody>
  <actuator><motor joint="left_hip" gear="2"/><motor joint="right_hip" gear="2"/></actuator>
</mujoco>
""")
BIPED_MJX = mjx.put_model(BIPED)
YAW90 = [math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)]  # turns body x onto world y
TILT = 0.6  # rad, about the world x axis
ROLL = [math.cos(TILT / 2), math.sin(TILT / 2), 0, 0]


def biped_state(
    quat=YAW90,
    height=0.45,
    linear=(0, 1, 0.3),
    angular=(0.1, -0.2, 0.3),
    joints=(0.95, 0.3, -1.2, -0.2),
    joint_vel=(2, 5, 3, 7),
    ctrl=(0.5, -1),
    command=None,
    action_history=None,
    feet=None,
) -> State:
    """A biped state; `command`, `action_history` and `feet` become the records of the
    combinators that keep them (velocity command outermost)."""
    d = mujoco.MjData(BIPED)
    d.qpos[:11] = [0, 0, height, *quat, *joints]
    d.qvel[:10] = [*linear, *angular, *joint_vel]
    d.ctrl[:] = ctrl
    mujoco.mj_forward(BIPED, d)
    layers = ()
    if feet is not None:
        layers = trackers.FeetState(**feet, inner=layers)
    if action_history is not None:
        layers = trackers.ActionHistoryState(actions=action_history, inner=layers)
    if command is not None:
        layers = commands.VelocityCommandState(countdown=jnp.zeros(()), target=command, command=command, inner=layers)
    return State.create(mjx.put_data(BIPED, d), jnp.zeros(1)).replace(layers=layers)


COMMAND = dict(command=jnp.array([1.0, 0.5, 0.5], jnp.float32))


@jax.jit
def evaluate(fn, state, next_state):
    """One term under jit, with its parameters as traced leaves."""
    return fn(BIPED_MJX, state, jnp.zeros(2), next_state)


def value(fn, next_state=None, state=None):
    fn = fn if isinstance(fn, jax.tree_util.Partial) else jax.tree_util.Partial(fn)  # plain items
    next_state = biped_state() if next_state is None else next_state
    out = evaluate(fn, biped_state(**COMMAND) if state is None else state, next_state)
    chex.assert_shape(out, ())
    chex.assert_type(out, jnp.float32)
    return float(out)


def test_base_velocity_terms_in_the_base_frame():
    # Yawed 90 deg: world velocity (0, 1, 0.3) is (1, 0, 0.3) in the base frame.
    # Command (1, 0.5) m/s: error 0^2 + 0.5^2 = 0.25; sigma 0.25 -> exp(-1).
    assert math.isclose(value(rewards.linear_velocity_tracking(BIPED)), math.exp(-1), rel_tol=1e-5)
    assert math.isclose(value(rewards.linear_velocity_tracking(BIPED, sigma=1.0)), math.exp(-0.25), rel_tol=1e-5)
    # Yaw rate 0.3 vs 0.5: exp(-0.04 / 0.25).
    assert math.isclose(value(rewards.angular_velocity_tracking(BIPED)), math.exp(-0.16), rel_tol=1e-5)
    assert math.isclose(value(rewards.vertical_velocity(BIPED)), 0.09, rel_tol=1e-5)
    assert math.isclose(value(rewards.roll_pitch_velocity(BIPED)), 0.1**2 + 0.2**2, rel_tol=1e-5)
    # Rolled by 0.6 rad: world (0, 0, 1) is (0, sin 0.6, cos 0.6) in the base frame.
    rolled = biped_state(quat=ROLL, linear=(0, 0, 1))
    assert math.isclose(value(rewards.vertical_velocity(BIPED), rolled), math.cos(TILT) ** 2, rel_tol=1e-5)
    command = biped_state(command=jnp.array([0.0, math.sin(TILT), 0.0]))
    assert math.isclose(value(rewards.linear_velocity_tracking(BIPED), rolled, command), 1.0, rel_tol=1e-5)


def test_command_progress_is_the_capped_velocity_along_the_command():
    # Base-frame velocity (1, 0); command (1, 0.5): along = 1 / |c| = 0.894 < |c| = 1.118.
    speed = math.hypot(1.0, 0.5)
    assert math.isclose(value(rewards.command_progress(BIPED)), 1.0 / speed, rel_tol=1e-5)
    # Command (0.6, 0): along 1 m/s, capped at 0.6; backwards (-1, 0): -1.
    capped, backwards = (biped_state(command=jnp.array(c, jnp.float32)) for c in ([0.6, 0, 0], [-1.0, 0, 0]))
    assert math.isclose(value(rewards.command_progress(BIPED), state=capped), 0.6, rel_tol=1e-5)
    assert math.isclose(value(rewards.command_progress(BIPED), state=backwards), -1.0, rel_tol=1e-5)
    assert value(rewards.command_progress(BIPED), state=biped_state(command=jnp.zeros(3))) == 0.0


def test_base_pose_terms():
    assert math.isclose(value(rewards.base_height(BIPED, 0.5)), 0.05**2, rel_tol=1e-4)  # z = 0.45
    assert value(rewards.base_height(BIPED, 0.4, 0.6)) == 0.0
    assert math.isclose(value(rewards.base_height(BIPED, 0.3, 0.4)), 0.05**2, rel_tol=1e-4)
    assert value(rewards.base_height(BIPED, 0.1, body="box")) < 1e-10  # the box rests at z = 0.1
    assert abs(value(rewards.flat_orientation(BIPED))) < 1e-7  # a yaw is still level
    assert math.isclose(value(rewards.upright(BIPED)), 1.0, rel_tol=1e-6)
    rolled = biped_state(quat=ROLL)
    assert math.isclose(value(rewards.flat_orientation(BIPED), rolled), math.sin(TILT) ** 2, rel_tol=1e-5)
    assert math.isclose(value(rewards.upright(BIPED), rolled), math.cos(TILT), rel_tol=1e-5)


def test_joint_terms():
    # Joints (0.95, 0.3, -1.2, -0.2) against qpos0 = 0: 0.9025 + 0.09 + 1.44 + 0.04.
    assert math.isclose(value(rewards.joint_deviation(BIPED)), 2.4725, rel_tol=1e-5)
    knees = rewards.joint_deviation(BIPED, ["left_knee", "right_knee"], pose=[0.1, 0.0])
    assert math.isclose(value(knees), 0.2**2 + 0.2**2, rel_tol=1e-5)
    # Hips limited to [-1, 1]; soft 0.9 -> [-0.9, 0.9]: 0.05 over + 0.3 under.
    assert math.isclose(value(rewards.joint_limits(BIPED)), 0.35, rel_tol=1e-5)
    assert math.isclose(value(rewards.joint_limits(BIPED, soft=1.0)), 0.2, rel_tol=1e-5)
    # Hips mirror (sign -1): 0.95 - 1.2; knees alike (+1): 0.3 + 0.2.
    pairs = [("left_hip", "right_hip"), ("left_knee", "right_knee")]
    assert math.isclose(value(rewards.symmetry(BIPED, pairs, [-1, 1])), 0.25**2 + 0.5**2, rel_tol=1e-5)
    assert math.isclose(value(rewards.symmetry(BIPED, pairs)), 2.15**2 + 0.5**2, rel_tol=1e-5)


def test_effort_terms():
    # Motors of gain 1: actuator forces = ctrl = (0.5, -1); joint torques = gear 2 x that.
    assert math.isclose(value(rewards.torque), 0.25 + 1.0, rel_tol=1e-6)
    # Power at the hips: |1 N m x 2 rad/s| + |-2 N m x 3 rad/s|; knees and torso unactuated.
    assert math.isclose(value(rewards.energy), 8.0, rel_tol=1e-5)


HISTORY = jnp.array([[1.0, 2.0], [0.0, 1.0], [0.0, 0.0], [1.0, 1.0]])  # most recent first


def test_action_difference_terms():
    after = biped_state(action_history=HISTORY)
    assert value(rewards.action_rate, after) == 2.0  # (1, 1)
    assert value(rewards.action_acceleration, after) == 1.0  # (1, 2) - 2 (0, 1) + 0 = (1, 0)
    assert value(rewards.action_jerk, after) == 4.0  # (1, 2) - 3 (0, 1) + 0 - (1, 1) = (0, -2)
    with pytest.raises(ValueError, match="with_action_history"):
        value(rewards.action_rate, biped_state())


FEET = dict(
    contact=jnp.array([True, False]),
    first_contact=jnp.array([True, False]),
    air_time=jnp.array([0.0, 0.3]),
    last_air_time=jnp.array([0.7, 0.3]),
    position=jnp.array([[0.0, 0.0, 0.03], [0.0, 0.0, 0.1]]),
    velocity=jnp.array([[0.3, 0.4, 1.0], [0.6, 0.8, 5.0]]),
)


def test_feet_terms():
    after = biped_state(feet=FEET)
    # Only foot 0 touched down: 0.7 - 0.5 s.
    assert math.isclose(value(rewards.feet_air_time(), after), 0.2, rel_tol=1e-5)
    assert math.isclose(value(rewards.feet_air_time(0.9), after), -0.2, rel_tol=1e-5)
    # Gated: command |(1, 0.5)| = 1.118 m/s is over 1 but not over 2.
    assert math.isclose(value(rewards.feet_air_time(min_command=1.0), after), 0.2, rel_tol=1e-5)
    assert value(rewards.feet_air_time(min_command=2.0), after) == 0.0
    # Slip: foot 0 stands and slides at (0.3, 0.4): 0.25; foot 1 is in the air.
    assert math.isclose(value(rewards.foot_slip, after), 0.25, rel_tol=1e-5)
    # Clearance: foot 1 swings at |(0.6, 0.8)| = 1 m/s, 0.1 m up: (0.1 - 0.08)^2 x 1.
    assert math.isclose(value(rewards.foot_clearance(0.08), after), 0.02**2, rel_tol=1e-4)
    with pytest.raises(ValueError, match="with_feet"):
        value(rewards.foot_slip, biped_state())


def test_terms_vmap_over_states_and_new_numbers_do_not_retrace():
    states = jax.tree.map(lambda *x: jnp.stack(x), biped_state(), biped_state(quat=ROLL, height=0.5))
    commands = jax.tree.map(lambda *x: jnp.stack(x), biped_state(**COMMAND), biped_state(**COMMAND))
    height = rewards.base_height(BIPED, 0.5)
    batch = jax.vmap(evaluate, in_axes=(None, 0, 0))(height, commands, states)
    np.testing.assert_allclose(batch, [0.05**2, 0.0], atol=1e-6)
    flat = jax.vmap(evaluate, in_axes=(None, 0, 0))(rewards.flat_orientation(BIPED), commands, states)
    np.testing.assert_allclose(flat, [0.0, math.sin(TILT) ** 2], rtol=1e-5, atol=1e-7)
    # Same structure, other numbers: one trace per term kind.
    value(rewards.base_height(BIPED, 0.5))
    value(rewards.linear_velocity_tracking(BIPED))
    traced = evaluate._cache_size()
    assert math.isclose(value(rewards.base_height(BIPED, 0.3)), 0.15**2, rel_tol=1e-4)
    assert math.isclose(value(rewards.linear_velocity_tracking(BIPED, 2.0)), math.exp(-0.125), rel_tol=1e-5)
    assert evaluate._cache_size() == traced


def test_bad_names_and_numbers_are_named():
    with pytest.raises(ValueError, match=r"no body named 'trunk'.*'torso'"):
        rewards.upright(BIPED, body="trunk")
    with pytest.raises(ValueError, match=r"body 'left' has no free joint.*\['torso', 'box'\]"):
        rewards.base_height(BIPED, 0.5, body="left")
    with pytest.raises(ValueError, match="no joint named 'ankle'"):
        rewards.joint_deviation(BIPED, ["ankle"])
    with pytest.raises(ValueError, match="'root' is not a hinge or slide"):
        rewards.joint_deviation(BIPED, ["root"])
    with pytest.raises(ValueError, match="one value per joint"):
        rewards.joint_deviation(BIPED, ["left_hip"], pose=[0.0, 1.0])
    with pytest.raises(ValueError, match="joint 'left_knee' has no range"):
        rewards.joint_limits(BIPED, joints=["left_hip", "left_knee"])
    with pytest.raises(ValueError, match="soft"):
        rewards.joint_limits(BIPED, soft=1.5)
    with pytest.raises(ValueError, match="sigma"):
        rewards.linear_velocity_tracking(BIPED, sigma=0.0)
    with pytest.raises(ValueError, match="lower <= upper"):
        rewards.base_height(BIPED, 0.6, 0.4)
    with pytest.raises(ValueError, match="signs"):
        rewards.symmetry(BIPED, [("left_hip", "right_hip")], [0.5])
    with pytest.raises(ValueError, match="pairs"):
        rewards.symmetry(BIPED, [("left_hip",)])
    with pytest.raises(ValueError, match="min_command"):
        rewards.feet_air_time(min_command=-1.0)


# --- alive and `terms`, on a task that runs: the step sets the torso height to action[0]
# (no physics), and the episode terminates once the torso is below `fall` = 0.2 m.


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Fall:
    fall: jax.Array


def _fall_reset(p, model, key):
    return State.create(mjx.make_data(model), jnp.zeros(1))


def _fall_step(p, model, state, action, key):
    return state.replace(data=state.data.replace(qpos=state.data.qpos.at[2].set(action[0])))


def _fall_terminate(p, model, state):
    return state.data.qpos[2] < p.fall, jnp.zeros((), bool)


def fall_task() -> Task:
    p = Fall(jnp.float32(0.2))
    return Task(
        BIPED_MJX,
        Partial(_fall_reset, p),
        Partial(_fall_step, p),
        Partial(lambda p, *a: {}, p),
        Partial(_fall_terminate, p),
        BIPED,
    )


@jax.jit
def fall_run(task, heights):
    def body(state, h):
        state = mjzoo.transition(task, state, jnp.array([h, 0.0]), jax.random.key(0))
        return state, state

    return jax.lax.scan(body, mjzoo.reset(task, jax.random.key(0)), heights)[1]


def test_alive_and_terms():
    base = trackers.with_action_history(fall_task(), length=2)
    task = rewards.terms(
        base,
        {
            "alive": (rewards.alive(base), 2.0),
            "rate": (rewards.action_rate, -0.5),
            "height": (rewards.base_height(BIPED, 0.5), -1.0),
        },
    )
    states = fall_run(task, jnp.array([0.4, 0.1]))
    np.testing.assert_array_equal(states.terminated, [False, True])
    np.testing.assert_allclose(states.metrics["reward/alive"], [2.0, 0.0])
    np.testing.assert_allclose(states.metrics["reward/rate"], [-0.5 * 0.16, -0.5 * 0.09], rtol=1e-5)
    np.testing.assert_allclose(states.metrics["reward/height"], [-0.01, -0.16], rtol=1e-5)
    np.testing.assert_allclose(states.reward, [2.0 - 0.08 - 0.01, -0.045 - 0.16], rtol=1e-5)
    # Under auto-reset the terminating transition still scores 0, the next one 1 again.
    reset_task = mjzoo.with_auto_reset(fall_task())
    reset_task = rewards.terms(reset_task, {"alive": (rewards.alive(reset_task), 1.0)})
    np.testing.assert_allclose(fall_run(reset_task, jnp.array([0.1, 0.4])).metrics["reward/alive"], [0.0, 1.0])
    # with_reward's duplicate-name check still fires, and entries must be (fn, weight).
    with pytest.raises(ValueError, match="already has a reward term named 'alive'"):
        rewards.terms(task, {"alive": (rewards.alive(base), 1.0)})
    with pytest.raises(ValueError, match="entry 'rate' must be a \\(fn, weight\\) pair"):
        rewards.terms(base, {"rate": rewards.action_rate})


def _height(model, state, action, next_state):
    return next_state.data.qpos[2]


def test_reward_clip_clips_the_sum_and_keeps_the_terms():
    # The term "z" is the height the action set (0.3 ... 1.2); the sum is clipped to [0, 0.5].
    task = mjzoo.with_reward_clip(rewards.terms(fall_task(), {"z": (_height, 1.0)}), 0.0, 0.5)
    states = fall_run(task, jnp.array([0.3, 0.6, 0.9, 1.2]))
    np.testing.assert_allclose(states.metrics["reward/z"], [0.3, 0.6, 0.9, 1.2], rtol=1e-6)  # unclipped
    np.testing.assert_allclose(states.metrics["reward/clip"], [0.0, -0.1, -0.4, -0.7], atol=1e-6)
    np.testing.assert_allclose(states.reward, [0.3, 0.5, 0.5, 0.5], rtol=1e-6)
    with pytest.raises(ValueError, match="low <= high"):
        mjzoo.with_reward_clip(fall_task(), 1.0, 0.0)
    with pytest.raises(ValueError, match="already has a reward term named 'clip'"):
        mjzoo.with_reward_clip(task, -1.0, 1.0)
