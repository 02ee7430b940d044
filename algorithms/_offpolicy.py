"""What the replay-based learners (`sac`, `fast_td3`) share: twin critics, the replay
of parallel env steps they learn from, and filling it.

Both keep every env step of `num_envs` auto-resetting envs in a `learning.Replay` of
rows (`replay.sample_n_step` draws from it), with the action in [-1, 1] (what the
critics see) in place of the task's controls. The train state holds the whole buffer,
so a checkpoint resumes exactly (at the cost of its size on disk).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any
from typing import ClassVar
from typing import Literal

import jax
import jax.numpy as jnp
import optax

from mjzoo import checks
from mjzoo import learning
from mjzoo.algorithms.ppo import _view
from mjzoo.learning import networks
from mjzoo.learning import normalization
from mjzoo.learning import replay
from mjzoo.learning.algorithm import Algorithm
from mjzoo.types import Task

Array = jax.Array
PyTree = Any
ACTIVATIONS = {"relu": jax.nn.relu, "swish": jax.nn.swish, "elu": jax.nn.elu, "tanh": jnp.tanh}


@dataclasses.dataclass(frozen=True, kw_only=True)
class ReplayConfig:
    """The structure every replay learner shares (its Config adds its own fields and
    may change these defaults); static under jit, hashable."""

    WHO: ClassVar[str] = "Config"  # the name its errors give
    num_envs: int = 16
    unroll_length: int = 1  # env steps of every env per update
    gradient_steps: int = 1  # critic steps per update
    batch_size: int = 256
    buffer_size: int = 1_000_000  # transitions kept (rows of num_envs steps)
    n_steps: int = 1  # the TD target's window (`replay.sample_n_step`)
    learning_starts: int = 5_000  # env steps of uniform actions before learning
    policy_hidden_sizes: tuple[int, ...] = (256, 256)
    critic_hidden_sizes: tuple[int, ...] = (256, 256)
    activation: Literal["relu", "swish", "elu", "tanh"] = "relu"
    layer_norm: bool = False  # in the critics' hidden layers
    # "bfloat16": mixed precision in the hidden layers (params, output layers, gradients
    # and the optimizer stay float32): the large critics' matmuls bound a big-batch update.
    compute_dtype: Literal["float32", "bfloat16"] = "float32"
    normalize_observations: bool = False
    # A dict observation: the entry each network sees ("outer/inner" nests); None: all of it.
    policy_obs_key: str | None = None
    critic_obs_key: str | None = None
    total_steps: int = 1_000_000

    def __post_init__(self):
        counts = ("num_envs", "unroll_length", "gradient_steps", "batch_size", "buffer_size", "n_steps", "total_steps")
        checks.fields(self.WHO, self, {f: (checks.is_count(getattr(self, f)), "an integer >= 1") for f in counts})
        switches = ("layer_norm", "normalize_observations")
        checks.fields(self.WHO, self, {f: (isinstance(getattr(self, f), bool), "True or False") for f in switches})
        checks.fields(
            self.WHO,
            self,
            {
                "learning_starts": (checks.is_count(self.learning_starts + 1), "an integer >= 0"),
                "activation": (self.activation in ACTIVATIONS, f"one of {sorted(ACTIVATIONS)}"),
                "compute_dtype": (self.compute_dtype in ("float32", "bfloat16"), "float32 or bfloat16"),
            },
        )

    @property
    def steps_per_update(self) -> int:
        return self.num_envs * self.unroll_length

    @property
    def num_updates(self) -> int:
        return max(1, self.total_steps // self.steps_per_update)


def actor_critic(config: ReplayConfig, policy_size: int, critic_size: int) -> tuple[networks.Network, networks.Network]:
    """The policy MLP ([..., policy_size] out) and the twin critics ([2, ..., critic_size]
    out) of `config`'s sizes, activation and arithmetic; layer norm in the critics if asked."""
    activation, dtype = ACTIVATIONS[config.activation], jnp.dtype(config.compute_dtype)
    policy_net = networks.mlp(policy_size, config.policy_hidden_sizes, activation, compute_dtype=dtype)
    critic = networks.mlp(
        critic_size, config.critic_hidden_sizes, activation, compute_dtype=dtype, layer_norm=config.layer_norm
    )
    return policy_net, twin(critic)


def twin(network: networks.Network) -> networks.Network:
    """Two independently initialized copies of `network`: params stacked [2, ...],
    apply ``(params, x) -> [2, ..., out]``."""

    def init(key: Array, example: Array) -> PyTree:
        return jax.vmap(network.init, in_axes=(0, None))(jax.random.split(key, 2), example)

    def apply(params: PyTree, x: Array) -> Array:
        return jax.vmap(network.apply, in_axes=(0, None))(params, x)

    return networks.Network(init=init, apply=apply)


def inputs(config: Any, stats: normalization.RunningStats, obs: PyTree) -> tuple[Array, Array]:
    """(policy input, critic input): the (normalized) observation's entries each sees."""
    obs = normalization.normalize(stats, obs) if config.normalize_observations else obs
    return _view(obs, config.policy_obs_key, "policy_obs_key"), _view(obs, config.critic_obs_key, "critic_obs_key")


