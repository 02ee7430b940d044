"""Episode-structure combinators, `Task -> Task`: time limits, auto-reset, action repeat,
extra reward terms, reward clipping and the divergence guard.

Each combinator rebinds some of the task's four functions around the originals; its
numbers are pytree leaves. One that keeps per-episode state owns a record type
(`ObservationState`, `TimeLimitState`, `AutoResetState`) kept in `state.layers` around
the records of the task it wraps (`mjzoo.layers`): any of them can be applied twice.

Three of them (auto-reset, action repeat, divergence guard) must see a whole transition
of the task they wrap before deciding what to return. Their `step` runs
`mjzoo.transition` on the inner task and hands its result on as ``state.outcome``
(`mjzoo.Outcome`); their `reward` and `terminate` report it, and the `transition` that
called them clears it (states never keep it).
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import Callable
from typing import Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import batching
from mjzoo import checks
from mjzoo import tree
from mjzoo.layers import layered
from mjzoo.layers import peel
from mjzoo.layers import wrap
from mjzoo.running import fill_transition_entries
from mjzoo.running import reset
from mjzoo.running import reward_terms
from mjzoo.running import transition_with_terms
from mjzoo.types import Outcome
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "with_observation",
    "with_time_limit",
    "with_auto_reset",
    "with_action_repeat",
    "with_reward",
    "with_reward_clip",
    "with_divergence_guard",
    "runs_transitions",
    "record",
    "ObservationState",
    "TimeLimitState",
    "AutoResetState",
]

Array = jax.Array
PyTree = Any
RESET_STREAM = 0x5E7  # fold_in tag: combinators pass keys through and derive their own


# --- observation transform ----------------------------------------------------------


class ObservationState(NamedTuple):
    """`with_observation`'s record: ``obs``, the wrapped task's own observation, which
    its step still receives."""

    obs: PyTree
    inner: Any = ()


def with_observation(task: Task, fn: Callable) -> Task:
    """Observes ``fn(obs)`` instead of the task's own observation (select, hide, reshape:
    e.g. drop velocities to make a task partially observable).

    `fn` maps one observation pytree to another; a plain function or a
    `jax.tree_util.Partial` with its parameters. Keeps an `ObservationState`: the inner
    task's own observation, which its step still receives.
    """
    if not callable(fn):
        raise TypeError(f"with_observation: fn must be callable, got {type(fn).__name__}")
    checks.retrace_hazard("with_observation", "fn", fn)
    if not isinstance(fn, jax.tree_util.Partial):
        fn = jax.tree_util.Partial(fn)
    return layered(
        task, ObservationState, Partial(_observed_reset, task.start, fn), Partial(_observed_step, task.step, fn)
    )


def _observed(state: State, fn) -> State:
    return wrap(state.replace(obs=fn(state.obs)), ObservationState(obs=state.obs))


def _observed_reset(reset_fn, fn, model, key) -> State:
    return _observed(reset_fn(model, key), fn)


def _observed_step(step_fn, fn, model, state, action, key) -> State:
    own, inner = peel(state, ObservationState)
    return _observed(step_fn(model, inner.replace(obs=own.obs), action, key), fn)


# --- time limit ---------------------------------------------------------------------


class TimeLimitState(NamedTuple):
    """`with_time_limit`'s record: ``steps``, int32 [], the steps taken in this episode."""

    steps: Array
    inner: Any = ()


def with_time_limit(task: Task, max_steps: int) -> Task:
    """Truncates episodes after `max_steps` steps of `task`; never terminates them.

    Keeps a `TimeLimitState`: the steps taken in this episode. An episode that
    terminates on its last step is reported terminated, not truncated. Nested time
    limits each count their own steps: an inner one still truncates at its own limit.
    """
    max_steps = checks.integer("with_time_limit", "max_steps", max_steps)
    return layered(
        task,
        TimeLimitState,
        start=Partial(_time_limit_reset, task.start),
        step=Partial(_time_limit_step, task.step),
        terminate=Partial(_time_limit_terminate, task.terminate, jnp.int32(max_steps)),
    ).replace(time_limit=jnp.int32(max_steps) if task.time_limit is None else jnp.minimum(task.time_limit, max_steps))


def _time_limit_reset(reset_fn, model: mjx.Model, key: Array) -> State:
    return wrap(reset_fn(model, key), TimeLimitState(steps=jnp.zeros((), jnp.int32)))


