"""A fixed-size FIFO replay buffer of samples, as a pytree of arrays.

AMP trains its discriminator on policy samples from a buffer of recent iterations as
well as the fresh ones, so the discriminator does not forget what older policies did.
`Replay` is a registered dataclass of arrays: it lives in a train state, passes through
`jax.jit` and `jax.vmap`, and checkpoints like any other pytree. Its capacity is the
leading axis of its data, so it is static; all shapes are fixed under jit (insertion
keeps a random subset through a mask, not a variable-length slice).

    from mjzoo.learning import replay

    buffer = replay.create(100_000, features[0])            # features: [B, F]
    buffer = replay.insert(buffer, features, key1, keep_probability=0.5)
    old = replay.sample(buffer, key2, 4096)                 # [4096, F]

Kept samples enter a ring in FIFO order: once full, each new sample overwrites the
oldest one.

Off-policy learners keep time-ordered rows of transitions instead: a "sample" is one
step of every parallel env (a `learning.Transitions` with [num_envs] leaves), inserted
with keep probability 1, so the ring's slots are consecutive env steps and
`sample_n_step` draws (step, env) pairs with n-step returns summed at sampling time:

    buffer = replay.create(capacity_steps, jax.tree.map(lambda x: x[0], transitions))  # one row
    buffer = replay.insert(buffer, transitions, key)                 # [T, num_envs, ...] rows
    batch = replay.sample_n_step(buffer, key, 256, n=3, discount=0.99)
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import NamedTuple

import jax
import jax.numpy as jnp

__all__ = ["NStep", "Replay", "create", "insert", "sample", "sample_n_step"]

Array = jax.Array
PyTree = Any


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Replay:
    """A ring buffer of samples.

    Attributes:
      data: pytree of arrays [capacity, ...] (e.g. one [capacity, F] array); slots
        [0, size) hold samples, the rest the zeros of `create`.
      size: int32 scalar, how many slots hold samples (<= capacity).
      cursor: int32 scalar in [0, capacity), the slot the next kept sample goes to (the
        oldest one, once full).
      inserted: int32 scalar, how many samples were ever kept (for logging: it wraps
        after 2**31 - 1, which the ring position, `cursor`, does not depend on).
    """

    data: PyTree
    size: Array
    cursor: Array
    inserted: Array

    @property
    def capacity(self) -> int:
        """The number of slots (static); for a vmapped batch of buffers, use it inside vmap."""
        return jax.tree.leaves(self.data)[0].shape[0]

    def replace(self, **changes: Any) -> Replay:
        return dataclasses.replace(self, **changes)


def _zero() -> Array:
    return jnp.zeros((), jnp.int32)


def create(capacity: int, example: PyTree) -> Replay:
    """An empty buffer for `capacity` samples shaped like `example`.

    Args:
      capacity: int >= 1.
      example: one sample, an array [...] or a pytree of arrays (only shapes and
        dtypes are read).

    Returns:
      A `Replay` whose data are zeros [capacity, ...], size, cursor and inserted 0.
    """
    if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 1:
        raise ValueError(f"replay.create: capacity={capacity!r} must be an int >= 1")
    if not jax.tree.leaves(example):
        raise ValueError("replay.create: example has no arrays")
    data = jax.tree.map(lambda x: jnp.zeros((capacity, *jnp.shape(x)), jnp.result_type(x)), example)
    return Replay(data=data, size=_zero(), cursor=_zero(), inserted=_zero())


def _check_samples(buffer: Replay, samples: PyTree) -> int:
    """The number of samples B; raises unless samples are [B, ...] shaped like the data."""
    data_def, samples_def = jax.tree.structure(buffer.data), jax.tree.structure(samples)
    if data_def != samples_def:
        raise ValueError(f"replay.insert: samples have structure {samples_def}, the buffer holds {data_def}")
    sizes = set()
    for d, s in zip(jax.tree.leaves(buffer.data), jax.tree.leaves(samples)):
        if jnp.ndim(s) != jnp.ndim(d) or jnp.shape(s)[1:] != d.shape[1:]:
            raise ValueError(f"replay.insert: samples of shape {jnp.shape(s)} must be [B, *{d.shape[1:]}]")
        sizes.add(jnp.shape(s)[0])
    if len(sizes) != 1:
        raise ValueError(f"replay.insert: the samples' leaves have different leading sizes {sorted(sizes)}")
    return sizes.pop()


def insert(buffer: Replay, samples: PyTree, key: Array, keep_probability: float | Array = 1.0) -> Replay:
    """Keeps each sample with probability `keep_probability` and writes the kept ones in.

    The kept samples, in their order in `samples`, go to consecutive ring slots from
    `cursor`, overwriting the oldest data once the buffer is full. If more than
    `capacity` are kept, only the last `capacity` of them are written (exactly what
    writing them one by one would leave). The slots are computed with a cumulative sum
    over the keep mask and the writes are one scatter that drops the samples not kept,
    so every shape is static.

    Args:
      buffer: the `Replay` to insert into.
      samples: [B, ...] samples shaped like the buffer's data (cast to its dtypes).
      key: PRNG key for the keep decisions (unused in effect when the probability is 1).
      keep_probability: scalar in [0, 1]; 1 keeps all, 0 none.

    Returns:
      The updated `Replay`.
    """
    num = _check_samples(buffer, samples)
    if isinstance(keep_probability, (int, float)) and not 0.0 <= keep_probability <= 1.0:
        raise ValueError(f"replay.insert: keep_probability={keep_probability!r} must be in [0, 1]")
    capacity = buffer.capacity
    # uniform is in [0, 1): `< 1` keeps every sample and `< 0` none.
    keep = jax.random.uniform(key, (num,)) < keep_probability
    rank = jnp.cumsum(keep, dtype=jnp.int32) - 1  # index among the kept samples
    num_kept = jnp.sum(keep, dtype=jnp.int32)
    # Of the kept samples only the last `capacity` survive; their slots are distinct.
    survives = keep & (rank >= num_kept - capacity)
    slots = jnp.where(survives, (buffer.cursor + rank) % capacity, capacity)  # capacity: out of range, dropped
    data = jax.tree.map(lambda d, s: d.at[slots].set(s.astype(d.dtype), mode="drop"), buffer.data, samples)
    return buffer.replace(
        data=data,
        size=jnp.minimum(buffer.size + num_kept, capacity),
        cursor=(buffer.cursor + num_kept) % capacity,
        inserted=buffer.inserted + num_kept,
    )


def sample(buffer: Replay, key: Array, num: int) -> PyTree:
    """`num` samples drawn uniformly, with replacement, from the filled slots.

    From an empty buffer (size 0) it returns zeros: callers that may sample before the
    first insert check `buffer.size > 0` (AMP inserts the current batch first).

    Args:
      buffer: a `Replay`.
      key: PRNG key.
      num: int >= 1, the number of samples (static).

    Returns:
      Pytree like the data with leaves [num, ...].
    """
    if isinstance(num, bool) or not isinstance(num, int) or num < 1:
        raise ValueError(f"replay.sample: num={num!r} must be an int >= 1")
    index = jax.random.randint(key, (num,), 0, jnp.maximum(buffer.size, 1))
    filled = buffer.size > 0
    return jax.tree.map(lambda d: jnp.where(filled, d[index], jnp.zeros_like(d[index])), buffer.data)


class NStep(NamedTuple):
    """A batch of n-step transitions, leaves [num, ...].

    Attributes:
      obs: the observation the first action was chosen from.
      action: that action.
      reward: [num] sum_{j<m} discount^j r_{t+j} over the m <= n steps taken.
      discount: [num] discount^m, 0 where step t+m-1 terminated: the factor of the
        bootstrapped value of `next_obs`.
      next_obs: the observation reached after the m steps (an episode's true final one
        where it ended).
    """

    obs: PyTree
    action: Array
    reward: Array
    discount: Array
    next_obs: PyTree


def sample_n_step(buffer: Replay, key: Array, num: int, n: int, discount: float | Array) -> NStep:
    """`num` (step, env) pairs drawn uniformly from a buffer of time-ordered rows, with
    n-step returns computed now (so n is a sampling choice, not a storage one).

    From step t of env e the window runs m = min(n, steps to the end of the episode,
    steps recorded so far) steps: it stops after the first terminated or truncated step
    (a truncated one bootstraps, a terminated one does not) and at the newest row (a
    shorter window is still a valid target).

    Args:
      buffer: a `Replay` whose data is a `learning.Transitions` of rows [capacity,
        num_envs, ...] (`obs`, `action`, `reward`, `terminated`, `truncated`,
        `next_obs` are read), inserted oldest first.
      key: PRNG key.
      num: int >= 1, the batch size (static).
      n: int >= 1, the longest window (static).
      discount: scalar in [0, 1].

    Returns:
      `NStep`, leaves [num, ...].
    """
    for name, value in (("num", num), ("n", n)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"replay.sample_n_step: {name}={value!r} must be an int >= 1")
    data, capacity = buffer.data, buffer.capacity
    num_envs = data.reward.shape[1]
    step_key, env_key = jax.random.split(key)
    t = jax.random.randint(step_key, (num,), 0, jnp.maximum(buffer.size, 1))
    env = jax.random.randint(env_key, (num,), 0, num_envs)
    available = (buffer.cursor - 1 - t) % capacity + 1  # rows from t to the newest, t's own included
    rows = (t[:, None] + jnp.arange(n)) % capacity  # [num, n]
    reward = data.reward[rows, env[:, None]]
    ended = data.terminated[rows, env[:, None]] | data.truncated[rows, env[:, None]]
    # Step j counts while no earlier step of the window ended and it has been recorded.
    ended_before = jnp.cumsum(ended, axis=1) - ended > 0
    taken = ~ended_before & (jnp.arange(n) < available[:, None])
    powers = jnp.asarray(discount, jnp.float32) ** jnp.arange(n, dtype=jnp.float32)
    m = jnp.sum(taken, axis=1)  # >= 1: step t itself always counts
    last = (t + m - 1) % capacity
    terminal = data.terminated[last, env]
    gather = lambda x, i: x[i, env]
    return NStep(
        obs=jax.tree.map(lambda x: gather(x, t), data.obs),
        action=gather(data.action, t),
        reward=jnp.sum(jnp.where(taken, powers * reward, 0.0), axis=1),
        discount=jnp.where(terminal, 0.0, jnp.asarray(discount, jnp.float32) ** m.astype(jnp.float32)),
        next_obs=jax.tree.map(lambda x: gather(x, last), data.next_obs),
    )
