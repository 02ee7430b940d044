"""Concrete tasks, by name or as a user's own factory.

    task = mjzoo.envs.make("cartpole_swingup", upright_weight=2.0, ctrl_dt=0.04)
    mjzoo.envs.names()  # ['cartpole_balance', 'cartpole_swingup', ...]
    task = mjzoo.envs.make("my_pkg.my_module:make_task", mass=2.0)  # any function returning a Task

Every function here takes a *task spec*: a registered name, ``package.module:factory``
naming a function whose keyword arguments are the overrides, or ``playground:NAME``, a
MuJoCo Playground env through `mjzoo.interop.playground` (its config fields the
overrides; needs ``pip install 'mjzoo[playground]'``). A registered env's record
(`EnvSpec`, `record(name)`) holds its factory, hyperparameters, planning setup and,
for AMP, the motion to imitate (`reference`); a factory's module may define
``PLANNING`` (a `base.PlanningSetup`) for `mjzoo plan` and ``REFERENCE`` (a function
``(task, **overrides) -> mjzoo.motion.Reference``, as `EnvSpec.reference`) for
`mjzoo train amp`; Playground envs plan with `PLAYGROUND_PLANNING`.

    task = mjzoo.envs.make("humanoid_amp_walk", ctrl_dt=0.01)
    reference = mjzoo.envs.reference("humanoid_amp_walk", task, ctrl_dt=0.01)  # for amp.make

Every task comes truncated after its episode length and guarded against diverging
physics; overrides change weights, targets, episode length and physics options
(`mjzoo.physics.OPTIONS`) without editing code.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
import numbers
import warnings
from types import ModuleType
from typing import TYPE_CHECKING
from typing import Any
from typing import Callable

import numpy as np

from mjzoo import checks
from mjzoo import motion
from mjzoo import physics
from mjzoo.envs import base
from mjzoo.envs import cartpole
from mjzoo.envs import cylinder_push
from mjzoo.envs import humanoid_amp
from mjzoo.envs import joystick
from mjzoo.envs import leap_cube
from mjzoo.envs import locomotion
from mjzoo.envs import motion_tracking
from mjzoo.envs import panda_pick
from mjzoo.envs import pendulum
from mjzoo.envs import point_mass
from mjzoo.envs import robot_amp
from mjzoo.envs import robot_joystick
from mjzoo.envs import robot_planning
from mjzoo.envs import teachers
from mjzoo.running import control_dt
from mjzoo.running import episode_steps
from mjzoo.types import Task

EnvSpec = base.EnvSpec

if TYPE_CHECKING:
    from mjzoo.planning.realtime import Problem
    from mjzoo.planning.sampling import SamplingConfig

__all__ = [
    "make",
    "names",
    "factory",
    "defaults",
    "accepts",
    "register",
    "record",
    "EnvSpec",
    "hyperparameters",
    "planning",
    "closed_loop_problem",
    "reference",
    "PLAYGROUND",
    "PLAYGROUND_PLANNING",
]

# One typed record per env (`base.EnvSpec`), defined beside it in its module: the factory,
# its hyperparameters per algorithm, its closed-loop planning setup.
_REGISTRY: dict[str, base.EnvSpec] = {
    "pendulum_swingup": pendulum.SWINGUP,
    "cartpole_balance": cartpole.BALANCE,
    "cartpole_swingup": cartpole.SWINGUP,
    "point_mass": point_mass.REACH,
    "cylinder_push": cylinder_push.PUSH,
    # Brax's models, from the installed brax package (envs/locomotion.py)
    "hopper": locomotion.HOPPER,
    "walker": locomotion.WALKER,
    "cheetah": locomotion.CHEETAH,
    "ant": locomotion.ANT,
    "humanoid_walk": locomotion.HUMANOID_WALK,
    "humanoid_run": locomotion.HUMANOID_RUN,
    "humanoid_standup": locomotion.HUMANOID_STANDUP,
    "ant_joystick": joystick.JOYSTICK,  # train with joystick.joystick_curriculum()
    # Real robots: Playground's scenes of Menagerie's models (envs/robot_joystick.py; mjzoo[robots])
    "g1_joystick": robot_joystick.G1,
    "t1_joystick": robot_joystick.T1,
    "berkeley_humanoid_joystick": robot_joystick.BERKELEY_HUMANOID,
    "go1_joystick": robot_joystick.GO1,
    "g1_amp_joystick": robot_amp.G1_AMP_JOYSTICK,  # AMP from retargeted human motion (envs/robot_amp.py)
    # Whole-body motion tracking of retargeted clips (envs/motion_tracking.py; mjzoo[robots])
    "g1_track": motion_tracking.G1_TRACK,
    # Whole-body MPC on real robots (envs/robot_planning.py; mjzoo[robots])
    "g1_standup": robot_planning.G1_STANDUP,
    "go1_trot": robot_planning.GO1_TROT,
    "leap_cube_rotate": leap_cube.LEAP_CUBE_ROTATE,  # dexterous manipulation (envs/leap_cube.py)
    "panda_pick": panda_pick.PANDA_PICK,  # a Panda lifts a cube (envs/panda_pick.py)
    # AMP: move like a reference motion (envs/humanoid_amp.py)
    "humanoid_amp_walk": humanoid_amp.WALK,
    "humanoid_amp_joystick": humanoid_amp.JOYSTICK,
    "cartpole_amp_swingup": teachers.CARTPOLE_AMP_SWINGUP,  # MPPI's swing-up as the reference
}
# A user's factory without `PLANNING`: one episode (`closed_loop_problem` measures it),
# replanning every step, the planners' own default configs, no success criterion.
_ONE_EPISODE = base.PlanningSetup(seconds=None, replan_every=1, plan_overrides={}, configs={}, success=None)
_LEARNERS = ("ppo", "amp", "sac", "fast_td3")  # the RL algorithms an env records config fields for
PLAYGROUND = "playground:"  # the spec prefix of MuJoCo Playground's envs
# Playground's envs: one episode, replanning every control step, 1 s horizons at the
# DM Control Suite's control steps (0.01-0.04 s: 25-100 steps); rewards are in [0, 1] per
# step, so MPPI's temperature is in those units.
_PLAYGROUND_SAMPLING = dict(num_samples=128, horizon_steps=50, num_knots=4, noise_scale=0.3)
PLAYGROUND_PLANNING = base.PlanningSetup(
    seconds=None,
    replan_every=1,
    plan_overrides={},
    success=None,
    configs={
        "predictive_sampling": _PLAYGROUND_SAMPLING,
        "mppi": dict(_PLAYGROUND_SAMPLING, temperature=0.1),
        "cem": dict(_PLAYGROUND_SAMPLING, num_elites=8, sigma_min=0.1),
        "dial": dict(_PLAYGROUND_SAMPLING, iterations=2, temperature=1.0, beta_horizon=4.0),
        "cma_es": dict(_PLAYGROUND_SAMPLING, num_elites=8),
        "ilqr": dict(horizon_steps=_PLAYGROUND_SAMPLING["horizon_steps"], iterations=3),
    },
)
# Per env where the shared setup fails: Playground's pendulum pays reward only within ~8
# degrees of upright, which noise of 0.3 over 0.5 s never reaches from hanging down.
_PLAYGROUND_TUNED = {"PendulumSwingup": dict(horizon_steps=100, noise_scale=1.0)}


def names() -> list[str]:
    """The registered task names, sorted."""
    return sorted(_REGISTRY)


def record(name: str) -> base.EnvSpec:
    """The registered env's record (KeyError naming the registered ones if unknown)."""
    factory(name)
    return _REGISTRY[name]


