"""`mjzoo.testing.check_task` passes a task that keeps the contract and names the
property each deliberately broken task breaks. The tasks move a 1 kg block on a slide
(catalog_tasks.BLOCK: dt 0.1 s, one motor), so each compile is small."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from catalog_tasks import BLOCK
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo import physics as physics_lib
from mjzoo import tree
from mjzoo.testing import PROPERTIES
from mjzoo.testing import TaskCheckError
from mjzoo.testing import check_task
from mjzoo.types import State
from mjzoo.types import Task

STEPS = 6  # every limit below is reached within one check's rollout


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Params:
    spread: jax.Array  # m, the start position is uniform in [0, spread]
    weight: jax.Array  # of the squared distance to 0


def _observe(data, size=2):
    return jnp.concatenate([data.qpos, data.qvel, jnp.zeros(size - 2)])


def _start(p: Params, model, key) -> State:
    data = mjx.make_data(model).replace(qpos=jax.random.uniform(key, (1,)) * p.spread)
    return State.create(data, _observe(data))


def _step(p: Params, model, state, action, key) -> State:
    data = physics_lib.step(model, state.data, action, 1)
    return state.replace(data=data, obs=_observe(data))


def _reward(p: Params, model, state, action, next_state) -> dict:
    return {"distance": -p.weight * next_state.data.qpos[0] ** 2}


def _terminate(p: Params, model, state):
    return jnp.abs(state.data.qpos[0]) > 100.0, jnp.zeros((), bool)


def make(step=_step, reward=_reward, limit: int | None = 4, weight=1.0, start=_start) -> Task:
    p = Params(jnp.float32(0.5), weight if isinstance(weight, tree.StaticValue) else jnp.float32(weight))
    task = Task(
        model=BLOCK.model,
        start=Partial(start, p),
        step=Partial(step, p),
        reward=Partial(reward, p),
        terminate=Partial(_terminate, p),
        mj_model=BLOCK.mj_model,
    )
    return task if limit is None else mjzoo.with_time_limit(task, limit)


def failures_of(task: Task) -> dict[str, str]:
    with pytest.raises(TaskCheckError) as raised:
        check_task(task, num_steps=STEPS)
    for name in raised.value.failures:
        assert name in str(raised.value)
    return raised.value.failures


def test_a_good_task_passes_every_property_with_one_trace():
    report = check_task(make(), num_steps=STEPS)
    assert report.passed == tuple(PROPERTIES) and report.skipped == {}
    assert report.traces == 1
    again = check_task(make(weight=2.0), num_steps=STEPS)  # new numbers: the same trace
    assert again.traces == 0


def test_without_a_time_limit_it_is_skipped_and_a_long_one_is_checked_shorter():
    assert set(check_task(make(limit=None), num_steps=STEPS).skipped) == {"time_limit"}
    assert "time_limit" in check_task(make(limit=100), num_steps=STEPS).passed  # under with_time_limit(task, 3)


def _step_longer_obs(p, model, state, action, key):
    next_state = _step(p, model, state, action, key)
    return next_state.replace(obs=_observe(next_state.data, 3))


def test_reset_observation_unlike_a_transitions_is_named():
    failures = failures_of(make(step=_step_longer_obs))
    assert list(failures) == ["reset_matches_transition"]
    assert "float32[2]" in failures["reset_matches_transition"]
    assert "float32[3]" in failures["reset_matches_transition"]


def _start_at_time_zero(p: Params, model, key) -> State:
    state = _start(p, model, key)  # as Playground's CheetahRun starts: its time a Python number
    return state.replace(data=state.data.replace(time=0.0))


def test_a_weakly_typed_reset_leaf_is_named():
    """A jitted loop fed its own output compiled twice for it (the second training chunk)."""
    failures = failures_of(make(start=_start_at_time_zero))
    assert list(failures) == ["reset_matches_transition"]
    assert failures["reset_matches_transition"] == ".data.time: reset float32[2] (weakly typed), transition float32[2]"


def _host_noise():
    return np.float32(np.random.default_rng().normal())


def _step_with_host_noise(p, model, state, action, key):
    noise = jax.pure_callback(_host_noise, jax.ShapeDtypeStruct((), jnp.float32), vmap_method="sequential")
    next_state = _step(p, model, state, action, key)
    return next_state.replace(obs=next_state.obs + noise)


def test_host_randomness_is_not_deterministic():
    assert list(failures_of(make(step=_step_with_host_noise))) == ["deterministic"]


def _reward_nan_from_step_4(p, model, state, action, next_state):
    return {"countdown": jnp.log(0.35 - next_state.data.time)}  # time 0.4 s after step 4


def test_nan_reward_is_not_finite():
    failures = failures_of(make(reward=_reward_nan_from_step_4))
    assert list(failures) == ["finite"]
    assert "transition ['reward'] at (env, step) (0, 3)" in failures["finite"]


def _static_weight_reward(p, model, state, action, next_state):
    return {"distance": -p.weight.value * next_state.data.qpos[0] ** 2}


def test_a_static_float_retraces():
    failures = failures_of(make(reward=_static_weight_reward, weight=tree.StaticValue(0.5)))
    assert list(failures) == ["no_retrace"] and "_step" in failures["no_retrace"]


def test_a_time_limit_the_task_does_not_keep_is_named():
    task = make(limit=4)
    failures = failures_of(task.replace(time_limit=jnp.int32(3)))  # it truncates after 4 steps
    assert list(failures) == ["time_limit"]
    assert "step 3 of its episode, limit 3" in failures["time_limit"]


def _vector_reward(p, model, state, action, next_state):
    return {"distance": -(next_state.data.qpos**2) * jnp.ones(2)}


def test_a_vector_reward_is_not_a_scalar_and_is_reported_not_raised():
    failures = failures_of(make(reward=_vector_reward, limit=None))
    assert list(failures) == ["scalars"] and "(2,)" in failures["scalars"]


def test_an_action_ignoring_observation_is_caught():
    def blind(p, model, state, action, key):
        return _step(p, model, state, action * 0.0, key).replace(obs=jnp.zeros(2))

    failures = failures_of(make(step=blind, limit=None))
    assert list(failures) == ["keys_differ"]
