"""The contract between an algorithm value (`mjzoo.learning.Algorithm`) and the training
harness: what `mjzoo.harness.training.run` needs of it, and the checks that name what is
missing before anything compiles. `training` re-exports all of it."""

from __future__ import annotations

import dataclasses
from typing import Any

from mjzoo.learning.algorithm import Algorithm

__all__ = ["Algorithm", "check_algorithm", "check_state"]


def _is_count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def check_algorithm(algorithm: Any) -> None:
    """Raises one TypeError naming everything `algorithm` lacks of the `Algorithm`
    contract (functions, counts, per-env field names)."""
    missing = [f"{name}()" for name in ("init", "update", "evaluate") if not callable(getattr(algorithm, name, None))]
    fields = getattr(algorithm, "per_env_fields", None)
    if not (isinstance(fields, (tuple, list)) and all(isinstance(f, str) for f in fields)):
        missing.append("per_env_fields (a tuple of the state's per-env field names; () if none)")
    missing += [
        f"{name} (an int >= 1)"
        for name in ("num_updates", "steps_per_update")
        if not _is_count(getattr(algorithm, name, None))
    ]
    if missing:
        name = getattr(algorithm, "name", type(algorithm).__name__)
        raise TypeError(
            f"training.run: {name} is not an algorithm value of the mjzoo.learning.Algorithm contract "
            f"(e.g. ppo.make(config)); it lacks {', '.join(missing)}"
        )


def check_state(algorithm: Algorithm, state: Any) -> None:
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
            f"training.run: the state {algorithm.name}'s init returns ({type(state).__name__}) must be "
            f"a dataclass with the fields {wrong} (updates, and each of per_env_fields)"
        )
