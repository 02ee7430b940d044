"""An RL algorithm as a value: a NamedTuple of pure functions, as optax's
`GradientTransformation` is, that anything may drive (a `lax.scan`, a user's loop, the
training harness `mjzoo.harness.training.run`).

    algo = ppo.make(ppo.Config(num_envs=256))         # structure bound, numbers not yet
    state = algo.init(task, ppo.Hyperparams(), key)   # the numbers live in the state
    state, metrics = jax.jit(algo.update)(task, state)

Structure (sizes, networks, the optimizer's kind) is fixed when the value is made; every
number a user may sweep (learning rate, coefficients, discount) is a hyperparameter
pytree that `init` stores in the train state, as `optax.inject_hyperparams` stores its
numbers in the optimizer state. So `update` reads them from the state, a checkpoint
records them, a resumed run continues with them, and `jax.vmap` over states (made from
a batch of hyperparameters) sweeps them in one program.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from collections.abc import Sequence
from typing import Any
from typing import NamedTuple

import jax

from mjzoo import checks

__all__ = ["Algorithm", "TrainingWarning", "check_algorithm", "check_state"]

Array = jax.Array
PyTree = Any


class TrainingWarning(UserWarning):
    """Training has gone wrong, or is set up to, in a way the config or the metrics show
    (e.g. a run shorter than one update; an algorithm's `diagnose`)."""


class Algorithm(NamedTuple):
    """An RL algorithm, its structure bound: pure functions of the task and the state.

    Attributes:
      name: short name ("ppo", "amp"), recorded in a run's config.json.
      config: the static structure the functions were made with (a frozen dataclass).
      hyperparams: the default hyperparameter pytree (`init`'s when a driver has none).
      init: ``(task, hyperparams, key) -> state``: a fresh train state, a dataclass
        pytree with an int32 scalar field `updates` and the hyperparameters inside it.
      update: ``(task, state) -> (state, metrics)``: one update (collect and learn);
        metrics a dict of scalars (NaN: nothing to report this update).
      evaluate: ``(task, state, key, num_envs, num_steps) -> learning.Evaluation``
        (returns [num_envs], lengths [num_envs], env 0's `mjzoo.Trajectory` or None),
        as `mjzoo.learning.evaluate` gives it; num_envs, num_steps static.
      steps_per_update: env steps one update collects (the step axis of metrics).
      num_updates: updates in a whole run.
      per_env_fields: the state's fields whose leaves have a leading [num_envs] axis (a
        dotted name reaches into a nested state); a driver may shard them over devices.
      policy: optional ``(task, deterministic=True) -> act`` with ``act(params, obs,
        key) -> ctrl`` for one env: the deployable policy (PPO's and AMP's have one).
      policy_params: optional ``state -> params`` that `policy`'s act needs.
      diagnose: optional ``(history of chunk metrics) -> str | None``, a warning when
        training has gone wrong in a way the numbers show.
    """

    name: str
    config: Any
    hyperparams: PyTree
    init: Callable[[Any, PyTree, Array], PyTree]
    update: Callable[[Any, PyTree], tuple[PyTree, dict[str, Array]]]
    evaluate: Callable[..., Any]
    steps_per_update: int
    num_updates: int
    per_env_fields: Sequence[str] = ()
    policy: Callable[..., Callable[[Any, Any, Array], Array]] | None = None
    policy_params: Callable[[PyTree], Any] | None = None
    diagnose: Callable[[Sequence[dict[str, float]]], str | None] | None = None


def check_algorithm(algorithm: Any, who: str = "check_algorithm") -> None:
    """Raises one TypeError naming everything `algorithm` lacks of the `Algorithm`
    contract (functions, counts, per-env field names)."""
    missing = [f"{name}()" for name in ("init", "update", "evaluate") if not callable(getattr(algorithm, name, None))]
    fields = getattr(algorithm, "per_env_fields", None)
    if not (isinstance(fields, (tuple, list)) and all(isinstance(f, str) for f in fields)):
        missing.append("per_env_fields (a tuple of the state's per-env field names; () if none)")
    missing += [
        f"{name} (an int >= 1)"
        for name in ("num_updates", "steps_per_update")
        if not checks.is_count(getattr(algorithm, name, None))
    ]
    if missing:
        name = getattr(algorithm, "name", type(algorithm).__name__)
        raise TypeError(
            f"{who}: {name} is not an algorithm value of the mjzoo.learning.Algorithm contract "
            f"(e.g. ppo.make(config)); it lacks {', '.join(missing)}"
        )


def check_state(algorithm: Algorithm, state: Any, who: str = "check_state") -> None:
    """The state `init` made has the fields the harness and `per_env_fields` name."""

    def has(path: str) -> bool:
        node = state
        for name in path.split("."):
            if not dataclasses.is_dataclass(node) or not hasattr(node, name):
                return False
            node = getattr(node, name)
        return True

    wrong = [n for n in ("updates", *algorithm.per_env_fields) if not has(n)]
    if wrong:
        raise TypeError(
            f"{who}: the state {algorithm.name}'s init returns ({type(state).__name__}) must be "
            f"a dataclass with the fields {wrong} (updates, and each of per_env_fields)"
        )
