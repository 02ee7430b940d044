"""Concrete tasks, by name.

    task = mjzoo.envs.make("cartpole_swingup", upright_weight=2.0, ctrl_dt=0.04)
    mjzoo.envs.names()  # ['cartpole_balance', 'cartpole_swingup', ...]

Every task comes truncated after its episode length and guarded against diverging
physics; overrides change weights, targets, episode length and physics options
(`mjzoo.physics.OPTIONS`) without editing code.
"""

from __future__ import annotations

import difflib
import functools
import inspect
import numbers
from types import ModuleType
from typing import Any, Callable

import numpy as np

from mjzoo import physics
from mjzoo.envs import base, cartpole, cylinder_push, joystick, locomotion, pendulum, point_mass
from mjzoo.planning.realtime import Problem
from mjzoo.planning.sampling import SamplingConfig
from mjzoo.types import Task

__all__ = ["make", "names", "factory", "defaults", "register", "hyperparameters", "planning",
           "closed_loop_problem"]

_REGISTRY: dict[str, Callable[..., Task]] = {
    "pendulum_swingup": pendulum.swingup,
    "cartpole_balance": cartpole.balance,
    "cartpole_swingup": cartpole.swingup,
    "point_mass": point_mass.reach,
    "cylinder_push": cylinder_push.push,
    # Brax's models, from the installed brax package (envs/locomotion.py)
    "hopper": locomotion.hopper,
    "walker": locomotion.walker,
    "cheetah": locomotion.cheetah,
    "ant": locomotion.ant,
    "humanoid_walk": locomotion.humanoid_walk,
    "humanoid_run": locomotion.humanoid_run,
    "humanoid_standup": locomotion.humanoid_standup,
    "ant_joystick": joystick.joystick,  # train with joystick.joystick_curriculum()
}
# Per-env algorithm defaults, defined beside each env.
_HYPERPARAMETERS: dict[str, dict[str, dict[str, Any]]] = {
    "pendulum_swingup": {"ppo": pendulum.PPO, **pendulum.PLANNING.configs},
    "cartpole_balance": {"ppo": cartpole.BALANCE_PPO},
    "cartpole_swingup": {"ppo": cartpole.SWINGUP_PPO, **cartpole.SWINGUP_PLANNING.configs},
    "point_mass": {"ppo": point_mass.PPO, **point_mass.PLANNING.configs},
    "cylinder_push": {"ppo": cylinder_push.PPO, **cylinder_push.PLANNING.configs},
    **{name: {"ppo": config} for name, config in locomotion.PPO.items()},
    "ant_joystick": {"ppo": joystick.PPO},
}
# How the sampling planners solve each env closed loop.
_PLANNING: dict[str, base.PlanningSetup] = {
    "pendulum_swingup": pendulum.PLANNING,
    "cartpole_swingup": cartpole.SWINGUP_PLANNING,
    "point_mass": point_mass.PLANNING,
    "cylinder_push": cylinder_push.PLANNING,
}


def names() -> list[str]:
    """The registered task names, sorted."""
    return sorted(_REGISTRY)


def register(
    name: str,
    factory: Callable[..., Task],
    hyperparameters: dict[str, dict] | None = None,
    planning_setup: base.PlanningSetup | None = None,
) -> None:
    """Adds a task factory (keyword-only arguments, each an override) under `name`, with
    optional per-algorithm default hyperparameters ({"ppo": {...}}) and planning setup."""
    if name in _REGISTRY:
        raise ValueError(f"a task named {name!r} is already registered")
    _REGISTRY[name] = factory
    _HYPERPARAMETERS[name] = dict(hyperparameters or {})
    if planning_setup is not None:
        _PLANNING[name] = planning_setup


def planning(name: str) -> base.PlanningSetup:
    """How the sampling planners solve `name` closed loop (error if no setup exists)."""
    factory(name)
    if name not in _PLANNING:
        raise KeyError(f"{name!r} has no planning setup; envs with one: {sorted(_PLANNING)}")
    return _PLANNING[name]


