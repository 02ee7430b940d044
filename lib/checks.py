"""Checking what users give, once, at construction.

A catalog constructor's arguments: each function returns the value ready to close over
as a pytree leaf (float32 arrays) or a static int, or raises a ValueError that says
which argument of which constructor is wrong and what it must be:
``"{who}: {name}={value!r} must be ..."``.

A config's fields (an algorithm's or a planner's Config and Hyperparams, the harness's
Settings and RenderConfig): `fields` and `ranges`, the one way they are checked, raise
one ValueError naming every wrong field: ``"{where}: {field}={value!r} is invalid;
expected ..."``. Hyperparameters may be traced (under jit or vmap): `ranges` checks the
values it can see on the host and leaves the rest.
"""

from __future__ import annotations

import difflib
import functools
import math
import numbers as _numbers
import os
import sys
import warnings
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "number",
    "integer",
    "interval",
    "numbers",
    "key",
    "is_count",
    "fields",
    "ranges",
    "host_value",
    "same_observation",
    "did_you_mean",
    "RetraceHazardWarning",
    "retrace_hazard",
]

Array = jax.Array


def _is_real(value) -> bool:
    return isinstance(value, _numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


def _floats(value) -> np.ndarray:
    """`value` as a float64 array; NaN (which every check rejects) if it is not numbers."""
    try:
        return np.asarray(value, np.float64)
    except (TypeError, ValueError):
        return np.full((), np.nan)


def number(
    who: str, name: str, value: float, low: float = -math.inf, high: float = math.inf, *, open_low: bool = False
) -> Array:
    """`value` as a float32 [] leaf; it must be finite, >= low (> low if `open_low`) and <= high."""
    if not (_is_real(value) and (value > low if open_low else value >= low) and value <= high):
        bounds = [f"{'>' if open_low else '>='} {low:.6g}"] if low > -math.inf else []
        bounds += [f"<= {high:.6g}"] if high < math.inf else []
        raise ValueError(f"{who}: {name}={value!r} must be a finite number {' and '.join(bounds)}".rstrip())
    return jnp.float32(value)


def integer(who: str, name: str, value: int, low: int = 1) -> int:
    """`value` as a Python int (for static shapes and loop counts); it must be an integer >= low."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"{who}: {name}={value!r} must be an integer >= {low}")
    return int(value)


def interval(who: str, name: str, value, low: float = -math.inf, *, open_low: bool = False) -> Array:
    """A (lo, hi) pair as a float32 [2] leaf: finite, lo <= hi, lo >= low (> low if `open_low`)."""
    array = _floats(value)
    ok = array.shape == (2,) and np.isfinite(array).all() and array[0] <= array[1]
    if not (ok and (array[0] > low if open_low else array[0] >= low)):
        bound = f" and lo {'>' if open_low else '>='} {low:.6g}" if low > -math.inf else ""
        raise ValueError(f"{who}: {name}={value!r} must be a finite (lo, hi) with lo <= hi{bound}")
    return jnp.asarray(array, jnp.float32)


def numbers(who: str, name: str, value, n: int, low: float = 0.0) -> Array:
    """A number or `n` numbers (one per joint, actuator or axis) as a float32 [n] leaf,
    each finite and >= low."""
    array = _floats(value)
    if array.ndim > 1 or (array.ndim == 1 and array.shape[0] != n) or not np.all(np.isfinite(array) & (array >= low)):
        raise ValueError(f"{who}: {name}={value!r} must be a finite number >= {low:.6g} or {n} of them")
    return jnp.broadcast_to(jnp.asarray(array, jnp.float32), (n,))


def is_count(value: Any) -> bool:
    """Whether `value` is an int >= 1 (a bool is not): a size, a length, a number of steps."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def fields(where: str, config: Any, expectations: Mapping[str, tuple[Any, str]]) -> None:
    """Raises one ValueError naming every field of `config` whose check fails.

    `expectations`: ``{field: (ok, what it must be)}``, `ok` a bool or a bool array (every
    element must hold, for a batch of values).
    """
    wrong = [
        f"{field}={_shown(getattr(config, field))!r} is invalid; expected {expected}"
        for field, (ok, expected) in expectations.items()
        if not np.all(ok)
    ]
    if wrong:
        raise ValueError(f"{where}: " + "; ".join(wrong))


def ranges(where: str, config: Any, bounds: Mapping[str, tuple[float, float, str]]) -> None:
    """`fields` for numeric fields: each host value (every element, for a batch) within
    ``(low, high, ends)``, `ends` one of "[]", "[)", "(]", "()" saying which ends are
    allowed. A traced value is not a number yet, and is left unchecked."""
    expectations = {}
    for field, (low, high, ends) in bounds.items():
        try:
            value = host_value(getattr(config, field))
        except TypeError:
            expectations[field] = (False, "a number")
            continue
        if value is not None:
            above = value >= low if ends[0] == "[" else value > low
            below = value <= high if ends[1] == "]" else value < high
            expectations[field] = (above & below, f"in {ends[0]}{low}, {high}{ends[1]}")
    fields(where, config, expectations)


def host_value(value: Any) -> np.ndarray | None:
    """A numeric field's value on the host, or None where it is not a number yet (traced,
    or a placeholder JAX puts in a pytree while it rebuilds one: None, object(), a shape).
    Raises TypeError for a string or a bool."""
    if isinstance(value, (str, bytes, bool, np.bool_)):
        raise TypeError(f"a hyperparameter must be a number, not {value!r}")
    if not isinstance(value, (int, float, np.ndarray, np.number, jax.Array)) or isinstance(value, jax.core.Tracer):
        return None
    return np.asarray(value, dtype=np.float64)


def _shown(value: Any) -> Any:
    """A field's value as an error shows it: a batch as a list."""
    return np.asarray(value).tolist() if isinstance(value, (np.ndarray, jax.Array)) and np.ndim(value) else value


def key(who: str, value) -> None:
    """Raises unless `value` is one JAX PRNG key: typed (``jax.random.key(0)``) or a legacy
    uint32 [2] (``jax.random.PRNGKey(0)``)."""
    dtype, shape = getattr(value, "dtype", None), getattr(value, "shape", None)
    typed = dtype is not None and jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key) and shape == ()
    if not (typed or (dtype == np.uint32 and shape == (2,))):
        got = f"{type(value).__name__} {value!r}" if dtype is None else f"an array of {dtype} {shape}"
        raise TypeError(f"{who}: key must be one JAX PRNG key such as jax.random.key(0); got {got}")