def register(
    name: str,
    factory: Callable[..., Task] | base.EnvSpec,
    hyperparameters: dict[str, dict] | None = None,
    planning_setup: base.PlanningSetup | None = None,
) -> None:
    """Adds an env under `name`: its record (`base.EnvSpec`), or a task factory
    (keyword-only arguments, each an override) with optional default hyperparameters
    ({"ppo": {...}, "amp": {...}, "sac": ..., "fast_td3": ...}) and planning setup (which
    holds the planners')."""
    if name in _REGISTRY:
        raise ValueError(f"a task named {name!r} is already registered")
    if isinstance(factory, base.EnvSpec):
        if hyperparameters or planning_setup:
            raise ValueError("register: an EnvSpec carries its own hyperparameters and planning setup")
        _REGISTRY[name] = factory
        return
    learned = dict(hyperparameters or {})
    others = sorted(set(learned) - set(_LEARNERS))
    if others:
        raise ValueError(f"register: hyperparameters for {others} belong in the planning setup's configs")
    _REGISTRY[name] = base.EnvSpec(
        make=factory,
        description=(factory.__doc__ or "").strip().partition("\n")[0],
        **{name: learned.get(name) for name in _LEARNERS},
        planning=planning_setup,
    )


def planning(spec: str) -> base.PlanningSetup:
    """How the sampling planners solve `spec` closed loop: a registered env's setup (error
    if it has none), a user module's ``PLANNING`` (default: one episode, replanning
    every step, no success criterion), or `PLAYGROUND_PLANNING` for a Playground env
    (with a longer, wider search for the ones it does not solve: the pendulum)."""
    factory(spec)
    if _is_playground(spec):
        tuned = _PLAYGROUND_TUNED.get(_playground_name(spec), {})
        configs = {planner: {**config, **tuned} for planner, config in PLAYGROUND_PLANNING.configs.items()}
        return dataclasses.replace(PLAYGROUND_PLANNING, configs=configs)
    if _is_user(spec):
        setup = getattr(importlib.import_module(spec.partition(":")[0]), "PLANNING", _ONE_EPISODE)
        if not isinstance(setup, base.PlanningSetup):
            raise TypeError(
                f"{spec}: its module's PLANNING (type {type(setup).__name__}) is not a mjzoo.envs.base.PlanningSetup"
            )
        return setup
    setup = _REGISTRY[spec].planning
    if setup is None:
        planned = sorted(name for name, entry in _REGISTRY.items() if entry.planning is not None)
        raise KeyError(f"{spec!r} has no planning setup; envs with one: {planned}")
    return setup


