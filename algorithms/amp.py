"""Adversarial Motion Priors (Peng et al., 2021): PPO whose reward adds a style term, the
judgment of a discriminator trained to tell the policy's motion from a reference's.

    reference = mjzoo.motion.reference(clips, task.mj_model, dt)  # or mjzoo.envs.reference(spec, task)
    config, hyperparams = amp.configure(num_envs=256, total_steps=5_000_000, task_weight=0.0)  # style only
    state = amp.init(config, task, reference, hyperparams, jax.random.key(0))
    state, metrics = jax.jit(amp.update, static_argnums=0)(config, task, state)
    mjzoo.harness.training.run(amp.make(config, reference), task, settings, hyperparams)  # with files, as PPO
    act = amp.policy(config, task)            # deployable: act(amp.policy_params(state), obs, key)

AMP is given its reference (a `mjzoo.motion.Reference` at the task's control rate):
the task knows nothing of it. `init` stores it in the train state, as it stores the
hyperparameters, so its arrays are ordinary leaves: `update` reads them from the state,
another clip of the same shape compiles nothing new, and a checkpoint records what the
run imitated. Each `update`, one jit:

1. `ppo.collect` on the task observed through `learning.with_feature_window`: each
   state's observation is ``{"policy": the task's own, "motion": [num_frames, F]}``,
   the window of `learning.motion_features` of its last frames (the policy sees only
   "policy").
2. The discriminator scores each transition's window (the true final one where an
   episode ended); the reward PPO learns from is
   ``task_weight * task reward + style_weight * style reward``.
3. `ppo.improve` on that reward (PPO's own code: GAE, clipped surrogate, minibatches).
4. The discriminator learns, `disc_epochs` x `disc_minibatches` steps of
   `learning.discriminator_loss`: reference windows (cut from the reference's frames,
   featurized by the SAME function as the simulation's) against policy windows, half
   fresh, half from a replay buffer of past policies' windows.

Discriminator inputs are normalized with running statistics of both kinds of windows.
Metrics: the discriminator's accuracy on each kind, mean logits, gradient penalty,
the style reward's mean and std; `diagnose` warns when the discriminator has won.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from collections.abc import Sequence
from typing import Any
from typing import Literal

import jax
import jax.numpy as jnp
import optax

from mjzoo import checks
from mjzoo import learning
from mjzoo import motion
from mjzoo.algorithms import ppo
from mjzoo.learning import discriminators
from mjzoo.learning import hyperparams as hyperparams_lib
from mjzoo.learning import motion_features
from mjzoo.learning import networks
from mjzoo.learning import normalization
from mjzoo.learning import replay
from mjzoo.learning.algorithm import Algorithm
from mjzoo.learning.hyperparams import INF
from mjzoo.types import Task

__all__ = [
    "Config",
    "Hyperparams",
    "TrainState",
    "configure",
    "evaluate",
    "init",
    "make",
    "policy",
    "policy_params",
    "style_task",
    "train",
    "update",
]

Array = jax.Array


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config(ppo.Config):
    """PPO's structure (all of `ppo.Config`) and AMP's (static under jit; hashable). The
    numbers are `Hyperparams`."""

    num_frames: int = 2  # frames per discriminator window (2: a transition)
    key_bodies: tuple[str, ...] = ()  # bodies whose positions (root-relative) the discriminator sees
    root_body: str | None = None  # None: the body of the model's first free joint, if any
    disc_loss: Literal["least_squares", "logistic"] = "least_squares"
    disc_hidden_sizes: tuple[int, ...] = (1024, 512)
    disc_epochs: int = 2
    disc_minibatches: int = 8
    policy_gradient_penalty: bool = False
    replay_size: int = 100_000  # windows of past policies

    def __post_init__(self):
        super().__post_init__()

        counts = ("num_frames", "disc_epochs", "disc_minibatches", "replay_size")
        checks.fields("amp.Config", self, {f: (checks.is_count(getattr(self, f)), "an integer >= 1") for f in counts})
        # AMP feeds PPO a dict observation {"policy": the task's, "motion"}; the keys name
        # entries of the task's own observation (None: it is an array).
        own_keys = "an entry of the task's own observation (None: the whole of it); AMP adds its own"
        checks.fields(
            "amp.Config",
            self,
            {
                "num_frames": (self.num_frames >= 2, ">= 2 (a window holds a transition)"),
                "disc_minibatches": (
                    self.steps_per_update % self.disc_minibatches == 0,
                    f"a divisor of num_envs * unroll_length = {self.steps_per_update}",
                ),
                "disc_loss": (self.disc_loss in ("least_squares", "logistic"), "least_squares or logistic"),
                "key_bodies": (isinstance(self.key_bodies, tuple), "a tuple of body names"),
                "policy_obs_key": (self.policy_obs_key is None or "/" not in self.policy_obs_key, own_keys),
                "value_obs_key": (self.value_obs_key is None or "/" not in self.value_obs_key, own_keys),
            },
        )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams:
    """AMP's numbers: PPO's (`ppo`) and the style reward's and discriminator's, a pytree
    of scalars (or batches of them, to sweep under `jax.vmap`). `disc_max_grad_norm` is
    off at inf."""

    ppo: ppo.Hyperparams = ppo.Hyperparams()
    task_weight: float | Array = 0.5  # on the task's own reward; 0: imitation by style alone
    style_weight: float | Array = 0.5
    disc_learning_rate: float | Array = 1e-4
    disc_weight_decay: float | Array = 1e-4
    disc_max_grad_norm: float | Array = 1.0  # inf: unclipped
    gradient_penalty_weight: float | Array = 5.0  # the AMP paper's w_gp / 2
    logit_l2_weight: float | Array = 0.01
    replay_keep_probability: float | Array = 0.05

    def __post_init__(self):
        checks.ranges("amp.Hyperparams", self, HYPERPARAM_RANGES)
        task, style = checks.host_value(self.task_weight), checks.host_value(self.style_weight)
        if task is not None and style is not None:
            checks.fields("amp.Hyperparams", self, {"style_weight": (task + style > 0, "> 0 where task_weight is 0")})

    def replace(self, **changes) -> Hyperparams:
        return dataclasses.replace(self, **changes)


HYPERPARAM_RANGES = {
    "task_weight": (0.0, INF, "[)"),
    "style_weight": (0.0, INF, "[)"),
    "disc_learning_rate": (0.0, INF, "()"),
    "disc_weight_decay": (0.0, INF, "[)"),
    "disc_max_grad_norm": (0.0, INF, "(]"),
    "gradient_penalty_weight": (0.0, INF, "[)"),
    "logit_l2_weight": (0.0, INF, "[)"),
    "replay_keep_probability": (0.0, 1.0, "[]"),
}


def configure(**fields: Any) -> tuple[Config, Hyperparams]:
    """(Config, Hyperparams) from one flat dict of field values, PPO's and AMP's alike
    (a registry's, `--config k=v`, a config.json's); unknown names and bad values are a
    ValueError naming them.

        config, hyperparams = amp.configure(num_envs=64, style_weight=1.0, learning_rate=1e-4)
    """
    names = hyperparams_lib.field_names
    own, ppo_numbers = names(Hyperparams) - {"ppo"}, names(ppo.Hyperparams)
    off_at_inf = (*ppo.OFF_AT_INF, "disc_max_grad_norm")
    config, numbers = hyperparams_lib.split_fields(
        "amp.configure", names(Config), own | ppo_numbers, fields, off_at_inf
    )
    ppo_hyper = {k: v for k, v in numbers.items() if k in ppo_numbers}
    mine = {k: v for k, v in numbers.items() if k in own}
    return Config(**config), Hyperparams(ppo=ppo.Hyperparams(**ppo_hyper), **mine)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrainState:
    """PPO's state (on the windowed task) and the discriminator's; a checkpoint saves it.

    Attributes:
      ppo: `ppo.TrainState`; its collector's observations hold the motion windows, its
        hyperparameters are `hyperparams.ppo` (each update hands them down).
      disc_params: the discriminator MLP's parameters.
      disc_opt_state: its optimizer's state.
      disc_stats: running statistics of discriminator inputs ([num_frames, F]).
      replay: `learning.replay.Replay` of past policy windows [replay_size, num_frames, F].
      hyperparams: AMP's `Hyperparams` (float32 leaves), PPO's among them.
      reference: the `mjzoo.motion.Reference` the discriminator learns from (qpos
        [frames, nq], qvel [frames, nv] at the task's control rate); `update` reads it
        here, never from the task.
    """

    ppo: ppo.TrainState
    disc_params: Any
    disc_opt_state: Any
    disc_stats: normalization.RunningStats
    replay: replay.Replay
    hyperparams: Hyperparams
    reference: motion.Reference

    @property
    def updates(self) -> Array:
        return self.ppo.updates

    def replace(self, **changes) -> TrainState:
        return dataclasses.replace(self, **changes)


PER_ENV_FIELDS = tuple(
    f"ppo.{f}" for f in ppo.PER_ENV_FIELDS
)  # a driver may shard these over devices (`Algorithm.per_env_fields`)


# --- the pieces AMP wires -----------------------------------------------------------


def _ppo(config: Config) -> ppo.Config:
    """The config PPO's functions get: the networks see the "policy" entry (the task's
    observation), or the entries of it that the config names."""

    def inside(key: str | None) -> str:
        return "policy" if key is None else f"policy/{key}"

    fields = {f.name: getattr(config, f.name) for f in dataclasses.fields(ppo.Config)}
    return ppo.Config(
        **{**fields, "policy_obs_key": inside(config.policy_obs_key), "value_obs_key": inside(config.value_obs_key)}
    )


def _features(config: Config, task: Task) -> jax.tree_util.Partial:
    return motion_features.motion_features(task.mj_model, config.key_bodies, config.root_body)


def style_task(config: Config, task: Task) -> Task:
    """`task` observed with its motion window (`learning.with_feature_window`), as AMP
    collects from it: observations ``{"policy": ..., "motion": [num_frames, F]}``."""
    return motion_features.with_feature_window(task, _features(config, task), config.num_frames)


def _checked_reference(who: str, task: Task, reference: Any) -> motion.Reference:
    """`reference`, or a TypeError saying how to give AMP one (it is AMP's data: the task
    holds none). Widths are checked here; the control step is `motion.check_reference`'s
    (it compiles a step, so it is the caller's choice)."""
    if not isinstance(reference, motion.Reference):
        raise TypeError(
            f"{who}: AMP needs a motion reference to imitate, got {type(reference).__name__}; give one: "
            "amp.make(config, reference) or amp.init(config, task, reference, ...), with reference = "
            "mjzoo.motion.reference(clips, task.mj_model, dt) or, for a registered env, "
            "mjzoo.envs.reference(spec, task)"
        )
    m = task.mj_model
    if reference.qpos.shape[-1] != m.nq or reference.qvel.shape[-1] != m.nv:
        raise ValueError(
            f"{who}: the reference has nq={reference.qpos.shape[-1]}, nv={reference.qvel.shape[-1]} "
            f"but the task's model nq={m.nq}, nv={m.nv}"
        )
    return reference


def _discriminator(config: Config) -> networks.Network:
    return networks.mlp(1, config.disc_hidden_sizes, jax.nn.relu)


def _disc_optimizer(hp: Hyperparams) -> optax.GradientTransformation:
    """The discriminator's optimizer of these (traced or not) numbers; its state's
    structure does not depend on them (as `ppo._optimizer`)."""
    return discriminators.discriminator_optimizer(hp.disc_learning_rate, hp.disc_weight_decay, hp.disc_max_grad_norm)


def _logit(config: Config) -> Callable[[Any, Array], Array]:
    """(params, normalized window [num_frames, F]) -> logit [1]. The gradient penalty is
    taken with respect to this input: normalized, so that it does not grow with 1/std of
    the features that barely vary."""
    net = _discriminator(config)
    return lambda params, window: net.apply(params, window.reshape(-1))


def reference_windows(
    config: Config, task: Task, reference: motion.Reference, template: Any, key: Array, num: int
) -> Array:
    """`num` windows [num, num_frames, F] cut at random from `reference` (clips by
    weight, starts uniform), featurized on `task`'s model by the function the
    simulation's are."""
    ref = reference
    frame_features = motion_features.frames_features(_features(config, task), task.model, template, ref.qpos, ref.qvel)
    clip, start = jax.vmap(lambda k: motion.sample_frame(ref, k, config.num_frames))(jax.random.split(key, num))
    index = jax.vmap(lambda c, t: motion.frame_index(ref, c, t + jnp.arange(config.num_frames)))(clip, start)
    return frame_features[index]  # every frame featurized once, then gathered


# --- init ---------------------------------------------------------------------------


@functools.partial(jax.jit, static_argnums=0, static_argnames="components")
def init(
    config: Config,
    task: Task,
    reference: motion.Reference,
    hyperparams: Hyperparams,
    key: Array,
    components: ppo.Components = ppo.NO_COMPONENTS,
) -> TrainState:
    """A fresh train state: PPO's (on `style_task`), the discriminator, an empty replay,
    and `reference` and `hyperparams`, which `update` reads from it."""
    ppo_key, disc_key = jax.random.split(key)
    reference = _checked_reference("amp.init", task, reference)
    hyperparams = hyperparams_lib.as_leaves(hyperparams)
    ppo_state = ppo.init(_ppo(config), style_task(config, task), hyperparams.ppo, ppo_key, components=components)
    window = jax.tree.map(lambda x: x[0], ppo_state.collector.env_state.obs["motion"])  # [num_frames, F]
    disc_params = _discriminator(config).init(disc_key, window.reshape(-1))
    return TrainState(
        ppo=ppo_state,
        disc_params=disc_params,
        disc_opt_state=_disc_optimizer(hyperparams).init(disc_params),
        disc_stats=normalization.init_stats(window),
        replay=replay.create(config.replay_size, window),
        hyperparams=hyperparams,
        reference=reference,
    )


# --- update -------------------------------------------------------------------------


def update(
    config: Config, task: Task, train_state: TrainState, components: ppo.Components = ppo.NO_COMPONENTS
) -> tuple[TrainState, dict[str, Array]]:
    """One AMP update (see the module docstring): collect, style reward, PPO, discriminator,
    with the state's hyperparameters and reference. Jit it with `config` static; `task` and
    `train_state` are ordinary arguments."""
    ts, pcfg, windowed, hp = train_state, _ppo(config), style_task(config, task), train_state.hyperparams
    ts = ts.replace(ppo=ts.ppo.replace(hyperparams=hp.ppo))  # AMP's hold PPO's: one source of the numbers
    key, collect_key, learn_key, disc_key = jax.random.split(ts.ppo.key, 4)
    collector, data, collect_metrics = ppo.collect(pcfg, windowed, ts.ppo, collect_key, components)

    windows = data.next_obs["motion"]  # [T, N, num_frames, F]: each transition's, ending at its next state
    normalized = normalization.normalize(ts.disc_stats, windows)
    logits = jax.vmap(jax.vmap(_logit(config), (None, 0)), (None, 0))(ts.disc_params, normalized)
    style = discriminators.style_reward(config.disc_loss, logits[..., 0])
    reward = hp.task_weight * data.reward + hp.style_weight * style
    ppo_state = ts.ppo.replace(collector=collector, key=key, updates=ts.ppo.updates + 1)
    ppo_state, learn_metrics = ppo.improve(
        pcfg, windowed, ppo_state, dataclasses.replace(data, reward=reward), learn_key, components
    )

    template = jax.tree.map(lambda x: x[0], collector.env_state.data)
    ts, disc_metrics = _learn_discriminator(config, task, ts.replace(ppo=ppo_state), windows, template, disc_key)
    style_metrics = {
        "amp/style_reward": jnp.mean(style),
        "amp/style_reward_std": jnp.std(style),
        "amp/task_reward": jnp.mean(data.reward),
        "amp/replay_size": ts.replay.size.astype(jnp.float32),
    }
    return ts, {**collect_metrics, **learn_metrics, **disc_metrics, **style_metrics}


def _learn_discriminator(
    config: Config, task: Task, ts: TrainState, windows: Array, template: Any, key: Array
) -> tuple[TrainState, dict[str, Array]]:
    """`disc_epochs` x `disc_minibatches` steps on this update's windows [T, N, k, F],
    as many replayed ones and as many reference ones."""
    t, n = windows.shape[:2]
    hp = ts.hyperparams
    insert_key, replay_key, reference_key, learn_key = jax.random.split(key, 4)
    buffer = replay.insert(
        ts.replay, windows.reshape((t * n,) + windows.shape[2:]), insert_key, hp.replay_keep_probability
    )
    replayed = replay.sample(buffer, replay_key, t * n).reshape(windows.shape)
    reference = reference_windows(config, task, ts.reference, template, reference_key, t * n).reshape(windows.shape)
    stats = normalization.update_stats(ts.disc_stats, windows, num_batch_dims=2)
    stats = normalization.update_stats(stats, reference, num_batch_dims=2)
    logit = _logit(config)
    optimizer = _disc_optimizer(hp)

    def loss(params, batch):
        policy = jnp.concatenate([batch["fresh"], batch["replayed"]])
        return discriminators.discriminator_loss(
            config.disc_loss,
            logit,
            params,
            batch["reference"],
            policy,
            hp.gradient_penalty_weight,
            config.policy_gradient_penalty,
            hp.logit_l2_weight,
        )

    def step(carry, batch):
        params, opt_state = carry
        grads, metrics = jax.grad(loss, has_aux=True)(params, batch)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return (optax.apply_updates(params, updates), opt_state), metrics

    data = jax.tree.map(
        lambda w: normalization.normalize(stats, w), {"fresh": windows, "replayed": replayed, "reference": reference}
    )
    (params, opt_state), metrics = learning.learn(
        step,
        (ts.disc_params, ts.disc_opt_state),
        data,
        learn_key,
        num_epochs=config.disc_epochs,
        num_minibatches=config.disc_minibatches,
        split_over_devices=config.split_minibatches,
    )
    return ts.replace(disc_params=params, disc_opt_state=opt_state, disc_stats=stats, replay=buffer), metrics


# --- acting, evaluation, training -----------------------------------------------------


def policy_params(train_state: TrainState) -> dict[str, Any]:
    """What a deployed policy needs: the policy network and the statistics of the task's
    own observation (not of the motion window)."""
    stats = train_state.ppo.obs_stats
    own = normalization.RunningStats(mean=stats.mean["policy"], var=stats.var["policy"], count=stats.count)
    return {"policy": train_state.ppo.params["policy"], "obs_stats": own}


def policy(
    config: Config, task: Task, deterministic: bool = True, components: ppo.Components = ppo.NO_COMPONENTS
) -> Callable[[Any, Any, Array], Array]:
    """A deployable policy ``(policy_params, obs, key) -> ctrl`` on the task's own
    observation: PPO's, with no motion window (the discriminator is for training only)."""
    return ppo.policy(config, task, deterministic, components)  # its obs keys name the task's entries


def evaluate(
    config: Config,
    task: Task,
    train_state: TrainState,
    key: Array,
    num_envs: int,
    num_steps: int | None = None,
    components: ppo.Components = ppo.NO_COMPONENTS,
) -> learning.Evaluation:
    """Deterministic episodes scored by the task's own reward: `ppo.evaluate`'s
    `learning.Evaluation` (returns, lengths [num_envs], env 0's Trajectory)."""
    return ppo.evaluate(_ppo(config), style_task(config, task), train_state.ppo, key, num_envs, num_steps, components)


def diagnose(history: Sequence[dict[str, float]], chunks: int = 3) -> str | None:
    """A warning when the discriminator has won: over the last `chunks` chunks of metrics
    it classified more than 99% of the reference windows right, and of the policy's too
    (reference accuracy alone also stays near 1 while it calls the policy's windows
    reference-like, which is no win). Its reward then no longer tells the policy how to
    improve: raise the gradient penalty, lower its learning rate, or shrink it."""
    names = ("disc/accuracy_reference", "disc/accuracy_policy")
    recent = [[m.get(name, 0.0) for name in names] for m in history[-chunks:]]
    if len(recent) == chunks and all(min(accuracies) > 0.99 for accuracies in recent):
        return (
            f"amp: the discriminator has won: accuracy > 0.99 on reference and policy windows over the last "
            f"{chunks} chunks; raise gradient_penalty_weight or lower disc_learning_rate"
        )
    return None


def train(
    config: Config,
    task: Task,
    reference: motion.Reference,
    hyperparams: Hyperparams,
    key: Array,
    components: ppo.Components = ppo.NO_COMPONENTS,
) -> tuple[TrainState, dict[str, Array]]:
    """A whole run, `init` then `config.num_updates` `update`s in one `lax.scan`, as
    `ppo.train`: jit it with `config` static, vmap it over hyperparameters and keys.
    Returns (final TrainState, per-update metrics, each [num_updates])."""
    state = init(config, task, reference, hyperparams, key, components=components)
    return jax.lax.scan(lambda s, _: update(config, task, s, components), state, None, length=config.num_updates)


def make(
    config: Config,
    reference: motion.Reference,
    *,
    policy_network: networks.Network | networks.RecurrentNetwork | None = None,
    value_network: networks.Network | None = None,
    optimizer: optax.GradientTransformation | Callable[[Any], optax.GradientTransformation] | None = None,
) -> Algorithm:
    """AMP as a value (`mjzoo.learning.Algorithm`), as `ppo.make`, imitating `reference`
    (a `mjzoo.motion.Reference`; e.g. `mjzoo.envs.reference(spec, task)`); its
    `diagnose` warns when the discriminator has won.

    Only `init` binds the reference (it puts it in the train state); `update`,
    `evaluate` and `policy` read it from the state or need none, so they come from a
    cache keyed by (config, pieces), as `ppo.make`'s: the harness caches compiles by
    those functions, so runs of equal settings in one process share them, whatever
    clip each imitates. A reference's arrays are not hashable, so `make` itself is not
    memoized; its `init` compiles once per value."""
    if not isinstance(reference, motion.Reference):
        raise TypeError(
            f"amp.make: AMP needs a motion reference to imitate, got {type(reference).__name__}; give one: "
            "amp.make(config, reference) with reference = mjzoo.motion.reference(clips, task.mj_model, dt) "
            "or, for a registered env, mjzoo.envs.reference(spec, task)"
        )
    shared = _make(config, policy_network, value_network, optimizer)
    components = ppo.Components(policy_network, value_network, optimizer)

    def bound_init(task: Task, hyperparams: Hyperparams, key: Array) -> TrainState:
        return init(config, task, reference, hyperparams, key, components=components)

    return shared._replace(init=bound_init)


# One value per (config, pieces): the harness caches compiles by the value's functions, so
# two runs of equal settings in one process share them.
@functools.lru_cache(maxsize=32)
def _make(
    config: Config,
    policy_network: networks.Network | networks.RecurrentNetwork | None,
    value_network: networks.Network | None,
    optimizer: optax.GradientTransformation | Callable[[Any], optax.GradientTransformation] | None,
) -> Algorithm:
    """AMP's functions that need no reference; `init` is bound by `make`."""
    components = ppo.Components(policy_network, value_network, optimizer)

    def unbound_init(task: Task, hyperparams: Hyperparams, key: Array) -> TrainState:
        raise TypeError("amp: this Algorithm has no reference; make it with amp.make(config, reference)")

    return Algorithm(
        name="amp",
        config=config,
        hyperparams=Hyperparams(),
        init=unbound_init,
        update=lambda task, state: update(config, task, state, components),
        evaluate=lambda task, state, key, num_envs, num_steps=None: evaluate(
            config, task, state, key, num_envs, num_steps, components
        ),
        policy=lambda task, deterministic=True: policy(config, task, deterministic, components),
        policy_params=policy_params,
        steps_per_update=config.steps_per_update,
        num_updates=config.num_updates,
        per_env_fields=PER_ENV_FIELDS,
        diagnose=diagnose,
    )
