"""Proximal Policy Optimization on any `mjzoo.Task`.

    config = ppo.Config(num_envs=256, total_steps=2_000_000)
    state = ppo.init(config, task, jax.random.key(0))
    state, metrics = jax.jit(ppo.update, static_argnums=0)(config, task, state)
    act = ppo.policy(config, task)                 # deployable: act(params, obs, key)
    act(ppo.policy_params(state), obs, key)

`update` is one jit: `rollout` (`learning.collect`) runs `unroll_length` steps of
`num_envs` auto-resetting envs, then `improve` (`learning.learn`) makes `num_epochs` x
`num_minibatches` clipped-surrogate steps; AMP runs the two with its own reward between
them. A dict observation feeds each network its entry (`policy_obs_key`,
`value_obs_key`: e.g. a critic on privileged state). Every piece is public in `mjzoo.learning` (collection, GAE,
losses, the learner loop, normalization, networks, the squashed Gaussian, evaluation);
this module only chooses and wires them. Actions are sampled in [-1, 1] (tanh) and
mapped onto the actuators' ctrlrange (`learning.to_controls`); GAE bootstraps
truncated episodes from their true final observation.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import warnings
from collections.abc import Callable
from typing import Any, Literal

import jax
import jax.numpy as jnp
import optax

from mjzoo import learning
from mjzoo.harness import training
from mjzoo.learning import distributions, losses, networks, normalization
from mjzoo.types import Task

__all__ = [
    "PER_ENV_FIELDS",
    "Config",
    "TrainState",
    "acting",
    "evaluate",
    "improve",
    "init",
    "policy",
    "policy_params",
    "rollout",
    "train",
    "update",
]

Array = jax.Array
ACTIVATIONS = {"swish": jax.nn.swish, "tanh": jnp.tanh, "relu": jax.nn.relu, "elu": jax.nn.elu}


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config:
    """PPO hyperparameters (static under jit; hashable)."""

    num_envs: int = 256
    unroll_length: int = 32
    num_minibatches: int = 8
    num_epochs: int = 4
    learning_rate: float = 3e-4
    lr_schedule: Literal["constant", "linear", "cosine"] = "constant"
    discount: float = 0.99
    gae_lambda: float = 0.95
    clip_epsilon: float = 0.2
    value_clip_epsilon: float | None = None
    value_coef: float = 0.5
    entropy_coef: float = 1e-2
    max_grad_norm: float | None = 1.0  # None: no clipping
    reward_scaling: float = 1.0
    normalize_observations: bool = True
    normalize_advantages: bool = True
    policy_hidden_sizes: tuple[int, ...] = (64, 64)
    value_hidden_sizes: tuple[int, ...] = (64, 64)
    activation: Literal["swish", "tanh", "relu", "elu"] = "swish"
    # "bfloat16": mixed precision in the default networks' hidden layers (params, output
    # layers, gradients and the optimizer stay float32); the learner's matmuls and
    # activations then move half the bytes.
    compute_dtype: Literal["float32", "bfloat16"] = "float32"
    # Several devices: each its share of every minibatch step, else all of it (`learning.learn`).
    split_minibatches: bool = True
    recurrent: bool = False
    gru_hidden_size: int = 64
    # A dict observation: the entry each network sees (Brax's names; e.g. the value
    # function on privileged state). None: the whole observation, which must be an array.
    policy_obs_key: str | None = None
    value_obs_key: str | None = None
    total_steps: int = 1_000_000
    # Users' own pieces (any JAX library): (init, apply) pairs and an optax optimizer.
    policy_network: networks.Network | networks.RecurrentNetwork | None = None
    value_network: networks.Network | None = None
    optimizer: optax.GradientTransformation | None = None

    def __post_init__(self):
        def need(ok: bool, field: str, allowed: str):
            if not ok:
                raise ValueError(f"ppo.Config: {field}={getattr(self, field)!r} is invalid; expected {allowed}")

        for field in ("num_envs", "unroll_length", "num_minibatches", "num_epochs", "total_steps", "gru_hidden_size"):
            value = getattr(self, field)
            need(isinstance(value, int) and not isinstance(value, bool) and value >= 1, field, "an integer >= 1")
        need(
            (self.num_envs * self.unroll_length) % self.num_minibatches == 0,
            "num_minibatches",
            f"a divisor of num_envs * unroll_length = {self.num_envs * self.unroll_length}",
        )
        need(
            not self.recurrent or self.num_envs % self.num_minibatches == 0,
            "num_minibatches",
            "a divisor of num_envs (recurrent minibatches split whole sequences)",
        )
        need(self.learning_rate > 0, "learning_rate", "> 0")
        need(self.lr_schedule in ("constant", "linear", "cosine"), "lr_schedule", "constant, linear or cosine")
        for field in ("discount", "gae_lambda"):
            need(0.0 <= getattr(self, field) <= 1.0, field, "in [0, 1]")
        need(self.clip_epsilon > 0, "clip_epsilon", "> 0")
        need(self.value_clip_epsilon is None or self.value_clip_epsilon > 0, "value_clip_epsilon", "None or > 0")
        for field in ("value_coef", "entropy_coef"):
            need(getattr(self, field) >= 0, field, ">= 0")
        need(self.max_grad_norm is None or self.max_grad_norm > 0, "max_grad_norm", "None or > 0")
        need(self.reward_scaling > 0, "reward_scaling", "> 0")
        need(self.activation in ACTIVATIONS, "activation", f"one of {sorted(ACTIVATIONS)}")
        need(self.compute_dtype in ("float32", "bfloat16"), "compute_dtype", "float32 or bfloat16")
        if self.total_steps < self.steps_per_update:  # a run is whole updates: this one is one, larger
            warnings.warn(
                f"ppo.Config: total_steps={self.total_steps} is less than one update (num_envs x "
                f"unroll_length = {self.steps_per_update} env steps); the run trains that one update",
                training.TrainingWarning,
                stacklevel=3,
            )

    @property
    def steps_per_update(self) -> int:
        return self.num_envs * self.unroll_length

    @property
    def num_updates(self) -> int:
        return max(1, self.total_steps // self.steps_per_update)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrainState:
    """Everything training needs to continue exactly: a checkpoint saves this.

    `collector` holds the per-env leaves ([num_envs, ...]): env states, recurrent policy
    carries and running episode returns (`learning.Collector`).
    """

    params: dict[str, Any]  # {"policy": ..., "value": ...}
    opt_state: Any
    obs_stats: normalization.RunningStats
    collector: learning.Collector
    key: jax.Array
    updates: jax.Array  # int32 count of updates done

    def replace(self, **changes) -> TrainState:
        return dataclasses.replace(self, **changes)


PER_ENV_FIELDS = ("collector",)  # the harness shards these over devices (training.Algorithm)


# --- networks and optimizer ---------------------------------------------------------


def _networks(config: Config, task: Task):
    activation = ACTIVATIONS[config.activation]
    dtype = jnp.dtype(config.compute_dtype)
    policy_net = config.policy_network
    if policy_net is None and config.recurrent:
        policy_net = networks.gru_mlp(
            2 * task.action_size,
            config.gru_hidden_size,
            config.policy_hidden_sizes,
            activation=activation,
            output_scale=0.01,
        )
    elif policy_net is None:
        policy_net = networks.mlp(
            2 * task.action_size, config.policy_hidden_sizes, activation, output_scale=0.01, compute_dtype=dtype
        )
    value_net = config.value_network or networks.mlp(1, config.value_hidden_sizes, activation, compute_dtype=dtype)
    return policy_net, value_net


def _optimizer(config: Config) -> optax.GradientTransformation:
    if config.optimizer is not None:
        return config.optimizer
    steps = config.num_updates * config.num_epochs * config.num_minibatches
    schedule = {
        "constant": optax.constant_schedule(config.learning_rate),
        "linear": optax.linear_schedule(config.learning_rate, 0.0, steps),
        "cosine": optax.cosine_decay_schedule(config.learning_rate, steps),
    }[config.lr_schedule]
    if config.max_grad_norm is None:
        return optax.adam(schedule)
    return optax.chain(optax.clip_by_global_norm(config.max_grad_norm), optax.adam(schedule))


def _view(obs: Any, key: str | None, field: str) -> Any:
    """The entry `key` of a dict observation (`policy_obs_key` / `value_obs_key`)."""
    if key is None:
        if isinstance(obs, dict):
            raise ValueError(
                f"ppo.Config: the observation is a dict with entries {sorted(obs)}; set {field} to "
                "the entry the network sees"
            )
        return obs
    if not isinstance(obs, dict) or key not in obs:
        found = sorted(obs) if isinstance(obs, dict) else f"an array of shape {jnp.shape(obs)}"
        raise ValueError(f"ppo.Config: {field}={key!r}, but the observation is {found}")
    return obs[key]


def _inputs(config: Config, stats: normalization.RunningStats, obs: Any) -> tuple[Any, Any]:
    """(policy input, value input): the (normalized) observation's entries each network sees."""
    obs = normalization.normalize(stats, obs) if config.normalize_observations else obs
    return _view(obs, config.policy_obs_key, "policy_obs_key"), _view(obs, config.value_obs_key, "value_obs_key")


