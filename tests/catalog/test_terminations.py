"""Hand-checked behaviour of the termination items and `with_terminations`
(`mjzoo.catalog.terminations`).

Items run on a free-floating 1 kg box "torso" (0.2 x 0.2 x 0.1 m) with a sphere "foot"
below it, over a floor; states are set by hand and completed with one `mjx.forward`.

`with_terminations` runs on a 1 kg block on a frictionless slide joint without gravity,
pushed by a constant force F with MuJoCo's semi-implicit Euler at dt = 0.1 s, from rest:
qvel_n = 0.1 F n after n steps.
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
from mjzoo.catalog import terminations as term
from mjzoo.types import State
from mjzoo.types import Task

XML = """
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="base" pos="0 0 0.5">
      <freejoint/>
      <geom name="torso" type="box" size="0.1 0.1 0.05" mass="1"/>
      <geom name="foot" type="sphere" size="0.02" pos="0 0 -0.08" mass="0.1"/>
      <geom name="ghost" type="sphere" size="0.02" pos="0 0 0.08" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
"""
MJ = mujoco.MjModel.from_xml_string(XML)
MODEL = mjx.put_model(MJ)
forward = jax.jit(mjx.forward)


def pose(x=0.0, y=0.0, z=0.5, roll=0.0) -> State:
    """The base at (x, y, z), rolled by `roll` rad about the world x axis, at rest."""
    qpos = jnp.array([x, y, z, np.cos(roll / 2), np.sin(roll / 2), 0.0, 0.0], jnp.float32)
    return State.create(forward(MODEL, mjx.make_data(MODEL).replace(qpos=qpos)), jnp.zeros(()))


@jax.jit
@chex.assert_max_traces(n=8)  # one per item function and index shape below: new limits do not retrace
def check(item, state):
    return item(MODEL, state)


def test_not_upright_compares_the_tilt_of_the_z_axis():
    item = term.not_upright(MJ, max_angle=1.0)
    assert not check(item, pose(roll=0.0))
    assert not check(item, pose(roll=0.9))
    assert check(item, pose(roll=1.1))
    assert check(item, pose(roll=-np.pi))  # upside down
    assert check(term.not_upright(MJ, max_angle=0.5), pose(roll=0.6))  # a new limit, the same trace
    assert not check(term.not_upright(MJ, max_angle=np.pi), pose(roll=-np.pi + 1e-3))


def test_base_too_low_too_high_and_far_from_origin():
    assert not check(term.base_too_low(MJ, min_height=0.3), pose(z=0.31))
    assert check(term.base_too_low(MJ, min_height=0.3), pose(z=0.29))
    assert check(term.base_too_low(MJ, min_height=0.3, body="base"), pose(z=-1.0))
    assert not check(term.base_too_high(MJ, max_height=1.0), pose(z=0.99))
    assert check(term.base_too_high(MJ, max_height=1.0), pose(z=1.01))
    # (1, 2) is sqrt(5) = 2.236 m from the origin; the height does not count.
    assert check(term.far_from_origin(MJ, radius=2.2), pose(x=1.0, y=2.0))
    assert not check(term.far_from_origin(MJ, radius=2.3), pose(x=1.0, y=2.0, z=100.0))


def test_illegal_contact_with_named_geoms():
    standing = pose(z=0.099)  # the foot's bottom at 0.099 - 0.1 = 1 mm below the floor
    fallen = pose(z=0.045, roll=np.pi)  # on its back, the torso 5 mm into the floor
    torso_on_floor = term.illegal_contact(MJ, ["torso"], others="floor")
    assert not check(torso_on_floor, standing)
    assert check(torso_on_floor, fallen)
    assert check(term.illegal_contact(MJ, ["torso", "foot"]), standing)  # any of them, with anything
    assert not check(term.illegal_contact(MJ, "foot", others=["floor"]), pose(z=0.5))


def test_bad_velocity_and_non_finite_physics():
    item = term.bad_velocity(5.0)
    data = mjx.make_data(MODEL)

    def at(qpos=data.qpos, qvel=data.qvel):
        return State.create(data.replace(qpos=qpos, qvel=qvel), jnp.zeros(()))

    assert not check(item, at(qvel=data.qvel.at[3].set(-4.9)))
    assert check(item, at(qvel=data.qvel.at[3].set(-5.1)))
    assert check(item, at(qvel=data.qvel.at[0].set(jnp.nan)))
    assert check(item, at(qpos=data.qpos.at[2].set(jnp.inf)))
    assert not check(
        term.episode_length(5), State.create(data, jnp.zeros(())).replace(layers=mjzoo.TimeLimitState(jnp.int32(4)))
    )
    assert check(
        term.episode_length(5), State.create(data, jnp.zeros(())).replace(layers=mjzoo.TimeLimitState(jnp.int32(5)))
    )


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: term.not_upright(MJ, max_angle=0.0), "max_angle=0.0 must be a finite number > 0 and <= 3.14159"),
        (lambda: term.not_upright(MJ, max_angle=4.0), "max_angle"),
        (lambda: term.not_upright(MJ, max_angle=True), "max_angle"),
        (lambda: term.base_too_low(MJ, min_height=float("nan")), "min_height"),
        (lambda: term.base_too_high(MJ, max_height=float("inf")), "max_height"),
        (lambda: term.far_from_origin(MJ, radius=-1.0), "radius"),
        (lambda: term.bad_velocity(0.0), "max_qvel"),
        (lambda: term.episode_length(0), "max_steps"),
        (lambda: term.episode_length(2.5), "max_steps"),
        (lambda: term.base_too_low(MJ, 0.2, body="pelvis"), "no body named 'pelvis'.*'base'"),
        (lambda: term.illegal_contact(MJ, ["knee"]), "no geom named 'knee'"),
        (lambda: term.illegal_contact(MJ, ["ghost"], "floor"), "'ghost' can never touch"),
        (lambda: term.not_upright(BLOCK.mj_model, 1.0), "no free joint"),
    ],
)
def test_bad_input_is_rejected_at_construction(make, message):
    with pytest.raises(ValueError, match=message):
        make()


# --- with_terminations, on the sliding block (catalog_tasks.BLOCK) -----------------------


def _reset(threshold, model, key):
    return State.create(mjx.make_data(model), jnp.zeros(2))


def _step(threshold, model, state, action, key):
    data = physics_lib.step(model, state.data, action, 1)
    return state.replace(data=data, obs=jnp.concatenate([data.qpos, data.qvel]))


def _reward(threshold, model, state, action, next_state):
    return {"x": next_state.data.qpos[0]}


def _terminate(threshold, model, state):  # the block's own termination: qpos beyond threshold
    return state.data.qpos[0] > threshold, jnp.zeros((), bool)


def block_task(threshold: float = 1e9, max_steps: int | None = 100) -> Task:
    t = jnp.float32(threshold)
    task = Task(
        model=BLOCK.model,
        start=Partial(_reset, t),
        step=Partial(_step, t),
        reward=Partial(_reward, t),
        terminate=Partial(_terminate, t),
        mj_model=BLOCK.mj_model,
    )
    return task if max_steps is None else mjzoo.with_time_limit(task, max_steps)


@jax.jit
@chex.assert_max_traces(n=3)  # one per task structure used below
def run(task: Task, force: jax.Array):
    """Reset, then six pushes of `force` N: (the reset state, the next states [6])."""
    state = mjzoo.reset(task, jax.random.key(0))
    _, trajectory = mjzoo.rollout(task, lambda o, k: force[None], state, jax.random.key(1), 6)
    return state, trajectory.next_state


def test_items_or_into_terminated_and_are_counted():
    # 1 N: qvel 0.1, 0.2, 0.3 > 0.25 from step 3 on; the episode length 5 is reached at step 5.
    task = term.with_terminations(block_task(), {"fast": term.bad_velocity(0.25), "long": term.episode_length(5)})
    first, states = run(task, jnp.float32(1.0))
    assert float(first.metrics["termination/fast"]) == 0.0 and float(first.metrics["termination/long"]) == 0.0
    np.testing.assert_array_equal(states.metrics["termination/fast"], [0, 0, 1, 1, 1, 1])
    np.testing.assert_array_equal(states.metrics["termination/long"], [0, 0, 0, 0, 1, 1])
    assert states.metrics["termination/fast"].dtype == jnp.float32
    np.testing.assert_array_equal(states.terminated, [0, 0, 1, 1, 1, 1])
    # 0.1 N never gets fast (qvel 0.06 at step 6): only the length ends it.
    _, states = run(task, jnp.float32(0.1))
    np.testing.assert_array_equal(states.terminated, [0, 0, 0, 0, 1, 1])
    # A tighter limit, the same trace: 0.2 > 0.15 at step 2.
    tighter = term.with_terminations(block_task(), {"fast": term.bad_velocity(0.15), "long": term.episode_length(5)})
    _, states = run(tighter, jnp.float32(1.0))
    np.testing.assert_array_equal(states.terminated, [0, 1, 1, 1, 1, 1])


def test_the_inner_terminate_is_kept_and_terminated_beats_truncated():
    # The block's own threshold 0.05: qpos 0.01, 0.03, 0.06 -> terminated at step 3 with no
    # item firing; a time limit of 5 coinciding with episode_length(5) is not a truncation.
    task = term.with_terminations(block_task(threshold=0.05, max_steps=5), {"long": term.episode_length(5)})
    _, states = run(task, jnp.float32(1.0))
    np.testing.assert_array_equal(states.terminated, [0, 0, 1, 1, 1, 1])
    np.testing.assert_array_equal(states.metrics["termination/long"], [0, 0, 0, 0, 1, 1])
    loose = term.with_terminations(block_task(max_steps=5), {"long": term.episode_length(5)})
    _, states = run(loose, jnp.float32(1.0))
    np.testing.assert_array_equal(states.terminated, [0, 0, 0, 0, 1, 1])
    assert not states.truncated.any()


def test_under_auto_reset_and_vmap():
    # Each episode ends at its 3rd step (qvel 0.3 > 0.25) and restarts from rest.
    task = mjzoo.with_auto_reset(term.with_terminations(block_task(), {"fast": term.bad_velocity(0.25)}))
    _, states = jax.vmap(run, in_axes=(None, 0))(task, jnp.array([1.0, 2.0]))
    np.testing.assert_array_equal(states.metrics["termination/fast"], [[0, 0, 1, 0, 0, 1], [0, 1, 0, 1, 0, 1]])
    np.testing.assert_array_equal(states.terminated, states.metrics["termination/fast"] > 0)


def _vector(model, state):
    return state.data.qpos > 0


def test_with_terminations_rejects_bad_items():
    task = block_task()
    with pytest.raises(ValueError, match="non-empty dict"):
        term.with_terminations(task, {})
    with pytest.raises(ValueError, match="non-empty string"):
        term.with_terminations(task, {"": term.bad_velocity(1.0)})
    with pytest.raises(TypeError, match="'fast' must be callable"):
        term.with_terminations(task, {"fast": 1.0})
    with pytest.raises(ValueError, match="'wide' must return a scalar"):
        term.with_terminations(task, {"wide": _vector})
    with pytest.raises(ValueError, match=r"'long': find: the state holds no TimeLimitState"):
        term.with_terminations(block_task(max_steps=None), {"long": term.episode_length(3)})
    once = term.with_terminations(task, {"fast": term.bad_velocity(1.0)})
    with pytest.raises(ValueError, match="already records metrics\\['termination/fast'\\]"):
        term.with_terminations(once, {"fast": term.bad_velocity(2.0)})
