"""The command line's words as checked values: NAME=VALUE assignments, an algorithm's
Config, counts and lengths; a mistake in them is a `UsageError`."""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import importlib
import inspect
import re
import types
import typing
from collections.abc import Iterator
from types import ModuleType
from typing import Annotated
from typing import Any
from typing import Literal

import tyro

import mjzoo
from mjzoo import checks

__all__ = ["UsageError", "as_usage_errors"]

# Flags several commands share, each with its line of --help (`mjzoo COMMAND --help`).
ConfigFields = Annotated[
    tuple[str, ...],
    tyro.conf.arg(
        help="NAME=VALUE fields of the algorithm's (or planner's) Config and Hyperparams, over the env's defaults"
    ),
]
EnvOverrides = Annotated[
    tuple[str, ...],
    tyro.conf.arg(help="NAME=VALUE overrides of the env (as `mjzoo envs` lists them) or a factory's keywords"),
]
RunTask = Annotated[
    str | None,
    tyro.conf.arg(help="the task, a registered env or package.module:factory; default: the one RUN/task.json names"),
]
Impl = Annotated[
    Literal["jax", "warp"] | None,
    tyro.conf.arg(
        help="physics: MJX's JAX implementation or MuJoCo Warp; default: Warp with a CUDA GPU, where installed"
    ),
]
Overwrite = Annotated[bool, tyro.conf.arg(help="replace what --out already holds")]

ALGORITHMS = ("ppo", "amp", "sac", "fast_td3")
PLANNERS = ("predictive_sampling", "cem", "mppi", "dial", "cma_es", "ilqr")
_MISMATCH = object()  # what _as_type returns for a value of another type
_USERS_ERRORS = (ValueError, TypeError, KeyError, FileNotFoundError, FileExistsError, NotADirectoryError)


class UsageError(Exception):
    """A user's mistake: `main` prints it as one line and exits with status 2."""


@contextlib.contextmanager
def as_usage_errors(*errors: type[Exception]) -> Iterator[None]:
    """Marks a block that only checks the user's input and builds from it (configs, the
    task): the ValueError, TypeError, KeyError and missing-file errors the library raises
    there (or just `errors`) are the user's mistakes, and become a `UsageError`. Outside
    such blocks they are bugs, and keep their tracebacks."""
    caught = errors or _USERS_ERRORS
    try:
        yield
    except caught as e:
        raise UsageError(e.args[0] if isinstance(e, KeyError) and e.args else str(e)) from e


def at_least_one(**flags: int) -> None:
    for name, value in ((k, v) for k, v in flags.items() if v < 1):
        raise UsageError(f"--{name.replace('_', '-')} must be >= 1, got {value}")


def parse_assignments(pairs: tuple[str, ...], what: str) -> dict[str, Any]:
    """["a=1", "b=(64, 64)", "c=swish", "d=(0.7, inf)"] -> {"a": 1, "b": (64, 64), "c":
    "swish", "d": (0.7, inf)}: ``inf`` is a number (an unbounded limit)."""
    parsed = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        if not sep or not name:
            raise UsageError(f"{what}: expected NAME=VALUE, got {pair!r}")
        try:
            parsed[name] = ast.literal_eval(re.sub(r"\binf\b", "1e999", text))  # 1e999 reads as inf
        except (ValueError, SyntaxError):
            parsed[name] = text  # a bare word: a string
    return parsed


def algorithm_module(name: str, choices: tuple[str, ...] = ALGORITHMS) -> ModuleType:
    """The module `mjzoo.algorithms.NAME`, one of `choices`."""
    if name not in choices:
        raise UsageError(f"unknown algorithm {name!r}; choices: {', '.join(choices)}")
    return importlib.import_module(f"mjzoo.algorithms.{name}")


def build_planner(module: ModuleType, spec: str, overrides: dict[str, Any], what: str = "--config") -> tuple[Any, Any]:
    """A planner's (Config, Hyperparams): the task's fields, then `overrides`, split and
    checked by `mjzoo.planning.configure` (the planners' one reader of a flat dict)."""
    from mjzoo.planning import configure

    name = module.__name__.split(".")[-1]
    values = {**mjzoo.envs.hyperparameters(spec, name), **overrides}
    try:
        return configure(module, values)
    except ValueError as e:  # "mppi: unknown field(s) ...": the flag says where it came from
        raise UsageError(f"{what}: {str(e).removeprefix(f'{name}: ')}") from None