def closed_loop_problem(
    spec: str,
    planner: ModuleType,
    config: SamplingConfig,
    seconds: float | None = None,
    backend: str = "auto",
    hyperparams: Any | None = None,
    sim_backend: str | None = None,
    plan_overrides: dict[str, Any] | None = None,
    **overrides: Any,
) -> Problem:
    """The task's closed-loop problem (its `planning` setup): the task as the world, its
    planning view as the planner's model, its hooks and success test, for `seconds`
    (default: the setup's, else one episode) of simulated time, on `backend` ("mjx",
    "native": C MuJoCo; "auto": native on a CPU). Registered envs run with no episode
    limit; `overrides` go to both tasks. A Playground env steps MJX itself, so it plans
    on MJX ("auto": "mjx", with a warning on a CPU; "native" is refused). `hyperparams`:
    the planner's numbers (None: its defaults; `mjzoo.planning.configure`). `sim_backend`:
    where the world steps if not on `backend` ("native": C MuJoCo beside an MJX planner).
    A model stepped natively is built on MJX-JAX (``impl="jax"``), whose states C MuJoCo
    replays (a planner on MuJoCo Warp starts each replan from it: `mjzoo.physics.switch_impl`).
    `plan_overrides` go to the planning task alone, over the setup's own: a planner's
    model may be coarser than the world, e.g. ``dict(dt=0.01, iterations=2)``."""
    # Imported here, not at the top: the registry is data (records of envs) and loads
    # nothing of the real-time machinery until a problem is asked for.
    from mjzoo.planning.realtime import Problem
    from mjzoo.planning.realtime import default_backend
    from mjzoo.planning.realtime import resolve_backend

    setup = planning(spec)
    if plan_overrides:
        setup = dataclasses.replace(setup, plan_overrides={**setup.plan_overrides, **plan_overrides})
    build = functools.partial(make, spec, **overrides)
    if _is_playground(spec):
        if backend == "native":
            raise ValueError(
                f"{spec}: Playground's envs step MJX themselves, which native C rollouts cannot replay; "
                "plan with backend 'mjx'"
            )
        if backend == "auto" and default_backend() == "native":  # say why a CPU plans on the slower engine
            warnings.warn(
                f"{spec}: planning on MJX, not native C MuJoCo (auto's choice on a CPU): Playground's envs "
                "step MJX themselves, which native C rollouts cannot replay",
                stacklevel=2,
            )
        backend = "mjx"
    own_limit = _is_user(spec) or _is_playground(spec)  # a factory may not take episode_steps
    unlimited = {} if own_limit else {"episode_steps": 10**9}
    # C MuJoCo replays a model's states through MJX's JAX implementation, so a model that
    # steps natively is built on it, whatever `impl` says (MuJoCo Warp is a GPU host's default).
    on_jax = {"impl": "jax"} if accepts(spec, "impl", catch_all=False) else {}

    def builder(stepped_on: str) -> Callable[..., Task]:
        return functools.partial(build, **on_jax) if resolve_backend(planner, stepped_on) == "native" else build

    sim_task = builder(sim_backend or backend)(**unlimited)
    seconds = seconds or setup.seconds or episode_steps(sim_task, spec, "seconds") * control_dt(sim_task)
    return Problem(
        planner=planner,
        config=config,
        sim_task=sim_task,
        plan_task=setup.plan_task(builder(backend), **unlimited),
        seconds=seconds,
        replan_every=setup.replan_every,
        hooks=setup.hooks,
        success=setup.success,
        backend=backend,
        hyperparams=hyperparams,
        sim_backend=sim_backend,
    )