def _time_limit_step(step_fn, model: mjx.Model, state: State, action: Array, key: Array) -> State:
    own, inner = peel(state, TimeLimitState)
    return wrap(step_fn(model, inner, action, key), TimeLimitState(steps=own.steps + 1))


def _time_limit_terminate(terminate_fn, max_steps: Array, model: mjx.Model, state: State):
    own, inner = peel(state, TimeLimitState)
    terminated, truncated = terminate_fn(model, inner)
    out_of_time = own.steps >= max_steps
    return terminated, (truncated | out_of_time) & ~terminated


# --- steps that run whole transitions: state.outcome ------------------------------------


def record(state: State, terms: dict[str, Array], terminated: Array, truncated: Array) -> State:
    """`state` carrying a whole transition's `Outcome` (reward terms, terminated,
    truncated) for the reward and terminate that `runs_transitions` installs."""
    return state.replace(outcome=Outcome(terms=terms, terminated=terminated, truncated=truncated))


def _select(cond: Array, on_true: State, on_false: State) -> State:
    """`on_false` (the running state) with data, obs, info and the combinators' records
    taken from `on_true` where `cond` holds."""
    return on_false.replace(
        data=batching.where(cond, on_true.data, on_false.data),
        obs=tree.where(cond, on_true.obs, on_false.obs),
        info=tree.where(cond, on_true.info, on_false.info),
        layers=tree.where(cond, on_true.layers, on_false.layers),
    )


def _recorded_reward(model, state, action, next_state) -> dict[str, Array]:
    return dict(next_state.outcome.terms)


def _recorded_terminate(model, state) -> tuple[Array, Array]:
    return state.outcome.terminated, state.outcome.truncated


def runs_transitions(task: Task, step_fn: Callable, *params) -> Task:
    """`task` with `step_fn(*params, inner, model, state, action, key)` as its step, for
    combinators that run whole transitions of the inner task (`inner`, with model None:
    put the call's model back in). The step returns ``record(state, terms, terminated,
    truncated)``; the task's reward and terminate then report that record."""
    inner = task.replace(model=None)  # the model comes from the call, so edits to it apply
    return task.replace(
        step=Partial(step_fn, *params, inner),
        reward=Partial(_recorded_reward),
        terminate=Partial(_recorded_terminate),
    )


# --- auto-reset ---------------------------------------------------------------------


class AutoResetState(NamedTuple):
    """`with_auto_reset`'s record: ``final_obs``, the observation the last transition
    actually ended in (the finished episode's last, where it ended; zeros at reset)."""

    final_obs: PyTree
    inner: Any = ()


def with_auto_reset(task: Task) -> Task:
    """Starts a new episode inside `step` whenever the inner transition ends one.

    The returned state carries the finished transition's reward, terminated, truncated
    and metrics, with the new episode's data and observation (the observation the next
    action is chosen from). Keeps an `AutoResetState`: ``final_obs``, the observation
    the episode actually ended in (equal to `obs` when it did not end), which PPO needs
    to bootstrap truncated episodes (``mjzoo.find(state, AutoResetState).final_obs``).

    A task that already resets itself (an auto-reset inside, as under a curriculum) is
    returned unchanged: a second reset would restart the combinators between the two
    (the curriculum's level) with every episode.

    Under `jax.vmap` (MJX-JAX physics) the new episodes are computed only on steps where
    some env of the batch ended, with the same results as choosing per env.
    """
    if resets_itself(task):
        return task
    return runs_transitions(task, _auto_reset_step).replace(start=Partial(_auto_reset_start, task.start))


def resets_itself(task: Task) -> bool:
    """Whether `with_auto_reset` is somewhere inside `task` (its functions' bound args)."""

    def found(node) -> bool:
        partials = jax.tree.leaves(node, is_leaf=lambda x: isinstance(x, jax.tree_util.Partial))
        return any(
            isinstance(p, jax.tree_util.Partial) and (p.func is _auto_reset_step or found((p.args, p.keywords)))
            for p in partials
        )

    return found(task.replace(model=None))


def _auto_reset_start(start_fn, model, key: Array) -> State:
    state = start_fn(model, key)
    zeros = jax.tree.map(lambda x: jnp.zeros(jnp.shape(x), jnp.result_type(x)), state.obs)  # strongly typed
    return wrap(state, AutoResetState(final_obs=zeros))


