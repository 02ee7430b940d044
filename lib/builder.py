"""The one way to build a task: from a model and a few plain functions to a `Task`.

    task = mjzoo.task(
        REACHER_XML,                                    # a file, XML text, an MjModel or a loaded Physics
        observe=observe,                                # (p, model, state) -> obs
        rewards={"reach": (reach, 1.0)},                # + weight * fn(p, model, state, action, next_state)
        costs={"effort": (effort, 0.01)},               # - weight * fn(...)
        start=random_arm,                               # (p, model, data, key) -> data | (data, info)
        resets=(random_goal,),                          # more items like start, each with its own key
        terminate={"fell": fell},                       # (p, model, state) -> bool [], or one function
        time_limit=200,
        params={"goal_radius": 0.2},
        ctrl_dt=0.02,                                   # physics options, as mjzoo.physics.load
    )
    task.with_params(reach_weight=2.0, goal_radius=0.1)  # no rebuild, no retrace

Every shipped env (`mjzoo.envs`) is built this way: `envs/pendulum.py` is the plain
example, `envs/locomotion.py` the one made of catalog items.

Every plain function gets the task's named parameters first: `p`, a dict of float32
leaves holding `params` and each term's weight (``"<term>_weight"``, or the parameter
named in its place), and two entries read from the model each call: ``p["dt"]``, the
physics timestep, and ``p["ctrl_dt"]``, the control step (timestep x substeps: the time
one step of the task advances), so they follow a changed or randomized timestep. A `jax.tree_util.Partial` (a catalog item, or ``Partial(fn,
...)``) carries its own numbers and is called without `p`; `named(item, "name", ...)`
moves a catalog item's numbers into `p` under those names. Since every number is a
leaf with a name, `mjzoo.with_params` changes any of them on the built task.

What the task does:
  start: the model at rest at ``qpos0`` (the data template), `start` given the reset key
    itself, then each reset item in order with keys drawn as `catalog.resets.with_resets`
    draws them (what an item returns next to its data goes to `state.info`),
    `mjx.forward`, then `observe`.
  step: the action as the controls (MuJoCo clamps them to ctrlrange) or, with
    `actuator`, the controls it computes before each physics substep, for ctrl_dt / dt
    substeps; then `observe`; `info` is kept. Each named termination is recorded in
    ``metrics["termination/<name>"]`` (1.0 / 0.0).
  reward: ``{name: weight * fn(...)}`` for `rewards`, then ``{name: -weight * fn(...)}``
    for `costs`, each a scalar; `alive` as a term pays 1 per step not terminated.
  terminate: any of the `terminate` functions on the next state (terminated, never
    truncated), or never.
It is guarded against diverging physics (`with_divergence_guard`) and, with
`time_limit`, truncated after that many steps (`with_time_limit`). Without `observe`
it observes joint positions and velocities; without rewards it has no reward term.
"""

from __future__ import annotations

import dataclasses
import keyword
import math
import os
from typing import Any
from typing import Callable
from typing import Mapping
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import batching
from mjzoo import checks
from mjzoo import physics as physics_lib
from mjzoo import solver
from mjzoo.combinators import with_divergence_guard
from mjzoo.combinators import with_time_limit
from mjzoo.tree import StaticValue
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["task", "named", "alive", "joint_state"]

Array = jax.Array
Term = Callable | tuple[Callable, float | str]
_RESETS_STREAM = 0x4E5  # `catalog.resets.RESETS_STREAM`: reset items draw keys as with_resets does
_SUBSTEP_STREAM = 0xAC7  # `catalog.actuators.SUBSTEP_STREAM`: an actuator's keys as actuators.step's
STEPS = ("dt", "ctrl_dt")  # what every function finds in `p` besides the parameters: read from the model