def _is_recurrent(net) -> bool:
    return isinstance(net, networks.RecurrentNetwork)


def _initial_carry(policy_net) -> Any:
    return policy_net.initial_carry() if _is_recurrent(policy_net) else ()


# --- init ---------------------------------------------------------------------------


@functools.partial(jax.jit, static_argnums=0)  # one compile: resetting op by op took minutes on a GPU
def init(config: Config, task: Task, key: jax.Array) -> TrainState:
    """A fresh train state: networks, optimizer, normalizer and `num_envs` reset envs."""
    policy_net, value_net = _networks(config, task)
    env_key, policy_key, value_key, key = jax.random.split(key, 4)
    collector = learning.Collector.create(task, env_key, config.num_envs, _initial_carry(policy_net))
    example = jax.tree.map(lambda x: x[0], collector.env_state.obs)
    stats = normalization.init_stats(example)
    policy_example, value_example = _inputs(config, stats, example)
    params = {"policy": policy_net.init(policy_key, policy_example), "value": value_net.init(value_key, value_example)}
    return TrainState(
        params=params,
        opt_state=_optimizer(config).init(params),
        obs_stats=stats,
        collector=collector,
        key=key,
        updates=jnp.zeros((), jnp.int32),
    )


# --- acting -------------------------------------------------------------------------