def _auto_reset_step(inner: Task, model, state: State, action: Array, key: Array) -> State:
    inner = inner.replace(model=model)
    _, state = peel(state, AutoResetState)
    ended, terms = transition_with_terms(inner, state, action, key)
    chosen = _restarted(inner, ended.terminated | ended.truncated, key, ended)
    chosen = wrap(chosen, AutoResetState(final_obs=ended.obs))
    return record(chosen, terms, ended.terminated, ended.truncated)


def _restarted_select(inner: Task, done: Array, key: Array, ended: State) -> State:
    """`ended` with a new episode's data, obs, info and records where `done` (its info
    holding `ended`'s entries it lacks, as zeros)."""
    fresh = reset(inner, jax.random.fold_in(key, RESET_STREAM))
    return _select(done, fresh.replace(info=tree.fill_missing(fresh.info, ended.info)), ended)


@jax.custom_batching.custom_vmap
def _restarted(inner: Task, done: Array, key: Array, ended: State) -> State:
    """`_restarted_select`, batched so that the new episodes are computed only when some
    env ended: under `jax.vmap` a per-env choice computes both sides for every env, and a
    reset can cost hundreds of steps (Playground's cheetah settles for 200)."""
    return jax.lax.cond(done, lambda: _restarted_select(inner, True, key, ended), lambda: ended)


@_restarted.def_vmap
def _restarted_batch(axis_size: int, in_batched: list, inner: Task, done: Array, key: Array, ended: State):
    """`_restarted` of a batch ([axis_size, ...]). Unbatched arguments are broadcast, but for
    Warp's shared contact pool: MJX keeps it unbatched under vmap and `_select` takes it
    from `ended`, so it passes through untouched (broadcasting it leaks its tracers)."""
    task_leaves, task_def = jax.tree.flatten(inner)
    task_batched = jax.tree.leaves(in_batched[0])
    ended_leaves, ended_def = jax.tree.flatten(ended)
    ended_batched = jax.tree.leaves(in_batched[3])
    kept = [s and not b for s, b in zip(jax.tree.leaves(batching.shared(ended)), ended_batched)]
    widen = lambda x, b: x if b else jnp.broadcast_to(x, (axis_size, *jnp.shape(x)))  # noqa: E731
    done, key = (widen(x, b) for x, b in zip((done, key), in_batched[1:3]))
    moving = [widen(x, b) for x, b, k in zip(ended_leaves, ended_batched, kept) if not k]
    mapped = [x for x, b in zip(task_leaves, task_batched) if b]

    def restart(mapped: list, done: Array, key: Array, moving: list) -> list:
        # The unmapped leaves (the task's constants, the shared pool) are closed over.
        task = jax.tree.unflatten(task_def, _merge(task_leaves, [not b for b in task_batched], mapped))
        state = jax.tree.unflatten(ended_def, _merge(ended_leaves, kept, moving))
        out = jax.tree.leaves(_restarted_select(task, done, key, state))
        return [x for x, k in zip(out, kept) if not k]

    fresh = jax.lax.cond(
        _any_of_batch(done), jax.vmap(restart), lambda *_: moving, mapped, done, key, moving
    )  # one branch for all
    out = jax.tree.unflatten(ended_def, _merge(ended_leaves, kept, fresh))
    return out, jax.tree.unflatten(ended_def, [not k for k in kept])


@jax.custom_batching.custom_vmap
def _any_of_batch(x: Array) -> Array:
    """`jnp.any(x)`, and under `jax.vmap` still one unbatched bool: true when any element
    of any batch member is. It keeps `_restarted_batch`'s condition unbatched under an
    outer vmap (seeds or hyperparameters over a batch of envs), where a batched one turns
    the `lax.cond` into a select that computes the new episodes on every step."""
    return jnp.any(x)


@_any_of_batch.def_vmap
def _any_of_batch_batch(axis_size: int, in_batched: list, x: Array) -> tuple[Array, bool]:
    return _any_of_batch(x), False


def _merge(leaves: list, fixed: list, others: list) -> list:
    """`leaves` where `fixed`, else the next of `others` in order."""
    others = iter(others)
    return [x if f else next(others) for x, f in zip(leaves, fixed)]


# --- action repeat ------------------------------------------------------------------