def task(
    model: str | os.PathLike | mujoco.MjModel | physics_lib.Physics,
    *,
    observe: Callable | None = None,
    rewards: Mapping[str, Term] | None = None,
    costs: Mapping[str, Term] | None = None,
    terminate: Callable | Mapping[str, Callable] | None = None,
    start: Callable | None = None,
    resets: Sequence[Callable] = (),
    actuator: Callable | None = None,
    combinators: Sequence[Callable[[Task], Task]] = (),
    time_limit: int | None = None,
    params: Mapping[str, Any] | None = None,
    check: bool = True,
    **physics_options: Any,
) -> Task:
    """A `Task` from a model and plain functions (see the module docstring).

    Args:
      model: an MJCF file path, MJCF text, a compiled `mujoco.MjModel` (then the only
        physics options are ctrl_dt, impl and capacities: set the others on its `opt`),
        or a `mjzoo.physics.Physics` already loaded (no physics options; load it first
        to build catalog items from its ``mj_model``).
      observe: ``(p, model, state) -> obs`` (any pytree of arrays), from ``state.data``
        and ``state.info``; default: `joint_state`, qpos and qvel [nq + nv].
      rewards: ``{name: fn}`` (weight 1) or ``{name: (fn, weight)}``, with ``fn(p,
        model, state, action, next_state) -> scalar`` and `weight` a number (the
        parameter ``"<name>_weight"``) or the name of a parameter; `alive` as `fn` pays
        1 per step that `terminate` does not end.
      costs: as `rewards`, each term charged: ``-weight * fn(...)`` with weight >= 0 as
        a rule, so a weight is a magnitude (``effort_weight=0.01``).
      terminate: ``(p, model, state) -> bool []``, whether `state` ends the episode, or
        ``{name: fn}``: ended when any is true, each recorded in metrics.
      start: ``(p, model, data, key) -> data`` or ``-> (data, {name: value})``, the first
        reset item, given the model at rest and the reset key itself.
      resets: reset items as `start`, after it, each with a key of its own.
      actuator: ``(p, model, data, action, key) -> ctrl [nu]`` evaluated before each
        physics substep (a catalog actuator, e.g. `actuators.pd`); default: the action
        is the controls. With an actuator the task's actions are the actuator's own
        (each in [-1, 1], as the catalog's take them): ``action_dim`` is set to nu, so
        `mjzoo.learning.to_controls` passes a policy's actions through instead of
        stretching them over the ctrlranges (``task.replace(action_dim=2 * nu)`` for
        `actuators.position_velocity`).
      combinators: ``Task -> Task`` functions (catalog ones: commands, latency, noise,
        domain randomization, pushes) applied in order to the model's own task (start,
        step, observation) before the terms: `rewards`, `costs` and `terminate` see the
        states they make (``info["command"]``), and the guard and time limit wrap them.
      time_limit: steps after which an episode is truncated; None: no limit.
      params: named numbers (scalars or arrays) given to every function as `p`, beside
        ``p["dt"]`` and ``p["ctrl_dt"]`` (`STEPS`: the model's timestep and control step,
        names params may not take). A bound may be infinite (a healthy height range ``(0.7, inf)``, a fall angle
        ``inf``: never binds); NaN is refused, and so is an infinite weight (a
        parameter a term names as its weight), whose product with 0 is NaN.
      check: trace a reset and a transition abstractly at construction (below); False
        for a part that combinators added later complete (an observation that reads
        what a tracker wrapped around it keeps).
      **physics_options: `mjzoo.physics.load`'s (dt, ctrl_dt, solver, iterations, ...).
        A model whose bodies can touch and that keeps solver iteration limits above
        10 (MuJoCo's are 100 and 50), none given here, warns once
        (`mjzoo.solver.SolverCostWarning`): a batched MJX step lasts as long as its
        slowest world's solve; ``**mjzoo.solver.SHIPPED`` are the shipped envs' settings.

    Raises ValueError or TypeError at construction, naming the argument: a name that is
    not an identifier or is taken twice, a weight naming no parameter, a function that
    is not callable; and, from one abstract trace of a reset and a transition, a reward
    term or termination that is not a scalar or an observation whose shape changes.
    """
    physics = _physics(model, physics_options)
    if not {"solver", "iterations", "ls_iterations"} & set(physics_options):  # else the caller chose them
        solver.warn_if_costly(physics, "mjzoo.task")  # MuJoCo's default iterations, batched on MJX: slow
    p = _params(params or {})
    ends = terminate if isinstance(terminate, Mapping) else ({} if terminate is None else {"": terminate})
    fns = {}
    for name, fn in ends.items():
        if name:
            _identifier("terminate", name)
        fns[name], p = _function(f"termination {name!r}" if name else "terminate", fn, p)
    observe, p = _function("observe", observe or joint_state, p)
    # A catalog observation is kept as it is, so `mjzoo.interop.deployment` can read it.
    observe, own = (observe.args[0], True) if observe.func is _own_numbers else (observe, False)
    items = []
    for i, fn in enumerate(((start,) if start is not None else ()) + tuple(resets)):
        item, p = _function("start" if start is not None and i == 0 else f"reset item {i}", fn, p)
        items.append(item)
    act = None
    if actuator is not None:
        act, p = _function("actuator", actuator, p)
    weighted = []  # (name, fn, weight's name, kind): the terms, bound once `p` is complete
    for kind, entries in (("reward", rewards), ("cost", costs)):
        for name, entry in (entries or {}).items():
            fn, weight = entry if isinstance(entry, tuple) else (entry, 1.0)
            _identifier(f"{kind}s", name)
            if any(name == other for other, *_ in weighted):
                raise ValueError(f"mjzoo.task: the term {name!r} is both a reward and a cost")
            if isinstance(weight, str):
                if weight not in p:
                    raise ValueError(
                        f"mjzoo.task: the weight of {kind} term {name!r} names the parameter {weight!r}, "
                        f"which params lacks; params: {', '.join(p) or 'none'}"
                    )
                if not np.all(np.isfinite(p[weight])):
                    raise ValueError(
                        f"mjzoo.task: the weight of {kind} term {name!r}, params[{weight!r}]="
                        f"{np.asarray(p[weight]).tolist()}, must be finite"
                    )
            else:
                value = checks.number("mjzoo.task", f"the weight of {name!r}", weight)
                weight, p = f"{name}_weight", _add(p, f"{name}_weight", value)
            if fn is not alive:
                fn, p = _function(f"{kind} term {name!r}", fn, p)
            weighted.append((name, fn, weight, kind))
    spec = Spec(
        observe=observe,
        observe_own=own,
        start=items[0] if start is not None else None,
        resets=tuple(items[1:] if start is not None else items),
        actuator=act,
        data0=physics.data0,
        n_substeps=physics.n_substeps,
    )
    core = Task(
        model=physics.model,
        start=Partial(_start, spec, p),
        step=Partial(_step, spec, p),
        reward=Partial(_no_terms),
        terminate=Partial(_never),
        mj_model=physics.mj_model,
        action_dim=None if actuator is None else int(physics.mj_model.nu),
    )
    for layer in combinators:
        core = layer(core)
        if not isinstance(core, Task):
            raise TypeError(f"mjzoo.task: a combinator returned {type(core).__name__}, not a Task")
    n = StaticValue(physics.n_substeps)
    ended = Partial(_terminate, tuple(fns.values()), p, n, core.terminate)
    terms = {}
    for name, fn, weight, kind in weighted:
        fn = Partial(_own_numbers, Partial(_alive, ended)) if fn is alive else fn
        terms[name] = (fn, StaticValue((weight, kind)))  # strings: no float is static
    ends = {name: fn for name, fn in fns.items() if name}  # the named ones, recorded in metrics
    built = core.replace(
        start=Partial(_start_ends, StaticValue(tuple(ends)), core.start),
        step=Partial(_step_ends, ends, p, n, core.step),
        reward=Partial(_reward, terms, p, n, core.reward),
        terminate=ended,
    )
    built = with_divergence_guard(built)
    if time_limit is not None:
        built = with_time_limit(built, time_limit)
    if check:
        jax.eval_shape(lambda key: built.reset(built.model, key), jax.random.key(0))  # mistakes surface here
    return built


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Spec:
    """How a built task starts and steps (Partials taking `p` first); the numbers live in `p`."""

    observe: jax.tree_util.Partial  # a catalog item (observe_own) or a function of `p` first
    start: jax.tree_util.Partial | None
    resets: tuple[jax.tree_util.Partial, ...]
    actuator: jax.tree_util.Partial | None
    data0: mjx.Data  # the reset template, `Physics.data0`
    n_substeps: int = dataclasses.field(metadata=dict(static=True))
    observe_own: bool = dataclasses.field(default=False, metadata=dict(static=True))

    def observed(self, p: dict, model: mjx.Model, state: State):
        return self.observe(model, state) if self.observe_own else self.observe(p, model, state)