def reference(spec: str, task: Task, **overrides: Any) -> motion.Reference:
    """The motion AMP imitates on `task`, which ``make(spec, **overrides)`` built: a
    registered env's `EnvSpec.reference`, or a user module's ``REFERENCE`` (a function
    ``(task, **overrides) -> mjzoo.motion.Reference`` beside the factory), called with
    the task and the same overrides. KeyError (registered envs) or ValueError (a user's
    module, a Playground env) naming where a reference comes from if there is none."""
    factory(spec)
    if _is_playground(spec):
        raise ValueError(f"{spec}: Playground's envs have no motion reference; AMP needs one (amp.make(config, ref))")
    if _is_user(spec):
        module_name = spec.partition(":")[0]
        build = getattr(importlib.import_module(module_name), "REFERENCE", None)
        if build is None:
            raise ValueError(
                f"{spec}: module {module_name!r} defines no REFERENCE, the function (task, **overrides) -> "
                "mjzoo.motion.Reference that AMP imitates; define one beside the factory"
            )
    else:
        build = _REGISTRY[spec].reference
        if build is None:
            imitated = sorted(name for name, entry in _REGISTRY.items() if entry.reference is not None)
            raise KeyError(f"{spec!r} has no motion reference for AMP; envs with one: {imitated}")
    ref = build(task, **overrides)
    if not isinstance(ref, motion.Reference):
        raise TypeError(f"{spec}: its reference function returned {type(ref).__name__}, not a mjzoo.motion.Reference")
    return ref


def hyperparameters(spec: str, algorithm: str) -> dict[str, Any]:
    """The task's default config fields for `algorithm` (empty if it has none; a user's
    task: its ``PLANNING.configs``, so PPO keeps ppo.Config's defaults; a Playground env:
    its tuned PPO config in mjzoo's terms, and `PLAYGROUND_PLANNING`'s)."""
    if _is_playground(spec) and algorithm == "ppo":
        return _playground(spec).ppo_hyperparameters(_playground_name(spec))
    if _is_user(spec) or _is_playground(spec):
        return dict(planning(spec).configs.get(algorithm, {}))
    return record(spec).hyperparameters(algorithm)


_KEYWORDS = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)


def defaults(spec: str) -> dict[str, Any]:
    """The overridable arguments of a task and their default values (a Playground env:
    its config, flattened)."""
    if _is_playground(spec):
        return _playground(spec).config_defaults(_playground_name(spec))
    kinds = _KEYWORDS if _is_user(spec) else (inspect.Parameter.KEYWORD_ONLY,)
    parameters = inspect.signature(factory(spec)).parameters.values()
    return {p.name: p.default for p in parameters if p.kind in kinds and p.default is not p.empty}


def accepts(spec: str, name: str, *, catch_all: bool = True) -> bool:
    """Whether `make(spec, **{name: ...})` accepts the override `name`: a registered env
    its keyword arguments and the physics options, a user's factory its own keyword
    arguments (any, with ``**kwargs``, unless `catch_all` is False: a ``**params`` may
    hold the task's parameters, which an option meant for something else would break),
    a Playground env its config's entries."""
    if _is_user(spec):
        parameters = inspect.signature(factory(spec)).parameters
        return (catch_all and any(p.kind == inspect.Parameter.VAR_KEYWORD for p in parameters.values())) or (
            name in parameters and parameters[name].kind in _KEYWORDS
        )
    return name in defaults(spec) or (not _is_playground(spec) and name in physics.OPTIONS)


def make(spec: str, **overrides: Any) -> Task:
    """Builds the task `spec` (a registered name or ``package.module:factory``), with
    `overrides` of its defaults (registered envs: also of physics options).

    Each override is checked against its default's type first (physics options by
    `physics.load`): a wrong one, e.g. episode_steps="abc" from a command line or a
    config file, would otherwise fail deep inside tracing with a message naming neither."""
    if _is_playground(spec):  # the adapter checks the overrides against the env's config
        return _playground(spec).task(_playground_name(spec), **overrides)
    build = factory(spec)
    parameters = inspect.signature(build).parameters
    if _is_user(spec):
        _check_arguments(spec, parameters, overrides)
    else:
        allowed = set(defaults(spec)) | set(physics.OPTIONS)
        unknown = sorted(set(overrides) - allowed)
        if unknown:
            raise TypeError(
                f"{spec}: unknown override(s) {unknown}{checks.did_you_mean(unknown, allowed)}; allowed: {sorted(allowed)}"
            )
    for key, value in overrides.items():
        if key in parameters and parameters[key].kind in _KEYWORDS:
            expected = _expected_type(parameters[key], value)
            if expected:
                raise TypeError(f"{spec}: override {key}={value!r} must be {expected}")
    task = build(**overrides)
    if not isinstance(task, Task):
        raise TypeError(f"{spec}: returned a value of type {type(task).__name__}, not a mjzoo.Task")
    return task