def with_action_repeat(task: Task, repeats: int) -> Task:
    """Applies each action for `repeats` (static) steps of `task`, summing the rewards.

    Terminated / truncated if any inner step was; after an inner episode end the
    remaining repeats leave the state unchanged and add no reward. Keeps no record. A time limit of L inner steps becomes ceil(L / repeats) steps.
    """
    repeats = checks.integer("with_action_repeat", "repeats", repeats)
    limit = None if task.time_limit is None else (task.time_limit + repeats - 1) // repeats
    return runs_transitions(task, _repeat_step, tree.StaticValue(repeats)).replace(time_limit=limit)


def _repeat_step(repeats: tree.StaticValue, inner: Task, model, state: State, action: Array, key: Array) -> State:
    inner = inner.replace(model=model)

    def body(carry, key):
        state, total, terminated, truncated = carry
        done = terminated | truncated
        next_state, terms = transition_with_terms(inner, state, action, key)
        total = {k: total[k] + jnp.where(done, 0.0, v) for k, v in terms.items()}
        metrics = tree.where(done, state.metrics, next_state.metrics)
        state = _select(done, state, next_state).replace(metrics=metrics)
        return (
            state,
            total,
            terminated | (~done & next_state.terminated),
            truncated | (~done & next_state.truncated),
        ), None

    state = fill_transition_entries(inner, state)  # adds what only inner transitions write (while `reset` traces)
    shape = jax.eval_shape(lambda: transition_with_terms(inner, state, action, key))
    # The carry holds the metrics an inner transition writes, and only those.
    state = state.replace(metrics=tree.zeros_like_shape(shape[0].metrics))
    zeros = tree.zeros_like_shape(shape[1])
    keys = jax.random.split(key, repeats.value)
    init = (state, zeros, jnp.zeros((), bool), jnp.zeros((), bool))
    (final, total, terminated, truncated), _ = jax.lax.scan(body, init, keys)
    return record(final, total, terminated, truncated & ~terminated)


# --- extra reward terms -------------------------------------------------------------


def with_reward(task: Task, name: str, fn: Callable, weight: float = 1.0) -> Task:
    """Adds the term ``name: weight * fn(model, state, action, next_state)``.

    `fn` returns a scalar; it may be a `jax.tree_util.Partial` carrying its own numeric
    parameters (leaves), or a plain module-level function. A lambda or nested function
    is a new object each time the task is built, so jit would retrace every rebuilt
    task: it gets a `checks.RetraceHazardWarning`. Keeps no record.
    """
    return with_rewards(task, {name: (fn, weight)})


def with_rewards(task: Task, terms: Mapping[str, tuple[Callable, float]]) -> Task:
    """`with_reward` for each ``name: (fn, weight)`` of `terms`, in order, checking the
    names against the task's with one trace of its reset (seconds, for a legged robot's
    stack) instead of one per term."""
    reward = task.reward
    for name, (fn, weight) in terms.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"with_reward: name must be a non-empty string, got {name!r}")
        if not callable(fn):
            raise TypeError(f"with_reward: fn for term {name!r} must be callable, got {type(fn).__name__}")
        checks.retrace_hazard("with_reward", f"the function of term {name!r}", fn)
        fn = fn if isinstance(fn, jax.tree_util.Partial) else jax.tree_util.Partial(fn)
        reward = Partial(_extra_reward, reward, tree.StaticValue(name), fn, jnp.float32(weight))
    _refuse_taken_names(task, terms, "with_reward")
    return task.replace(reward=reward)


def _refuse_taken_names(task: Task, names, who: str) -> None:
    """Raises if `task` already has a reward term named like one of `names`."""
    existing = reward_terms(jax.eval_shape(lambda key: reset(task, key), jax.random.key(0)))
    for name in names:
        if name in existing:
            raise ValueError(f"{who}: the task already has a reward term named {name!r}: {sorted(existing)}")


def _extra_reward(reward_fn, name: tree.StaticValue, fn, weight, model, state, action, next_state):
    terms = reward_fn(model, state, action, next_state)
    return {**terms, name.value: weight * jnp.asarray(fn(model, state, action, next_state), jnp.float32)}


def with_reward_clip(task: Task, low: float, high: float) -> Task:
    """Clips the summed reward of each transition to [low, high] (either may be infinite).

    `mjzoo.transition` sums the task's reward terms; clipping the terms one by one would
    not clip their sum, so this adds the term ``"clip" = clip(sum, low, high) - sum``
    (0 when the sum is within bounds). The reward is the clipped sum, and the metrics
    keep every unclipped term under ``"reward/<name>"`` next to ``"reward/clip"``. Add
    other terms inside it. Keeps no record.
    """
    if not (low <= high):  # also rejects NaN
        raise ValueError(f"with_reward_clip: the range low={low!r}, high={high!r} must have low <= high")
    _refuse_taken_names(task, ["clip"], "with_reward_clip")
    return task.replace(reward=Partial(_clipped_reward, task.reward, jnp.float32(low), jnp.float32(high)))


