"""Any Brax `Env` on MJX physics as an mjzoo task: the reverse of `to_brax_env`.

    env = brax.envs.get_environment("ant", backend="mjx")
    task = mjzoo.interop.brax.task(env)                       # episode_length=1000, Brax's usual
    config, hyperparams = ppo.configure(num_envs=2048, ...)
    state, metrics = jax.jit(ppo.train, static_argnums=0)(config, task, hyperparams, jax.random.key(0))

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

from brax.envs import base as brax_base
from brax.envs.wrappers import training as brax_training

from mjzoo import checks
from mjzoo import tree
from mjzoo.interop import _foreign
from mjzoo.types import Task

__all__ = ["task", "NAME"]

NAME = "brax"  # the reward term's name, the info key and the metrics prefix
# Brax's State keeps the mjx.Data as pipeline_state and flags a time limit's done in info.
_KIND = _foreign.Kind(
    NAME, model_attr="sys", data_field="pipeline_state", state_type=brax_base.State, truncation_key="truncation"
)
# Brax's training wrappers batch, limit or reset episodes: mjzoo's algorithms and combinators do that.
_TRAINING_WRAPPERS = (
    brax_training.VmapWrapper,
    brax_training.DomainRandomizationVmapWrapper,
    brax_training.EpisodeWrapper,
    brax_training.AutoResetWrapper,
    brax_training.EvalWrapper,
)


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
            raise TypeError(
                f"brax.task: the env is inside Brax's {type(layer).__name__}; pass the env before "
                "brax.envs.training.wrap (mjzoo batches, limits and resets episodes itself)"
            )
        layer = layer.env
    if env.backend != "mjx":
        raise ValueError(
            f"brax.task: the env's backend is {env.backend!r}; only 'mjx' gives an mjx.Data to carry "
            "(brax.envs.get_environment(name, backend='mjx'))"
        )
    model = _foreign.env_model(_KIND, env)
    mj_model = getattr(env.unwrapped, "mj_model", None)  # `to_brax_env`'s envs: their task's
    mj_model = getattr(model, "mj_model", None) if mj_model is None else mj_model  # Brax's: sys.mj_model
    if mj_model is None:
        raise TypeError(f"brax.task: found no mujoco.MjModel for {type(env.unwrapped).__name__} (sys.mj_model)")
    if episode_length is not None:
        episode_length = checks.integer("brax.task", "episode_length", episode_length)
    # Brax's System keeps viscosity and density weakly typed: as float32 arrays like every
    # other number, an edit to them shares the trace instead of changing the argument's type.
    return _foreign.task(_KIND, env, tree.strongly_typed(model), mj_model, episode_length)