def joint_state(p: dict, model: mjx.Model, state: State) -> Array:
    """[nq + nv]: joint positions (rad or m, quaternions for free and ball joints) and
    velocities; the default observation."""
    return jnp.concatenate([state.data.qpos, state.data.qvel])


def alive(p: dict, model: mjx.Model, state: State, action: Array, next_state: State) -> Array:
    """Reward term: 1 per transition that the task's `terminate` does not end, else 0.
    A marker: `task` puts its own terminations in its place."""
    raise TypeError("mjzoo.builder.alive is a reward term of mjzoo.task, which binds it to the task's terminations")


def named(item: jax.tree_util.Partial, *names: str) -> jax.tree_util.Partial:
    """A catalog item whose numbers are the task's named parameters `names`.

    The item's floating-point leaves (in the order its constructor binds them; integer
    indices are not numbers to tune) become the parameters `names`, one each, with the
    item's values as defaults: a scalar where all of a leaf's values are equal (a
    per-joint scale given as one number), else the array. Two items may share a name
    (one reset noise for positions and velocities) if their values agree.

        terminate={"too_low": named(terminations.base_too_low(m, 0.7), "min_height")}
    """
    if not isinstance(item, jax.tree_util.Partial):
        raise TypeError(f"mjzoo.named: expected a catalog item (a jax.tree_util.Partial), got {type(item).__name__}")
    slots = [i for i, leaf in enumerate(jax.tree.leaves((item.args, item.keywords))) if _floating(leaf)]
    if len(slots) != len(names):
        raise ValueError(
            f"mjzoo.named: {getattr(item.func, '__name__', item.func)} binds {len(slots)} number(s), "
            f"but {len(names)} name(s) were given: {names}"
        )
    for name in names:
        _parameter_name("named", name)
    return _Named(item, tuple(zip(slots, names)))


