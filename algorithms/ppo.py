"""Proximal Policy Optimization on any `mjzoo.Task`.

    config, hyperparams = ppo.configure(num_envs=256, total_steps=2_000_000, learning_rate=1e-3)
    state, metrics = jax.jit(ppo.train, static_argnums=0)(config, task, hyperparams, key)  # a whole run
    act = ppo.policy(config, task)                 # deployable: act(params, obs, key)
    act(ppo.policy_params(state), obs, key)

    algo = ppo.make(config)                        # the same as a value the harness drives
    mjzoo.harness.training.run(algo, task, Settings(out_dir="runs/x"), hyperparams)

`Config` is the structure (static, hashable); `Hyperparams` every number a user may sweep
(a pytree: `jax.vmap` of `train` over a batch of them is one program). `init` stores the
hyperparameters in the `TrainState`, and `update` reads them there.

`update` is one jit: `collect` (`learning.collect`) runs `unroll_length` steps of
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
import types
import warnings
from collections.abc import Callable
from typing import Any
from typing import Literal
from typing import Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax

from mjzoo import checks
from mjzoo import learning
from mjzoo import tree
from mjzoo.learning import distributions
from mjzoo.learning import hyperparams as hyperparams_lib
from mjzoo.learning import losses
from mjzoo.learning import networks
from mjzoo.learning import normalization
from mjzoo.learning import reward_scaling as reward_scaling_lib
from mjzoo.learning import schedules
from mjzoo.learning import value_normalization as value_norm
from mjzoo.learning.algorithm import Algorithm
from mjzoo.learning.algorithm import TrainingWarning
from mjzoo.learning.guards import skip_non_finite_update
from mjzoo.learning.hyperparams import INF
from mjzoo.types import Task

__all__ = [
    "Batch",
    "Components",
    "Config",
    "PLAIN",
    "Extras",
    "Hyperparams",
    "TrainState",
    "acting",
    "configure",
    "value",
    "value_params",
    "evaluate",
    "improve",
    "init",
    "make",
    "policy",
    "policy_params",
    "collect",
    "train",
    "update",
]

Array = jax.Array
LR_SCHEDULES = ("constant", "linear", "cosine", "adaptive", "adaptive_update")
VALUE_NORMALIZATIONS = ("none", "running", "popart")
# `Config` fields of PPO without its stability switches: its defaults before them, and
# Brax's PPO (`interop.playground`'s translation of Brax's configs pins them).
PLAIN = types.MappingProxyType(
    {"lr_schedule": "constant", "value_normalization": "none", "reward_normalization": False}
)
ACTIVATIONS = {"swish": jax.nn.swish, "tanh": jnp.tanh, "relu": jax.nn.relu, "elu": jax.nn.elu}


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config:
    """PPO's structure: sizes, network shapes, what is normalized, the learning rate
    schedule's kind (static under jit; hashable). The numbers are `Hyperparams`."""

    num_envs: int = 256
    unroll_length: int = 32
    num_minibatches: int = 8
    num_epochs: int = 4
    # The learning rate's schedule: a shape that multiplies Hyperparams.learning_rate over
    # the run's steps, or "adaptive": raised or lowered at every minibatch step by the
    # measured approximate KL against Hyperparams.target_kl (rsl_rl's schedule), or
    # "adaptive_update": the same rule once per update, on the update's mean KL (one
    # minibatch's KL is noisy, and 32 steps can move the rate 1.5^32-fold). The
    # defaults of this and the two normalizations below were chosen by measurement
    # (benchmarks/ppo_stability.py; docs/sweeps.md): on Playground's CheetahRun they took
    # 3 seeds from 534 +- 170 to 889 +- 4, and with rewards x100 from 353 to 844. `PLAIN`
    # switches all three off.
    lr_schedule: Literal["constant", "linear", "cosine", "adaptive", "adaptive_update"] = "adaptive"
    # The entropy coefficient's decay from Hyperparams.entropy_coef to final_entropy_coef.
    entropy_schedule: Literal["constant", "linear", "cosine"] = "constant"
    # The value function's targets: as they are ("none"), in units of their running
    # mean and spread ("running"), or so and with PopArt's rescaling of the value head,
    # which keeps its outputs when the statistics move ("popart"; needs the default value
    # network or an mlp-shaped one: `init` says so of another).
    value_normalization: Literal["none", "running", "popart"] = "popart"
    # Rewards divided by the running spread of each env's discounted return.
    reward_normalization: bool = True
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
    # function on privileged state; "outer/inner" for an entry of a nested dict). None:
    # the whole observation, which must be an array.
    policy_obs_key: str | None = None
    value_obs_key: str | None = None
    total_steps: int = 1_000_000

    def __post_init__(self):
        counts = ("num_envs", "unroll_length", "num_minibatches", "num_epochs", "total_steps", "gru_hidden_size")
        checks.fields("ppo.Config", self, {f: (checks.is_count(getattr(self, f)), "an integer >= 1") for f in counts})
        switches = (
            "normalize_observations",
            "normalize_advantages",
            "reward_normalization",
            "split_minibatches",
            "recurrent",
        )
        checks.fields("ppo.Config", self, {f: (isinstance(getattr(self, f), bool), "True or False") for f in switches})
        steps = self.num_envs * self.unroll_length
        divides = steps % self.num_minibatches == 0 and (
            not self.recurrent or self.num_envs % self.num_minibatches == 0
        )
        checks.fields(
            "ppo.Config",
            self,
            {
                "num_minibatches": (
                    divides,
                    f"a divisor of num_envs * unroll_length = {steps}"
                    + (" and of num_envs (recurrent minibatches split whole sequences)" if self.recurrent else ""),
                ),
                "lr_schedule": (self.lr_schedule in LR_SCHEDULES, ", ".join(LR_SCHEDULES)),
                "entropy_schedule": (
                    self.entropy_schedule in schedules.ENTROPY_SCHEDULES,
                    ", ".join(schedules.ENTROPY_SCHEDULES),
                ),
                "value_normalization": (
                    self.value_normalization in VALUE_NORMALIZATIONS,
                    ", ".join(VALUE_NORMALIZATIONS),
                ),
                "activation": (self.activation in ACTIVATIONS, f"one of {sorted(ACTIVATIONS)}"),
                "compute_dtype": (self.compute_dtype in ("float32", "bfloat16"), "float32 or bfloat16"),
            },
        )
        if self.total_steps < self.steps_per_update:  # a run is whole updates: this one is one, larger
            warnings.warn(
                f"ppo.Config: total_steps={self.total_steps} is less than one update (num_envs x "
                f"unroll_length = {self.steps_per_update} env steps); the run trains that one update",
                TrainingWarning,
                stacklevel=3,
            )

    @property
    def steps_per_update(self) -> int:
        return self.num_envs * self.unroll_length

    @property
    def num_updates(self) -> int:
        return max(1, self.total_steps // self.steps_per_update)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams:
    """PPO's numbers: a pytree of scalars (or of [n] batches of them, to sweep under
    `jax.vmap`). `init` stores them in the train state; changing one never recompiles.
    `value_clip_epsilon`, `max_grad_norm` and `max_kl` switch off at inf (the defaults:
    no value clipping; clipping gradients at norm 1; no early stop), a number to sweep."""

    learning_rate: float | Array = 3e-4  # the schedule's base rate (Config.lr_schedule), or the adaptive one's start
    target_kl: float | Array = 0.01  # the KL the adaptive schedule steers to
    max_learning_rate: float | Array = 1e-2  # the adaptive schedule's ceiling (rsl_rl's)
    max_kl: float | Array = INF  # an update's remaining minibatch steps are skipped once a step's KL exceeds it
    entropy_coef: float | Array = 1e-2  # at the start of the run (Config.entropy_schedule)
    final_entropy_coef: float | Array = 0.0  # at its end, for a decaying schedule
    value_coef: float | Array = 0.5
    clip_epsilon: float | Array = 0.2
    value_clip_epsilon: float | Array = INF  # inf: the value loss unclipped
    discount: float | Array = 0.99
    gae_lambda: float | Array = 0.95
    reward_scaling: float | Array = 1.0
    max_grad_norm: float | Array = 1.0  # inf: gradients unclipped

    def __post_init__(self):
        checks.ranges("ppo.Hyperparams", self, HYPERPARAM_RANGES)

    def replace(self, **changes) -> Hyperparams:
        return dataclasses.replace(self, **changes)


HYPERPARAM_RANGES = {
    "learning_rate": (0.0, INF, "()"),
    "target_kl": (0.0, INF, "()"),
    "max_learning_rate": (0.0, INF, "()"),
    "max_kl": (0.0, INF, "(]"),
    "entropy_coef": (0.0, INF, "[)"),
    "final_entropy_coef": (0.0, INF, "[)"),
    "value_coef": (0.0, INF, "[)"),
    "clip_epsilon": (0.0, INF, "()"),
    "value_clip_epsilon": (0.0, INF, "(]"),
    "discount": (0.0, 1.0, "[]"),
    "gae_lambda": (0.0, 1.0, "[]"),
    "reward_scaling": (0.0, INF, "()"),
    "max_grad_norm": (0.0, INF, "(]"),
}
OFF_AT_INF = ("value_clip_epsilon", "max_grad_norm", "max_kl")  # None in a flat dict means inf (off)


def configure(**fields: Any) -> tuple[Config, Hyperparams]:
    """(Config, Hyperparams) from one flat dict of field values (a registry's, `--config
    k=v`, a config.json's): each name goes where it belongs. Unknown names and bad values
    are a ValueError naming them.

        config, hyperparams = ppo.configure(num_envs=64, learning_rate=1e-3)
    """
    names = hyperparams_lib.field_names
    config, hyper = hyperparams_lib.split_fields("ppo.configure", names(Config), names(Hyperparams), fields, OFF_AT_INF)
    return Config(**config), Hyperparams(**hyper)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrainState:
    """Everything training needs to continue exactly: a checkpoint saves this.

    `collector` holds the per-env leaves ([num_envs, ...]): env states, recurrent policy
    carries and running episode returns (`learning.Collector`). `hyperparams` are the
    numbers `update` learns with (float32 leaves). The statistics of the value targets
    and of the discounted returns, and the adaptive learning rate, are kept whatever the
    Config uses (scalars, and [num_envs] returns): one structure for every Config.
    """

    params: dict[str, Any]  # {"policy": ..., "value": ...}
    opt_state: Any
    obs_stats: normalization.RunningStats
    value_stats: normalization.RunningStats  # scalar: the value targets' (Config.value_normalization)
    reward_scaling: reward_scaling_lib.RewardScaling  # Config.reward_normalization's
    learning_rate: jax.Array  # float32 scalar: where the adaptive schedule has steered the rate
    collector: learning.Collector
    key: jax.Array
    updates: jax.Array  # int32 count of updates done
    hyperparams: Hyperparams

    def replace(self, **changes) -> TrainState:
        return dataclasses.replace(self, **changes)


PER_ENV_FIELDS = (
    "collector",
    "reward_scaling.discounted_return",
)  # a driver may shard these over devices (`Algorithm.per_env_fields`)


class Components(NamedTuple):
    """A user's own pieces (any JAX library); None: PPO's default of the Config.

    Attributes:
      policy_network: an (init, apply) pair (`learning.Network` or `RecurrentNetwork`)
        whose output is [2 * action_size] (mean, scale parameters).
      value_network: a `learning.Network` with output [1].
      optimizer: an optax `GradientTransformation`, used as it is (the hyperparameters
        learning_rate and max_grad_norm, and Config.lr_schedule, are then unused), or a
        function of the learning rate (e.g. `optax.sgd`), which gets the scheduled,
        traced rate and follows the gradient clipping at max_grad_norm. Default:
        `optax.adam`.
    """

    policy_network: networks.Network | networks.RecurrentNetwork | None = None
    value_network: networks.Network | None = None
    optimizer: optax.GradientTransformation | Callable[[Any], optax.GradientTransformation] | None = None


NO_COMPONENTS = Components()  # PPO's own networks and optimizer


class Extras(NamedTuple):
    """What the sampling policy records beside each action ([T, N, ...] once collected)."""

    raw: Array  # [action_size] the pre-tanh sample
    log_prob: Array  # [] its log-probability
    carry: Any  # the recurrent carry the step started from (() feed-forward)


class Batch(NamedTuple):
    """What the learner's minibatches are cut from: [T, N, ...] leaves."""

    obs: Any
    start: Array  # [T, N] bool, obs begins an episode
    extras: Extras
    advantages: Array  # [T, N]
    returns: Array  # [T, N] GAE's value targets, in the value head's units (normalized or not)
    values: Array  # [T, N] the value function's estimate when collected, in the same units


# --- networks and optimizer ---------------------------------------------------------


def _networks(config: Config, task: Task, components: Components = NO_COMPONENTS):
    activation = ACTIVATIONS[config.activation]
    dtype = jnp.dtype(config.compute_dtype)
    policy_net = components.policy_network
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
    value_net = components.value_network or networks.mlp(1, config.value_hidden_sizes, activation, compute_dtype=dtype)
    return policy_net, value_net


def _optimizer(
    config: Config, hyperparams: Hyperparams, components: Components = NO_COMPONENTS, adaptive_lr: Any = None
) -> optax.GradientTransformation:
    """The optimizer of these hyperparameters (traced or not), at the adaptive schedule's
    current rate `adaptive_lr` where it is used. Built afresh where it is used, as
    `optax.inject_hyperparams` rebuilds its inner one: its state's structure does not
    depend on the numbers, so init's state serves every value."""
    if isinstance(components.optimizer, optax.GradientTransformation):
        return components.optimizer
    steps = config.num_updates * config.num_epochs * config.num_minibatches
    shape = {
        "constant": optax.constant_schedule(1.0),
        "adaptive": optax.constant_schedule(1.0),
        "adaptive_update": optax.constant_schedule(1.0),
        "linear": optax.linear_schedule(1.0, 0.0, steps),
        "cosine": optax.cosine_decay_schedule(1.0, steps),
    }[config.lr_schedule]
    base = hyperparams.learning_rate if adaptive_lr is None else adaptive_lr

    def schedule(count: Array) -> Array:
        return base * shape(count)

    make = components.optimizer or optax.adam
    return optax.chain(optax.clip_by_global_norm(hyperparams.max_grad_norm), make(schedule))


def _view(obs: Any, key: str | None, field: str) -> Any:
    """The entry `key` of a dict observation (`policy_obs_key` / `value_obs_key`)."""
    if key is None:
        if isinstance(obs, dict):
            raise ValueError(
                f"ppo.Config: the observation is a dict with entries {sorted(obs)}; set {field} to "
                "the entry the network sees"
            )
        return obs
    entry = obs
    for part in key.split("/"):  # "outer/inner": a nested dict's entry
        if not isinstance(entry, dict) or part not in entry:
            found = sorted(entry) if isinstance(entry, dict) else f"an array of shape {jnp.shape(entry)}"
            raise ValueError(f"ppo.Config: {field}={key!r}, but the observation is {found}")
        entry = entry[part]
    return entry


def _inputs(config: Config, stats: normalization.RunningStats, obs: Any) -> tuple[Any, Any]:
    """(policy input, value input): the (normalized) observation's entries each network sees."""
    obs = normalization.normalize(stats, obs) if config.normalize_observations else obs
    return _view(obs, config.policy_obs_key, "policy_obs_key"), _view(obs, config.value_obs_key, "value_obs_key")


def _is_recurrent(net) -> bool:
    return isinstance(net, networks.RecurrentNetwork)


def _initial_carry(policy_net) -> Any:
    return policy_net.initial_carry() if _is_recurrent(policy_net) else ()


# --- init ---------------------------------------------------------------------------


@functools.partial(jax.jit, static_argnums=0, static_argnames="components")  # one compile: op by op took minutes
def init(
    config: Config, task: Task, hyperparams: Hyperparams, key: jax.Array, components: Components = NO_COMPONENTS
) -> TrainState:
    """A fresh train state: networks, optimizer, normalizer, `num_envs` reset envs, and
    `hyperparams`, which `update` reads from it."""
    policy_net, value_net = _networks(config, task, components)
    env_key, policy_key, value_key, key = jax.random.split(key, 4)
    collector = learning.Collector.create(task, env_key, config.num_envs, _initial_carry(policy_net))
    example = jax.tree.map(lambda x: x[0], collector.env_state.obs)
    stats = normalization.init_stats(example)
    policy_example, value_example = _inputs(config, stats, example)
    params = {"policy": policy_net.init(policy_key, policy_example), "value": value_net.init(value_key, value_example)}
    if config.value_normalization == "popart" and not _mlp_shaped(params["value"]):
        raise ValueError(
            "ppo.Config: value_normalization='popart' (the default) rescales the value network's output "
            "layer, which must be an mlp's params (a list ending in {'kernel', 'bias'}); this value_network's "
            f"are a {type(params['value']).__name__}: set value_normalization='running' (or 'none')"
        )
    hyperparams = hyperparams_lib.as_leaves(hyperparams)
    return TrainState(
        params=params,
        opt_state=_optimizer(config, hyperparams, components).init(params),
        obs_stats=stats,
        value_stats=value_norm.init_value_stats(),
        reward_scaling=reward_scaling_lib.init_reward_scaling(config.num_envs),
        learning_rate=hyperparams.learning_rate,
        collector=collector,
        key=key,
        updates=jnp.zeros((), jnp.int32),
        hyperparams=hyperparams,
    )


def _mlp_shaped(params: Any) -> bool:
    """Whether `params` are a list of layers ending in a Dense one, as PopArt needs."""
    last = params[-1] if isinstance(params, (list, tuple)) and params else None
    return isinstance(last, Mapping) and {"kernel", "bias"} <= set(last)


# --- acting -------------------------------------------------------------------------


def acting(
    config: Config,
    task: Task,
    params: dict[str, Any],
    deterministic: bool,
    components: Components = NO_COMPONENTS,
) -> learning.Actor:
    """The policy of `policy_params` for one env, as `learning.collect` and
    `learning.evaluate` take it: ``act(carry, obs, start, key) -> (carry, ctrl, extras)``,
    the carry () for a feed-forward network, `start` restarting a recurrent one. A sample
    records `Extras`: its pre-tanh value, its log-probability and the carry it started
    from (the learner's sequences begin there); the deterministic action is tanh of the
    mean, with no extras."""
    policy_net, _ = _networks(config, task, components)

    def act(carry, obs, start, key):
        obs, _ = _inputs(config, params["obs_stats"], obs)
        if _is_recurrent(policy_net):
            new_carry, out = policy_net.apply(params["policy"], carry, obs, start)
        else:
            new_carry, out = carry, policy_net.apply(params["policy"], obs)
        loc, scale = distributions.split_params(out)
        if deterministic:
            return new_carry, learning.to_controls(task, distributions.mode(loc)), ()
        action, raw = distributions.sample(loc, scale, key)
        extras = Extras(raw=raw, log_prob=distributions.log_prob(loc, scale, raw), carry=carry)
        return new_carry, learning.to_controls(task, action), extras

    return act


def policy_params(train_state: TrainState) -> dict[str, Any]:
    """What a deployed policy needs: the policy network and the observation statistics."""
    return {"policy": train_state.params["policy"], "obs_stats": train_state.obs_stats}


def policy(
    config: Config, task: Task, deterministic: bool = True, components: Components = NO_COMPONENTS
) -> Callable[[Any, Any, jax.Array], jax.Array]:
    """A deployable feed-forward policy ``(policy_params, obs, key) -> ctrl`` for one env.

    Deterministic: the mean action (tanh of the Gaussian's mean); else a sample.
    (Recurrent policies: use `evaluate`, which carries the hidden state.)
    """
    if _is_recurrent(_networks(config, task, components)[0]):
        raise ValueError("ppo.policy: a recurrent policy needs its carry; use ppo.evaluate or the network directly")

    def act(params, obs, key):
        return acting(config, task, params, deterministic, components)((), obs, jnp.ones((), bool), key)[1]

    return act


def value_params(config: Config, train_state: TrainState) -> dict[str, Any]:
    """What `value` needs: the value network, observation and value statistics, and `scale` [],
    learner reward units to the task's (1 / reward_scaling, x the return std normalization divided by)."""
    scale = 1.0 / train_state.hyperparams.reward_scaling
    if config.reward_normalization:
        scale = scale * jnp.sqrt(train_state.reward_scaling.return_stats.var + reward_scaling_lib.VAR_EPS)
    return {
        "value": train_state.params["value"],
        "obs_stats": train_state.obs_stats,
        "value_stats": train_state.value_stats,
        "scale": jnp.asarray(scale, jnp.float32),
    }


def value(
    config: Config, task: Task, components: Components = NO_COMPONENTS
) -> Callable[[dict[str, Any], Any], jax.Array]:
    """The learned value ``(value_params, obs) -> []`` of one observation, in the task's
    reward units: the discounted return the critic expects from there (a planner's
    terminal value, `mjzoo.planning.prior`)."""
    _, value_net = _networks(config, task, components)

    def value_of(params, obs):
        out = value_net.apply(params["value"], _inputs(config, params["obs_stats"], obs)[1])[..., 0]
        if config.value_normalization != "none":
            out = value_norm.denormalize_values(params["value_stats"], out)
        return out * params["scale"]

    return value_of


# --- update -------------------------------------------------------------------------


def _loss(
    config: Config,
    task: Task,
    components: Components,
    hp: Hyperparams,
    entropy_coef: Array,
    params,
    stats,
    batch: Batch,
    key,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """PPO loss on one minibatch: [T, n, ...] sequences (recurrent) or [n, ...] samples;
    `key` draws the entropy estimate's fresh sample. The value head's outputs and
    `batch.returns` / `batch.values` are in the same units (normalized or not)."""
    policy_net, value_net = _networks(config, task, components)
    obs, value_obs = _inputs(config, stats, batch.obs)
    if _is_recurrent(policy_net):

        def step(carry, inputs):  # over time, vmapped over the minibatch's envs
            return jax.vmap(lambda c, o, s: policy_net.apply(params["policy"], c, o, s))(carry, *inputs)

        initial = jax.tree.map(lambda c: c[0], batch.extras.carry)  # each sequence's carry at its start
        _, out = jax.lax.scan(step, initial, (obs, batch.start))
    else:
        out = policy_net.apply(params["policy"], obs)
    loc, scale = distributions.split_params(out)
    log_prob = distributions.log_prob(loc, scale, batch.extras.raw)
    entropy = jnp.mean(distributions.entropy(loc, scale, jax.random.normal(key, loc.shape)))
    adv = losses.normalize_advantages(batch.advantages) if config.normalize_advantages else batch.advantages
    policy_loss, aux = losses.clipped_surrogate_loss(log_prob, batch.extras.log_prob, adv, hp.clip_epsilon)
    values = value_net.apply(params["value"], value_obs)[..., 0]
    # inf switches clipping off: the unclipped loss exactly (the clipped one, old + (v - old), rounds).
    clipped = losses.value_loss(values, batch.returns, batch.values, hp.value_clip_epsilon)
    v_loss = jnp.where(jnp.isinf(hp.value_clip_epsilon), losses.value_loss(values, batch.returns), clipped)
    total = policy_loss + hp.value_coef * v_loss - entropy_coef * entropy
    return total, {
        "loss/policy": policy_loss,
        "loss/value": v_loss,
        "loss/entropy": entropy,
        "loss/total": total,
        "loss/approx_kl": aux["approx_kl"],
        "loss/clip_fraction": aux["clip_fraction"],
    }


def collect(
    config: Config, task: Task, train_state: TrainState, key: jax.Array, components: Components = NO_COMPONENTS
):
    """Collects `unroll_length` steps of every env with the current sampling policy.

    Returns (collector to continue from, `learning.Transitions` [unroll_length,
    num_envs, ...] with `Extras`, collection metrics). AMP rewrites the transitions'
    reward between this and `improve`.
    """
    act = acting(config, task, policy_params(train_state), False, components)
    return learning.collect(task, act, train_state.collector, key, config.unroll_length)


def improve(
    config: Config,
    task: Task,
    train_state: TrainState,
    data: learning.Transitions,
    key: jax.Array,
    components: Components = NO_COMPONENTS,
) -> tuple[TrainState, dict[str, jax.Array]]:
    """Learns from `data` (from `collect`, rewards as given) with the state's
    hyperparameters: the observation statistics, the rewards (scaled, and normalized
    where the Config says), GAE from the value function, the value targets' statistics,
    then `num_epochs` x `num_minibatches` clipped-surrogate steps. A step whose loss,
    gradients or results are not finite is dropped ("loss/skipped_steps"); once a step
    measures a KL above `max_kl`, the update's remaining steps are ("loss/kl_stopped").
    Returns the state with new params, optimizer state, statistics and rate (its
    collector and key as given) and the learning metrics."""
    ts, hp = train_state, train_state.hyperparams
    policy_net, value_net = _networks(config, task, components)
    stats = ts.obs_stats
    if config.normalize_observations:
        stats = normalization.update_stats(stats, data.obs, num_batch_dims=2)

    rewards, reward_scaling = data.reward * hp.reward_scaling, ts.reward_scaling
    if config.reward_normalization:
        ended = data.terminated | data.truncated
        reward_scaling = reward_scaling_lib.update_reward_scaling(reward_scaling, rewards, ended, hp.discount)
        rewards = reward_scaling_lib.scale_rewards(reward_scaling, rewards)

    normalized = config.value_normalization != "none"

    def value_of(obs):  # in the units of `rewards`
        out = value_net.apply(ts.params["value"], _inputs(config, stats, obs)[1])[..., 0]
        return value_norm.denormalize_values(ts.value_stats, out) if normalized else out

    values = value_of(data.obs)
    adv, returns = learning.gae(
        rewards, values, value_of(data.next_obs), data.terminated, data.truncated, hp.discount, hp.gae_lambda
    )
    params, value_stats = ts.params, ts.value_stats
    if normalized:  # the value head learns (returns - mean) / std, and its old values read alike
        value_stats = value_norm.update_value_stats(value_stats, returns)
        if config.value_normalization == "popart":
            head = value_norm.popart_rescale(params["value"][-1], ts.value_stats, value_stats)
            params = {**params, "value": [*params["value"][:-1], head]}
        returns, values = (
            value_norm.normalize_values(value_stats, returns),
            value_norm.normalize_values(value_stats, values),
        )
    batch = Batch(obs=data.obs, start=data.start, extras=data.extras, advantages=adv, returns=returns, values=values)

    progress = (ts.updates - 1).astype(jnp.float32) / config.num_updates  # done before this update (`update` counts it)
    entropy_coef = schedules.entropy_coef_schedule(
        config.entropy_schedule, progress, hp.entropy_coef, hp.final_entropy_coef
    )
    grad_fn = jax.grad(lambda p, b, k: _loss(config, task, components, hp, entropy_coef, p, stats, b, k), has_aux=True)
    adaptive = config.lr_schedule in ("adaptive", "adaptive_update")
    every_step = config.lr_schedule == "adaptive"

    def sgd_step(carry, minibatch):
        params, opt_state, key, lr, stopped = carry
        key, entropy_key = jax.random.split(key)
        grads, metrics = grad_fn(params, minibatch, entropy_key)
        kl = metrics["loss/approx_kl"]  # at the params this step starts from
        lr = schedules.kl_adaptive_lr(lr, kl, hp.target_kl, max_lr=hp.max_learning_rate) if every_step else lr
        stopped = schedules.kl_early_stop(stopped, kl, hp.max_kl)
        optimizer = _optimizer(config, hp, components, lr if adaptive else None)
        updates, new_opt_state = optimizer.update(grads, opt_state, params)
        new_params, new_opt_state, skipped = skip_non_finite_update(
            optax.apply_updates(params, updates), new_opt_state, params, opt_state, grads, metrics["loss/total"]
        )
        params, opt_state = schedules.skip_when_stopped(stopped, (params, opt_state), (new_params, new_opt_state))
        dropped = {"loss/skipped_steps": skipped.astype(jnp.float32), "loss/kl_stopped": stopped.astype(jnp.float32)}
        metrics = {**metrics, **dropped}
        return (params, opt_state, key, lr, stopped), metrics

    shuffle_key, entropy_key = jax.random.split(key)
    (params, opt_state, _, lr, _), metrics = learning.learn(
        sgd_step,
        (params, ts.opt_state, entropy_key, ts.learning_rate, jnp.zeros((), bool)),
        batch,
        shuffle_key,
        num_epochs=config.num_epochs,
        num_minibatches=config.num_minibatches,
        sequences=_is_recurrent(policy_net),
        split_over_devices=config.split_minibatches,
    )
    if config.lr_schedule == "adaptive_update":  # for the next update, by this one's mean KL
        lr = schedules.kl_adaptive_lr(lr, metrics["loss/approx_kl"], hp.target_kl, max_lr=hp.max_learning_rate)
    if adaptive:
        metrics["learning_rate"] = lr
    if config.entropy_schedule != "constant":
        metrics["loss/entropy_coef"] = entropy_coef
    # A batch with a NaN or inf in it must not poison the statistics every later update reads.
    stats, value_stats, reward_scaling = _finite_or(
        (ts.obs_stats, ts.value_stats, ts.reward_scaling), (stats, value_stats, reward_scaling)
    )
    new_state = ts.replace(
        params=params,
        opt_state=opt_state,
        obs_stats=stats,
        value_stats=value_stats,
        reward_scaling=reward_scaling,
        learning_rate=lr,
    )
    return new_state, metrics


def _finite_or(old: Any, new: Any) -> Any:
    """`new` where every one of its inexact leaves is finite, else `old`."""
    return tree.where(tree.all_finite(new), new, old)


def update(
    config: Config, task: Task, train_state: TrainState, components: Components = NO_COMPONENTS
) -> tuple[TrainState, dict[str, jax.Array]]:
    """One PPO update, `collect` then `improve`, with the state's hyperparameters. Jit it
    with `config` (and `components`) static; `task` and `train_state` are ordinary
    arguments."""
    key, collect_key, learn_key = jax.random.split(train_state.key, 3)
    collector, data, collect_metrics = collect(config, task, train_state, collect_key, components)
    ts = train_state.replace(collector=collector, key=key, updates=train_state.updates + 1)
    ts, learn_metrics = improve(config, task, ts, data, learn_key, components)
    return ts, {**collect_metrics, **learn_metrics}


# --- evaluate, train, make ----------------------------------------------------------


def evaluate(
    config: Config,
    task: Task,
    train_state: TrainState,
    key: jax.Array,
    num_envs: int,
    num_steps: int | None = None,
    components: Components = NO_COMPONENTS,
) -> learning.Evaluation:
    """Deterministic episodes: `learning.evaluate` of the mean action, scoring the first
    episode of `num_envs` envs over at most `num_steps` steps (static; None: the task's
    own episode length, read on the host).

    Returns `learning.Evaluation`: returns [num_envs], lengths [num_envs], env 0's
    Trajectory [num_steps].
    """
    act = acting(config, task, policy_params(train_state), True, components)
    carry = _initial_carry(_networks(config, task, components)[0])
    return learning.evaluate(task, act, key, num_envs, num_steps, carry)


def train(
    config: Config, task: Task, hyperparams: Hyperparams, key: jax.Array, components: Components = NO_COMPONENTS
) -> tuple[TrainState, dict[str, jax.Array]]:
    """A whole run: `init`, then `config.num_updates` `update`s in one `lax.scan` (as
    purejaxrl's make_train). Jit it with `config` static; vmap it over hyperparameters
    and keys to sweep them in one program:

        rates = jnp.array([1e-4, 3e-4])  # every leaf batched [2]: the defaults repeated, the rates swept
        hps = jax.tree.map(lambda x: jnp.full(2, x), ppo.Hyperparams()).replace(learning_rate=rates)
        run = jax.jit(jax.vmap(lambda hp, key: ppo.train(config, task, hp, key)))
        states, metrics = run(hps, jax.random.split(key, 2))  # docs/sweeps.md

    Returns (final TrainState, per-update metrics, each [num_updates]). With files on
    disk, progress, evaluation and checkpoints: `mjzoo.harness.training.run(ppo.make(config), ...)`.
    """
    state = init(config, task, hyperparams, key, components=components)

    def body(state, _):
        return update(config, task, state, components)

    return jax.lax.scan(body, state, None, length=config.num_updates)


# One value per (config, pieces): the harness caches compiles by the value's functions, so
# two runs of equal settings in one process share them.
@functools.lru_cache(maxsize=32)
def make(
    config: Config,
    *,
    policy_network: networks.Network | networks.RecurrentNetwork | None = None,
    value_network: networks.Network | None = None,
    optimizer: optax.GradientTransformation | Callable[[Any], optax.GradientTransformation] | None = None,
) -> Algorithm:
    """PPO as a value (`mjzoo.learning.Algorithm`): this module's functions with `config`
    and the user's pieces (`Components`) bound, default `Hyperparams()`."""
    components = Components(policy_network, value_network, optimizer)
    return Algorithm(
        name="ppo",
        config=config,
        hyperparams=Hyperparams(),
        init=lambda task, hyperparams, key: init(config, task, hyperparams, key, components=components),
        update=lambda task, state: update(config, task, state, components),
        evaluate=lambda task, state, key, num_envs, num_steps=None: evaluate(
            config, task, state, key, num_envs, num_steps, components
        ),
        policy=lambda task, deterministic=True: policy(config, task, deterministic, components),
        policy_params=policy_params,
        steps_per_update=config.steps_per_update,
        num_updates=config.num_updates,
        per_env_fields=PER_ENV_FIELDS,
    )