class RetraceHazardWarning(UserWarning):
    """A function given to a task is not one fixed module-level function, so `jax.jit`
    sees a new task structure each time the task is built: every rebuilt task (another
    weight, another seed) compiles again, and numbers it captures are trace constants."""


def retrace_hazard(who: str, what: str, fn) -> None:
    """Warns (`RetraceHazardWarning`) when `fn`, or the function a `jax.tree_util.Partial`
    wraps, is a lambda, a nested function or a `functools.partial`: each is a new object
    whenever the code that makes it runs, and a Partial's function is part of its
    pytree structure, compared by identity."""
    func = getattr(fn, "func", fn) if isinstance(fn, jax.tree_util.Partial) else fn
    qualname = getattr(func, "__qualname__", "")
    if isinstance(func, functools.partial):
        why = "a functools.partial (compared by identity)"
    elif qualname.endswith("<lambda>"):
        why = "a lambda"
    elif "<locals>" in qualname:
        why = f"a nested function ({qualname})"
    else:
        return
    captured = [c.cell_contents for c in getattr(func, "__closure__", None) or () if _is_numeric(c)]
    numbers = f", and the numbers it captures ({_preview(captured)}) are constants of the trace" if captured else ""
    warnings.warn(
        f"{who}: {what} is {why}: a rebuilt task holds a new function object, so jax.jit retraces it{numbers}. "
        "Use a module-level function and pass its numbers as leaves (jax.tree_util.Partial(fn, weight), or a named "
        "parameter of mjzoo.task).",
        RetraceHazardWarning,
        stacklevel=_first_caller_outside(),
    )


def _first_caller_outside() -> int:
    """The warning's stack level of the first frame outside the core package: the user's line."""
    frame, level, here = sys._getframe(1), 1, os.path.dirname(__file__)
    while frame is not None and frame.f_code.co_filename.startswith(here + os.sep):
        frame, level = frame.f_back, level + 1
    return level


def _is_numeric(cell) -> bool:
    try:
        value = cell.cell_contents
    except ValueError:  # an empty cell
        return False
    return _is_real(value) or hasattr(value, "dtype")


def _preview(values: list) -> str:
    return ", ".join(repr(v) if _is_real(v) else f"an array {getattr(v, 'shape', ())}" for v in values[:3])


def same_observation(reset_obs, step_obs) -> None:
    """Raises unless a step observes what the episode's first state does (same pytree
    structure, shapes and dtypes), naming the first leaf that differs."""
    reset_leaves, reset_tree = jax.tree_util.tree_flatten_with_path(reset_obs)
    step_leaves, step_tree = jax.tree_util.tree_flatten_with_path(step_obs)
    if reset_tree != step_tree:
        raise ValueError(f"the observation's structure differs between reset ({reset_tree}) and step ({step_tree})")
    for (path, a), (_, b) in zip(reset_leaves, step_leaves):
        (sa, da), (sb, db) = (jnp.shape(a), jnp.result_type(a)), (jnp.shape(b), jnp.result_type(b))
        if (sa, da) != (sb, db):
            raise ValueError(
                f"the observation{jax.tree_util.keystr(path)} differs between reset ({da}{list(sa)}) "
                f"and step ({db}{list(sb)}): a step must observe what the reset does"
            )


def did_you_mean(unknown: Any, known: Any) -> str:
    """`` (did you mean 'num_envs'?)`` for the first of the `unknown` names (an iterable
    of strings) that is close to one of the `known` names, else ``""``: the hint an
    error message about a misspelled name ends with."""
    known = [str(k) for k in known]
    for name in unknown:
        close = difflib.get_close_matches(str(name), known, n=1)
        if close:
            return f" (did you mean {close[0]!r}?)"
    return ""
