"""Curricula (`mjzoo.catalog.curriculum`) on a body whose motion is worked out by hand.

The model: a free 2 kg box "base", no contacts, semi-implicit Euler with dt = 0.02 s and
one physics step per control step. The task's reset puts the base at x = `spawn` moving
at `speed` m/s along x, so after n steps x = spawn + 0.02 n speed; it terminates once
x > `threshold`. `make(level)` wraps it as a curriculum would:

  gravity (0, 0, -g level)                    a physics model field following the level
  velocity pushes of up to push * level m/s along x, due every step from the 2nd on
  (interval 0.02 s), inside a time limit and an auto-reset.

Runs use the SAME key at every step, so every push draws the same unit random number:
a push at level l changes the velocity by l * c for one constant c per environment.
"""

from __future__ import annotations

import dataclasses
import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
import mjzoo.envs
from mjzoo import physics as physics_lib
from mjzoo.catalog import curriculum
from mjzoo.catalog import events
from mjzoo.layers import find
from mjzoo.types import State
from mjzoo.types import Task

XML = """
<mujoco model="base">
  <option timestep="0.02" gravity="0 0 0" integrator="Euler"/>
  <worldbody>
    <body name="base">
      <freejoint name="root"/>
      <geom type="box" size="0.1 0.1 0.1" mass="2" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
</mujoco>
"""
PHYSICS = physics_lib.load(XML)
MJ = PHYSICS.mj_model
T, B, DT = 12, 2, 0.02


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Params:
    speed: jax.Array  # m/s along x at reset
    spawn: jax.Array  # x at reset, m
    threshold: jax.Array  # terminated once x > threshold


def _observe(data):
    return jnp.concatenate([data.qpos, data.qvel])


def _reset(p: Params, model, key):
    data = mjx.make_data(model)
    data = data.replace(qpos=data.qpos.at[0].set(p.spawn), qvel=data.qvel.at[0].set(p.speed))
    return State.create(data, _observe(data))


def _step(p, model, state, action, key):
    data = physics_lib.step(model, state.data, jnp.zeros((0,)), 1)
    return state.replace(data=data, obs=_observe(data))


def _reward(p, model, state, action, next_state):
    return {"x": next_state.data.qpos[0]}


def _terminate(p, model, state):
    return state.data.qpos[0] > p.threshold, jnp.zeros((), bool)


def make(level: float, *, speed=0.0, spawn=0.0, threshold=np.inf, push=0.0, gravity=0.0, limit=100) -> Task:
    p = Params(jnp.float32(speed), jnp.float32(spawn), jnp.float32(threshold))
    model = PHYSICS.model.replace(opt=PHYSICS.model.opt.replace(gravity=jnp.array([0.0, 0.0, -gravity * level])))
    task = Task(
        model=model,
        start=Partial(_reset, p),
        step=Partial(_step, p),
        reward=Partial(_reward, p),
        terminate=Partial(_terminate, p),
        mj_model=MJ,
    )
    task = events.with_velocity_pushes(task, interval=(DT, DT), linear=(push * level, 0.0, 0.0))
    return mjzoo.with_auto_reset(mjzoo.with_time_limit(task, limit))


@jax.jit
@chex.assert_max_traces(
    n=4
)  # one per rule (by_distance's only_falls a second); the numbers of make and of the rules are leaves
def run(task: Task, keys: jax.Array):
    """B environments, T zero-action transitions each, the same key at every step."""

    def one(key):
        state = mjzoo.reset(task, key)

        def body(state, _):
            state = mjzoo.transition(task, state, jnp.zeros((0,)), key)
            return state, state

        return state, jax.lax.scan(body, state, None, length=T)[1]

    return jax.vmap(one)(keys)


KEYS = jax.random.split(jax.random.key(0), B)


def test_push_size_and_gravity_grow_with_the_level():
    task = curriculum.with_curriculum(functools.partial(make, push=2.0, gravity=10.0), curriculum.by_steps(4))
    start, s = run(task, KEYS)
    # by_steps(4): transition t runs at level (t - 1) / 4, capped at 1.
    levels = np.minimum(np.arange(T) / 4, 1.0)
    np.testing.assert_allclose(s.metrics["curriculum/level"], np.broadcast_to(levels, (B, T)), atol=1e-7)
    after = np.minimum(np.arange(1, T + 1) / 4, 1.0)  # the level each transition leaves for the next
    np.testing.assert_allclose(find(s, curriculum.CurriculumState).level, np.broadcast_to(after, (B, T)))
    assert float(find(start, curriculum.CurriculumState).level[0]) == 0.0
    # Pushes from the 2nd step on, each of size level * |c| with |c| <= 2 fixed per environment.
    size = np.asarray(s.metrics["velocity_push/linear"])  # [B, T]
    np.testing.assert_array_equal(size[:, 0], 0.0)
    c = size[:, 4]  # a step at level 1
    assert np.all((0 < c) & (c <= 2.0))
    np.testing.assert_allclose(size[:, 1:], levels[1:] * c[:, None], rtol=1e-5)
    assert np.all(np.diff(size[:, :5], axis=1) > 0)  # grows while the level does
    # The x velocity is the sum of the kicks (no other force along x): 0.25 c, 0.75 c, 1.5 c, 2.5 c, ...
    kicks = np.sign(np.asarray(s.data.qvel[:, 4, 0]))[:, None] * size
    np.testing.assert_allclose(s.data.qvel[:, :, 0], np.cumsum(kicks, axis=1), rtol=1e-5, atol=1e-7)
    # Gravity -10 level along z: v_z(t) = -0.2 * (sum of the levels so far) = 0, -0.05, -0.15, -0.3, -0.5, ...
    v_z = np.broadcast_to(-0.2 * np.cumsum(levels), (B, T))
    np.testing.assert_allclose(s.data.qvel[:, :, 2], v_z, rtol=1e-5, atol=1e-7)


