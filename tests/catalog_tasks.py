"""Small models and tasks shared by the catalog tests, simple enough to work out by hand.

BASE_AND_ARM (`make_task`), for resets, events and commands: zero gravity, no contacts,
semi-implicit Euler with dt = 0.02 s and one physics step per control step:

  base   a free 2 kg box at (0, 0, 0.5) (qpos 0..6, qvel 0..5: linear world, angular body)
  arm    a hinge "hip" (range [-1, 0.5] rad, qpos 7, qvel 6, driven by the motor "hip")
         carrying body "hand" on a slide "wrist" (range [-0.1, 0.2] m, qpos 8, qvel 7)
  wheel  an unlimited hinge "spin" (qpos 9, qvel 8)

Left alone, the base keeps its velocity: qvel' = qvel + dt F / m, qpos' = qpos + dt qvel'.
The task's reset puts qpos / qvel at its leaves and observes [qpos, qvel] (19,); its step
reports the size of the observation it was given in ``metrics["inner_obs_size"]``.

BLOCK, for observation and termination combinators: a 1 kg block on a frictionless slide
"x" without gravity, pushed by the motor "push", Euler at dt = 0.1 s.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo import physics as physics_lib
from mjzoo.types import State
from mjzoo.types import Task

BASE_AND_ARM = physics_lib.load("""
<mujoco model="base-and-arm">
  <compiler angle="radian"/>
  <option timestep="0.02" gravity="0 0 0" integrator="Euler"/>
  <default><geom contype="0" conaffinity="0"/></default>
  <worldbody>
    <body name="base" pos="0 0 0.5">
      <freejoint name="root"/>
      <geom type="box" size="0.1 0.1 0.1" mass="2"/>
    </body>
    <body name="arm" pos="1 0 0">
      <joint name="hip" type="hinge" axis="0 1 0" range="-1 0.5"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.02" mass="0.5"/>
      <body name="hand" pos="0 0 -0.3">
        <joint name="wrist" type="slide" axis="0 0 1" range="-0.1 0.2"/>
        <geom type="sphere" size="0.03" mass="0.1"/>
      </body>
    </body>
    <body name="wheel" pos="2 0 0">
      <joint name="spin" type="hinge" axis="0 0 1"/>
      <geom type="cylinder" size="0.1 0.02" mass="0.2"/>
    </body>
  </worldbody>
  <actuator><motor name="hip" joint="hip"/></actuator>
</mujoco>
""")
MJ = BASE_AND_ARM.mj_model
DT, MASS = 0.02, 2.0  # s per step, base mass kg
QPOS0 = np.array([0, 0, 0.5, 1, 0, 0, 0, 0, 0, 0], np.float32)
QVEL0 = np.zeros(9, np.float32)
T, B = 24, 3  # steps per run, runs per batch of `run`

BLOCK = physics_lib.load("""
<mujoco>
  <option timestep="0.1" integrator="Euler" gravity="0 0 0"/>
  <worldbody>
    <body name="block">
      <joint name="x" type="slide" axis="1 0 0"/><inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
    </body>
  </worldbody>
  <actuator><motor name="push" joint="x"/></actuator>
</mujoco>
""")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Params:
    qpos: jax.Array  # [10] the reset pose
    qvel: jax.Array  # [9] the reset velocity


def observe(model, state: State) -> jax.Array:
    """The task's observation item: [qpos, qvel] (19,)."""
    return jnp.concatenate([state.data.qpos, state.data.qvel])


def _reset(p: Params, model, key) -> State:
    data = mjx.make_data(model).replace(qpos=p.qpos, qvel=p.qvel)
    return State.create(data, observe(model, State.create(data, None)))


def _step(p: Params, model, state, action, key) -> State:
    data = physics_lib.step(model, state.data, action, 1)
    size = jnp.float32(state.obs.shape[0])
    return state.replace(data=data, obs=observe(model, state.replace(data=data)), metrics={"inner_obs_size": size})


def _reward(p: Params, model, state, action, next_state) -> dict:
    return {"zero": jnp.zeros(())}


def _terminate(p: Params, model, state):
    return jnp.zeros((), bool), jnp.zeros((), bool)


def make_task(qpos=QPOS0, qvel=QVEL0) -> Task:
    """The BASE_AND_ARM task, reset to `qpos` [10] and `qvel` [9]."""
    p = Params(jnp.asarray(qpos, jnp.float32), jnp.asarray(qvel, jnp.float32))
    return Task(
        model=BASE_AND_ARM.model,
        start=Partial(_reset, p),
        step=Partial(_step, p),
        reward=Partial(_reward, p),
        terminate=Partial(_terminate, p),
        mj_model=MJ,
    )


@jax.jit
def run(task: Task, key: jax.Array):
    """B episodes of T zero-action steps: (reset states [B], next states [B, T])."""

    def one(key):
        state = mjzoo.reset(task, key)
        return state, mjzoo.rollout(task, lambda obs, k: jnp.zeros((1,)), state, key, T)[1].next_state

    return jax.vmap(one)(jax.random.split(key, B))


@jax.jit
def resets_of(task: Task, keys: jax.Array) -> State:
    """A reset per key: states [len(keys)]."""
    return jax.vmap(lambda key: mjzoo.reset(task, key))(keys)
