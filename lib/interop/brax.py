"""One mjzoo `Task` presented as a Brax `Env`, for Brax's own trainers; and the reverse,
any Brax `Env` as an mjzoo Task (`task`, from `mjzoo.interop.brax_envs`).

    env = mjzoo.interop.brax.to_brax_env(mjzoo.envs.make("cartpole_balance"))
    brax.training.agents.ppo.train(env, ..., episode_length=500,
                                   wrap_env_fn=mjzoo.interop.brax.wrap_for_training)

Every step goes through `mjzoo.transition`, so reward, termination and truncation are
exactly the task's. The Brax state holds:

  pipeline_state          the mjx.Data of the mjzoo State
  obs                     the observation, as one flat float32 vector
  reward                  float32, the summed reward terms
  done                    float32, terminated | truncated
  metrics                 the mjzoo metrics: ``"reward/<name>"`` per term, ``"diverged"``
  info["rng"]             uint32 PRNG key data of this env; each step splits it into the
                          next one and the key of its `mjzoo.transition`
  info["truncation"]      float32, truncated (Brax PPO masks truncated steps)
  info["mjzoo"]["state"]  the rest of the mjzoo State (info, metrics, reward, flags)
  info["mjzoo"]["first"]  the same, as it was after `reset`
  info["mjzoo"]["time"]   data.time of the physics state the last call returned

Brax's `AutoResetWrapper` restarts an ended episode by putting the env's FIRST
pipeline_state and obs back (Brax's convention: one start state per env), but leaves
`info` alone. A step therefore restarts from ``info["mjzoo"]["first"]`` when the last
one ended the episode or when it is handed a physics state other than the one it
returned (an outer time limit, e.g. `EpisodeWrapper`, ended the episode), so mjzoo's
own per-episode info (step counter, randomized physics) restarts with the physics.

Brax's `EpisodeWrapper` overwrites ``info["truncation"]`` with its own time limit's
flag only, and counts an episode that our `done` ended at its limit as terminal. Use
`wrap_for_training` (Brax's `wrap` plus the task's truncation put back) as ppo.train's
`wrap_env_fn` so truncated episodes are not learnt as terminal.
"""

from __future__ import annotations

import math
from typing import Any
from typing import Callable
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from brax.envs import base as brax_base
from brax.envs.wrappers import training as brax_training

from mjzoo import tree
from mjzoo.interop import _foreign
from mjzoo.interop.brax_envs import task
from mjzoo.running import reset as mjzoo_reset
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["to_brax_env", "task", "MjzooBraxEnv", "wrap_for_training", "patch_brax_for_current_jax"]

Array = jax.Array
KEY = "mjzoo"  # this adapter's info entry


def to_brax_env(task: Task) -> "MjzooBraxEnv":
    """`task` as a Brax `Env` (backend "mjx"); see the module docstring for its state."""
    if not isinstance(task, Task):
        raise TypeError(f"to_brax_env: expected an mjzoo.Task, got {type(task).__name__}")
    return MjzooBraxEnv(task)


class MjzooBraxEnv(brax_base.Env):
    """A Brax `Env` stepping one mjzoo `Task` through `mjzoo.transition`.

    `sys` is the task's mjx.Model and is what reset and step use, so Brax's
    `DomainRandomizationVmapWrapper` (``randomization_fn(sys, rng) -> (sys, in_axes)``
    over an mjx.Model) randomizes the task's physics.
    """

    def __init__(self, task: Task):
        self._task = task
        self.sys = task.model
        shape = jax.eval_shape(lambda key: mjzoo_reset(task, key), jax.random.key(0))
        self._obs_tree = jax.tree.structure(shape.obs)
        self._obs_shapes = [leaf.shape for leaf in jax.tree.leaves(shape.obs)]
        self._obs_size = sum(math.prod(s) for s in self._obs_shapes)

    # --- the Brax Env interface ----------------------------------------------------

    @property
    def task(self) -> Task:
        """The task, with `sys` as its model."""
        return self._task.replace(model=self.sys)

    @property
    def mj_model(self):
        """The task's host `mujoco.MjModel` (static)."""
        return self._task.mj_model

    @property
    def observation_size(self) -> int:
        return self._obs_size

    @property
    def action_size(self) -> int:
        return self._task.action_size

    @property
    def backend(self) -> str:
        return "mjx"

    def reset(self, rng: Array) -> brax_base.State:
        """Starts an episode with ``mjzoo.reset(task, split(rng)[1])``; keeps
        ``split(rng)[0]`` as ``info["rng"]``. `rng`: uint32 key data (Brax) or a typed key."""
        rng, reset_key = jax.random.split(_foreign.key_data(rng))
        state = mjzoo_reset(self.task, jax.random.wrap_key_data(reset_key))
        rest = _rest(state)
        info = {"rng": rng, KEY: {"state": rest, "first": rest, "time": state.data.time}}
        return self._to_brax(state, info)

    def step(self, state: brax_base.State, action: Array) -> brax_base.State:
        """One ``mjzoo.transition`` with the key split from ``info["rng"]``."""
        own = state.info[KEY]
        handed_other = state.pipeline_state.time != own["time"]
        ended = own["state"].terminated | own["state"].truncated
        rest = tree.where(ended | handed_other, own["first"], own["state"])
        current = rest.replace(data=state.pipeline_state, obs=self._unflatten(state.obs))
        rng, step_key = jax.random.split(state.info["rng"])
        action = jnp.asarray(action, jnp.float32)
        next_state = transition(self.task, current, action, jax.random.wrap_key_data(step_key))
        info = {
            **state.info,
            "rng": rng,
            KEY: {"state": _rest(next_state), "first": own["first"], "time": next_state.data.time},
        }
        return self._to_brax(next_state, info, state.metrics)

    # --- conversions ---------------------------------------------------------------

    def _to_brax(self, state: State, info: dict[str, Any], metrics: dict | None = None) -> brax_base.State:
        # Entries wrappers added to metrics (EvalWrapper's "reward") are carried, like info's.
        metrics = {**(metrics or {}), **{k: jnp.asarray(v, jnp.float32) for k, v in state.metrics.items()}}
        return brax_base.State(
            pipeline_state=state.data,
            obs=self._flatten(state.obs),
            reward=jnp.asarray(state.reward, jnp.float32),
            done=(state.terminated | state.truncated).astype(jnp.float32),
            metrics=metrics,
            info={**info, "truncation": state.truncated.astype(jnp.float32)},
        )

    def _flatten(self, obs: Any) -> Array:
        return jnp.concatenate([jnp.ravel(x).astype(jnp.float32) for x in jax.tree.leaves(obs)])

    def _unflatten(self, flat: Array) -> Any:
        # Splits at the static leaf sizes; a single flat leaf comes back as is.
        sizes = np.cumsum([math.prod(s) for s in self._obs_shapes])[:-1]
        parts = jnp.split(flat, sizes) if len(sizes) else [flat]
        leaves = [p.reshape(s) for p, s in zip(parts, self._obs_shapes)]
        return jax.tree.unflatten(self._obs_tree, leaves)


