"""FastTD3 (Seo et al., 2025) on any `mjzoo.Task`: TD3 made fast by many parallel envs,
large batches, n-step returns and a distributional critic.

    config, hyperparams = fast_td3.configure(num_envs=1024, total_steps=10_000_000)
    state, metrics = jax.jit(fast_td3.train, static_argnums=0)(config, task, hyperparams, key)
    mjzoo.harness.training.run(fast_td3.make(config), task, Settings(out_dir="runs/x"), hyperparams)

The recipe: a deterministic tanh policy explores with Gaussian noise whose scale each
env draws anew, uniform in [noise_std_min, noise_std_max], at every episode start (so
the batch mixes careful and bold exploration); twin categorical critics (C51: a
softmax over `num_atoms` atoms on [v_min, v_max]) learn by cross-entropy against the
projected n-step target of the smaller-valued target critic (clipped double Q) at a
smoothed target action; the policy maximizes the smaller critic's expected value every
`policy_delay` critic steps; targets follow by Polyak averaging; observations are
normalized; AdamW. The same form and contract as `ppo` and `sac` (`Config` static,
`Hyperparams` a vmappable pytree in the state, the replay buffer in the state).
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
from mjzoo.learning import hyperparams as hyperparams_lib
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
    """FastTD3's structure (static under jit; hashable): `_offpolicy.ReplayConfig`'s
    fields at the paper's defaults, and the policy delay and the critic's atoms. The
    numbers are `Hyperparams`."""

    WHO: ClassVar[str] = "fast_td3.Config"
    num_envs: int = 1024
    gradient_steps: int = 2
    batch_size: int = 32_768
    buffer_size: int = 1_048_576
    n_steps: int = 3
    learning_starts: int = 10_240
    policy_hidden_sizes: tuple[int, ...] = (512, 256, 128)
    critic_hidden_sizes: tuple[int, ...] = (1024, 512, 256)
    normalize_observations: bool = True
    total_steps: int = 10_000_000
    policy_delay: int = 2  # critic steps per policy step
    num_atoms: int = 101

    def __post_init__(self):
        super().__post_init__()
        checks.fields(
            self.WHO,
            self,
            {
                "policy_delay": (checks.is_count(self.policy_delay), "an integer >= 1"),
                "num_atoms": (checks.is_count(self.num_atoms - 1), "an integer >= 2"),
            },
        )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams:
    """FastTD3's numbers: a pytree of scalars (or [n] batches, to sweep under `jax.vmap`)."""

    learning_rate: float | Array = 3e-4  # the policy's and the critics'
    weight_decay: float | Array = 0.1  # AdamW's
    discount: float | Array = 0.99
    tau: float | Array = 0.1  # Polyak averaging's step toward the critics and the policy
    v_min: float | Array = -250.0  # the critics' support, in (scaled) reward units
    v_max: float | Array = 250.0
    policy_noise: float | Array = 0.2  # target-policy smoothing's scale
    noise_clip: float | Array = 0.5
    noise_std_min: float | Array = 0.001  # exploration's per-env noise scale range
    noise_std_max: float | Array = 0.4
    reward_scaling: float | Array = 1.0
    max_grad_norm: float | Array = INF  # inf: gradients unclipped

    def __post_init__(self):
        checks.ranges("fast_td3.Hyperparams", self, HYPERPARAM_RANGES)

    def replace(self, **changes) -> Hyperparams:
        return dataclasses.replace(self, **changes)


HYPERPARAM_RANGES = {
    "learning_rate": (0.0, INF, "()"),
    "weight_decay": (0.0, INF, "[)"),
    "discount": (0.0, 1.0, "[]"),
    "tau": (0.0, 1.0, "[]"),
    "v_min": (-INF, INF, "()"),
    "v_max": (-INF, INF, "()"),
    "policy_noise": (0.0, INF, "[)"),
    "noise_clip": (0.0, INF, "[)"),
    "noise_std_min": (0.0, INF, "[)"),
    "noise_std_max": (0.0, INF, "[)"),
    "reward_scaling": (0.0, INF, "()"),
    "max_grad_norm": (0.0, INF, "(]"),
}


def configure(**fields: Any) -> tuple[Config, Hyperparams]:
    """(Config, Hyperparams) from one flat dict of field values; unknown names and bad
    values are a ValueError naming them."""
    names = hyperparams_lib.field_names
    config, hyper = hyperparams_lib.split_fields(
        "fast_td3.configure", names(Config), names(Hyperparams), fields, ("max_grad_norm",)
    )
    hyper = Hyperparams(**hyper)
    if not hyper.v_min < hyper.v_max:  # host numbers here; a traced sweep is the user's to keep ordered
        raise ValueError(f"fast_td3.configure: v_min={hyper.v_min} must be below v_max={hyper.v_max}")
    return Config(**config), hyper


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrainState:
    """Everything training needs to continue exactly, the replay buffer included. Each
    env's exploration noise scale is its collector's carry."""

    params: dict[str, Any]  # {"policy", "critic" (twin, [2, ...]), "target_policy", "target_critic"}
    opt_state: dict[str, Any]  # {"policy", "critic"}
    obs_stats: normalization.RunningStats
    collector: learning.Collector
    replay: replay.Replay
    key: Array
    updates: Array  # int32 count of updates done
    critic_steps: Array  # int32 count of critic steps (the policy steps every policy_delay)
    hyperparams: Hyperparams

    def replace(self, **changes) -> TrainState:
        return dataclasses.replace(self, **changes)


