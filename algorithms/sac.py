"""Soft actor-critic (Haarnoja et al., 2018) on any `mjzoo.Task`: a tanh-squashed
Gaussian policy, twin critics with Polyak-averaged targets, and an entropy temperature
tuned to a target entropy.

    config, hyperparams = sac.configure(num_envs=16, total_steps=100_000)
    state, metrics = jax.jit(sac.train, static_argnums=0)(config, task, hyperparams, key)
    act = sac.policy(config, task)                 # deployable: act(params, obs, key)
    mjzoo.harness.training.run(sac.make(config), task, Settings(out_dir="runs/x"), hyperparams)

The same form as `ppo`: `Config` is the structure (static), `Hyperparams` every number
(a pytree `init` stores in the state; `jax.vmap` of `train` over a batch of them is one
program). `update` is one jit: `unroll_length` steps of `num_envs` envs go into the
replay (`learning.replay`, rows of parallel steps; the state holds it, so checkpoints
resume exactly), then `gradient_steps` steps on `batch_size` n-step samples. Until
`learning_starts` env steps, actions are uniform and nothing is learned.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
from typing import Any
from typing import ClassVar

import jax
import jax.numpy as jnp
import optax

from mjzoo import checks
from mjzoo import learning
from mjzoo.algorithms import _offpolicy
from mjzoo.learning import distributions
from mjzoo.learning import hyperparams as hyperparams_lib
from mjzoo.learning import losses
from mjzoo.learning import networks
from mjzoo.learning import normalization
from mjzoo.learning import replay
from mjzoo.learning import targets
from mjzoo.learning.algorithm import Algorithm
from mjzoo.learning.hyperparams import INF
from mjzoo.types import Task

__all__ = ["Config", "Hyperparams", "TrainState", "configure", "evaluate", "init", "make", "policy", "train", "update"]

Array = jax.Array


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config(_offpolicy.ReplayConfig):
    """SAC's structure (static under jit; hashable): `_offpolicy.ReplayConfig`'s fields
    (envs, replay, batch, networks, warm-up), at SAC's usual defaults. The numbers are
    `Hyperparams`."""

    WHO: ClassVar[str] = "sac.Config"


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams:
    """SAC's numbers: a pytree of scalars (or [n] batches, to sweep under `jax.vmap`)."""

    learning_rate: float | Array = 3e-4  # the policy's and the critics'
    alpha_learning_rate: float | Array = 3e-4
    initial_alpha: float | Array = 1.0
    target_entropy_per_action: float | Array = -1.0  # the target entropy over action_size
    discount: float | Array = 0.99
    tau: float | Array = 0.005  # Polyak averaging's step toward the critics
    reward_scaling: float | Array = 1.0
    max_grad_norm: float | Array = INF  # inf: gradients unclipped

    def __post_init__(self):
        checks.ranges("sac.Hyperparams", self, HYPERPARAM_RANGES)

    def replace(self, **changes) -> Hyperparams:
        return dataclasses.replace(self, **changes)


HYPERPARAM_RANGES = {
    "learning_rate": (0.0, INF, "()"),
    "alpha_learning_rate": (0.0, INF, "[)"),
    "initial_alpha": (0.0, INF, "()"),
    "target_entropy_per_action": (-INF, INF, "()"),
    "discount": (0.0, 1.0, "[]"),
    "tau": (0.0, 1.0, "[]"),
    "reward_scaling": (0.0, INF, "()"),
    "max_grad_norm": (0.0, INF, "(]"),
}


def configure(**fields: Any) -> tuple[Config, Hyperparams]:
    """(Config, Hyperparams) from one flat dict of field values; unknown names and bad
    values are a ValueError naming them."""
    names = hyperparams_lib.field_names
    config, hyper = hyperparams_lib.split_fields(
        "sac.configure", names(Config), names(Hyperparams), fields, ("max_grad_norm",)
    )
    return Config(**config), Hyperparams(**hyper)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrainState:
    """Everything training needs to continue exactly, the replay buffer included."""

    params: dict[str, Any]  # {"policy", "critic" (twin, [2, ...]), "target_critic"}
    log_alpha: Array  # float32 scalar
    opt_state: dict[str, Any]  # {"policy", "critic", "alpha"}
    obs_stats: normalization.RunningStats
    collector: learning.Collector
    replay: replay.Replay
    key: Array
    updates: Array  # int32 count of updates done
    hyperparams: Hyperparams

    def replace(self, **changes) -> TrainState:
        return dataclasses.replace(self, **changes)


