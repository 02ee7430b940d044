"""A kit for one's own task: from an MJCF model and a few plain functions to a `Task`.

    task = mjzoo.task(
        REACHER_XML,                                    # a file, an XML string or an MjModel
        observe=observe,                                # (p, model, state) -> obs
        rewards={"reach": (reach, 1.0), "effort": (effort, "effort_weight")},
        resets=(random_arm, random_goal),               # (p, model, data, key) -> data | (data, info)
        terminate=None,                                 # (p, model, state) -> bool []
        time_limit=200,
        params={"effort_weight": -0.01, "goal_radius": 0.2},
        ctrl_dt=0.02,                                   # physics options, as mjzoo.physics.load
    )
    task.with_params(reach_weight=2.0)                  # no rebuild, no retrace

Every plain function gets the task's named parameters first: `p`, a dict of float32
leaves holding `params` and each reward term's weight (``"<term>_weight"``, or the
parameter named in its place). A `jax.tree_util.Partial` (a catalog item, or
``mjzoo.bind(fn, ...)``) carries its own numbers and is called without `p`. Since
every number is a leaf, `mjzoo.with_params` changes any of them on the built task.

What the task does:
  start: the model's ``qpos0`` at rest, then each reset item in order (each with its own
    key; what an item returns next to its data goes to `state.info`), `mjx.forward`,
    then `observe`.
  step: the action as the controls (MuJoCo clamps them to ctrlrange), held for ctrl_dt
    / dt physics steps, then `observe`; `info` is kept.
  reward: ``{name: weight * fn(p, model, state, action, next_state)}``, each a scalar.
  terminate: `terminate` on the next state (terminated, never truncated), or never.
It is guarded against diverging physics (`with_divergence_guard`) and, with
`time_limit`, truncated after that many steps (`with_time_limit`). Without `observe`
it observes joint positions and velocities; without rewards it has no reward term.
"""

from __future__ import annotations

import dataclasses
import keyword
import math
import os
from typing import Any, Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjzoo import checks
from mjzoo import physics as physics_lib
from mjzoo.combinators import with_divergence_guard, with_time_limit
from mjzoo.tree import Static
from mjzoo.types import State, Task, bind

__all__ = ["task", "joint_state"]

Array = jax.Array
Term = Callable | tuple[Callable, float | str]


def task(
    model: str | os.PathLike | mujoco.MjModel,
    *,
    observe: Callable | None = None,
    rewards: Mapping[str, Term] | None = None,
    terminate: Callable | None = None,
    resets: Sequence[Callable] = (),
    time_limit: int | None = None,
    params: Mapping[str, Any] | None = None,
    **physics_options: Any,
) -> Task:
    """A `Task` from a model and plain functions (see the module docstring).

    Args:
      model: an MJCF file path, MJCF text, or a compiled `mujoco.MjModel` (then the only
        physics option is ctrl_dt: set the others on its `opt`).
      observe: ``(p, model, state) -> obs`` (any pytree of arrays), from ``state.data``
        and ``state.info``; default: `joint_state`, qpos and qvel [nq + nv].
      rewards: ``{name: fn}`` (weight 1) or ``{name: (fn, weight)}``, with ``fn(p,
        model, state, action, next_state) -> scalar`` and `weight` a number (the
        parameter ``"<name>_weight"``) or the name of a parameter.
      terminate: ``(p, model, state) -> bool []``, whether `state` ends the episode.
      resets: reset items ``(p, model, data, key) -> data`` or ``-> (data, {name:
        value})``, the entries kept in `state.info` (a goal, a target).
      time_limit: steps after which an episode is truncated; None: no limit.
      params: named numbers (scalars or arrays) given to every function as `p`.
      **physics_options: `mjzoo.physics.load`'s (dt, ctrl_dt, solver, iterations, ...).

    Raises ValueError or TypeError at construction, naming the argument: a name that is
    not an identifier or is taken twice, a weight naming no parameter, a function that
    is not callable; and, from one abstract trace of a reset and a transition, a reward
    term or termination that is not a scalar or an observation whose shape changes.
    """
    physics = _physics(model, physics_options)
    p = _params(params or {})
    terms = {}
    for name, entry in (rewards or {}).items():
        fn, weight = entry if isinstance(entry, tuple) else (entry, 1.0)
        _identifier("rewards", name)
        if isinstance(weight, str):
            if weight not in p:
                raise ValueError(
                    f"mjzoo.task: the weight of reward term {name!r} names the parameter {weight!r}, "
                    f"which params lacks; params: {', '.join(p) or 'none'}"
                )
        else:
            value = checks.number("mjzoo.task", f"the weight of {name!r}", weight)
            weight, p = f"{name}_weight", _add(p, f"{name}_weight", value)
        terms[name] = (_function(f"reward term {name!r}", fn), Static(weight))
    spec = Spec(
        observe=_function("observe", observe or joint_state),
        terms=terms,
        terminate=None if terminate is None else _function("terminate", terminate),
        resets=tuple(_function(f"reset item {i}", fn) for i, fn in enumerate(resets)),
        data0=physics.data0,
        n_substeps=physics.n_substeps,
    )
    built = Task(
        model=physics.model,
        start=bind(_start, spec, p),
        step=bind(_step, spec, p),
        reward=bind(_reward, spec, p),
        terminate=bind(_terminate, spec, p),
        mj_model=physics.mj_model,
    )
    built = with_divergence_guard(built)
    if time_limit is not None:
        built = with_time_limit(built, time_limit)
    jax.eval_shape(lambda key: built.reset(built.model, key), jax.random.key(0))  # mistakes surface here
    return built


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Spec:
    """The functions of a kit task (Partials taking `p` first); the numbers live in `p`."""

    observe: jax.tree_util.Partial
    terms: dict[str, tuple[jax.tree_util.Partial, Static]]
    terminate: jax.tree_util.Partial | None
    resets: tuple[jax.tree_util.Partial, ...]
    data0: mjx.Data  # the reset template, `Physics.data0`
    n_substeps: int = dataclasses.field(metadata=dict(static=True))


