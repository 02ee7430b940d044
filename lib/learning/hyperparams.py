"""Checking and splitting an algorithm's numbers: the pieces `ppo` and `amp` build their
`Hyperparams` and `configure` from, for a user's algorithm to reuse.

A Hyperparams class is a frozen dataclass registered as a pytree, every field a number
(or a batch of numbers, to sweep under `jax.vmap`). It checks its ranges where values
are host numbers (`mjzoo.checks.ranges`, in `__post_init__`); traced values, and the
placeholders JAX rebuilds a pytree with, pass unchecked.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp

from mjzoo import checks

__all__ = ["INF", "as_leaves", "split_fields"]

INF = float("inf")  # a number that switches a clip off, so the switch can be swept too


def split_fields(
    where: str, structure: set[str], numbers: set[str], fields: dict[str, Any], off_at_inf: tuple[str, ...] = ()
) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the Config's fields, the Hyperparams' fields) of one flat dict, by name; a
    ValueError lists the valid names when one is neither. None for a number in
    `off_at_inf` means INF (off: what a Config's None meant before); None for another
    number is a ValueError (Hyperparams lets None pass, as JAX rebuilds pytrees with it)."""
    unknown = sorted(set(fields) - structure - numbers)
    if unknown:
        known = sorted(structure | numbers)
        raise ValueError(f"{where}: unknown field(s) {unknown}{checks.did_you_mean(unknown, known)}; fields: {known}")
    config = {k: v for k, v in fields.items() if k in structure}
    hyper = {k: (INF if v is None and k in off_at_inf else v) for k, v in fields.items() if k in numbers}
    for name in [k for k, v in hyper.items() if v is None]:
        raise ValueError(f"{where}: {name}=None is invalid; expected a number")
    return config, hyper


def as_leaves(hyperparams: Any) -> Any:
    """Hyperparameters as float32 arrays, as a train state holds them (one dtype for a
    checkpoint and for the chunk's compile, whatever Python numbers they were given as)."""
    return jax.tree.map(lambda x: jnp.asarray(x, jnp.float32), hyperparams)


def field_names(cls: type) -> set[str]:
    """The names of a dataclass's fields."""
    return {f.name for f in dataclasses.fields(cls)}