def build_algorithm(
    module: ModuleType, spec: str, overrides: dict[str, Any], what: str = "--config"
) -> tuple[Any, Any]:
    """An RL algorithm's (Config, Hyperparams): its defaults, then the task's, then
    `overrides` (the command line, or a saved config.json's "config" and "hyperparams"
    merged), each checked against its field's type first, then split by the module's
    `configure` (whose range errors name the field)."""
    hints = {**_number_hints(module.Hyperparams), **typing.get_type_hints(module.Config)}
    overrides = {k: v for k, v in overrides.items() if not str(v).startswith("<custom")}
    values = {**mjzoo.envs.hyperparameters(spec, module.__name__.split(".")[-1]), **overrides}
    unknown = sorted(set(values) - set(hints))
    if unknown:
        raise UsageError(
            f"{what}: unknown field(s) {unknown}{checks.did_you_mean(unknown, hints)}; fields: {sorted(hints)}"
        )
    for name, value in values.items():
        values[name] = _as_type(value, hints[name])
        if values[name] is _MISMATCH:
            raise UsageError(f"{what}: {name}={value!r} must be {_describe(hints[name])}")
    with as_usage_errors(ValueError):
        return module.configure(**values)


def imitated(module: ModuleType, spec: str, task: mjzoo.Task, overrides: dict[str, Any]) -> tuple[Any, ...]:
    """The data an algorithm module takes beside its config: (the env's motion reference,)
    for one whose `make` takes a `reference` (AMP: `mjzoo.envs.reference`, from the
    task and its overrides), else (). Splice it after the config: ``module.make(cfg,
    *data)``, after the task: ``module.init(cfg, task, *data, hyperparams, key)``."""
    if "reference" not in inspect.signature(module.make).parameters:
        return ()
    return (mjzoo.envs.reference(spec, task, **overrides),)


def _number_hints(hyperparams: type) -> dict[str, Any]:
    """Each number of a Hyperparams dataclass (nested ones' too, as AMP's `ppo`), as the
    command line gives it: a number, or None (for a switch off at inf; `configure` says
    where None is wrong)."""
    hints: dict[str, Any] = {}
    for field in dataclasses.fields(hyperparams):
        if dataclasses.is_dataclass(field.default):
            hints.update(_number_hints(type(field.default)))
        else:
            hints[field.name] = float | None
    return hints


def _as_type(value: Any, hint: Any) -> Any:
    """`value` as a field annotated `hint` holds it (JSON's lists as tuples, 1e6 as an
    int), or _MISMATCH. Objects (networks, optimizers, functions) come only from Python."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return next((v for v in (_as_type(value, arm) for arm in args) if v is not _MISMATCH), _MISMATCH)
    if origin is Literal:
        return value if value in args else _MISMATCH
    if origin is tuple and isinstance(value, (tuple, list)):
        arms = [args[0]] * len(value) if len(args) == 2 and args[1] is Ellipsis else list(args)
        items = [_as_type(v, arm) for v, arm in zip(value, arms)]
        return tuple(items) if len(arms) == len(value) and all(i is not _MISMATCH for i in items) else _MISMATCH
    if hint is int and isinstance(value, float) and value.is_integer():
        return int(value)
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if hint in (bool, int, float, str, type(None)) and type(value) is hint:
        return value
    return _MISMATCH


def _describe(hint: Any) -> str:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(arm) for arm in args)
    if origin is Literal:
        return "one of " + ", ".join(map(repr, args))
    if origin is tuple:
        return f"a tuple of {getattr(args[0], '__name__', args[0])}, e.g. (64, 64)"
    simple = {bool: "True or False", int: "an int", float: "a number", str: "a string", type(None): "None"}
    return simple.get(hint, f"a {getattr(hint, '__name__', hint)} (set in Python, not here)")


def episode_steps(task: mjzoo.Task, spec: str, steps: int | None) -> int:
    """--steps if given, else the task's own episode length (its time limit)."""
    if steps is not None:
        at_least_one(steps=steps)
        return steps
    with as_usage_errors(ValueError):
        return mjzoo.episode_steps(task, spec, "--steps")


def slug(spec: str) -> str:
    """A task spec as part of a directory name: my_pkg.tasks:reach -> my_pkg.tasks.reach."""
    return spec.replace(":", ".")


def settings_flags(name: str, doc: str, fields: tuple[str, ...]) -> type:
    """A frozen dataclass of `training.Settings`' `fields` for a command's flags: each
    with Settings' type and default, and the comment beside it in Settings as its --help,
    so the command line restates none of them."""
    from mjzoo.harness.settings import Settings

    hints = typing.get_type_hints(Settings)
    defaults = {f.name: f.default for f in dataclasses.fields(Settings)}
    source = inspect.getsource(Settings)
    flags = []
    for field in fields:
        comment = re.search(rf"^\s+{field}: [^#\n]*#\s*(.*)$", source, re.M)
        help_text = comment.group(1) if comment else None
        flags.append((field, Annotated[hints[field], tyro.conf.arg(help=help_text)], defaults[field]))
    cls = dataclasses.make_dataclass(name, flags, frozen=True)
    cls.__doc__ = doc
    return cls
