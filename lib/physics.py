"""Loading MuJoCo models for MJX, with validated physics options, and stepping them.

    physics = mjzoo.physics.load("robot.xml", dt=0.005, ctrl_dt=0.02, solver="newton")
    physics.model          # mjx.Model (a pytree: masses, gains, timestep are leaves)
    physics.n_substeps     # 4 physics steps per control step
    physics.id("body", "torso")

Every mistake is reported at load time with the model's source and what exists:
a missing file, malformed XML, an option out of range, a name the model lacks.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import os
from pathlib import Path
from typing import Any

import jax
import mujoco
from mujoco import mjx

__all__ = ["Physics", "load", "step", "OPTIONS"]

SOLVERS = {"cg": mujoco.mjtSolver.mjSOL_CG, "newton": mujoco.mjtSolver.mjSOL_NEWTON}
INTEGRATORS = {
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
}
OPTIONS = (
    "dt", "ctrl_dt", "solver", "iterations", "ls_iterations", "integrator", "tolerance",
    "disable_euler_damping",
)  # fmt: skip
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
        counts = {"body": "nbody", "joint": "njnt", "geom": "ngeom", "site": "nsite",
                  "sensor": "nsensor", "actuator": "nu"}  # fmt: skip
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

    Identical calls return the same `Physics` (cached), so tasks built twice from the
    same model share one jit cache entry.
    """
    text, label, mtime = _read(source)
    options = dict(
        dt=dt, ctrl_dt=ctrl_dt, solver=solver, iterations=iterations,
        ls_iterations=ls_iterations, integrator=integrator, tolerance=tolerance,
        disable_euler_damping=disable_euler_damping,
    )  # fmt: skip
    _validate(label, options)
    options = {k: v.item() if hasattr(v, "item") else v for k, v in options.items()}  # numpy scalars
    return _compile(text, label, mtime, tuple(sorted(options.items())))


def step(model: mjx.Model, data: mjx.Data, ctrl: jax.Array, n_substeps: int) -> mjx.Data:
    """Applies `ctrl` ([nu]) and advances `n_substeps` (static) physics steps."""
    data = data.replace(ctrl=ctrl)
    if n_substeps == 1:
        return mjx.step(model, data)
    return jax.lax.fori_loop(0, n_substeps, lambda _, d: mjx.step(model, d), data)


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


@functools.lru_cache(maxsize=64)
def _compile(text: str, label: str, mtime: float, options: tuple[tuple[str, Any], ...]) -> Physics:
    o = dict(options)
    try:
        if label == "<xml string>":
            mj_model = mujoco.MjModel.from_xml_string(text)
        else:
            mj_model = mujoco.MjModel.from_xml_path(text)
    except ValueError as e:
        raise ValueError(f"{label}: could not compile the MJCF model: {e}") from None
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
    try:
        model = mjx.put_model(mj_model)
    except NotImplementedError as e:
        raise ValueError(f"{label}: MJX cannot simulate this model: {e}") from None
    return Physics(source=label, mj_model=mj_model, model=model, n_substeps=n_substeps)