def acting(config: Config, task: Task, params: dict[str, Any], deterministic: bool) -> learning.Policy:
    """The policy of `policy_params` for one env, as `learning.collect` and
    `learning.evaluate` take it: ``act(carry, obs, start, key) -> (carry, ctrl, extras)``,
    the carry () for a feed-forward network, `start` restarting a recurrent one. A sample
    records its pre-tanh value, its log-probability and the carry it started from (the
    learner's sequences begin there); the deterministic action is tanh of the mean."""
    policy_net, _ = _networks(config, task)

    def act(carry, obs, start, key):
        obs, _ = _inputs(config, params["obs_stats"], obs)
        if _is_recurrent(policy_net):
            new_carry, out = policy_net.apply(params["policy"], carry, obs, start)
        else:
            new_carry, out = carry, policy_net.apply(params["policy"], obs)
        loc, scale = distributions.split_params(out)
        if deterministic:
            return new_carry, learning.to_controls(task, distributions.mode(loc)), {}
        action, raw = distributions.sample(loc, scale, key)
        extras = {"raw": raw, "log_prob": distributions.log_prob(loc, scale, raw), "carry": carry}
        return new_carry, learning.to_controls(task, action), extras

    return act


def policy_params(train_state: TrainState) -> dict[str, Any]:
    """What a deployed policy needs: the policy network and the observation statistics."""
    return {"policy": train_state.params["policy"], "obs_stats": train_state.obs_stats}


def policy(config: Config, task: Task, deterministic: bool = True) -> Callable[[Any, Any, jax.Array], jax.Array]:
    """A deployable feed-forward policy ``(policy_params, obs, key) -> ctrl`` for one env.

    Deterministic: the mean action (tanh of the Gaussian's mean); else a sample.
    (Recurrent policies: use `evaluate`, which carries the hidden state.)
    """
    if _is_recurrent(_networks(config, task)[0]):
        raise ValueError("ppo.policy: a recurrent policy needs its carry; use ppo.evaluate or the network directly")

    def act(params, obs, key):
        return acting(config, task, params, deterministic)((), obs, jnp.ones((), bool), key)[1]

    return act


# --- update -------------------------------------------------------------------------


def _loss(config: Config, task: Task, params, stats, batch, key) -> tuple[jax.Array, dict[str, jax.Array]]:
    """PPO loss on one minibatch: [T, n, ...] sequences (recurrent) or [n, ...] samples;
    `key` draws the entropy estimate's fresh sample."""
    policy_net, value_net = _networks(config, task)
    obs, value_obs = _inputs(config, stats, batch["obs"])
    if _is_recurrent(policy_net):

        def step(carry, inputs):  # over time, vmapped over the minibatch's envs
            return jax.vmap(lambda c, o, s: policy_net.apply(params["policy"], c, o, s))(carry, *inputs)

        initial = jax.tree.map(lambda c: c[0], batch["carry"])  # each sequence's carry at its start
        _, out = jax.lax.scan(step, initial, (obs, batch["start"]))
    else:
        out = policy_net.apply(params["policy"], obs)
    loc, scale = distributions.split_params(out)
    log_prob = distributions.log_prob(loc, scale, batch["raw"])
    entropy = jnp.mean(distributions.entropy(loc, scale, jax.random.normal(key, loc.shape)))
    adv = losses.normalize_advantages(batch["advantages"]) if config.normalize_advantages else batch["advantages"]
    policy_loss, aux = losses.clipped_surrogate_loss(log_prob, batch["log_prob"], adv, config.clip_epsilon)
    values = value_net.apply(params["value"], value_obs)[..., 0]
    old_values = batch["values"] if config.value_clip_epsilon else None
    v_loss = losses.value_loss(values, batch["returns"], old_values, config.value_clip_epsilon)
    total = policy_loss + config.value_coef * v_loss - config.entropy_coef * entropy
    return total, {
        "loss/policy": policy_loss,
        "loss/value": v_loss,
        "loss/entropy": entropy,
        "loss/total": total,
        "loss/approx_kl": aux["approx_kl"],
        "loss/clip_fraction": aux["clip_fraction"],
    }