def _clipped_reward(reward_fn, low, high, model, state, action, next_state) -> dict[str, Array]:
    terms = reward_fn(model, state, action, next_state)
    total = sum((jnp.asarray(v, jnp.float32) for v in terms.values()), jnp.zeros((), jnp.float32))
    return {**terms, "clip": jnp.clip(total, low, high) - total}


# --- divergence guard ---------------------------------------------------------------

# The fields of mjx.Data a step integrates from; everything else in it is recomputed.
INTEGRATION_STATE = (
    "time",
    "qpos",
    "qvel",
    "act",
    "history",
    "qacc_warmstart",
    "plugin_state",
    "ctrl",
    "qfrc_applied",
    "xfrc_applied",
    "eq_active",
    "mocap_pos",
    "mocap_quat",
    "userdata",
)


def with_divergence_guard(task: Task, max_qvel: float = 1e3) -> Task:
    """Ends an episode whose physics goes NaN/inf or explodes, without leaking NaN.

    A transition diverges when qpos, qvel, the observation or a reward term is not
    finite, or when any |qvel| exceeds `max_qvel`. Then the state returned has
    terminated=True, every reward term zero, ``metrics["diverged"]`` = 1, the previous
    observation, info and combinators' records, and the previous physics state (`INTEGRATION_STATE`: what the
    next step integrates from); quantities derived from it in `data` (body poses,
    contacts, forces), which the next step recomputes, are zeroed. Keeps no record.

    On MuJoCo Warp it also counts what Warp would print: ``metrics["physics/capacity_overflow"]``
    (1 when the step outgrew the contact or constraint capacity and dropped some) and
    ``metrics["physics/solver_limit"]`` (1 when the solver stopped at its iteration limit).
    """
    if not max_qvel > 0:
        raise ValueError(f"with_divergence_guard: max_qvel={max_qvel!r} must be > 0")
    return runs_transitions(task, _guard_step, jnp.float32(max_qvel))


def _revert_physics(ok: Array, new: mjx.Data, old: mjx.Data) -> mjx.Data:
    """`new` where `ok`; else `old`'s integration state with the derived fields zeroed.

    Selecting the whole of `old` would keep every buffer of the previous step alive and
    force XLA to copy them all each step (measured: +25% per step on a cheap model).
    """
    zeroed = batching.where(~ok, jax.tree.map(jnp.zeros_like, new), new)
    names = {f.name for f in dataclasses.fields(new)}
    restored = {k: tree.where(ok, getattr(new, k), getattr(old, k)) for k in INTEGRATION_STATE if k in names}
    return zeroed.replace(**restored)


def _guard_step(max_qvel, inner: Task, model, state: State, action: Array, key: Array) -> State:
    inner = inner.replace(model=model)
    next_state, terms = transition_with_terms(inner, state, action, key)
    checks.same_observation(state.obs, next_state.obs)  # named here, before selecting between them
    state = state.replace(info=tree.fill_missing(state.info, next_state.info))  # while `reset` traces
    data = next_state.data
    ok = tree.all_finite((data.qpos, data.qvel, next_state.obs, terms))
    ok &= jnp.all(jnp.abs(jnp.nan_to_num(data.qvel)) <= max_qvel)
    safe = next_state.replace(
        data=_revert_physics(ok, next_state.data, state.data),
        obs=tree.where(ok, next_state.obs, state.obs),
        info=tree.where(ok, next_state.info, state.info),
        layers=tree.where(ok, next_state.layers, state.layers),
    )
    # zeros_like, not 0.0: an integer metric (a count) keeps its dtype, as a rollout's carry must
    metrics = jax.tree.map(lambda v: jnp.where(jnp.isfinite(v), v, jnp.zeros_like(v)), next_state.metrics)
    metrics = {**metrics, "diverged": (~ok).astype(jnp.float32), **batching.overflow_metrics(data)}
    safe = safe.replace(metrics=metrics)
    terms = {k: jnp.where(ok, v, 0.0) for k, v in terms.items()}
    return record(safe, terms, next_state.terminated | ~ok, next_state.truncated & ok)