def joint_state(p: dict, model: mjx.Model, state: State) -> Array:
    """[nq + nv]: joint positions (rad or m, quaternions for free and ball joints) and
    velocities; the default observation."""
    return jnp.concatenate([state.data.qpos, state.data.qvel])


# --- the task's four functions ------------------------------------------------------


def _start(spec: Spec, p: dict, model: mjx.Model, key: Array) -> State:
    data, info = spec.data0, {}
    for item, item_key in zip(spec.resets, jax.random.split(key, len(spec.resets))):
        out = item(p, model, data, item_key)
        data, written = out if isinstance(out, tuple) else (out, {})
        info.update(written)
    state = State.create(physics_lib.forward(model, data), jnp.zeros((0,), jnp.float32), info)
    return state.replace(obs=spec.observe(p, model, state))


def _step(spec: Spec, p: dict, model: mjx.Model, state: State, action: Array, key: Array) -> State:
    data = physics_lib.step(model, state.data, jnp.asarray(action, jnp.float32), spec.n_substeps)
    next_state = state.replace(data=data)
    return next_state.replace(obs=spec.observe(p, model, next_state))


def _reward(spec: Spec, p: dict, model, state, action, next_state) -> dict[str, Array]:
    terms = spec.terms.items()
    return {name: p[weight.value] * fn(p, model, state, action, next_state) for name, (fn, weight) in terms}


def _terminate(spec: Spec, p: dict, model: mjx.Model, state: State) -> tuple[Array, Array]:
    never = jnp.zeros((), bool)
    return (never if spec.terminate is None else spec.terminate(p, model, state)), never


def _own_numbers(item: jax.tree_util.Partial, p: dict, *args):
    """A Partial (a catalog item) carries its own numbers: called without `p`."""
    return item(*args)


# --- construction -------------------------------------------------------------------


def _function(what: str, fn) -> jax.tree_util.Partial:
    if not callable(fn):
        raise TypeError(f"mjzoo.task: {what} must be callable, got {type(fn).__name__}")
    checks.retrace_hazard("mjzoo.task", what, fn)
    return bind(_own_numbers, fn) if isinstance(fn, jax.tree_util.Partial) else jax.tree_util.Partial(fn)


def _params(values: Mapping[str, Any]) -> dict[str, Array]:
    p = {}
    for name, value in values.items():
        _identifier("params", name)
        array = np.asarray(value, np.float64) if _numeric(value) else None
        if array is None or not np.all(np.isfinite(array)):
            raise ValueError(f"mjzoo.task: params[{name!r}]={value!r} must be finite numbers")
        p[name] = jnp.asarray(array, jnp.float32)
    return p


def _numeric(value) -> bool:
    try:
        return np.asarray(value).dtype.kind in "biuf"
    except (TypeError, ValueError):
        return False


def _add(p: dict, name: str, value: Array) -> dict:
    if name in p:
        raise ValueError(
            f"mjzoo.task: the parameter {name!r} is given in params and as a reward term's weight; "
            f"give the term the weight {name!r} (its name) or drop it from params"
        )
    return {**p, name: value}


def _identifier(where: str, name) -> None:
    if not (isinstance(name, str) and name.isidentifier() and not keyword.iskeyword(name)):
        raise ValueError(f"mjzoo.task: {where} name {name!r} must be a Python identifier (usable in with_params)")


def _physics(model, options: dict[str, Any]) -> physics_lib.Physics:
    unknown = sorted(set(options) - set(physics_lib.OPTIONS))
    if unknown:
        raise TypeError(
            f"mjzoo.task: unknown physics option {', '.join(unknown)}; options: {', '.join(physics_lib.OPTIONS)}"
        )
    if not isinstance(model, mujoco.MjModel):
        return physics_lib.load(model, **options)
    if set(options) - {"ctrl_dt", "impl", "max_contacts", "max_constraints"}:
        raise ValueError(
            "mjzoo.task: for an MjModel, set physics options other than ctrl_dt, impl and the capacities on model.opt"
        )
    dt = float(model.opt.timestep)
    ctrl_dt = checks.number("mjzoo.task", "ctrl_dt", options.get("ctrl_dt", dt), 0.0, open_low=True)
    n_substeps = round(float(ctrl_dt) / dt)
    if n_substeps < 1 or not math.isclose(n_substeps * dt, float(ctrl_dt), rel_tol=1e-6):
        raise ValueError(f"mjzoo.task: ctrl_dt={float(ctrl_dt)} must be a whole multiple of the model's dt={dt}")
    impl = options.get("impl") or physics_lib.default_impl()
    if impl not in physics_lib.IMPLS:
        raise ValueError(
            f"mjzoo.task: physics option impl={impl!r} is invalid; expected one of {list(physics_lib.IMPLS)}"
        )
    return physics_lib.of_model(model, n_substeps, impl, options.get("max_contacts"), options.get("max_constraints"))
