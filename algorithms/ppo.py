"""Proximal Policy Optimization on any `mjzoo.Task`.

    config = ppo.Config(num_envs=256, total_steps=2_000_000)
    state = ppo.init(config, task, jax.random.key(0))
    state, metrics = jax.jit(ppo.update, static_argnums=0)(config, task, state)
    act = ppo.policy(config, task)                 # deployable: act(params, obs, key)
    act(ppo.policy_params(state), obs, key)

`update` is one jit: collect `unroll_length` steps from `num_envs` auto-resetting envs,
then `num_epochs` x `num_minibatches` clipped-surrogate updates. The pieces (GAE,
losses, observation normalization, networks, the squashed Gaussian) live in lib/.
Actions are sampled in [-1, 1] (tanh) and mapped affinely onto the actuators'
ctrlrange. GAE bootstraps truncated episodes from their true final observation.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
from typing import Any, Callable, Literal

import jax
import jax.numpy as jnp
import numpy as np
import optax

import mjzoo
from mjzoo.learning import advantages, distributions, losses, networks, normalization
from mjzoo.harness import training
from mjzoo.types import State, Task

__all__ = ["Config", "TrainState", "init", "update", "train", "policy", "policy_params", "evaluate"]

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
    recurrent: bool = False
    gru_hidden_size: int = 64
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
        need((self.num_envs * self.unroll_length) % self.num_minibatches == 0, "num_minibatches",
             f"a divisor of num_envs * unroll_length = {self.num_envs * self.unroll_length}")  # fmt: skip
        need(not self.recurrent or self.num_envs % self.num_minibatches == 0, "num_minibatches",
             "a divisor of num_envs (recurrent minibatches split whole sequences)")  # fmt: skip
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

    Per-env leaves ([num_envs, ...]): env_state, carry, episode_return, episode_length.
    """

    params: dict[str, Any]  # {"policy": ..., "value": ...}
    opt_state: Any
    obs_stats: normalization.RunningStats
    env_state: State
    carry: Any  # recurrent policy carry per env ([num_envs, hidden]); () if feed-forward
    episode_return: Array
    episode_length: Array
    key: Array
    updates: Array  # int32 count of updates done

    def replace(self, **changes) -> "TrainState":
        return dataclasses.replace(self, **changes)


# --- networks and optimizer ---------------------------------------------------------


def _networks(config: Config, task: Task):
    activation = ACTIVATIONS[config.activation]
    policy_net = config.policy_network
    if policy_net is None and config.recurrent:
        policy_net = networks.gru_mlp(2 * task.action_size, config.gru_hidden_size, config.policy_hidden_sizes,
                                      activation=activation, output_scale=0.01)  # fmt: skip
    elif policy_net is None:
        policy_net = networks.mlp(2 * task.action_size, config.policy_hidden_sizes, activation, output_scale=0.01)
    value_net = config.value_network or networks.mlp(1, config.value_hidden_sizes, activation)
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


def _is_recurrent(net) -> bool:
    return isinstance(net, networks.RecurrentNetwork)


def _to_ctrl(task: Task, action: Array) -> Array:
    """[-1, 1] actions onto each actuator's ctrlrange (unlimited actuators: unchanged)."""
    limited = np.asarray(task.mj_model.actuator_ctrllimited, bool)
    low, high = task.model.actuator_ctrlrange[:, 0], task.model.actuator_ctrlrange[:, 1]
    return jnp.where(limited, low + (action + 1.0) * 0.5 * (high - low), action)


# --- init ---------------------------------------------------------------------------


@functools.partial(jax.jit, static_argnums=0)  # one compile: resetting op by op took minutes on a GPU
def init(config: Config, task: Task, key: Array) -> TrainState:
    """A fresh train state: networks, optimizer, normalizer and `num_envs` reset envs."""
    policy_net, value_net = _networks(config, task)
    env_key, policy_key, value_key, key = jax.random.split(key, 4)
    env_state = jax.vmap(mjzoo.reset, in_axes=(None, 0))(
        mjzoo.with_auto_reset(task), jax.random.split(env_key, config.num_envs)
    )
    example = jax.tree.map(lambda x: x[0], env_state.obs)
    params = {"policy": policy_net.init(policy_key, example), "value": value_net.init(value_key, example)}
    carry = ()
    if _is_recurrent(policy_net):
        carry = jax.tree.map(lambda c: jnp.broadcast_to(c, (config.num_envs,) + c.shape), policy_net.initial_carry())
    return TrainState(
        params=params,
        opt_state=_optimizer(config).init(params),
        obs_stats=normalization.init_stats(example),
        env_state=env_state,
        carry=carry,
        episode_return=jnp.zeros((config.num_envs,), jnp.float32),
        episode_length=jnp.zeros((config.num_envs,), jnp.float32),
        key=key,
        updates=jnp.zeros((), jnp.int32),
    )