@dataclasses.dataclass(frozen=True)
class _Named:
    item: jax.tree_util.Partial
    slots: tuple[tuple[int, str], ...]  # (leaf index, parameter name)

    def __call__(self, *args):
        raise TypeError("mjzoo.named(...) is an argument of mjzoo.task, which gives it the task's parameters")


# --- the task's four functions ------------------------------------------------------


def _timed(p: dict, model: mjx.Model, n_substeps: int) -> dict:
    """`p` with `STEPS`, read from the model on every call: a changed or randomized
    timestep is the one the functions see."""
    dt = jnp.asarray(model.opt.timestep, jnp.float32)
    return {**p, "dt": dt, "ctrl_dt": dt * n_substeps}


def _start(spec: Spec, p: dict, model: mjx.Model, key: Array) -> State:
    p = _timed(p, model, spec.n_substeps)
    data, info = spec.data0, {}
    keys = jax.random.split(jax.random.fold_in(key, _RESETS_STREAM), max(len(spec.resets), 1))
    calls = ([(spec.start, key)] if spec.start is not None else []) + list(zip(spec.resets, keys))
    for item, item_key in calls:
        out = item(p, model, data, item_key)
        data, written = out if isinstance(out, tuple) else (out, {})
        info.update(written)
    state = State.create(physics_lib.forward(model, data), jnp.zeros((0,), jnp.float32), info)
    return state.replace(obs=spec.observed(p, model, state))