def _networks(config: Config, task: Task) -> tuple[networks.Network, networks.Network]:
    return _offpolicy.actor_critic(config, 2 * task.action_size, 1)


@functools.partial(jax.jit, static_argnums=0)
def init(config: Config, task: Task, hyperparams: Hyperparams, key: Array) -> TrainState:
    """A fresh train state: networks, optimizers, `num_envs` reset envs, an empty replay."""
    policy_net, critic_net = _networks(config, task)
    env_key, policy_key, critic_key, key = jax.random.split(key, 4)
    collector = learning.Collector.create(task, env_key, config.num_envs)
    stats = normalization.init_stats(jax.tree.map(lambda x: x[0], collector.env_state.obs))
    policy_in, critic_in = _offpolicy.inputs(config, stats, jax.tree.map(lambda x: x[0], collector.env_state.obs))
    critic_example = jnp.concatenate([critic_in, jnp.zeros(task.action_size)])
    critic_params = critic_net.init(critic_key, critic_example)
    params = {"policy": policy_net.init(policy_key, policy_in), "critic": critic_params, "target_critic": critic_params}
    hp = hyperparams_lib.as_leaves(hyperparams)
    log_alpha = jnp.log(hp.initial_alpha)
    rows = _offpolicy.capacity_rows(config.buffer_size, config.num_envs)
    return TrainState(
        params=params,
        log_alpha=log_alpha,
        opt_state={
            "policy": _offpolicy.optimizer(hp.learning_rate, hp.max_grad_norm).init(params["policy"]),
            "critic": _offpolicy.optimizer(hp.learning_rate, hp.max_grad_norm).init(critic_params),
            "alpha": optax.adam(hp.alpha_learning_rate).init(log_alpha),
        },
        obs_stats=stats,
        collector=collector,
        replay=_offpolicy.empty_replay(collector, task.action_size, rows),
        key=key,
        updates=jnp.zeros((), jnp.int32),
        hyperparams=hp,
    )


def _distribution(config: Config, task: Task, policy_params: Any, stats: normalization.RunningStats, obs: Any):
    """(loc, scale) of the squashed Gaussian at `obs` ([..., A] each)."""
    policy_in, _ = _offpolicy.inputs(config, stats, obs)
    return distributions.split_params(_networks(config, task)[0].apply(policy_params, policy_in))


def acting(config: Config, task: Task, params: dict[str, Any], mode: Array | bool) -> learning.Actor:
    """One env's actor for `learning.collect`: mode True the mean action, False a sample,
    "uniform" (an array flag under jit) uniform actions; extras: the action in [-1, 1]."""

    def act(carry, obs, start, key):
        loc, scale = _distribution(config, task, params["policy"], params["obs_stats"], obs)
        sampled, _ = distributions.sample(loc, scale, key)
        action = distributions.mode(loc) if mode is True else sampled
        if not isinstance(mode, bool):  # before learning starts: uniform in [-1, 1]
            action = jnp.where(mode, jax.random.uniform(key, loc.shape, minval=-1.0, maxval=1.0), action)
        return carry, learning.to_controls(task, action), action

    return act


policy_params = _offpolicy.policy_params


def policy(config: Config, task: Task, deterministic: bool = True):
    """A deployable policy ``(policy_params, obs, key) -> ctrl`` for one env (the mean
    action, or a sample)."""

    return _offpolicy.deployable(lambda params: acting(config, task, params, deterministic))


def _critic_values(config: Config, task: Task, critic_params: Any, critic_in: Array, action: Array) -> Array:
    """[2, B] the twin critics' values."""
    return _networks(config, task)[1].apply(critic_params, jnp.concatenate([critic_in, action], -1))[..., 0]


