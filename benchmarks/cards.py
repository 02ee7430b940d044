"""The name a benchmark's result files carry for the device they ran on."""

from __future__ import annotations

import re

import jax


def card_name(device_kind: str | None = None) -> str:
    """A device's kind (default: this one's) as a file name part ("nvidia_h100_80gb_hbm3", "cpu")."""
    kind = jax.devices()[0].device_kind if device_kind is None else device_kind
    return re.sub(r"[^a-z0-9]+", "_", kind.lower()).strip("_")