def rollout(config: Config, task: Task, train_state: TrainState, key: jax.Array):
    """Collects `unroll_length` steps of every env with the current sampling policy.

    Returns (collector to continue from, `learning.Transitions` [unroll_length,
    num_envs, ...], collection metrics). AMP rewrites the transitions' reward between
    this and `improve`.
    """
    act = acting(config, task, policy_params(train_state), deterministic=False)
    return learning.collect(task, act, train_state.collector, key, config.unroll_length)


def improve(
    config: Config, task: Task, train_state: TrainState, data: learning.Transitions, key: jax.Array
) -> tuple[TrainState, dict[str, jax.Array]]:
    """Learns from `data` (from `rollout`, rewards as given): the observation statistics,
    GAE from the value function, then `num_epochs` x `num_minibatches` clipped-surrogate
    steps. Returns the state with new params, optimizer state and statistics (its
    collector and key as given) and the learning metrics."""
    ts = train_state
    policy_net, value_net = _networks(config, task)
    stats = ts.obs_stats
    if config.normalize_observations:
        stats = normalization.update_stats(stats, data.obs, num_batch_dims=2)

    def value_of(obs):
        return value_net.apply(ts.params["value"], _inputs(config, stats, obs)[1])[..., 0]

    values = value_of(data.obs)
    adv, returns = learning.gae(
        data.reward * config.reward_scaling,
        values,
        value_of(data.next_obs),
        data.terminated,
        data.truncated,
        config.discount,
        config.gae_lambda,
    )
    batch = {
        "obs": data.obs,
        "start": data.start,
        **data.extras,
        "advantages": adv,
        "returns": returns,
        "values": values,
    }

    optimizer = _optimizer(config)
    grad_fn = jax.grad(lambda p, b, k: _loss(config, task, p, stats, b, k), has_aux=True)

    def sgd_step(carry, minibatch):
        params, opt_state, key = carry
        key, entropy_key = jax.random.split(key)
        grads, metrics = grad_fn(params, minibatch, entropy_key)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return (optax.apply_updates(params, updates), opt_state, key), metrics

    shuffle_key, entropy_key = jax.random.split(key)
    (params, opt_state, _), metrics = learning.learn(
        sgd_step,
        (ts.params, ts.opt_state, entropy_key),
        batch,
        shuffle_key,
        num_epochs=config.num_epochs,
        num_minibatches=config.num_minibatches,
        sequences=_is_recurrent(policy_net),
        split_over_devices=config.split_minibatches,
    )
    return ts.replace(params=params, opt_state=opt_state, obs_stats=stats), metrics


def update(config: Config, task: Task, train_state: TrainState) -> tuple[TrainState, dict[str, jax.Array]]:
    """One PPO update, `rollout` then `improve`. Jit it with `config` static; `task` and
    `train_state` are ordinary arguments."""
    key, collect_key, learn_key = jax.random.split(train_state.key, 3)
    collector, data, collect_metrics = rollout(config, task, train_state, collect_key)
    ts = train_state.replace(collector=collector, key=key, updates=train_state.updates + 1)
    ts, learn_metrics = improve(config, task, ts, data, learn_key)
    return ts, {**collect_metrics, **learn_metrics}


# --- evaluate and train -------------------------------------------------------------


def evaluate(
    config: Config, task: Task, train_state: TrainState, key: jax.Array, num_envs: int, num_steps: int | None = None
):
    """Deterministic episodes (`learning.evaluate` of the mean action): the mean return
    of the first episode of `num_envs` envs over at most `num_steps` steps (static;
    None: the task's own episode length, read on the host), and env 0's trajectory.

    Returns (mean return, per-env returns [num_envs], Trajectory of env 0 [num_steps]).
    """
    act = acting(config, task, policy_params(train_state), deterministic=True)
    carry = _initial_carry(_networks(config, task)[0])
    returns, _, trajectory = learning.evaluate(task, act, key, num_envs, num_steps, carry)
    return jnp.mean(returns), returns, trajectory


def train(config: Config, task: Task, settings: training.Settings | None = None, **settings_kwargs):
    """Trains with the shared harness (`mjzoo.harness.training.run`): jitted chunks of updates,
    evaluation, metrics.jsonl / TensorBoard, checkpoints, curves and a video when
    `settings.out_dir` is set. Returns (final TrainState, last metrics)."""
    settings = settings or training.Settings(**settings_kwargs)
    return training.run(sys.modules[__name__], config, task, settings)