# --- acting -------------------------------------------------------------------------


def _policy_output(config, policy_net, params, obs_stats, carry, obs, reset):
    """(carry, network output) for one env; normalizes the observation first."""
    if config.normalize_observations:
        obs = normalization.normalize(obs_stats, obs)
    if _is_recurrent(policy_net):
        return policy_net.apply(params, carry, obs, reset)
    return carry, policy_net.apply(params, obs)


def policy_params(train_state: TrainState) -> dict[str, Any]:
    """What a deployed policy needs: the policy network and the observation statistics."""
    return {"policy": train_state.params["policy"], "obs_stats": train_state.obs_stats}


def policy(config: Config, task: Task, deterministic: bool = True) -> Callable[[Any, Any, Array], Array]:
    """A deployable feed-forward policy ``(policy_params, obs, key) -> ctrl`` for one env.

    Deterministic: the mean action (tanh of the Gaussian's mean); else a sample.
    (Recurrent policies: use `evaluate`, which carries the hidden state.)
    """
    policy_net, _ = _networks(config, task)
    if _is_recurrent(policy_net):
        raise ValueError("ppo.policy: a recurrent policy needs its carry; use ppo.evaluate or the network directly")

    def act(params, obs, key):
        _, out = _policy_output(config, policy_net, params["policy"], params["obs_stats"], (), obs, False)
        loc, scale = distributions.split_params(out)
        action = distributions.mode(loc) if deterministic else distributions.sample(loc, scale, key)[0]
        return _to_ctrl(task, action)

    return act


# --- collect ------------------------------------------------------------------------


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Rollout:
    """One unroll, every leaf [T, num_envs, ...]."""

    obs: Any  # the observation each action was chosen from
    next_obs: Any  # the true next observation (an episode's final one where it ended)
    starts: Array  # bool: obs begins a new episode (recurrent carries reset here)
    raw_action: Array  # pre-tanh sample, [T, N, A]
    log_prob: Array
    reward: Array
    terminated: Array
    truncated: Array


def _collect(config: Config, task: Task, ts: TrainState) -> tuple[TrainState, Rollout, dict[str, Array]]:
    policy_net, _ = _networks(config, task)
    env = mjzoo.with_auto_reset(task)
    params, stats = ts.params["policy"], ts.obs_stats
    act = jax.vmap(lambda c, o, s: _policy_output(config, policy_net, params, stats, c, o, s))
    to_ctrl = jax.vmap(lambda a: _to_ctrl(task, a))
    step_env = jax.vmap(mjzoo.transition, in_axes=(None, 0, 0, 0))

    def body(carry, key):
        env_state, pcarry, ep_return, ep_length = carry
        act_key, step_key = jax.random.split(key)
        starts = env_state.terminated | env_state.truncated
        pcarry, out = act(pcarry, env_state.obs, starts)
        loc, scale = distributions.split_params(out)
        action, raw = distributions.sample(loc, scale, act_key)
        next_state = step_env(env, env_state, to_ctrl(action), jax.random.split(step_key, config.num_envs))
        done = next_state.terminated | next_state.truncated
        ep_return, ep_length = ep_return + next_state.reward, ep_length + 1.0
        episode = {
            "episodes": jnp.sum(done),
            "return_sum": jnp.sum(jnp.where(done, ep_return, 0.0)),
            "length_sum": jnp.sum(jnp.where(done, ep_length, 0.0)),
            "metrics": jax.tree.map(jnp.mean, next_state.metrics),
        }
        rollout = Rollout(
            obs=env_state.obs,
            next_obs=next_state.info["auto_reset"]["final_obs"],
            starts=starts,
            raw_action=raw,
            log_prob=distributions.log_prob(loc, scale, raw),
            reward=next_state.reward,
            terminated=next_state.terminated,
            truncated=next_state.truncated,
        )
        carry = (next_state, pcarry, jnp.where(done, 0.0, ep_return), jnp.where(done, 0.0, ep_length))
        return carry, (rollout, episode)

    key, unroll_key = jax.random.split(ts.key)
    init = (ts.env_state, ts.carry, ts.episode_return, ts.episode_length)
    (env_state, carry, ep_return, ep_length), (rollout, episode) = jax.lax.scan(
        body, init, jax.random.split(unroll_key, config.unroll_length)
    )
    finished = jnp.sum(episode["episodes"])
    per_episode = lambda total: jnp.where(finished > 0, total / jnp.maximum(finished, 1), jnp.nan)  # noqa: E731
    metrics = {  # NaN where no episode ended in this unroll; the harness averages with nanmean
        "train/episode_return": per_episode(jnp.sum(episode["return_sum"])),
        "train/episode_length": per_episode(jnp.sum(episode["length_sum"])),
        "train/episodes": jnp.sum(episode["episodes"]).astype(jnp.float32),
        **{f"env/{k}": jnp.mean(v) for k, v in episode["metrics"].items()},
    }
    ts = ts.replace(env_state=env_state, carry=carry, episode_return=ep_return, episode_length=ep_length, key=key)
    return ts, rollout, metrics


