"""The contract between an algorithm module and the training harness: what
`mjzoo.harness.training.run` needs of a module (`Algorithm`) and of its config
(`AlgorithmConfig`), and the checks that name what is missing before anything compiles.
`training` re-exports all of it."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, Protocol

import jax

from mjzoo.types import Task

__all__ = ["Algorithm", "AlgorithmConfig", "check_algorithm", "check_state"]


class AlgorithmConfig(Protocol):
    """What `run` reads of an algorithm's config (a frozen dataclass, static under jit)."""

    @property
    def num_updates(self) -> int: ...  # updates in the whole run

    @property
    def steps_per_update(self) -> int: ...  # env steps one update collects (for the step axis)


class Algorithm(Protocol):
    """The contract of an algorithm module, which `run` trains.

    The state `init` returns is a dataclass pytree (a checkpoint saves it whole) with
    an int32 scalar field `updates`, the number of updates done. `run` jits `init` and
    `evaluate` (config static; `num_envs` and `num_steps` static too), and a whole
    chunk of `update`s as one `lax.scan`.

    Attributes:
      PER_ENV_FIELDS: names of the state's fields whose leaves have a leading
        [num_envs] axis (env states, recurrent carries); `run` shards them over the
        devices, and replicates the rest. ``()``: all replicated. A dotted name reaches
        into a nested state (AMP's ``"ppo.collector"``).

    Optionally ``diagnose(history) -> str | None``: given every chunk's metrics so far,
    a warning `run` prints (once per new message) when training has gone wrong in a way
    the numbers show (AMP: the discriminator has won).
    """

    PER_ENV_FIELDS: Sequence[str]

    def init(self, config: Any, task: Task, key: jax.Array) -> Any:
        """A fresh training state."""

    def update(self, config: Any, task: Task, state: Any) -> tuple[Any, dict[str, jax.Array]]:
        """One update; metrics are scalars (NaN: nothing to report this update)."""

    def evaluate(self, config: Any, task: Task, state: Any, key: jax.Array, num_envs: int, num_steps: int) -> tuple:
        """(mean return, per-env returns [num_envs], env 0's `mjzoo.Trajectory` or None)."""


def check_algorithm(algorithm: Any, config: Any) -> None:
    """Raises one TypeError naming everything `algorithm` or `config` lacks of the
    `Algorithm` / `AlgorithmConfig` contract."""
    missing = [f"{name}()" for name in ("init", "update", "evaluate") if not callable(getattr(algorithm, name, None))]
    fields = getattr(algorithm, "PER_ENV_FIELDS", None)
    if not (isinstance(fields, (tuple, list)) and all(isinstance(f, str) for f in fields)):
        missing.append("PER_ENV_FIELDS (a tuple of the state's per-env field names; () if none)")
    missing += [f"config.{name}" for name in ("num_updates", "steps_per_update") if not hasattr(config, name)]
    if missing:
        name = getattr(algorithm, "__name__", type(algorithm).__name__)
        raise TypeError(
            f"training.run: {name} is not an algorithm of the training.Algorithm contract; "
            f"it lacks {', '.join(missing)}"
        )


def check_state(algorithm: Algorithm, state: Any) -> None:
    """The state `init` made has the fields the harness and PER_ENV_FIELDS name."""

    def has(path: str) -> bool:
        node = state
        for name in path.split("."):
            if not dataclasses.is_dataclass(node) or not hasattr(node, name):
                return False
            node = getattr(node, name)
        return True

    wrong = [n for n in ("updates", *algorithm.PER_ENV_FIELDS) if not has(n)]
    if wrong:
        raise TypeError(
            f"training.run: the state {algorithm.__name__}.init returns ({type(state).__name__}) must be "
            f"a dataclass with the fields {wrong} (updates, and each of PER_ENV_FIELDS)"
        )