def test_by_episode_length_moves_the_level_at_episode_ends():
    rule = curriculum.by_episode_length(max_steps=5, fraction=0.8, up=0.25, down=0.1, initial=0.5)
    # Episodes last 5 steps (>= 0.8 * 5): +0.25 after steps 5 and 10, capped at 1.
    task = curriculum.with_curriculum(functools.partial(make, speed=1.0, limit=5), rule)
    _, s = run(task, KEYS)
    np.testing.assert_allclose(s.metrics["curriculum/level"][0], [0.5] * 5 + [0.75] * 5 + [1.0] * 2)
    np.testing.assert_array_equal(find(s, curriculum.CurriculumState).memory[0], [1, 2, 3, 4, 0] * 2 + [1, 2])
    # At 1 m/s, x = 0.02 n passes 0.05 at step 3: episodes of 3 steps (< 4): -0.1 each.
    task = curriculum.with_curriculum(functools.partial(make, speed=1.0, limit=5, threshold=0.05), rule)
    _, s = run(task, KEYS)
    np.testing.assert_array_equal(s.terminated[0], [False, False, True] * 4)
    np.testing.assert_allclose(s.metrics["curriculum/level"][0], np.repeat([0.5, 0.4, 0.3, 0.2], 3), rtol=1e-6)


def test_by_distance_measures_from_the_episode_start():
    # Episodes of 5 steps at 1 m/s from x = 1: the distance at the state before the final
    # transition is 4 * 0.02 = 0.08 m (from the start, not from the origin).
    task = curriculum.with_curriculum(
        functools.partial(make, speed=1.0, spawn=1.0, limit=5),
        curriculum.by_distance(MJ, target=0.07, up=0.25, down=0.1, initial=0.5),
    )
    _, s = run(task, KEYS)
    np.testing.assert_allclose(s.metrics["curriculum/level"][0], [0.5] * 5 + [0.75] * 5 + [1.0] * 2)
    np.testing.assert_allclose(find(s, curriculum.CurriculumState).memory[0], np.broadcast_to([1.0, 0.0], (T, 2)))
    task = curriculum.with_curriculum(
        functools.partial(make, speed=1.0, spawn=1.0, limit=5),
        curriculum.by_distance(MJ, target=0.09, up=0.25, down=0.1, initial=0.5),
    )
    _, s = run(task, KEYS)
    np.testing.assert_allclose(s.metrics["curriculum/level"][0], [0.5] * 5 + [0.4] * 5 + [0.3] * 2, rtol=1e-6)


def test_by_distance_only_falls_lowers_the_level_after_falls_alone():
    # Time-outs short of the target (5 steps at 1 m/s: 0.08 m < 0.09 m): the level stays.
    rule = curriculum.by_distance(MJ, target=0.09, up=0.25, down=0.1, initial=0.5, only_falls=True)
    _, s = run(curriculum.with_curriculum(functools.partial(make, speed=1.0, spawn=1.0, limit=5), rule), KEYS)
    np.testing.assert_allclose(s.metrics["curriculum/level"][0], [0.5] * T)
    # Falls short of it (terminated once x > 1.05: after 3 steps, 0.04 m from the start at
    # the state before): one step down each.
    make_falls = functools.partial(make, speed=1.0, spawn=1.0, threshold=1.05, limit=5)
    _, s = run(curriculum.with_curriculum(make_falls, rule), KEYS)
    np.testing.assert_allclose(s.metrics["curriculum/level"][0], np.repeat([0.5, 0.4, 0.3, 0.2], 3), rtol=1e-6)


# --- errors at construction ---------------------------------------------------------------


def test_tasks_the_level_cannot_interpolate_are_refused():
    rule = curriculum.by_steps(10)
    # The message names the bound function and argument: _velocity_step's 4th, its limits.
    with pytest.raises(ValueError, match=r"<_velocity_step>\[3\] is not affine in the level: .* \[0\.5 0\. .* at 0\.5"):
        curriculum.with_curriculum(lambda level: make(level**2, push=2.0), rule)
    with pytest.raises(ValueError, match="<_time_limit_terminate>.* int32 number that changes with the level"):
        curriculum.with_curriculum(lambda level: make(level, limit=int(5 + 10 * level)), rule)
    with pytest.raises(ValueError, match="different structure"):
        curriculum.with_curriculum(
            lambda level: make(level) if level < 1 else mjzoo.with_reward(make(level), "y", _reward_y), rule
        )
    with pytest.raises(TypeError, match="must return a Task"):
        curriculum.with_curriculum(lambda level: 3, rule)
    with pytest.raises(TypeError, match="curriculum.Rule"):
        curriculum.with_curriculum(make, lambda *a: 0.0)


def _reward_y(model, state, action, next_state):
    return next_state.data.qpos[1]


def test_bad_rule_arguments():
    with pytest.raises(ValueError, match="ramp_steps"):
        curriculum.by_steps(0)
    with pytest.raises(ValueError, match="max_steps"):
        curriculum.by_episode_length(0)
    with pytest.raises(ValueError, match="initial"):
        curriculum.by_episode_length(10, initial=1.5)
    with pytest.raises(ValueError, match="up"):
        curriculum.by_distance(MJ, 1.0, up=-0.1)
    with pytest.raises(ValueError, match="free joint"):
        curriculum.by_distance(mjzoo.envs.make("pendulum_swingup").mj_model, 1.0)