# --- learn --------------------------------------------------------------------------


def _loss(config, policy_net, value_net, params, stats, initial_carry, batch):
    """PPO loss on one minibatch: [T, n, ...] sequences (recurrent) or [n, ...] samples."""
    obs = normalization.normalize(stats, batch["obs"]) if config.normalize_observations else batch["obs"]
    if _is_recurrent(policy_net):
        def step(carry, inputs):  # over time, vmapped over the minibatch's envs
            o, s = inputs
            return jax.vmap(lambda c, o, s: policy_net.apply(params["policy"], c, o, s))(carry, o, s)

        _, out = jax.lax.scan(step, initial_carry, (obs, batch["starts"]))
    else:
        out = policy_net.apply(params["policy"], obs)
    loc, scale = distributions.split_params(out)
    log_prob = distributions.log_prob(loc, scale, batch["raw_action"])
    entropy = jnp.mean(distributions.entropy(loc, scale, batch["raw_action"]))
    adv = losses.normalize_advantages(batch["advantages"]) if config.normalize_advantages else batch["advantages"]
    policy_loss, aux = losses.clipped_surrogate_loss(log_prob, batch["log_prob"], adv, config.clip_epsilon)
    values = value_net.apply(params["value"], obs)[..., 0]
    old_values = batch["values"] if config.value_clip_epsilon else None
    v_loss = losses.value_loss(values, batch["returns"], old_values, config.value_clip_epsilon)
    total = policy_loss + config.value_coef * v_loss - config.entropy_coef * entropy
    return total, {"loss/policy": policy_loss, "loss/value": v_loss, "loss/entropy": entropy,
                   "loss/total": total, "loss/approx_kl": aux["approx_kl"],
                   "loss/clip_fraction": aux["clip_fraction"]}  # fmt: skip