def _rest(state: State) -> State:
    """The mjzoo State without what Brax keeps itself (data, obs)."""
    return state.replace(data=None, obs=None)


# --- training wrappers --------------------------------------------------------------


class _TaskTruncation(brax_base.Wrapper):
    """Puts the task's own truncation back into ``info["truncation"]`` after Brax's
    `EpisodeWrapper` replaced it by its time limit's flag alone."""

    def step(self, state: brax_base.State, action: Array) -> brax_base.State:
        state = self.env.step(state, action)
        truncated = state.info[KEY]["state"].truncated.astype(jnp.float32)
        state.info["truncation"] = jnp.maximum(state.info["truncation"], truncated)
        return state


def wrap_for_training(
    env: brax_base.Env,
    episode_length: int = 1000,
    action_repeat: int = 1,
    randomization_fn: Callable | None = None,
) -> brax_base.Wrapper:
    """Brax's `envs.training.wrap` for an adapted task, keeping its truncation flags.

    Same signature, so it goes to ``ppo.train(wrap_env_fn=...)``. `episode_length`
    should be the task's own episode length (or more); `action_repeat` must be 1: Brax
    repeats past an episode's end, use `mjzoo.with_action_repeat` on the task instead.
    """
    if action_repeat != 1:
        raise ValueError(
            f"wrap_for_training: action_repeat={action_repeat} must be 1; "
            "wrap the task with mjzoo.with_action_repeat instead"
        )
    if randomization_fn is None:
        env = brax_training.VmapWrapper(env)
    else:
        env = brax_training.DomainRandomizationVmapWrapper(env, randomization_fn)
    env = brax_training.EpisodeWrapper(env, episode_length, action_repeat)
    return brax_training.AutoResetWrapper(_TaskTruncation(env))


# --- Brax on current JAX (peer baseline only) ---------------------------------------


def patch_brax_for_current_jax() -> None:
    """Lets Brax 0.14's trainers run on JAX >= 0.10. Exists only for the peer baseline
    (Brax PPO in benchmarks/); mjzoo itself never needs it.

    JAX 0.10 removed `jax.device_put_replicated`, which Brax's ppo/sac/apg `train` call
    to copy the training state onto each device; this installs an equivalent when it is
    missing. Nothing else in ppo.train's path fails on JAX 0.10 (`jax.pmap` is still
    there, rebuilt on shard_map), so nothing else is touched. Idempotent.

    Left alone, as a one-time cost: Brax's evaluator compiles its unroll twice, because
    the parameters it gets after the first training epoch carry pmap's sharding.
    """
    if not hasattr(jax, "device_put_replicated"):
        jax.device_put_replicated = _device_put_replicated


_BRAX_PMAP_AXIS = "i"  # the axis name Brax's trainers give jax.pmap


def _device_put_replicated(x: Any, devices: Sequence[jax.Device]) -> Any:
    """Each leaf of `x` stacked once per device on a new leading axis, one slice per
    device. The mesh axis carries Brax's pmap axis name: the new `jax.pmap` returns
    arrays sharded over a mesh of that name, so the initial training state then has
    the sharding of every later one and Brax's training epoch compiles once, not twice."""
    devices = list(devices)
    if not devices:
        raise ValueError("device_put_replicated: devices must be a non-empty sequence")
    mesh = jax.sharding.Mesh(np.array(devices), (_BRAX_PMAP_AXIS,))
    sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec(_BRAX_PMAP_AXIS))

    def put(leaf):
        leaf = jnp.asarray(leaf)
        return jax.device_put(jnp.broadcast_to(leaf, (len(devices), *leaf.shape)), sharding)

    return jax.tree.map(put, x)
