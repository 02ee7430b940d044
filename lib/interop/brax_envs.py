"""Any Brax `Env` on MJX physics as an mjzoo task: the reverse of `to_brax_env`.

    env = brax.envs.get_environment("ant", backend="mjx")
    task = mjzoo.interop.brax.task(env)                       # episode_length=1000, Brax's usual
    state, metrics = ppo.train(ppo.Config(...), task)

One Brax transition becomes one mjzoo transition:

  Brax State              mjzoo State
  pipeline_state          data (Brax's MJX pipeline state is an mjx.Data)
  obs                     obs (any pytree)
  reward                  the one reward term ``"brax"``: `reward` and ``metrics["reward/brax"]``
  done                    terminated, unless ``info["truncation"]`` marks it a time limit
                          (Brax's convention), then truncated
  (episode_length)        truncated, by `mjzoo.with_time_limit`: Brax envs have no episode
                          length of their own (Brax's trainers add one)
  metrics[k]              ``metrics["brax/<k>"]``: the env's reward components and the rest
  info                    ``info["brax"]``: the env's info as it returned it

Brax's reset is given ``jax.random.key_data(key)`` of mjzoo's reset key; a step's
randomness is the env's own (from its info, if any), so mjzoo's step key is not used. The
task is guarded against diverging physics (``metrics["diverged"]``).

The env object is bound as static pytree metadata (equal by identity: tasks from one env
share a trace). The physics model is `task.model` (the env's `sys`), a leaf: while the
env's reset or step is traced, its ``sys`` is set to the model the task is called with
(as Brax's own domain-randomization wrapper does), so model edits apply without a
recompile. The env's other numbers (reward weights) are trace constants; `mjzoo.params`
finds none. Only the "mjx" backend: the others' pipeline states are not an mjx.Data.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Iterator

import jax
import jax.numpy as jnp
from brax.envs import base as brax_base
from brax.envs.wrappers import training as brax_training
from mujoco import mjx

from mjzoo import checks, tree
from mjzoo.combinators import record, with_divergence_guard, with_time_limit
from mjzoo.running import OUTCOME
from mjzoo.types import State, Task, bind

__all__ = ["task", "NAME"]

Array = jax.Array
NAME = "brax"  # the reward term's name, the info key and the metrics prefix
_LOCK = threading.RLock()  # the model swap mutates the env: one trace of it at a time
# Brax's training wrappers batch, limit or reset episodes: mjzoo's algorithms and combinators do that.
_TRAINING_WRAPPERS = (
    brax_training.VmapWrapper, brax_training.DomainRandomizationVmapWrapper, brax_training.EpisodeWrapper,
    brax_training.AutoResetWrapper, brax_training.EvalWrapper,
)  # fmt: skip


def task(env: brax_base.Env, episode_length: int | None = 1000) -> Task:
    """A Brax env (backend "mjx") as an mjzoo `Task` (see the module docstring).

    Args:
      env: a `brax.envs.Env`, maybe inside wrappers of its own, but not Brax's training
        wrappers (vmap, episode, auto-reset: mjzoo's algorithms and combinators do those).
      episode_length: control steps after which an episode is truncated; None: no limit
        beyond the env's own (``info["truncation"]``).

    Returns:
      A Task with action ``[env.action_size]``, the env's observation, one reward term,
      guarded against divergence.
    """
    if not isinstance(env, brax_base.Env):
        raise TypeError(f"brax.task: expected a brax.envs.Env, got {type(env).__name__}")
    layer = env
    while isinstance(layer, brax_base.Wrapper):
        if isinstance(layer, _TRAINING_WRAPPERS):
            raise TypeError(f"brax.task: the env is inside Brax's {type(layer).__name__}; pass the env before "
                            "brax.envs.training.wrap (mjzoo batches, limits and resets episodes itself)")  # fmt: skip
        layer = layer.env
    if env.backend != "mjx":
        raise ValueError(f"brax.task: the env's backend is {env.backend!r}; only 'mjx' gives an mjx.Data to carry "
                         "(brax.envs.get_environment(name, backend='mjx'))")  # fmt: skip
    model = getattr(env.unwrapped, "sys", None)
    if not isinstance(model, mjx.Model):
        raise TypeError(f"brax.task: {type(env.unwrapped).__name__}.sys is not an mjx.Model")
    mj_model = getattr(env.unwrapped, "mj_model", None)  # `to_brax_env`'s envs: their task's
    mj_model = getattr(model, "mj_model", None) if mj_model is None else mj_model  # Brax's: sys.mj_model
    if mj_model is None:
        raise TypeError(f"brax.task: found no mujoco.MjModel for {type(env.unwrapped).__name__} (sys.mj_model)")
    static = tree.Static(env)
    action_size = int(env.action_size)
    bare = Task(
        model=_strongly_typed(model),
        start=bind(_start, static),
        step=bind(_step, static),
        reward=bind(_recorded_reward),
        terminate=bind(_recorded_terminate),
        mj_model=mj_model,
        action_dim=None if action_size == mj_model.nu else action_size,
    )
    guarded = with_divergence_guard(bare)
    if episode_length is None:
        return guarded
    return with_time_limit(guarded, checks.integer("brax.task", "episode_length", episode_length))


def _strongly_typed(model: mjx.Model) -> mjx.Model:
    """`model` with its weakly typed scalars (Brax's System keeps viscosity and density so)
    as float32 arrays: an edit to them, a float32 like every other number, then shares
    the trace instead of changing the argument's type."""
    strong = lambda x: x.astype(x.dtype) if isinstance(x, jax.Array) and x.weak_type else x  # noqa: E731
    return jax.tree.map(strong, model)


@contextlib.contextmanager
def _holding(env: brax_base.Env, model: mjx.Model) -> Iterator[brax_base.Env]:
    """`env` stepping `model` (the task's, maybe traced) for the duration of a call."""
    inner = env.unwrapped
    with _LOCK:
        own = inner.sys
        inner.sys = model
        try:
            yield env
        finally:
            inner.sys = own


def _key_data(key: Array) -> Array:
    return jax.random.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key) else key


def _start(env: tree.Static, model: mjx.Model, key: Array) -> State:
    with _holding(env.value, model) as held:
        first = held.reset(_key_data(key))
    state = State.create(first.pipeline_state, first.obs, info={NAME: dict(first.info)})
    return state.replace(metrics=_prefixed(first.metrics))


def _step(env: tree.Static, model: mjx.Model, state: State, action: Array, key: Array) -> State:
    prefix = f"{NAME}/"
    own = brax_base.State(
        pipeline_state=state.data, obs=state.obs, reward=state.reward, done=state.terminated.astype(jnp.float32),
        metrics={k[len(prefix):]: v for k, v in state.metrics.items() if k.startswith(prefix)},
        info=dict(state.info[NAME]),  # fresh dicts: Brax's envs update the ones they get in place
    )  # fmt: skip
    with _holding(env.value, model) as held:
        after = held.step(own, action)
    next_state = state.replace(
        data=after.pipeline_state, obs=after.obs, info={**state.info, NAME: dict(after.info)},
        metrics={**state.metrics, **_prefixed(after.metrics)},
    )  # fmt: skip
    done = jnp.asarray(after.done) != 0
    limit = jnp.asarray(after.info.get("truncation", 0.0)) != 0  # Brax: this done is a time limit
    terms = {NAME: jnp.asarray(after.reward, jnp.float32)}
    return record(next_state, terms, done & ~limit, done & limit)


def _prefixed(metrics: dict[str, Array]) -> dict[str, Array]:
    return {f"{NAME}/{k}": v for k, v in metrics.items()}


def _recorded_reward(model, state: State, action: Array, next_state: State) -> dict[str, Array]:
    return dict(next_state.info[OUTCOME]["reward"])


def _recorded_terminate(model, state: State) -> tuple[Array, Array]:
    return state.info[OUTCOME]["terminated"], state.info[OUTCOME]["truncated"]