def _learn(config: Config, task: Task, ts: TrainState, rollout: Rollout, initial_carry) -> tuple[TrainState, dict]:
    policy_net, value_net = _networks(config, task)
    optimizer = _optimizer(config)
    stats = ts.obs_stats
    if config.normalize_observations:
        stats = normalization.update_stats(stats, rollout.obs, num_batch_dims=2)
    value_of = lambda obs: value_net.apply(  # noqa: E731
        ts.params["value"], normalization.normalize(stats, obs) if config.normalize_observations else obs
    )[..., 0]
    values, next_values = value_of(rollout.obs), value_of(rollout.next_obs)
    adv, returns = advantages.gae(
        rollout.reward * config.reward_scaling, values, next_values, rollout.terminated, rollout.truncated,
        config.discount, config.gae_lambda,
    )  # fmt: skip
    data = {"obs": rollout.obs, "starts": rollout.starts, "raw_action": rollout.raw_action,
            "log_prob": rollout.log_prob, "advantages": adv, "returns": returns, "values": values}  # fmt: skip
    grad_fn = jax.grad(lambda p, c, b: _loss(config, policy_net, value_net, p, stats, c, b), has_aux=True)
    recurrent = _is_recurrent(policy_net)
    m = config.num_minibatches

    def minibatches(key):
        """[m, ...] minibatches: whole env sequences (recurrent) or shuffled samples."""
        if recurrent:
            order = jax.random.permutation(key, config.num_envs).reshape(m, -1)
            batch = jax.tree.map(lambda x: jnp.moveaxis(x[:, order], 1, 0), data)  # [m, T, n, ...]
            return batch, jax.tree.map(lambda c: c[order], initial_carry)
        flat = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), data)
        order = jax.random.permutation(key, config.steps_per_update).reshape(m, -1)
        return jax.tree.map(lambda x: x[order], flat), jnp.zeros((m,))

    def sgd_step(carry, inputs):
        params, opt_state = carry
        batch, initial = inputs
        grads, metrics = grad_fn(params, initial, batch)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return (optax.apply_updates(params, updates), opt_state), metrics

    def epoch(carry, key):
        return jax.lax.scan(sgd_step, carry, minibatches(key))

    key, epoch_key = jax.random.split(ts.key)
    (params, opt_state), metrics = jax.lax.scan(
        epoch, (ts.params, ts.opt_state), jax.random.split(epoch_key, config.num_epochs)
    )
    ts = ts.replace(params=params, opt_state=opt_state, obs_stats=stats, key=key, updates=ts.updates + 1)
    return ts, jax.tree.map(jnp.mean, metrics)


def update(config: Config, task: Task, train_state: TrainState) -> tuple[TrainState, dict[str, Array]]:
    """One PPO update: collect an unroll from every env, then learn from it. Jit it with
    `config` static; `task` and `train_state` are ordinary arguments."""
    initial_carry = train_state.carry
    train_state, rollout, collect_metrics = _collect(config, task, train_state)
    train_state, learn_metrics = _learn(config, task, train_state, rollout, initial_carry)
    return train_state, {**collect_metrics, **learn_metrics}


# --- evaluate -----------------------------------------------------------------------


def evaluate(config: Config, task: Task, train_state: TrainState, key: Array, num_envs: int, num_steps: int):
    """Deterministic episodes: the mean return of the first episode of `num_envs` envs
    over at most `num_steps` steps (static), and the first env's trajectory (for video).

    Returns (mean return, per-env returns [num_envs], Trajectory of env 0 [num_steps]).
    """
    policy_net, _ = _networks(config, task)
    params, stats = train_state.params["policy"], train_state.obs_stats
    carry0 = policy_net.initial_carry() if _is_recurrent(policy_net) else ()

    def one(key):
        state = mjzoo.reset(task, key)

        def body(carry, key):
            state, pcarry, first = carry
            pcarry, out = _policy_output(config, policy_net, params, stats, pcarry, state.obs, first)
            action = distributions.mode(distributions.split_params(out)[0])
            next_state = mjzoo.transition(task, state, _to_ctrl(task, action), key)
            return (next_state, pcarry, jnp.zeros((), bool)), (state.obs, action, next_state)

        _, (obs, action, states) = jax.lax.scan(body, (state, carry0, jnp.ones((), bool)), jax.random.split(key, num_steps))
        done = states.terminated | states.truncated
        alive = (jnp.cumsum(done) - done) == 0  # up to and including the first episode end
        return jnp.sum(states.reward * alive), mjzoo.Trajectory(obs=obs, action=action, next_state=states)

    returns, trajectories = jax.vmap(one)(jax.random.split(key, num_envs))
    return jnp.mean(returns), returns, jax.tree.map(lambda x: x[0], trajectories)


def train(config: Config, task: Task, settings: "training.Settings | None" = None, **settings_kwargs):
    """Trains with the shared harness (`mjzoo.harness.training.run`): jitted chunks of updates,
    evaluation, metrics.jsonl / TensorBoard, checkpoints, curves and a video when
    `settings.out_dir` is set. Returns (final TrainState, last metrics)."""
    settings = settings or training.Settings(**settings_kwargs)
    return training.run(sys.modules[__name__], config, task, settings)