def optimizer(learning_rate: Array, max_grad_norm: Array, weight_decay: Array = 0.0) -> optax.GradientTransformation:
    """Adam(W) after clipping at `max_grad_norm` (inf: unclipped); numbers may be traced."""
    return optax.chain(optax.clip_by_global_norm(max_grad_norm), optax.adamw(learning_rate, weight_decay=weight_decay))


def empty_replay(collector: learning.Collector, action_size: int, capacity: int) -> replay.Replay:
    """A buffer of `capacity` rows of every env's step, shaped like `collector`'s envs."""
    obs = collector.env_state.obs
    num_envs = collector.start.shape[0]
    row = learning.Transitions(
        obs=obs,
        action=jnp.zeros((num_envs, action_size), jnp.float32),
        extras=(),
        reward=jnp.zeros((num_envs,), jnp.float32),
        terminated=jnp.zeros((num_envs,), bool),
        truncated=jnp.zeros((num_envs,), bool),
        start=jnp.zeros((num_envs,), bool),
        next_obs=obs,
    )
    return replay.create(capacity, row)


def gather(
    config: Any,
    task: Task,
    act: learning.Actor,
    collector: learning.Collector,
    buffer: replay.Replay,
    stats: normalization.RunningStats,
    key: Array,
) -> tuple[learning.Collector, replay.Replay, normalization.RunningStats, dict[str, Array]]:
    """`config.unroll_length` steps of every env into the buffer. `act`'s extras must be
    the action in [-1, 1], which the buffer keeps as the action; the observation
    statistics take in the new observations (when the Config normalizes them)."""
    collector, data, metrics = learning.collect(task, act, collector, key, config.unroll_length)
    data = dataclasses.replace(data, action=data.extras, extras=())
    buffer = replay.insert(buffer, data, key)  # keep probability 1: the key is unused
    if config.normalize_observations:
        stats = normalization.update_stats(stats, data.obs, num_batch_dims=2)
    return collector, buffer, stats, metrics


def capacity_rows(buffer_size: int, num_envs: int) -> int:
    """Rows of `num_envs` steps that hold `buffer_size` transitions (at least one)."""
    return max(1, buffer_size // num_envs)


def update(
    config: Any,
    task: Task,
    train_state: Any,
    acting: Callable[[Array], learning.Actor],
    gradient_step: Callable[[Any, Array], tuple[Any, dict[str, Array]]],
) -> tuple[Any, dict[str, Array]]:
    """One update of a replay learner: `unroll_length` steps of every env into the replay
    by ``acting(warming)`` (`warming`: a bool array, true before `learning_starts` env
    steps), then `gradient_steps` of ``gradient_step(state, key)`` once the replay
    holds `learning_starts` steps (before: NaN learning metrics)."""
    ts = train_state
    key, collect_key, learn_key = jax.random.split(ts.key, 3)
    warming = ts.updates * config.steps_per_update < config.learning_starts
    collector, buffer, stats, collect_metrics = gather(
        config, task, acting(warming), ts.collector, ts.replay, ts.obs_stats, collect_key
    )
    ts = ts.replace(collector=collector, replay=buffer, obs_stats=stats, key=key, updates=ts.updates + 1)

    def learn(ts):
        ts, metrics = jax.lax.scan(gradient_step, ts, jax.random.split(learn_key, config.gradient_steps))
        return ts, jax.tree.map(jnp.nanmean, metrics)

    def wait(ts):
        return ts, jax.tree.map(lambda s: jnp.full(s.shape, jnp.nan, s.dtype), jax.eval_shape(learn, ts)[1])

    ts, metrics = jax.lax.cond(ts.updates * config.steps_per_update >= config.learning_starts, learn, wait, ts)
    return ts, {**collect_metrics, **metrics}


def train(init: Callable, update: Callable, config: Any, task: Task, hyperparams: Any, key: Array):
    """A whole run: ``init(config, task, hyperparams, key)``, then `config.num_updates`
    ``update(config, task, state)`` in one `lax.scan`."""
    state = init(config, task, hyperparams, key)
    return jax.lax.scan(lambda s, _: update(config, task, s), state, None, length=config.num_updates)


def algorithm(name: str, module: Any, config: Any) -> Algorithm:
    """A replay learner's module as a value (`mjzoo.learning.Algorithm`), `config` bound."""
    return Algorithm(
        name=name,
        config=config,
        hyperparams=module.Hyperparams(),
        init=lambda task, hyperparams, key: module.init(config, task, hyperparams, key),
        update=lambda task, state: module.update(config, task, state),
        evaluate=lambda task, state, key, num_envs, num_steps=None: module.evaluate(
            config, task, state, key, num_envs, num_steps
        ),
        policy=lambda task, deterministic=True: module.policy(config, task, deterministic),
        policy_params=policy_params,
        steps_per_update=config.steps_per_update,
        num_updates=config.num_updates,
        per_env_fields=("collector",),
    )


def policy_params(train_state: Any) -> dict[str, Any]:
    """What a deployed policy needs: the policy network and the observation statistics."""
    return {"policy": train_state.params["policy"], "obs_stats": train_state.obs_stats}


def deployable(acting: Callable[[Any], learning.Actor]) -> Callable[[Any, Any, Array], Array]:
    """``(policy_params, obs, key) -> ctrl`` for one env from ``acting(params)``."""

    def act(params, obs, key):
        return acting(params)((), obs, jnp.ones((), bool), key)[1]

    return act