def _networks(config: Config, task: Task) -> tuple[networks.Network, networks.Network]:
    return _offpolicy.actor_critic(config, task.action_size, config.num_atoms)


def _optimizer(hp: Hyperparams) -> optax.GradientTransformation:
    return _offpolicy.optimizer(hp.learning_rate, hp.max_grad_norm, hp.weight_decay)


@functools.partial(jax.jit, static_argnums=0)
def init(config: Config, task: Task, hyperparams: Hyperparams, key: Array) -> TrainState:
    """A fresh train state: networks and their targets, optimizers, `num_envs` reset envs
    (each to draw its noise scale at its first step), an empty replay."""
    policy_net, critic_net = _networks(config, task)
    env_key, policy_key, critic_key, key = jax.random.split(key, 4)
    collector = learning.Collector.create(task, env_key, config.num_envs, carry=jnp.zeros((), jnp.float32))
    example = jax.tree.map(lambda x: x[0], collector.env_state.obs)
    stats = normalization.init_stats(example)
    policy_in, critic_in = _offpolicy.inputs(config, stats, example)
    params = {
        "policy": policy_net.init(policy_key, policy_in),
        "critic": critic_net.init(critic_key, jnp.concatenate([critic_in, jnp.zeros(task.action_size)])),
    }
    params = {**params, "target_policy": params["policy"], "target_critic": params["critic"]}
    hp = hyperparams_lib.as_leaves(hyperparams)
    rows = _offpolicy.capacity_rows(config.buffer_size, config.num_envs)
    zero = jnp.zeros((), jnp.int32)
    return TrainState(
        params=params,
        opt_state={"policy": _optimizer(hp).init(params["policy"]), "critic": _optimizer(hp).init(params["critic"])},
        obs_stats=stats,
        collector=collector,
        replay=_offpolicy.empty_replay(collector, task.action_size, rows),
        key=key,
        updates=zero,
        critic_steps=zero,
        hyperparams=hp,
    )


def _action(config: Config, task: Task, policy_params: Any, stats: normalization.RunningStats, obs: Any) -> Array:
    """The deterministic action in [-1, 1] at `obs`, [..., A]."""
    policy_in, _ = _offpolicy.inputs(config, stats, obs)
    return jnp.tanh(_networks(config, task)[0].apply(policy_params, policy_in))


def acting(
    config: Config, task: Task, params: dict[str, Any], explore: bool, hp: Hyperparams | None = None, uniform=False
) -> learning.Actor:
    """One env's actor for `learning.collect`; extras: the action in [-1, 1]. Exploring,
    the carry is the env's noise scale, drawn from hp's range where `start` begins an
    episode; `uniform` (an array flag under jit) takes uniform actions instead."""

    def act(carry, obs, start, key):
        action = _action(config, task, params["policy"], params["obs_stats"], obs)
        if explore:
            scale_key, noise_key, uniform_key = jax.random.split(key, 3)
            fresh = jax.random.uniform(scale_key, (), minval=hp.noise_std_min, maxval=hp.noise_std_max)
            carry = jnp.where(start, fresh, carry)
            action = jnp.clip(action + carry * jax.random.normal(noise_key, action.shape), -1.0, 1.0)
            action = jnp.where(uniform, jax.random.uniform(uniform_key, action.shape, minval=-1.0, maxval=1.0), action)
        return carry, learning.to_controls(task, action), action

    return act


policy_params = _offpolicy.policy_params


def policy(config: Config, task: Task, deterministic: bool = True):
    """A deployable policy ``(policy_params, obs, key) -> ctrl`` for one env: the
    deterministic action (TD3's policy has no other; `deterministic` is accepted for
    the contract)."""

    return _offpolicy.deployable(lambda params: acting(config, task, params, False))


def _critic_logits(config: Config, task: Task, critic_params: Any, critic_in: Array, action: Array) -> Array:
    """[2, B, num_atoms] the twin critics' logits."""
    return _networks(config, task)[1].apply(critic_params, jnp.concatenate([critic_in, action], -1))


