"""`training.run`'s algorithm contract (`training.Algorithm`): what a module lacks is
named in one error before anything runs; the per-env fields it names are the ones
sharded; evaluation runs the task's own episode length unless told otherwise."""

from __future__ import annotations

import dataclasses
import types

import jax
import jax.numpy as jnp
import pytest

import mjzoo
from mjzoo.harness import training

XML = """
<mujoco model="block">
  <worldbody><body><joint name="x" type="slide"/><geom type="box" size="0.1 0.1 0.1"/></body></worldbody>
  <actuator><motor joint="x"/></actuator>
</mujoco>
"""
TASK = mjzoo.task(XML, time_limit=7)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Count:
    updates: jax.Array
    per_env: jax.Array  # [num_envs]


@dataclasses.dataclass(frozen=True)
class CountConfig:
    num_updates: int = 2
    steps_per_update: int = 10


def counter(**overrides) -> types.ModuleType:
    """An algorithm whose state counts its updates; its evaluation returns num_steps."""
    module = types.ModuleType("counter")
    module.PER_ENV_FIELDS = ("per_env",)
    module.init = lambda config, task, key: Count(jnp.zeros((), jnp.int32), jnp.zeros(4))
    module.update = lambda config, task, s: (Count(s.updates + 1, s.per_env + 1.0), {})
    module.evaluate = lambda config, task, s, key, n, steps: (jnp.float32(steps), jnp.zeros(n), None)
    for name, value in overrides.items():
        setattr(module, name, value) if value is not None else delattr(module, name)
    return module


SETTINGS = training.Settings(updates_per_chunk=1, video=False, progress=False)


def test_evaluation_runs_the_task_s_own_episode_length():
    state, last = training.run(counter(), CountConfig(), TASK, SETTINGS)
    assert last["eval/return"] == 7.0 and int(state.updates) == 2
    _, last = training.run(counter(), CountConfig(), TASK, dataclasses.replace(SETTINGS, eval_steps=3))
    assert last["eval/return"] == 3.0


def test_a_task_without_time_limit_needs_eval_steps():
    with pytest.raises(ValueError, match="eval_steps=None evaluates the task's own episode length, but the task "
                                         "has no time limit"):  # fmt: skip
        training.run(counter(), CountConfig(), TASK.replace(time_limit=None), SETTINGS)


def test_what_a_module_lacks_is_named_at_once():
    with pytest.raises(TypeError, match=r"counter is not an algorithm of the training.Algorithm contract; it lacks "
                                        r"evaluate\(\), PER_ENV_FIELDS \(.*\), config.steps_per_update"):  # fmt: skip
        training.run(counter(evaluate=None, PER_ENV_FIELDS=None), types.SimpleNamespace(num_updates=1), TASK, SETTINGS)
    with pytest.raises(TypeError, match=r"must be a dataclass with the fields \['per_env_typo'\]"):
        training.run(counter(PER_ENV_FIELDS=("per_env_typo",)), CountConfig(), TASK, SETTINGS)


def test_per_env_fields_are_sharded_the_rest_replicated():
    """On one device: everything placed on it (the state is committed, see shard_envs)."""
    state = training.shard_envs(Count(jnp.zeros((), jnp.int32), jnp.zeros(4)), ("per_env",))
    assert state.per_env.committed and state.updates.committed


def test_init_is_jitted_by_the_harness():
    traces = []

    def init(config, task, key):
        traces.append(isinstance(key, jax.core.Tracer))
        return Count(jnp.zeros((), jnp.int32), jnp.zeros(4))

    training.run(counter(init=init), CountConfig(), TASK, SETTINGS)
    assert traces == [True]  # traced (under jit), once