def _gradient_step(config: Config, task: Task, ts: TrainState, key: Array) -> tuple[TrainState, dict[str, Array]]:
    """One step of the critics, the policy and the temperature on one sampled batch."""
    hp, params = ts.hyperparams, ts.params
    sample_key, next_key, policy_key = jax.random.split(key, 3)
    batch = replay.sample_n_step(ts.replay, sample_key, config.batch_size, config.n_steps, hp.discount)
    alpha = jnp.exp(ts.log_alpha)
    _, critic_in = _offpolicy.inputs(config, ts.obs_stats, batch.obs)
    _, next_critic_in = _offpolicy.inputs(config, ts.obs_stats, batch.next_obs)

    loc, scale = _distribution(config, task, params["policy"], ts.obs_stats, batch.next_obs)
    next_action, next_raw = distributions.sample(loc, scale, next_key)
    next_q = _critic_values(config, task, params["target_critic"], next_critic_in, next_action)
    next_log_prob = distributions.log_prob(loc, scale, next_raw)
    y = targets.twin_td_target(batch.reward * hp.reward_scaling, batch.discount, *next_q, next_log_prob, alpha)

    def critic_loss(critic_params):
        q = _critic_values(config, task, critic_params, critic_in, batch.action)
        return 0.5 * jnp.mean(jnp.sum(jnp.square(q - y), axis=0)), jnp.mean(q)

    def policy_loss(policy_params):
        loc, scale = _distribution(config, task, policy_params, ts.obs_stats, batch.obs)
        action, raw = distributions.sample(loc, scale, policy_key)
        log_prob = distributions.log_prob(loc, scale, raw)
        q = jnp.min(_critic_values(config, task, params["critic"], critic_in, action), axis=0)
        return jnp.mean(alpha * log_prob - q), log_prob

    (c_loss, q_mean), c_grads = jax.value_and_grad(critic_loss, has_aux=True)(params["critic"])
    (p_loss, log_prob), p_grads = jax.value_and_grad(policy_loss, has_aux=True)(params["policy"])
    a_loss, a_grad = jax.value_and_grad(losses.temperature_loss)(
        ts.log_alpha, log_prob, hp.target_entropy_per_action * task.action_size
    )
    opt = _offpolicy.optimizer(hp.learning_rate, hp.max_grad_norm)
    c_updates, c_opt = opt.update(c_grads, ts.opt_state["critic"], params["critic"])
    p_updates, p_opt = opt.update(p_grads, ts.opt_state["policy"], params["policy"])
    a_update, a_opt = optax.adam(hp.alpha_learning_rate).update(a_grad, ts.opt_state["alpha"])
    critic = optax.apply_updates(params["critic"], c_updates)
    new = ts.replace(
        params={
            "policy": optax.apply_updates(params["policy"], p_updates),
            "critic": critic,
            "target_critic": targets.polyak(params["target_critic"], critic, hp.tau),
        },
        log_alpha=ts.log_alpha + a_update,
        opt_state={"policy": p_opt, "critic": c_opt, "alpha": a_opt},
    )
    metrics = {
        "loss/critic": c_loss,
        "loss/policy": p_loss,
        "loss/alpha": a_loss,
        "loss/q": q_mean,
        "loss/entropy": -jnp.mean(log_prob),
        "alpha": alpha,
    }
    return new, metrics


def update(config: Config, task: Task, train_state: TrainState) -> tuple[TrainState, dict[str, Array]]:
    """One SAC update: `unroll_length` steps of every env into the replay, then
    `gradient_steps` learning steps (none, and uniform actions, before
    `learning_starts` env steps). Jit it with `config` static."""
    return _offpolicy.update(
        config,
        task,
        train_state,
        lambda warming: acting(config, task, policy_params(train_state), warming),
        lambda s, k: _gradient_step(config, task, s, k),
    )


def evaluate(
    config: Config, task: Task, train_state: TrainState, key: Array, num_envs: int, num_steps: int | None = None
) -> learning.Evaluation:
    """Deterministic episodes of the mean action (`learning.evaluate`)."""
    return learning.evaluate(task, acting(config, task, policy_params(train_state), True), key, num_envs, num_steps)


def train(config: Config, task: Task, hyperparams: Hyperparams, key: Array) -> tuple[TrainState, dict[str, Array]]:
    """A whole run: `init`, then `config.num_updates` `update`s in one `lax.scan`. Jit
    it with `config` static; vmap it over hyperparameters and keys to sweep them."""
    return _offpolicy.train(init, update, config, task, hyperparams, key)


@functools.lru_cache(maxsize=32)
def make(config: Config) -> Algorithm:
    """SAC as a value (`mjzoo.learning.Algorithm`) the harness drives."""
    return _offpolicy.algorithm("sac", sys.modules[__name__], config)
