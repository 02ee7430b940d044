"""The stepping clock (`mjzoo.catalog.gait`) against hand-computed phases and heights.

Model: a free base at z = 1 (its keyframe) with two feet, spheres 0.9 m below it at
y = +-0.1, so each foot rests at z = 0.1. At 1 Hz with offsets (0, pi):
  t = 0     phases (0, -pi)         curve heights (h, 0)
  t = 0.25  phases (pi/2, -pi/2)    curve heights (h/2, h/2)   (the Bezier piece at u = 1/2 is 1/2)
"""

from __future__ import annotations

import math

import chex
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from mjzoo.catalog import commands
from mjzoo.catalog import gait
from mjzoo.types import State

MJ = mujoco.MjModel.from_xml_string("""
<mujoco model="feet">
  <worldbody>
    <body name="base" pos="0 0 1">
      <freejoint/>
      <geom name="left" pos="0 0.1 -0.9" size="0.05"/>
      <geom name="right" pos="0 -0.1 -0.9" size="0.05"/>
    </body>
  </worldbody>
  <keyframe><key name="stand" qpos="0 0 1 1 0 0 0"/></keyframe>
</mujoco>""")
MODEL = mjx.put_model(MJ)
H = 0.15


def state(time: float, base_z: float = 1.0, command=(0.5, 0.0, 0.0)) -> State:
    d = mujoco.MjData(MJ)
    d.qpos[:] = [0, 0, base_z, 1, 0, 0, 0]
    d.time = time
    mujoco.mj_forward(MJ, d)
    command = jnp.asarray(command, jnp.float32)
    layers = commands.VelocityCommandState(countdown=jnp.zeros(()), target=command, command=command, inner=())
    return State.create(mjx.put_data(MJ, d), jnp.zeros(1)).replace(layers=layers)


def test_phases_wrap_into_minus_pi_to_pi():
    offsets = jnp.asarray(gait.BIPED, jnp.float32)
    np.testing.assert_allclose(gait.phases(1.0, offsets, 0.25), [math.pi / 2, -math.pi / 2], atol=1e-6)
    np.testing.assert_allclose(gait.phases(2.0, offsets, 0.5), [0.0, -math.pi], atol=1e-6)  # one whole cycle


def test_the_swing_curve_rises_to_its_height_and_back():
    phase = jnp.array([-math.pi, -math.pi / 2, 0.0, math.pi / 2, math.pi - 1e-6])
    np.testing.assert_allclose(gait.swing_height(phase, H), [0.0, H / 2, H, H / 2, 0.0], atol=1e-6)


def test_the_clock_observes_cos_then_sin_of_each_phase():
    obs = jax.jit(gait.clock(1.0))(MODEL, state(0.25))
    chex.assert_shape(obs, (4,))
    np.testing.assert_allclose(obs, [0.0, 0.0, 1.0, -1.0], atol=1e-6)


@jax.jit
def paid(term, before: State, after: State) -> jax.Array:
    return term(MODEL, before, jnp.zeros(0), after)


def test_feet_phase_pays_for_feet_on_the_curve():
    term = gait.feet_phase(MJ, ["left", "right"], 1.0, height=H, width=0.01)
    lifted = state(0.25, base_z=1.0 + H / 2)  # both feet H/2 above rest
    # At t = 0.25 the curve asks H/2 of both: on it.
    assert math.isclose(float(paid(term, state(0.25), lifted)), 1.0, rel_tol=1e-5)
    # At t = 0 it asks (H, 0): off by H/2 each, exp(-2 (H/2)^2 / 0.01).
    assert math.isclose(float(paid(term, state(0.0), lifted)), math.exp(-2 * (H / 2) ** 2 / 0.01), rel_tol=1e-4)
    # Standing still under a zero command is not paid.
    assert float(paid(term, state(0.25, command=(0.0, 0.0, 0.0)), lifted)) == 0.0


def test_bad_settings_are_named():
    with pytest.raises(ValueError, match="frequency"):
        gait.clock(0.0)
    with pytest.raises(ValueError, match="2 feet .* need as many offsets, got 4"):
        gait.feet_phase(MJ, ["left", "right"], 1.0, gait.TROT)
    with pytest.raises(ValueError, match="width"):
        gait.feet_phase(MJ, ["left", "right"], 1.0, width=0.0)