def closed_loop_problem(
    name: str, planner: ModuleType, config: SamplingConfig, seconds: float | None = None
) -> Problem:
    """The env `name`'s tested closed-loop problem (its `planning` setup): the env as the
    world, its planning view as the planner's model, its hooks and success test, for
    `seconds` (default: the setup's) of simulated time with no episode limit."""
    setup = planning(name)
    return Problem(
        planner=planner, config=config, sim_task=make(name, episode_steps=10**9),
        plan_task=setup.plan_task(functools.partial(make, name), episode_steps=10**9),
        seconds=seconds or setup.seconds, replan_every=setup.replan_every, hooks=setup.hooks, success=setup.success,
    )  # fmt: skip


def hyperparameters(name: str, algorithm: str) -> dict[str, Any]:
    """The env's default config fields for `algorithm` (empty if it has none)."""
    factory(name)
    return dict(_HYPERPARAMETERS.get(name, {}).get(algorithm, {}))


def defaults(name: str) -> dict[str, Any]:
    """The overridable arguments of a task and their default values."""
    signature = inspect.signature(factory(name))
    return {
        k: p.default for k, p in signature.parameters.items() if p.kind == inspect.Parameter.KEYWORD_ONLY
    }


def make(name: str, **overrides: Any) -> Task:
    """Builds the task `name`, with `overrides` of its defaults or of physics options.

    Each override is checked against its default's type first (physics options by
    `physics.load`): a wrong one, e.g. episode_steps="abc" from a command line or a
    config file, would otherwise fail deep inside tracing with a message naming neither."""
    build = factory(name)
    allowed = set(defaults(name)) | set(physics.OPTIONS)
    unknown = sorted(set(overrides) - allowed)
    if unknown:
        raise TypeError(f"{name}: unknown override(s) {unknown}; allowed: {sorted(allowed)}")
    parameters = inspect.signature(build).parameters
    for key, value in overrides.items():
        if key in parameters and parameters[key].kind == inspect.Parameter.KEYWORD_ONLY:
            expected = _expected_type(parameters[key], value)
            if expected:
                raise TypeError(f"{name}: override {key}={value!r} must be {expected}")
    return build(**overrides)


def _expected_type(parameter: inspect.Parameter, value: Any) -> str | None:
    """What `value` should have been for `parameter`, judged by its default (bool is not
    an int; a float accepts an int; a tuple a list, as JSON gives back) and whether its
    annotation admits None; None if it fits or nothing can be judged."""
    default, annotation = parameter.default, str(parameter.annotation)
    optional = default is None or "None" in annotation or "Optional" in annotation
    if value is None and optional:
        return None
    kinds = {bool: ((bool, np.bool_), "True or False"), int: ((numbers.Integral,), "an int"),
             float: ((numbers.Real,), "a number"), str: ((str,), "a string"),
             tuple: ((tuple, list), "a tuple or list"), list: ((tuple, list), "a list or tuple")}  # fmt: skip
    if default is None:
        if "Callable" not in annotation or callable(value):
            return None
        expected = "callable"
    elif type(default) in kinds:
        accepted, expected = kinds[type(default)]
        if isinstance(value, accepted) and (type(default) is bool or not isinstance(value, (bool, np.bool_))):
            return None
        if type(default) is float and getattr(value, "shape", None) == () and hasattr(value, "dtype"):
            if np.issubdtype(value.dtype, np.number):  # a 0-d NumPy or JAX array, e.g. a swept weight
                return None
    else:
        return None
    return expected + (" or None" if optional else "")


def factory(name: str) -> Callable[..., Task]:
    """The function that builds `name` (KeyError naming the registered envs if unknown)."""
    if name not in _REGISTRY:
        close = difflib.get_close_matches(name, _REGISTRY, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise KeyError(f"unknown env {name!r}{hint}; registered envs: {names()}")
    return _REGISTRY[name]