def _check_arguments(spec: str, parameters: dict[str, inspect.Parameter], overrides: dict[str, Any]) -> None:
    """A user's factory takes exactly its own keyword arguments (any, with ``**kwargs``)."""
    named = [k for k, p in parameters.items() if p.kind in _KEYWORDS]
    open_ended = any(p.kind == inspect.Parameter.VAR_KEYWORD for p in parameters.values())
    unknown = [] if open_ended else sorted(set(overrides) - set(named))
    if unknown:
        hint = checks.did_you_mean(unknown, named)
        raise TypeError(f"{spec}: unknown override(s) {unknown}{hint}; {spec.partition(':')[2]} takes {named}")
    missing = [k for k in named if parameters[k].default is parameters[k].empty and k not in overrides]
    if missing:
        raise TypeError(f"{spec}: required argument(s) {missing} not given; {spec.partition(':')[2]} takes {named}")


def _expected_type(parameter: inspect.Parameter, value: Any) -> str | None:
    """What `value` should have been for `parameter`, judged by its default (bool is not
    an int; a float accepts an int; a tuple a list, as JSON gives back) and whether its
    annotation admits None; None if it fits or nothing can be judged."""
    default, annotation = parameter.default, str(parameter.annotation)
    optional = default is None or "None" in annotation or "Optional" in annotation
    if value is None and optional:
        return None
    kinds = {
        bool: ((bool, np.bool_), "True or False"),
        int: ((numbers.Integral,), "an int"),
        float: ((numbers.Real,), "a number"),
        str: ((str,), "a string"),
        tuple: ((tuple, list), "a tuple or list"),
        list: ((tuple, list), "a list or tuple"),
    }
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


def factory(spec: str) -> Callable[..., Task]:
    """The function that builds `spec`: a registered env's (KeyError naming them if
    unknown), or the function ``package.module:factory`` names (ValueError or TypeError
    naming what is missing), or for ``playground:NAME`` the adapter bound to NAME (ValueError
    if Playground is not installed, KeyError naming near envs if NAME is unknown)."""
    if _is_playground(spec):
        return functools.partial(_playground(spec).task, _playground_name(spec))
    if _is_user(spec):
        return _imported(spec)
    name = spec
    if name not in _REGISTRY:
        raise KeyError(f"unknown env {name!r}{checks.did_you_mean([name], _REGISTRY)}; registered envs: {names()}")
    return _REGISTRY[name].make


def _is_user(spec: str) -> bool:
    return ":" in spec and not _is_playground(spec)


def _is_playground(spec: str) -> bool:
    return spec.startswith(PLAYGROUND)


def _playground(spec: str) -> ModuleType:
    """The Playground adapter, or a one-line error if Playground is not installed."""
    try:
        from mjzoo.interop import playground
    except ModuleNotFoundError as e:
        if (e.name or "").partition(".")[0] != "mujoco_playground":
            raise
        raise ValueError(f"{spec}: MuJoCo Playground is not installed; pip install 'mjzoo[playground]'") from e
    return playground


def _playground_name(spec: str) -> str:
    """The env name of ``playground:NAME``, checked (KeyError naming near ones)."""
    name = spec[len(PLAYGROUND) :]
    _playground(spec).config_defaults(name)
    return name


def _imported(spec: str) -> Callable[..., Task]:
    """The function ``package.module:factory`` names, imported."""
    module_name, _, attribute = spec.partition(":")
    if not module_name or not attribute.isidentifier():
        raise ValueError(f"task spec {spec!r}: expected a registered env or package.module:factory")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        if not e.name or not (module_name + ".").startswith(e.name + "."):
            raise  # a module the user's module imports: their bug, with its traceback
        raise ValueError(
            f"task spec {spec!r}: no module named {e.name!r} (from the current directory or sys.path)"
        ) from e
    if not hasattr(module, attribute):
        raise ValueError(f"task spec {spec!r}: module {module_name!r} has no attribute {attribute!r}")
    found = getattr(module, attribute)
    if not callable(found):
        raise TypeError(
            f"task spec {spec!r}: {attribute} is not callable (type {type(found).__name__}); "
            "expected a function returning a Task"
        )
    return found