def _step(spec: Spec, p: dict, model: mjx.Model, state: State, action: Array, key: Array) -> State:
    p = _timed(p, model, spec.n_substeps)
    action = jnp.asarray(action, jnp.float32)
    if spec.actuator is None:
        data = physics_lib.step(model, state.data, action, spec.n_substeps)
    else:
        data = _actuated(spec.actuator, p, model, state.data, action, spec.n_substeps, key)
    next_state = state.replace(data=data)
    return next_state.replace(obs=spec.observed(p, model, next_state))


def _actuated(actuator, p: dict, model: mjx.Model, data: mjx.Data, action: Array, n_substeps: int, key: Array):
    """`n_substeps` physics steps, the controls from `actuator` before each (as
    `catalog.actuators.step`: key_i = fold_in(fold_in(key, tag), i))."""
    key = jax.random.fold_in(key, _SUBSTEP_STREAM)

    def substep(i, data: mjx.Data) -> mjx.Data:
        ctrl = actuator(p, model, data, action, jax.random.fold_in(key, i))
        return physics_lib.substep(model, data.replace(ctrl=jnp.asarray(ctrl, data.ctrl.dtype)))

    return jax.lax.fori_loop(0, n_substeps, substep, batching.clear_overflow(data))


def _start_ends(names: StaticValue, start_fn, model: mjx.Model, key: Array) -> State:
    """The start, each named termination's metric at 0."""
    state = start_fn(model, key)
    if not names.value:
        return state
    zeros = {f"termination/{name}": jnp.zeros((), jnp.float32) for name in names.value}
    return state.replace(metrics={**state.metrics, **zeros})


def _step_ends(ends: dict, p: dict, n: StaticValue, step_fn, model, state: State, action: Array, key: Array) -> State:
    """The step, each named termination recorded on the state it returns (1.0 / 0.0)."""
    next_state = step_fn(model, state, action, key)
    if not ends:
        return next_state
    p = _timed(p, model, n.value)
    flags = {f"termination/{name}": _flag(fn, p, model, next_state) for name, fn in ends.items()}
    return next_state.replace(metrics={**next_state.metrics, **flags})


def _reward(weighted: dict, p: dict, n: StaticValue, reward_fn, model, state, action, next_state) -> dict[str, Array]:
    """The inner task's terms, then each ``name: (fn, StaticValue((weight's name, kind)))``,
    a "cost" charged."""
    p = _timed(p, model, n.value)
    terms = dict(reward_fn(model, state, action, next_state))
    for name, (fn, weight) in weighted.items():
        weight_name, kind = weight.value
        value = p[weight_name] * fn(p, model, state, action, next_state)
        terms[name] = -value if kind == "cost" else value
    return terms


def _flag(fn, p: dict, model: mjx.Model, state: State) -> Array:
    return jnp.asarray(fn(p, model, state), bool).astype(jnp.float32)


def _terminate(fns: tuple, p: dict, n: StaticValue, terminate_fn, model, state: State) -> tuple[Array, Array]:
    terminated, truncated = terminate_fn(model, state)
    terminated = jnp.asarray(terminated, bool)
    if fns:
        p = _timed(p, model, n.value)
        terminated = terminated | jnp.any(jnp.stack([jnp.asarray(fn(p, model, state), bool) for fn in fns]))
    return terminated, jnp.asarray(truncated, bool) & ~terminated


def _no_terms(model, state, action, next_state) -> dict[str, Array]:
    return {}


def _never(model: mjx.Model, state: State) -> tuple[Array, Array]:
    return jnp.zeros((), bool), jnp.zeros((), bool)


def _alive(terminate_fn, model, state, action, next_state) -> Array:
    terminated, _ = terminate_fn(model, next_state)
    return 1.0 - jnp.asarray(terminated, jnp.float32)


def _own_numbers(item: jax.tree_util.Partial, p: dict, *args):
    """A Partial (a catalog item) carries its own numbers: called without `p`."""
    return item(*args)


