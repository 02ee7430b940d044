"""Submodules that load on first use (PEP 562): importing a package does not pay for the
heavy dependencies (orbax, TensorBoard, matplotlib, Brax) of modules its caller never
touches, yet every submodule is reachable as an attribute.

    __getattr__, __dir__ = lazy.submodules(__name__, ("training", "metrics"))
"""

from __future__ import annotations

import importlib
import sys
from types import ModuleType
from typing import Callable
from typing import Sequence

__all__ = ["submodules"]


def submodules(package: str, names: Sequence[str]) -> tuple[Callable[[str], ModuleType], Callable[[], list[str]]]:
    """The module-level ``(__getattr__, __dir__)`` of `package`, importing each of
    `names` (``package.<name>``) the first time it is asked for."""
    lazy = tuple(names)

    def getattr_(name: str) -> ModuleType:
        if name in lazy:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def dir_() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(lazy))

    return getattr_, dir_
