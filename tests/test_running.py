"""Shape checks of `mjzoo.running`: a reward term or a termination that is not a scalar,
and an observation whose shape changes between reset and step, are named when the
transition is first traced (the task's reset traces one), not found later as a
`lax.scan` carry mismatch. The task is a hand-written one on a 1-DoF slide joint, its
functions bound with `jax.tree_util.Partial` so each test swaps one of them."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import pytest
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo.types import State
from mjzoo.types import Task

XML = """
<mujoco><worldbody><body><joint name="x" type="slide" axis="1 0 0"/><geom type="box" size="0.1 0.1 0.1"/>
</body></worldbody><actuator><motor joint="x"/></actuator></mujoco>
"""


def start(obs_size, model, key):
    data = mjx.make_data(model)
    return State.create(data, jnp.zeros(obs_size.value))


def step(model, state, action, key):
    data = mjzoo.physics.step(model, state.data, action, 1)
    return state.replace(data=data, obs={"q": data.qpos} if isinstance(state.obs, dict) else data.qpos)


def scalar_reward(model, state, action, next_state):
    return {"x": next_state.data.qpos[0]}


def vector_reward(model, state, action, next_state):
    return {"x": next_state.data.qpos[0], "both": jnp.concatenate([next_state.data.qpos, next_state.data.qvel])}


def never(model, state):
    return jnp.zeros((), bool), jnp.zeros((), bool)


def one_flag(model, state):
    return jnp.zeros((), bool)


def per_joint(model, state):
    return state.data.qpos > 1.0, jnp.zeros((), bool)


def make(obs_size=1, reward=scalar_reward, terminate=never) -> Task:
    physics = mjzoo.physics.load(XML)
    return Task(
        model=physics.model,
        start=Partial(start, mjzoo.tree.StaticValue(obs_size)),
        step=Partial(step),
        reward=Partial(reward),
        terminate=Partial(terminate),
        mj_model=physics.mj_model,
    )


def reset_shape(task):
    return jax.eval_shape(lambda key: mjzoo.reset(task, key), jax.random.key(0))


def test_a_well_shaped_task_resets():
    state = reset_shape(make())
    assert state.obs.shape == (1,) and "reward/x" in state.metrics


def test_a_reward_term_that_is_not_a_scalar_is_named_with_its_shape():
    with pytest.raises(ValueError, match=r"reward term 'both' has shape \(2,\); each term must be a scalar"):
        reset_shape(make(reward=vector_reward))


@pytest.mark.parametrize(
    "terminate, got", [(one_flag, r"one value of shape \(\)"), (per_joint, r"shapes \[\(1,\), \(\)\]")]
)
def test_a_terminate_that_is_not_two_scalars_is_named(terminate, got):
    with pytest.raises(ValueError, match=f"terminate must return two scalars \\(terminated, truncated\\), got {got}"):
        reset_shape(make(terminate=terminate))


def test_an_observation_that_changes_shape_between_reset_and_step_is_named():
    with pytest.raises(ValueError, match=r"observation differs between reset \(float32\[3\]\) and step \(float32\[1"):
        reset_shape(make(obs_size=3))


def test_a_wrong_action_size_is_named():
    task = make()
    state = mjzoo.reset(task, jax.random.key(0))
    with pytest.raises(ValueError, match=r"the action has shape \(2,\), but the task takes \(1,\)"):
        mjzoo.transition(task, state, jnp.zeros(2), jax.random.key(0))


def test_a_transitions_shape_is_traced_once_whatever_the_tasks_sharding():
    """`fill_transition_entries` (every reset) asks `jax.eval_shape` for a transition's structure,
    memoized: the same task placed on a mesh, as the harness replicates it over several
    devices, must not trace its step again (a humanoid's step takes seconds to trace)."""
    import numpy as np
    from jax.sharding import Mesh
    from jax.sharding import NamedSharding
    from jax.sharding import PartitionSpec

    traced = []

    def counted(model, state, action, key):
        traced.append(1)
        return step(model, state, action, key)

    task = make().replace(step=Partial(counted))
    mjzoo.reset(task, jax.random.key(0))
    assert len(traced) == 1
    whole = NamedSharding(Mesh(np.array(jax.devices()[:1]), ("envs",)), PartitionSpec())
    placed = jax.device_put(task, whole)
    assert jax.typeof(placed.model.qpos0) != jax.typeof(task.model.qpos0)  # the types differ by their mesh
    mjzoo.reset(placed, jax.random.key(1))
    assert len(traced) == 1