def _with_named(func, leaves: tuple, treedef: StaticValue, slots: StaticValue, p: dict, *args):
    """A catalog item called with its numbered leaves taken from `p` (`named`)."""
    leaves = list(leaves)
    for index, name in slots.value:
        leaves[index] = jnp.broadcast_to(p[name], jnp.shape(leaves[index])).astype(_dtype(leaves[index]))
    bound_args, keywords = jax.tree.unflatten(treedef.value, leaves)
    return func(*bound_args, *args, **keywords)


# --- construction -------------------------------------------------------------------


def _function(what: str, fn, p: dict) -> tuple[jax.tree_util.Partial, dict]:
    """`fn` as a Partial taking `p` first, and `p` with the numbers `named` adds."""
    if isinstance(fn, _Named):
        leaves, treedef = jax.tree.flatten((fn.item.args, fn.item.keywords))
        for index, name in fn.slots:
            value = np.asarray(leaves[index], np.float64)
            value = value.ravel()[0] if value.size and np.all(value == value.ravel()[0]) else value
            if name in p and not np.array_equal(np.asarray(p[name]), np.asarray(value, np.float32)):
                given, have = np.asarray(value).tolist(), np.asarray(p[name]).tolist()
                raise ValueError(f"mjzoo.task: {what} gives {name}={given}, but the task already has {name}={have}")
            p = {**p, name: p[name] if name in p else jnp.asarray(value, jnp.float32)}
        func = jax.tree_util.Partial(fn.item.func)  # the function in the treedef, not a leaf
        return Partial(_with_named, func, tuple(leaves), StaticValue(treedef), StaticValue(fn.slots)), p
    if not callable(fn):
        raise TypeError(f"mjzoo.task: {what} must be callable, got {type(fn).__name__}")
    checks.retrace_hazard("mjzoo.task", what, fn)
    if isinstance(fn, jax.tree_util.Partial):
        return Partial(_own_numbers, fn), p
    return jax.tree_util.Partial(fn), p


def _floating(leaf) -> bool:
    try:
        return isinstance(leaf, float) or np.issubdtype(_dtype(leaf), np.floating)
    except TypeError:  # a PRNG key's dtype
        return False


def _dtype(leaf):
    """A leaf's dtype as JAX holds it: a Python float float32 (weakly typed), float64
    float32 unless x64 is on."""
    if isinstance(leaf, float):
        return np.dtype(np.float32)
    return jax.dtypes.canonicalize_dtype(leaf.dtype if hasattr(leaf, "dtype") else np.asarray(leaf).dtype)


def _params(values: Mapping[str, Any]) -> dict[str, Array]:
    """`values` as float32 leaves: numbers, +-inf allowed (bounds), NaN never."""
    p = {}
    for name, value in values.items():
        _parameter_name("params", name)
        array = np.asarray(value, np.float64) if _numeric(value) else None
        if array is None or np.any(np.isnan(array)):
            raise ValueError(f"mjzoo.task: params[{name!r}]={value!r} must be numbers (+-inf for a bound), not NaN")
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
    return {**p, name: jnp.asarray(value, jnp.float32)}


def _identifier(where: str, name) -> None:
    if not (isinstance(name, str) and name.isidentifier() and not keyword.iskeyword(name)):
        raise ValueError(f"mjzoo.task: {where} name {name!r} must be a Python identifier (usable in with_params)")


def _parameter_name(where: str, name) -> None:
    _identifier(where, name)
    if name in STEPS:  # a copy would drift from the model's timestep
        raise ValueError(
            f"mjzoo.task: {where} name {name!r} is taken: every function finds the model's {name} in "
            f"p[{name!r}], read from the model each step; drop it from {where}"
        )


def _physics(model, options: dict[str, Any]) -> physics_lib.Physics:
    unknown = sorted(set(options) - set(physics_lib.OPTIONS))
    if unknown:
        raise TypeError(
            f"mjzoo.task: unknown physics option {', '.join(unknown)}; options: {', '.join(physics_lib.OPTIONS)}"
        )
    if isinstance(model, physics_lib.Physics):
        if options:
            raise ValueError("mjzoo.task: a loaded Physics takes no physics options; give them to mjzoo.physics.load")
        return model
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
