"""Loading MuJoCo models for MJX, with validated physics options, and stepping them.

    physics = mjzoo.physics.load("robot.xml", dt=0.005, ctrl_dt=0.02, solver="newton")
    physics.model          # mjx.Model (a pytree: masses, gains, timestep are leaves)
    physics.data0          # the template every reset starts from
    physics.n_substeps     # 4 physics steps per control step
    physics.id("body", "torso")

Every mistake is reported at load time with the model's source and what exists:
a missing file, malformed XML, an option out of range, a name the model lacks.

Two implementations run behind the same `mjx.Model` / `mjx.Data` (``impl=``): MJX's
pure-JAX one, and MuJoCo Warp (CUDA kernels; the default where it is installed and a
CUDA GPU is present). Warp keeps its contacts in one pool shared by every simulated
world of a batch, sized ``max_contacts`` per world, and ``max_constraints`` constraint
rows per world: both are measured by a probe rollout of C MuJoCo at load time unless
given; `mjzoo.batching` sizes the pool for a batch, and is the one reader of Warp's
private fields.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import importlib.util
import math
import numbers
import os
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from mjzoo.batching import clear_overflow
from mjzoo.batching import probe_capacity

__all__ = [
    "Physics",
    "load",
    "of_model",
    "of_spec",
    "with_options",
    "step",
    "forward",
    "switch_impl",
    "OPTIONS",
    "IMPLS",
    "default_impl",
]

SOLVERS = {"cg": mujoco.mjtSolver.mjSOL_CG, "newton": mujoco.mjtSolver.mjSOL_NEWTON}
INTEGRATORS = {
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
}
OPTIONS = (
    "dt",
    "ctrl_dt",
    "solver",
    "iterations",
    "ls_iterations",
    "integrator",
    "tolerance",
    "disable_euler_damping",
    "impl",
    "max_contacts",
    "max_constraints",
)
IMPLS = ("jax", "warp")
WARP_ON_CPU = "MJZOO_WARP_ON_CPU"  # =1: let impl="warp" run on Warp's CPU backend (slow; for debugging)
_KINDS = {
    "body": mujoco.mjtObj.mjOBJ_BODY,
    "joint": mujoco.mjtObj.mjOBJ_JOINT,
    "geom": mujoco.mjtObj.mjOBJ_GEOM,
    "site": mujoco.mjtObj.mjOBJ_SITE,
    "sensor": mujoco.mjtObj.mjOBJ_SENSOR,
    "actuator": mujoco.mjtObj.mjOBJ_ACTUATOR,
}


@dataclasses.dataclass(frozen=True, eq=False)
class Physics:
    """A loaded model: the host `MjModel`, its MJX twin and the control timing.

    Attributes:
      source: where the model came from (a file path, or "<xml string>").
      mj_model: the compiled host model (names, rendering); treat as read-only.
      model: the `mjx.Model` given to tasks.
      n_substeps: physics steps per control step, ctrl_dt / dt.
    """

    source: str
    mj_model: mujoco.MjModel
    model: mjx.Model
    n_substeps: int
    impl: str = "jax"
    max_contacts: int | None = None
    max_constraints: int | None = None

    @functools.cached_property
    def data0(self) -> mjx.Data:
        """The template every reset starts from: ``qpos = qpos0``, zero velocity, nothing
        computed; on Warp, with a contact pool for one world (`mjzoo.batching.sized` sizes it)."""
        device = jax.local_devices()[0]  # this process's (MJX's default is process 0's in a multi-process run)
        if self.impl == "jax":
            return mjx.make_data(self.mj_model, device=device, impl="jax")
        data = mjx.make_data(
            self.mj_model, device=device, impl="warp", naconmax=self.max_contacts, njmax=self.max_constraints
        )
        return data.replace(_impl=data._impl.replace(nworld=1))  # nworld: the worlds the pool is sized for

    @property
    def dt(self) -> float:
        return float(self.mj_model.opt.timestep)

    @property
    def ctrl_dt(self) -> float:
        return self.dt * self.n_substeps

    def names(self, kind: str) -> list[str]:
        """All names of one kind of element ("body", "joint", "geom", "site", ...)."""
        obj, count = self._kind(kind)
        return [mujoco.mj_id2name(self.mj_model, obj, i) or "" for i in range(count)]

    def id(self, kind: str, name: str) -> int:
        """The index of the element `name` of `kind`; a clear KeyError if it is absent."""
        obj, _ = self._kind(kind)
        index = mujoco.mj_name2id(self.mj_model, obj, name)
        if index < 0:
            known = ", ".join(repr(n) for n in self.names(kind) if n) or "none"
            raise KeyError(f"{self.source}: no {kind} named {name!r}; {kind} names in this model: {known}")
        return index

    def qpos_address(self, joint: str) -> int:
        """Index of the first `qpos` entry of a joint."""
        return int(self.mj_model.jnt_qposadr[self.id("joint", joint)])

    def dof_address(self, joint: str) -> int:
        """Index of the first `qvel` entry of a joint."""
        return int(self.mj_model.jnt_dofadr[self.id("joint", joint)])

    def _kind(self, kind: str) -> tuple[Any, int]:
        if kind not in _KINDS:
            raise ValueError(f"unknown element kind {kind!r}; expected one of {sorted(_KINDS)}")
        counts = {
            "body": "nbody",
            "joint": "njnt",
            "geom": "ngeom",
            "site": "nsite",
            "sensor": "nsensor",
            "actuator": "nu",
        }
        return _KINDS[kind], int(getattr(self.mj_model, counts[kind]))


def load(
    source: str | os.PathLike,
    *,
    dt: float | None = None,
    ctrl_dt: float | None = None,
    solver: str | None = None,
    iterations: int | None = None,
    ls_iterations: int | None = None,
    integrator: str | None = None,
    tolerance: float | None = None,
    disable_euler_damping: bool = False,
    impl: str | None = None,
    max_contacts: int | None = None,
    max_constraints: int | None = None,
) -> Physics:
    """Compiles an MJCF file or XML string for MJX, applying validated physics options.

    Args:
      source: a path to an MJCF file, or the XML text itself (starts with "<").
      dt: physics timestep in seconds (> 0); default: the model's own.
      ctrl_dt: control period in seconds, a whole multiple of dt; default: dt.
      solver: "cg" or "newton" (MJX supports no other).
      iterations: maximum constraint-solver iterations (>= 1).
      ls_iterations: maximum line-search iterations (>= 1).
      integrator: "euler", "implicitfast" or "rk4".
      tolerance: solver tolerance (>= 0).
      disable_euler_damping: skip the implicit joint damping of the Euler integrator.
      impl: "jax" (MJX in JAX: runs anywhere, differentiable) or "warp" (MuJoCo Warp:
        CUDA kernels, several times faster on a GPU, no derivatives); default
        `default_impl()`.
      max_contacts: Warp only: contacts per simulated world the shared pool holds;
        default: measured by a probe rollout (`mjzoo.batching.probe_capacity`).
      max_constraints: Warp only: constraint rows per world (MuJoCo Warp's njmax);
        default: measured by the same probe.

    Identical calls return the same `Physics` (cached), so tasks built twice from the
    same model share one jit cache entry.
    """
    text, label, mtime = _read(source)
    options = dict(
        dt=dt,
        ctrl_dt=ctrl_dt,
        solver=solver,
        iterations=iterations,
        ls_iterations=ls_iterations,
        integrator=integrator,
        tolerance=tolerance,
        disable_euler_damping=disable_euler_damping,
        impl=impl,
        max_contacts=max_contacts,
        max_constraints=max_constraints,
    )
    _validate(label, options)
    options["impl"] = impl or default_impl()
    options = {k: v.item() if hasattr(v, "item") else v for k, v in options.items()}  # numpy scalars
    return _compile(text, label, mtime, tuple(sorted(options.items())))


def step(model: mjx.Model, data: mjx.Data, ctrl: jax.Array, n_substeps: int) -> mjx.Data:
    """Applies `ctrl` ([nu]) and advances `n_substeps` (static) physics steps.

    On Warp, the overflow flags (`mjzoo.batching.overflow`) are cleared first, so afterwards they
    report this control step's substeps.
    """
    data = clear_overflow(data).replace(ctrl=ctrl)
    # On Warp a lone substep goes through the loop too: called bare under a vmap inside a
    # scan (the evaluation's), MJX's Warp step leaked its tracers (UnexpectedTracerError).
    if n_substeps == 1 and data.impl != mjx.Impl.WARP:
        return substep(model, data)
    return jax.lax.fori_loop(0, n_substeps, lambda _, d: substep(model, d), data)


class StandIn:
    """A model stand-in that replaces the physics of a task's step: `substep` calls its
    ``substep(data)`` instead of `mjx.step`. Every other attribute reads through to the
    `mjx.Model` it holds as ``model``, so a task's functions use it as their model
    (`mjzoo.planning.native` replays C MuJoCo's states through it)."""

    model: mjx.Model

    def substep(self, data: mjx.Data) -> mjx.Data:
        raise NotImplementedError

    def __getattr__(self, name: str) -> Any:
        if name == "model":  # not yet set (copying, unpickling)
            raise AttributeError(name)
        return getattr(self.model, name)


def substep(model: mjx.Model, data: mjx.Data) -> mjx.Data:
    """One physics step, `mjx.step`; on Warp, differentiating through it raises a clear
    error; a `StandIn` model steps its own way."""
    if isinstance(model, StandIn):
        return model.substep(data)
    if data.impl == mjx.Impl.WARP:
        return _warp_step(model, data)
    return _jax_step(model, data)


def forward(model: mjx.Model, data: mjx.Data) -> mjx.Data:
    """`mjx.forward`: positions, velocities and forces of `data`'s state, without stepping."""
    if isinstance(model, StandIn):
        return mjx.forward(model, data)
    return _forward(model, data)


def switch_impl(data: mjx.Data, like: mjx.Data) -> mjx.Data:
    """`data` on `like`'s implementation: its public fields (the state and what MJX
    computed of it: qpos, qvel, act, ctrl, time, poses, sensordata, ...) over `like`'s
    own (`_impl`: MJX-JAX's or MuJoCo Warp's contacts, constraint rows and buffers, which
    the next step computes afresh). How a planner on Warp starts from a world stepped in
    C MuJoCo or on MJX-JAX; `data` itself where both are on one implementation."""
    if data.impl == like.impl:
        return data
    public = [f.name for f in dataclasses.fields(data) if f.name != "_impl"]
    cast = lambda x, y: jnp.asarray(x, jnp.result_type(y))  # noqa: E731
    return like.replace(**{n: jax.tree.map(cast, getattr(data, n), getattr(like, n)) for n in public})


# Jitted so that JAX traces the physics once per model layout and reuses it: a task's
# construction checks and every program that resets or steps it (rollout, evaluation,
# planner) would otherwise each trace MJX anew, and a humanoid's forward takes ~2 s to trace.
_jax_step = jax.jit(mjx.step)
_forward = jax.jit(mjx.forward)


@jax.custom_jvp
def _warp_step(model: mjx.Model, data: mjx.Data) -> mjx.Data:
    return mjx.step(model, data)


@_warp_step.defjvp
def _warp_step_jvp(primals, tangents):
    check_differentiable(primals[1], "jax.grad / jax.jvp through mjzoo.physics.step")
    raise AssertionError  # unreachable


def quiet(model: mjx.Model) -> mjx.Model:
    """`model` with MuJoCo Warp's overflow prints off: a device printf per world and step
    that hits a solver or capacity limit, which slows a batch down; mjzoo counts them in
    metrics instead (`mjzoo.batching.overflow`). A JAX model is returned as it is."""
    if model.impl != mjx.Impl.WARP:
        return model
    return model.replace(opt=model.opt.replace(_impl=model.opt._impl.replace(warn_overflow=0)))


def check_differentiable(data: mjx.Data, who: str) -> None:
    """Raises a clear error when `data` comes from Warp physics, which has no derivatives."""
    if data.impl == mjx.Impl.WARP:
        raise NotImplementedError(
            f"{who}: the physics runs on MuJoCo Warp (impl='warp'), which MJX cannot "
            "differentiate; load the task with impl='jax' to take gradients through physics"
        )


def default_impl() -> str:
    """ "warp" where MuJoCo Warp is installed and JAX sees a CUDA GPU, else "jax"."""
    return "warp" if _warp_installed() and _has_cuda() else "jax"


def _warp_installed() -> bool:
    return importlib.util.find_spec("warp") is not None


def _has_cuda() -> bool:
    try:
        return bool(jax.devices("cuda"))
    except RuntimeError:
        return False


def _require_warp(label: str) -> None:
    if not _warp_installed():
        raise ValueError(
            f"{label}: physics option impl='warp' needs MuJoCo Warp, which is not installed: "
            "pip install -e '.[warp]' (or pip install 'mujoco-mjx[warp]'); or use impl='jax'"
        )
    if not _has_cuda() and os.environ.get(WARP_ON_CPU) != "1":
        platforms = sorted({d.platform for d in jax.devices()})
        raise ValueError(
            f"{label}: physics option impl='warp' needs a CUDA GPU, and JAX sees only "
            f"{', '.join(platforms)}; use impl='jax' (or set {WARP_ON_CPU}=1 to debug on Warp's slow CPU backend)"
        )
    import warp  # a dependency of the 'warp' extra

    warp.config.quiet = True  # no banner,
    warp.config.log_level = max(warp.config.log_level, warp.LOG_WARNING)  # nor a line per kernel module loaded


def _read(source: str | os.PathLike) -> tuple[str, str, float]:
    """(XML text or resolved path, label for messages, file mtime: part of the cache key)."""
    if isinstance(source, str) and source.lstrip().startswith("<"):
        return source, "<xml string>", 0.0
    path = Path(source)
    if not path.is_file():
        raise FileNotFoundError(f"model file not found: {path}")
    return str(path.resolve()), str(path), path.stat().st_mtime


def _is_number(value: Any, minimum: float, *, integer: bool = False, strict: bool = False) -> bool:
    kind = numbers.Integral if integer else numbers.Real
    if isinstance(value, bool) or not isinstance(value, kind) or not math.isfinite(value):
        return False
    return value > minimum if strict else value >= minimum


def _validate(label: str, o: dict[str, Any]) -> None:
    def check(name: str, ok: bool, allowed: str, optional: bool = True) -> None:
        if not ok and not (optional and o[name] is None):
            raise ValueError(f"{label}: physics option {name}={o[name]!r} is invalid; expected {allowed}")

    for name in ("dt", "ctrl_dt"):
        check(name, _is_number(o[name], 0.0, strict=True), "a finite number of seconds > 0")
    check("solver", o["solver"] in SOLVERS, f"one of {sorted(SOLVERS)}")
    check("integrator", o["integrator"] in INTEGRATORS, f"one of {sorted(INTEGRATORS)}")
    for name in ("iterations", "ls_iterations"):
        check(name, _is_number(o[name], 1, integer=True), "an integer >= 1")
    check("tolerance", _is_number(o["tolerance"], 0.0), "a finite number >= 0")
    check("disable_euler_damping", isinstance(o["disable_euler_damping"], bool), "True or False", optional=False)
    check("impl", o["impl"] in IMPLS, f"one of {list(IMPLS)}")
    for name in ("max_contacts", "max_constraints"):
        check(name, _is_number(o[name], 1, integer=True), "an integer >= 1 (per simulated world)")


@functools.lru_cache(maxsize=64)
def _compile(text: str, label: str, mtime: float, options: tuple[tuple[str, Any], ...]) -> Physics:
    try:
        if label == "<xml string>":
            mj_model = mujoco.MjModel.from_xml_string(text)
        else:
            mj_model = mujoco.MjModel.from_xml_path(text)
    except ValueError as e:
        raise ValueError(f"{label}: could not compile the MJCF model: {e}") from None
    return _configured(mj_model, label, dict(options))


def of_spec(spec: mujoco.MjSpec, *, label: str = "<MjSpec>", **physics_options: Any) -> Physics:
    """Compiles an edited model (`mujoco.MjSpec`, e.g. a robot's scene with a terrain
    added) for MJX with the physics options of `load`. Not cached: the caller keeps the
    result (a spec has no stable identity to key on)."""
    unknown = sorted(set(physics_options) - set(_OPTION_DEFAULTS))
    if unknown:
        raise TypeError(f"{label}: unknown physics option(s) {unknown}; the options: {sorted(_OPTION_DEFAULTS)}")
    options = {**_OPTION_DEFAULTS, **physics_options}
    _validate(label, options)
    options["impl"] = options["impl"] or default_impl()
    try:
        mj_model = spec.compile()
    except ValueError as e:
        raise ValueError(f"{label}: could not compile the model: {e}") from None
    return _configured(mj_model, label, options)


_OPTION_DEFAULTS = {name: False if name == "disable_euler_damping" else None for name in OPTIONS}


def _configured(mj_model: mujoco.MjModel, label: str, o: dict[str, Any]) -> Physics:
    """The physics options `o` applied to a compiled model, and its `Physics`."""
    if o["dt"] is not None:
        mj_model.opt.timestep = o["dt"]
    dt = float(mj_model.opt.timestep)
    ctrl_dt = o["ctrl_dt"] if o["ctrl_dt"] is not None else dt
    n_substeps = round(ctrl_dt / dt)
    if n_substeps < 1 or not math.isclose(n_substeps * dt, ctrl_dt, rel_tol=1e-6):
        raise ValueError(
            f"{label}: ctrl_dt={ctrl_dt} must be a whole multiple of the physics dt={dt} "
            f"(ctrl_dt / dt = {ctrl_dt / dt:.4g})"
        )
    if o["solver"] is not None:
        mj_model.opt.solver = SOLVERS[o["solver"]]
    if o["integrator"] is not None:
        mj_model.opt.integrator = INTEGRATORS[o["integrator"]]
    if o["iterations"] is not None:
        mj_model.opt.iterations = int(o["iterations"])
    if o["ls_iterations"] is not None:
        mj_model.opt.ls_iterations = int(o["ls_iterations"])
    if o["tolerance"] is not None:
        mj_model.opt.tolerance = o["tolerance"]
    if o["disable_euler_damping"]:
        mj_model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    return of_model(mj_model, n_substeps, o["impl"], o["max_contacts"], o["max_constraints"], source=label)


def with_options(physics: Physics, **options: Any) -> Physics:
    """`physics` with other solver options (`load`'s solver, iterations, ls_iterations,
    integrator, tolerance, disable_euler_damping), set on a copy of its host model; the
    timestep, control step and backend stay. Not cached."""
    kept = sorted(set(options) & {"dt", "ctrl_dt", "impl", "max_contacts", "max_constraints"})
    unknown = sorted(set(options) - set(_OPTION_DEFAULTS))
    if kept or unknown:
        raise ValueError(
            f"{physics.source}: with_options changes solver options only, not {', '.join(kept + unknown)}; "
            f"the options: solver, iterations, ls_iterations, integrator, tolerance, disable_euler_damping"
        )
    kept = dict(ctrl_dt=physics.ctrl_dt, impl=physics.impl)
    kept.update(max_contacts=physics.max_contacts, max_constraints=physics.max_constraints)
    options = {**_OPTION_DEFAULTS, **options, **kept}
    _validate(physics.source, options)
    return _configured(copy.copy(physics.mj_model), physics.source, options)


def of_model(
    mj_model: mujoco.MjModel,
    n_substeps: int,
    impl: str = "jax",
    max_contacts: int | None = None,
    max_constraints: int | None = None,
    source: str = "<MjModel>",
) -> Physics:
    """The `Physics` of a compiled host model (whose options are set on ``mj_model.opt``)."""
    if impl == "warp":
        _require_warp(source)
    try:
        # On this process's device: MJX's default (the first device, or the first GPU for Warp) is
        # process 0's in a multi-process run.
        model = mjx.put_model(mj_model, device=jax.local_devices()[0], impl=impl)
    except NotImplementedError as e:
        raise ValueError(f"{source}: MJX ({impl}) cannot simulate this model: {e}") from None
    if impl != "warp":
        return Physics(source=source, mj_model=mj_model, model=model, n_substeps=n_substeps)
    model = quiet(model)
    contacts, constraints = probe_capacity(mj_model)
    return Physics(
        source=source,
        mj_model=mj_model,
        model=model,
        n_substeps=n_substeps,
        impl=impl,
        max_contacts=max_contacts or contacts,
        max_constraints=max_constraints or constraints,
    )
