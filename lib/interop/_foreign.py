"""The core shared by the adapters that run another ecosystem's MJX env as an mjzoo Task
(`mjzoo.interop.brax.task`, `mjzoo.interop.playground.task`).

Brax's `Env` and Playground's `MjxEnv` have one shape: ``reset(rng) -> State`` and
``step(state, action) -> State``, their State holding an mjx.Data, obs, reward, done,
metrics and info; they differ in names. A `Kind` names those differences, and `task` does
the rest for either:

  foreign State           mjzoo State
  <data_field>            data
  obs                     obs (any pytree)
  reward                  the one reward term `kind.name`
  done                    terminated, unless ``info[kind.truncation_key]`` marks it a time
                          limit, then truncated
  metrics[k]              ``metrics["<kind.name>/<k>"]``, apart from mjzoo's own
  info                    ``info[kind.name]``, as the env returned it

The env's reset is given ``jax.random.key_data(key)`` of mjzoo's reset key; its steps draw
randomness from its own info, so mjzoo's step key is not used. The env object is bound as
static pytree metadata (`tree.StaticValue`, equal by identity: tasks from one env share a
trace); the physics model is `task.model`, a leaf, set on the env (``<model_attr>``) while
its reset or step is traced, as both libraries' own domain-randomization wrappers do, so
model edits apply without a recompile.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from typing import Any
from typing import Iterator

import jax
import jax.numpy as jnp
import mujoco
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import physics
from mjzoo import tree
from mjzoo.combinators import record
from mjzoo.combinators import with_divergence_guard
from mjzoo.combinators import with_time_limit
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Kind", "task", "env_model", "key_data"]

Array = jax.Array
_LOCK = threading.RLock()  # the model swap mutates the env: one trace of one env at a time


@dataclasses.dataclass(frozen=True)
class Kind:
    """How one ecosystem names the parts of its env and State (the module docstring's table).

    Attributes:
      name: the reward term's name, the info key and the metrics prefix ("brax").
      model_attr: the attribute of the bare env (``env.unwrapped``) holding its mjx.Model.
      data_field: the field of its State holding the mjx.Data.
      state_type: its State class, built from an mjzoo State for each step.
      truncation_key: the info entry that marks a done as a time limit (Brax's
        "truncation"); None: every done is terminated.
    """

    name: str
    model_attr: str
    data_field: str
    state_type: type
    truncation_key: str | None = None


def env_model(kind: Kind, env: Any) -> mjx.Model:
    """The mjx.Model the bare env steps; TypeError naming the env if it keeps none."""
    model = getattr(env.unwrapped, kind.model_attr, None)
    if not isinstance(model, mjx.Model):
        raise TypeError(
            f"{kind.name}.task: {type(env.unwrapped).__name__}.{kind.model_attr} is not an mjx.Model, "
            "so the task's model could not be handed to it"
        )
    return model


def task(kind: Kind, env: Any, model: mjx.Model, mj_model: mujoco.MjModel, episode_length: int | None) -> Task:
    """`env` as a Task stepping `model`: action ``[env.action_size]``, the env's observation,
    one reward term, guarded against divergence and, unless `episode_length` is None,
    truncated after that many control steps. The caller has checked `env` and the length.
    On Warp, the model's overflow prints are off (`mjzoo.physics.quiet`)."""
    static_kind, static_env = tree.StaticValue(kind), tree.StaticValue(env)
    action_size = int(env.action_size)
    bare = Task(
        model=physics.quiet(model),
        start=Partial(_start, static_kind, static_env),
        step=Partial(_step, static_kind, static_env),
        reward=Partial(_recorded_reward),
        terminate=Partial(_recorded_terminate),
        mj_model=mj_model,
        action_dim=None if action_size == mj_model.nu else action_size,
    )
    guarded = with_divergence_guard(bare)
    return guarded if episode_length is None else with_time_limit(guarded, episode_length)


@contextlib.contextmanager
def _holding(kind: Kind, env: Any, model: mjx.Model) -> Iterator[Any]:
    """`env` stepping `model` (the task's, maybe traced) for the duration of a call."""
    inner = env.unwrapped
    with _LOCK:
        own = getattr(inner, kind.model_attr)
        setattr(inner, kind.model_attr, model)
        try:
            yield env
        finally:
            setattr(inner, kind.model_attr, own)


def key_data(key: Array) -> Array:
    """The raw uint32 data of a typed PRNG key (what both libraries' envs take); raw keys as given."""
    return jax.random.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key) else key


def _start(kind: tree.StaticValue, env: tree.StaticValue, model: mjx.Model, key: Array) -> State:
    kind = kind.value
    with _holding(kind, env.value, model) as held:
        first = held.reset(key_data(key))
    state = State.create(getattr(first, kind.data_field), first.obs, info={kind.name: dict(first.info)})
    # Strongly typed, as is a step: a jitted loop fed its own output would compile twice. Playground's
    # CheetahRun resets `data.time` to a Python 0.0; Brax's ant steps metrics to one.
    return tree.strongly_typed(state.replace(metrics=_prefixed(kind, first.metrics)))


def _step(
    kind: tree.StaticValue, env: tree.StaticValue, model: mjx.Model, state: State, action: Array, key: Array
) -> State:
    kind = kind.value
    prefix = f"{kind.name}/"
    own = kind.state_type(
        **{kind.data_field: state.data},
        obs=state.obs,
        reward=state.reward,
        done=state.terminated.astype(jnp.float32),
        metrics={k[len(prefix) :]: v for k, v in state.metrics.items() if k.startswith(prefix)},
        info=dict(state.info[kind.name]),  # fresh dicts: both libraries' envs write into the ones they get
    )
    with _holding(kind, env.value, model) as held:
        after = held.step(own, action)
    next_state = state.replace(
        data=getattr(after, kind.data_field),
        obs=after.obs,
        info={**state.info, kind.name: dict(after.info)},
        metrics={**state.metrics, **_prefixed(kind, after.metrics)},
    )
    done = jnp.asarray(after.done) != 0
    limit = jnp.zeros((), bool)
    if kind.truncation_key is not None:
        limit = jnp.asarray(after.info.get(kind.truncation_key, 0.0)) != 0
    terms = {kind.name: jnp.asarray(after.reward, jnp.float32)}
    return tree.strongly_typed(record(next_state, terms, done & ~limit, done & limit))


def _prefixed(kind: Kind, metrics: dict[str, Array]) -> dict[str, Array]:
    return {f"{kind.name}/{k}": v for k, v in metrics.items()}


def _recorded_reward(model, state: State, action: Array, next_state: State) -> dict[str, Array]:
    return dict(next_state.outcome.terms)


def _recorded_terminate(model, state: State) -> tuple[Array, Array]:
    return state.outcome.terminated, state.outcome.truncated
