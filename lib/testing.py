"""`check_task`: the Task contract's properties, checked on any task, shipped.

    report = mjzoo.testing.check_task(my_task)  # raises TaskCheckError naming what broke

One jitted, vmapped rollout (a reset per key, then `num_steps` transitions of random
actions) serves every property: it runs once, again on the same keys (determinism),
and on a task with every floating leaf nudged (no retrace); a task whose time limit is
longer than the rollout costs a second compile under a shorter `with_time_limit`. A
task that fails to trace is traced piece by piece (no compile) to name the property it
breaks. The project's conformance tests (tests/conformance/) run it on every env and
combinator.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo import batching
from mjzoo import running
from mjzoo.combinators import resets_itself
from mjzoo.combinators import with_time_limit
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["check_task", "TaskReport", "TaskCheckError", "PROPERTIES"]

PyTree = Any
PROPERTIES = {
    "traces": "the task's reset and transition trace",
    "jit_vmap": "a reset and a rollout, vmapped over keys, compile under jax.jit and run",
    "reset_matches_transition": "a reset state has the pytree structure, shapes and dtypes (weak types too) of every "
    "later state",
    "scalars": "reward (float32), terminated and truncated (bool), reward terms and metrics are scalars; "
    "observations are floating",
    "reward_terms": "the reward equals the sum of the terms recorded in metrics",
    "finite": "observations, rewards, metrics, qpos and qvel stay finite under random actions",
    "deterministic": "the same key gives the same trajectory",
    "keys_differ": "different keys (and so different actions) give different observations",
    "no_retrace": "new numbers (every floating leaf nudged) run under the same trace; no float is static",
    "time_limit": "an episode (each, when the task resets itself) is truncated exactly at task.time_limit unless "
    "it terminated first; never both",
}
NUDGE = 1e-3  # relative change of every floating leaf in the no-retrace run


@dataclasses.dataclass(frozen=True)
class TaskReport:
    """What `check_task` found: the properties that hold, those it could not check (with
    why), and how many traces (compiles) the check cost."""

    passed: tuple[str, ...]
    skipped: dict[str, str]
    traces: int


class TaskCheckError(AssertionError):
    """A task breaks the contract: `failures` maps each broken property to why."""

    def __init__(self, failures: dict[str, str], skipped: dict[str, str]):
        self.failures, self.skipped = failures, skipped
        lines = [f"check_task: {len(failures)} propert{'y' if len(failures) == 1 else 'ies'} failed:"]
        lines += [f"  {name} ({PROPERTIES[name]}): {why}" for name, why in failures.items()]
        for why in dict.fromkeys(skipped.values()):  # one line per reason
            lines.append(f"  not checked ({why}): {', '.join(p for p in skipped if skipped[p] == why)}")
        super().__init__("\n".join(lines))


def check_task(
    task: Task,
    *,
    key: jax.Array | None = None,
    num_steps: int = 10,
    num_envs: int = 2,
    policy: running.Policy | None = None,
) -> TaskReport:
    """Checks every property of `PROPERTIES` on `task` over `num_envs` episodes of
    `num_steps` transitions.

    Args:
      task: any `mjzoo.Task`.
      key: the PRNG key the episodes' keys are split from (default ``jax.random.key(0)``).
      num_steps: transitions per episode (static). A task with a longer time limit has
        its limit checked under ``with_time_limit(task, num_steps // 2)`` (a compile more).
      num_envs: episodes, vmapped (at least 2, to compare keys).
      policy: ``(obs, key) -> action [action_size]`` (hashable: it is a static argument);
        default uniform in [-1, 1].

    Returns:
      A `TaskReport`. Raises `TaskCheckError` (an AssertionError) listing every broken
      property with why: the leaf, the shapes, the step.
    """
    if num_envs < 2 or num_steps < 1:
        raise ValueError(f"check_task: num_envs={num_envs} must be >= 2 and num_steps={num_steps} >= 1")
    keys = jax.random.split(jax.random.key(0) if key is None else key, num_envs)
    failures: dict[str, str] = {}
    skipped: dict[str, str] = {}
    traces_before = _TRACES[0]

    def check(name: str, fn: Callable[[], str | None]) -> None:
        try:
            why = fn()
        except Exception as error:  # a property that crashes is broken, and the others still run
            why = _describe(error)
        if why:
            failures[name] = why

    try:
        first, trajectory = _episodes(task, keys, policy, num_steps)
    except Exception as error:
        name, diagnosis = _blame(task, keys[0])
        failures[name] = "; ".join(filter(None, [diagnosis, _describe(error)]))
        skipped.update({p: "the task does not run" for p in PROPERTIES if p not in failures})
        raise TaskCheckError(failures, skipped) from error

    states = trajectory.next_state

    def step_0(x):  # types only (no compile), weak types too: a jitted loop compiles twice for one
        return jax.ShapeDtypeStruct(x.shape[:1] + x.shape[2:], x.dtype, weak_type=jax.typeof(x).weak_type)

    check("reset_matches_transition", lambda: _differences(first, jax.tree.map(step_0, states)))
    check("scalars", lambda: _scalar_problems(states, num_envs, num_steps))
    check("reward_terms", lambda: _reward_terms_problem(states))
    check("finite", lambda: _non_finite(first, states))
    check(
        "deterministic",
        lambda: _differences(
            (first, trajectory), _episodes(task, keys, policy, num_steps), ("first run", "second run"), values=True
        ),
    )
    check("keys_differ", lambda: _same_across_keys(trajectory))
    check("no_retrace", lambda: _retraces(task, keys, policy, num_steps))
    if task.time_limit is None:
        skipped["time_limit"] = "the task has no time limit (task.time_limit is None)"
    elif resets_itself(task) and int(task.time_limit) > num_steps:
        skipped["time_limit"] = (
            f"the task starts its own episodes and their limit ({int(task.time_limit)} steps) is past the "
            f"rollout's {num_steps}: an outer limit would cut across them; run num_steps > the limit to check it"
        )
    else:
        check("time_limit", lambda: _time_limit_problem(task, keys, policy, num_steps, trajectory))
    if failures:
        raise TaskCheckError(failures, skipped)
    passed = tuple(p for p in PROPERTIES if p not in skipped)
    return TaskReport(passed=passed, skipped=skipped, traces=_TRACES[0] - traces_before)


# --- the one rollout ----------------------------------------------------------------

_TRACES = [0]  # how often `_episodes` was traced, in this process


def _uniform(size: int, obs: PyTree, key: jax.Array) -> jax.Array:
    return jax.random.uniform(key, (size,), minval=-1.0, maxval=1.0)


@functools.partial(jax.jit, static_argnums=(2, 3))
def _episodes(task: Task, keys: jax.Array, policy, num_steps: int):
    """A reset per key ([E]) and the `Trajectory` of `num_steps` transitions from it ([E, T]),
    with every leaf per env (`batching.own`)."""
    _TRACES[0] += 1  # runs only while tracing
    policy = policy or functools.partial(_uniform, task.action_size)
    task = batching.sized(task, keys.shape[0])  # Warp: a contact pool for every env

    def one(key):
        reset_key, run_key = jax.random.split(key)
        first = running.reset(task, reset_key)
        return first, running.rollout(task, policy, first, run_key, num_steps)[1]

    return batching.own(jax.vmap(one)(keys))  # Warp's shared contact pool is not one env's


# --- properties: each returns why it fails, or None ----------------------------------


def _leaves(tree: PyTree) -> dict[str, Any]:
    return {jax.tree_util.keystr(path): leaf for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]}


def _differences(a: PyTree, b: PyTree, names=("reset", "transition"), values: bool = False) -> str | None:
    """Where two pytrees differ: entries only in one, then shapes and dtypes (and values)."""
    la, lb = _leaves(a), _leaves(b)
    problems = [f"{p} only in the {names[0]}" for p in la if p not in lb]
    problems += [f"{p} only in the {names[1]}" for p in lb if p not in la]
    for p in la.keys() & lb.keys():
        x, y = la[p], lb[p]
        if _type(x) != _type(y):
            problems.append(f"{p}: {names[0]} {_type(x)}, {names[1]} {_type(y)}")
        elif values and not np.array_equal(np.asarray(x), np.asarray(y), equal_nan=np.issubdtype(x.dtype, np.inexact)):
            problems.append(f"{p} differs")
    if jax.tree.structure(a) != jax.tree.structure(b) and not problems:
        problems.append(f"pytree structures differ: {jax.tree.structure(a)} vs {jax.tree.structure(b)}")
    return _listed(sorted(problems))


def _scalar_problems(states: State, num_envs: int, num_steps: int) -> str | None:
    batch = (num_envs, num_steps)
    expected = {".reward": jnp.float32, ".terminated": jnp.bool_, ".truncated": jnp.bool_}
    leaves = _leaves(states)
    problems = [
        f"{p} is {_type(leaves[p], 2)}, expected {jnp.dtype(d).name}[]"
        for p, d in expected.items()
        if leaves[p].shape != batch or leaves[p].dtype != d
    ]
    problems += [
        f"{p} has shape {leaves[p].shape[2:]}, not a scalar"
        for p in leaves
        if p.startswith(".metrics") and leaves[p].shape != batch
    ]
    floating = {p: jnp.issubdtype(leaves[p].dtype, jnp.floating) for p in leaves if p.startswith(".obs")}
    problems += [f"{p} is {_type(leaves[p], 2)}, not floating" for p, ok in floating.items() if not ok]
    return _listed(problems)


def _reward_terms_problem(states: State) -> str | None:
    terms = {name: np.asarray(term) for name, term in running.reward_terms(states).items()}
    reward = np.asarray(states.reward)
    total = sum(terms.values(), np.zeros_like(reward))  # on the host: no compile
    wrong = ~np.isclose(total, reward, rtol=1e-5, atol=1e-5, equal_nan=True)
    if wrong.any():
        env, step = np.argwhere(wrong)[0]
        at = f"at (env, step) ({env}, {step})"
        return f"{at}: reward {reward[env, step]}, but its terms {sorted(terms)} sum to {total[env, step]}"
    return None


def _non_finite(first: State, states: State) -> str | None:
    """Each leaf with NaN or inf, with the first (env, step) it appears at."""
    problems = []
    for name, tree in (("reset", first), ("transition", states)):
        watched = {
            "obs": tree.obs,
            "reward": tree.reward,
            "metrics": tree.metrics,
            "qpos": tree.data.qpos,
            "qvel": tree.data.qvel,
        }
        for path, leaf in _leaves(watched).items():
            bad = ~np.isfinite(np.asarray(leaf))
            if bad.any():
                where = np.argwhere(bad)[0][: 1 if name == "reset" else 2]
                problems.append(
                    f"{name} {path} at {'(env, step)' if len(where) == 2 else 'env'} {tuple(where.tolist())}"
                )
    return _listed(problems)


def _same_across_keys(trajectory) -> str | None:
    actions, obs = np.asarray(trajectory.action), [np.asarray(x) for x in jax.tree.leaves(trajectory.next_state.obs)]
    if np.array_equal(actions[0], actions[1]):
        return None  # a deterministic policy on a deterministic start: nothing tells the keys apart
    if all(np.array_equal(x[0], x[1]) for x in obs):
        return "two episodes with different actions observed exactly the same: the observation ignores the actions"
    return None


def _retraces(task: Task, keys: jax.Array, policy, num_steps: int) -> str | None:
    static = _static_floats(jax.tree.structure(task.replace(model=None)), "task")
    if static:
        return _listed([f"a static float at {p}: changing it recompiles (make it a leaf)" for p in static])
    before = _TRACES[0]
    _episodes(_nudged(task), keys, policy, num_steps)
    if _TRACES[0] != before:
        return (
            f"the task with every floating leaf scaled by {1 + NUDGE} traced again: a number is part of its structure"
        )
    return None


def _nudged(task: Task) -> Task:
    """`task` with every floating leaf scaled by 1 + NUDGE, each keeping its type."""

    def nudge(x):
        if isinstance(x, float):
            return x * (1 + NUDGE)
        if not (isinstance(x, (np.ndarray, np.generic, jax.Array)) and jnp.issubdtype(x.dtype, jnp.floating)):
            return x
        if isinstance(x, jax.Array) and (x.weak_type or len(x.sharding.device_set) > 1):
            return (x * (1 + NUDGE)).astype(x.dtype)
        # On the host: an eager multiply per leaf shape is a compile each (hundreds per model).
        value = (np.asarray(x) * (1 + NUDGE)).astype(x.dtype)
        if not isinstance(x, jax.Array):
            return value
        # Placed as the leaf was (committed or not): the jit cache keys on it, and a
        # difference would recompile without a retrace.
        return jax.device_put(value, x.sharding) if getattr(x, "_committed", True) else jnp.asarray(value)

    return jax.tree.map(nudge, task)


def _static_floats(node, path: str) -> list[str]:
    """Paths to floats held as pytree metadata (a treedef's node data), outside MJX's own types."""
    data = node.node_data()
    if data is not None:
        kind, aux = data
        if kind.__module__.startswith("mujoco"):
            return []
        path = f"{path}/{getattr(aux, '__name__', None) or kind.__name__}"
        if any(isinstance(x, (float, np.floating)) for x in jax.tree.leaves(aux if isinstance(aux, tuple) else ())):
            return [path]
    return [found for child in node.children() for found in _static_floats(child, path)]


def _time_limit_problem(task: Task, keys, policy, num_steps: int, trajectory) -> str | None:
    limit = int(task.time_limit)
    if limit > num_steps:  # check the semantics under a limit the rollout reaches
        task = with_time_limit(task, max(1, num_steps // 2))
        limit = int(task.time_limit)
        trajectory = _episodes(task, keys, policy, num_steps)[1]
    terminated, truncated = (np.asarray(x) for x in (trajectory.next_state.terminated, trajectory.next_state.truncated))
    again = resets_itself(task)  # then every episode in the rollout counts, not only the first
    for env in range(terminated.shape[0]):
        length = 0
        for step, (term, trunc) in enumerate(zip(terminated[env], truncated[env])):
            length += 1
            at = f"env {env}, step {step} (step {length} of its episode, limit {limit})"
            if term and trunc:
                return f"{at}: terminated and truncated both set"
            if trunc and length != limit:
                return f"{at}: truncated before the limit"
            if length == limit and not (term or trunc):
                return f"{at}: neither truncated nor terminated at the limit"
            if term or trunc:
                if not again:
                    break
                length = 0
    return None


# --- a task that does not run: which property it breaks ------------------------------


def _blame(task: Task, key: jax.Array) -> tuple[str, str | None]:
    """The property broken by a task that fails to trace or compile, found by tracing
    (no compile) its reset and a transition, or, when those fail, its raw functions."""
    action = jax.ShapeDtypeStruct((task.action_size,), jnp.float32)
    try:
        first = jax.eval_shape(lambda k: running.reset(task, k), key)
        after, terms = jax.eval_shape(lambda s, a: running.transition_with_terms(task, s, a, key), first, action)
        done = (after.terminated, after.truncated)
        traced = True
    except Exception:  # the task's functions alone, before mjzoo's own checks
        try:
            first = jax.eval_shape(task.start, task.model, key)
            after = jax.eval_shape(task.step, task.model, first, action, key)
            terms = jax.eval_shape(task.reward, task.model, first, action, after)
            done = jax.eval_shape(task.terminate, task.model, after)
        except Exception:
            return "traces", None
        traced = False
    not_scalar = [
        f"{name} has shape {x.shape}" for name, x in _leaves({"reward": terms, "done": done}).items() if x.shape != ()
    ]
    if not_scalar:  # first: a non-scalar reward also makes the reset's differ from a transition's
        return "scalars", _listed(not_scalar)
    mismatch = _differences(first, after) if traced else _differences({"obs": first.obs}, {"obs": after.obs})
    if mismatch:
        return "reset_matches_transition", mismatch
    return ("jit_vmap", None) if traced else ("traces", None)


# --- messages -----------------------------------------------------------------------


def _type(x, batch_dims: int = 0) -> str:
    """dtype[shape] of an array or a `jax.ShapeDtypeStruct`, less its leading batch axes,
    and whether it is weakly typed (a Python number's type, which a jitted loop fed its
    own output compiles for twice)."""
    dtype = x.dtype if hasattr(x, "dtype") else jnp.result_type(x)
    weak = " (weakly typed)" if getattr(x, "weak_type", False) else ""  # a key array has none
    return f"{jnp.dtype(dtype).name}{list(np.shape(x)[batch_dims:])}{weak}"


def _listed(problems: list[str], most: int = 6) -> str | None:
    if not problems:
        return None
    more = f" (and {len(problems) - most} more)" if len(problems) > most else ""
    return "; ".join(problems[:most]) + more


def _describe(error: Exception) -> str:
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0] if text else ''}"[:400]