def _gradient_step(config: Config, task: Task, ts: TrainState, key: Array) -> tuple[TrainState, dict[str, Array]]:
    """One critic step, and a policy step (with the targets' Polyak step) every
    `policy_delay` of them, on one sampled batch."""
    hp, params, stats = ts.hyperparams, ts.params, ts.obs_stats
    sample_key, noise_key = jax.random.split(key)
    batch = replay.sample_n_step(ts.replay, sample_key, config.batch_size, config.n_steps, hp.discount)
    support = targets.categorical_support(hp.v_min, hp.v_max, config.num_atoms)
    _, critic_in = _offpolicy.inputs(config, stats, batch.obs)
    _, next_critic_in = _offpolicy.inputs(config, stats, batch.next_obs)

    next_action = targets.smoothed_action(
        _action(config, task, params["target_policy"], stats, batch.next_obs), noise_key, hp.policy_noise, hp.noise_clip
    )
    next_probs = jax.nn.softmax(_critic_logits(config, task, params["target_critic"], next_critic_in, next_action))
    reward = batch.reward * hp.reward_scaling
    projected = jax.vmap(targets.categorical_projection, in_axes=(None, 0, None, None))(
        support, next_probs, reward, batch.discount
    )  # [2, B, K]
    values = targets.categorical_value(support, next_probs)  # [2, B]
    target = jnp.where((values[0] <= values[1])[:, None], projected[0], projected[1])  # clipped double Q

    def critic_loss(critic_params):
        logits = _critic_logits(config, task, critic_params, critic_in, batch.action)
        cross_entropy = -jnp.sum(target * jax.nn.log_softmax(logits), axis=-1)  # [2, B]
        return jnp.mean(jnp.sum(cross_entropy, axis=0)), jnp.mean(
            targets.categorical_value(support, jax.nn.softmax(logits))
        )

    def policy_loss(policy_params):
        action = _action(config, task, policy_params, stats, batch.obs)
        probs = jax.nn.softmax(_critic_logits(config, task, params["critic"], critic_in, action))
        return -jnp.mean(jnp.min(targets.categorical_value(support, probs), axis=0))

    (c_loss, q_mean), c_grads = jax.value_and_grad(critic_loss, has_aux=True)(params["critic"])
    c_updates, c_opt = _optimizer(hp).update(c_grads, ts.opt_state["critic"], params["critic"])
    critic = optax.apply_updates(params["critic"], c_updates)

    def policy_step(_):
        p_loss, p_grads = jax.value_and_grad(policy_loss)(params["policy"])
        p_updates, p_opt = _optimizer(hp).update(p_grads, ts.opt_state["policy"], params["policy"])
        return optax.apply_updates(params["policy"], p_updates), p_opt, p_loss

    def no_step(_):
        return params["policy"], ts.opt_state["policy"], jnp.full((), jnp.nan)

    acts = ts.critic_steps % config.policy_delay == 0
    policy_params_, p_opt, p_loss = jax.lax.cond(acts, policy_step, no_step, None)
    new = ts.replace(
        params={
            "policy": policy_params_,
            "critic": critic,
            "target_policy": targets.polyak(params["target_policy"], policy_params_, hp.tau),
            "target_critic": targets.polyak(params["target_critic"], critic, hp.tau),
        },
        opt_state={"policy": p_opt, "critic": c_opt},
        critic_steps=ts.critic_steps + 1,
    )
    return new, {"loss/critic": c_loss, "loss/policy": p_loss, "loss/q": q_mean}


def update(config: Config, task: Task, train_state: TrainState) -> tuple[TrainState, dict[str, Array]]:
    """One FastTD3 update: `unroll_length` noisy steps of every env into the replay, then
    `gradient_steps` critic steps (none, and uniform actions, before `learning_starts`
    env steps). Jit it with `config` static."""
    return _offpolicy.update(
        config,
        task,
        train_state,
        lambda warming: acting(config, task, policy_params(train_state), True, train_state.hyperparams, warming),
        lambda s, k: _gradient_step(config, task, s, k),
    )


def evaluate(
    config: Config, task: Task, train_state: TrainState, key: Array, num_envs: int, num_steps: int | None = None
) -> learning.Evaluation:
    """Deterministic episodes of the policy (`learning.evaluate`)."""
    return learning.evaluate(task, acting(config, task, policy_params(train_state), False), key, num_envs, num_steps)


def train(config: Config, task: Task, hyperparams: Hyperparams, key: Array) -> tuple[TrainState, dict[str, Array]]:
    """A whole run: `init`, then `config.num_updates` `update`s in one `lax.scan`. Jit
    it with `config` static; vmap it over hyperparameters and keys to sweep them."""
    return _offpolicy.train(init, update, config, task, hyperparams, key)


@functools.lru_cache(maxsize=32)
def make(config: Config) -> Algorithm:
    """FastTD3 as a value (`mjzoo.learning.Algorithm`) the harness drives."""
    return _offpolicy.algorithm("fast_td3", sys.modules[__name__], config)
