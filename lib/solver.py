"""What a model's constraint-solver settings cost per step, and the settings the shipped envs use.

    mjzoo.solver.settings(physics)     # newton, iterations=100, ls_iterations=50, rk4, 4 substeps: ...
    mjzoo.task(XML, **mjzoo.solver.SHIPPED, ...)          # the shipped envs' settings instead
    mjzoo.solver.accuracy(physics)     # what they cost in accuracy, in C MuJoCo: qpos drift

An MJCF file that sets no solver options keeps MuJoCo's (Newton, 100 iterations, 50
line-search steps), made for one float64 world on a CPU. MJX runs a batch of worlds in
lockstep, so a step lasts as long as its slowest world's solve: the limits bound what a
step may cost, and the more worlds, the likelier one of them needs many iterations. The
shipped envs (hopper, walker, cheetah: Brax's MJX settings) allow 4 of each. `mjzoo.task`
warns once (`SolverCostWarning`) when a model whose bodies can touch keeps iteration
limits above `COSTLY_ITERATIONS` that no physics option chose; docs/own-task.md has
measured costs.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any
from typing import NamedTuple

import mujoco
import numpy as np

from mjzoo import physics as physics_lib

__all__ = [
    "SHIPPED",
    "COSTLY_ITERATIONS",
    "SolverCostWarning",
    "Settings",
    "settings",
    "shipped",
    "Accuracy",
    "accuracy",
    "warn_if_costly",
]

# The planar locomotion envs' physics options (envs/locomotion.py); free-floating ones go to iterations=1.
SHIPPED = dict(solver="newton", iterations=4, ls_iterations=4, disable_euler_damping=True)
COSTLY_ITERATIONS = 10  # above this many (solver or line-search) iterations, a contact model is warned of
_STAGES = {mujoco.mjtIntegrator.mjINT_RK4: 4}  # constraint solves per physics step (RK4 solves at each stage)
_WARNED: set[str] = set()


class SolverCostWarning(UserWarning):
    """A task's model with contacts keeps costly constraint-solver limits (MuJoCo's
    defaults): a batched MJX step may run many more solver iterations than with the
    shipped envs' settings. Silence it with
    ``warnings.simplefilter("ignore", mjzoo.solver.SolverCostWarning)``."""


@dataclasses.dataclass(frozen=True)
class Settings:
    """A loaded model's solver settings and the work they allow per control step.

    Attributes:
      solver, integrator: their MuJoCo names ("newton", "cg"; "euler", "implicitfast", "rk4").
      iterations, ls_iterations: the solver's iteration limits.
      n_substeps: physics steps per control step.
      stages: constraint solves per physics step (4 for RK4, which solves at each stage).
      euler_damping: whether Euler's implicit joint damping is on (the shipped envs turn it off).
      contacts: whether any two bodies can touch (contacts enabled and a colliding geom pair).
    """

    solver: str
    iterations: int
    ls_iterations: int
    integrator: str
    n_substeps: int
    stages: int
    euler_damping: bool
    contacts: bool

    @property
    def solves(self) -> int:
        """Constraint solves per control step: substeps x integrator stages (4 for RK4)."""
        return self.n_substeps * self.stages

    @property
    def bound(self) -> int:
        """At most this many solver iterations per control step (each with up to
        `ls_iterations` line-search steps): what a batched MJX step may cost."""
        return self.solves * self.iterations

    @property
    def costly(self) -> bool:
        """Contacts solved with iteration limits above `COSTLY_ITERATIONS`."""
        return self.contacts and max(self.iterations, self.ls_iterations) > COSTLY_ITERATIONS

    def __str__(self) -> str:
        return (
            f"{self.solver}, iterations={self.iterations}, ls_iterations={self.ls_iterations}, "
            f"{self.integrator}{f' ({self.stages} solves a step)' if self.stages > 1 else ''}, "
            f"{self.n_substeps} substep(s): "
            f"up to {self.bound} solver iterations per control step"
        )


def settings(physics: physics_lib.Physics) -> Settings:
    """The solver settings of a loaded model (`mjzoo.physics.Physics`) and what they allow."""
    m = physics.mj_model
    return Settings(
        solver=_name(physics_lib.SOLVERS, m.opt.solver, mujoco.mjtSolver),
        iterations=int(m.opt.iterations),
        ls_iterations=int(m.opt.ls_iterations),
        integrator=_name(physics_lib.INTEGRATORS, m.opt.integrator, mujoco.mjtIntegrator),
        n_substeps=physics.n_substeps,
        stages=_STAGES.get(m.opt.integrator, 1),
        euler_damping=not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_EULERDAMP,
        contacts=_may_touch(m),
    )


def shipped(physics: physics_lib.Physics, **options: Any) -> physics_lib.Physics:
    """`physics` with the shipped envs' solver settings (`SHIPPED`, updated by `options`:
    physics options of `mjzoo.physics.load` other than dt, ctrl_dt and impl)."""
    return physics_lib.with_options(physics, **{**SHIPPED, **options})


class Accuracy(NamedTuple):
    """How far a model with other solver settings drifts from the model as it is, in C MuJoCo.

    Attributes:
      qpos_drift: the largest |qpos difference| over the rollouts (m or rad).
      seconds: the length of each rollout.
      iterations: the mean solver iterations per physics step, (own, other).
    """

    qpos_drift: float
    seconds: float
    iterations: tuple[float, float]


def accuracy(
    physics: physics_lib.Physics, other: physics_lib.Physics | None = None, seconds: float = 1.0, seeds: int = 4
) -> Accuracy:
    """The accuracy that `other`'s settings (default: `shipped(physics)`) cost against
    `physics`' own: both simulated by C MuJoCo (float64, cheap) from qpos0 with the same
    random initial velocities and controls (drawn anew each control step, uniform over
    the ctrlranges), for `seeds` rollouts of `seconds`."""
    other = shipped(physics) if other is None else other
    models = (physics.mj_model, other.mj_model)
    m = models[0]
    same = (m.nq, m.nu, m.opt.timestep, physics.n_substeps)
    if same != (models[1].nq, models[1].nu, models[1].opt.timestep, other.n_substeps):
        raise ValueError("mjzoo.solver.accuracy: the two must be one model (joints, actuators, timestep, substeps)")
    low, high = np.where(m.actuator_ctrllimited.astype(bool)[None], m.actuator_ctrlrange.T, [[-1.0], [1.0]])
    steps = max(1, round(seconds / m.opt.timestep))
    drift, niter = 0.0, np.zeros(2)
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        qvel, ctrls = rng.normal(0.0, 1.0, m.nv), rng.uniform(low, high, (steps // physics.n_substeps + 1, m.nu))
        datas = [mujoco.MjData(model) for model in models]
        for data in datas:
            data.qvel[:] = qvel
        for i in range(steps):
            for j, (model, data) in enumerate(zip(models, datas, strict=True)):
                data.ctrl[:] = ctrls[i // physics.n_substeps]
                mujoco.mj_step(model, data)
                niter[j] += data.solver_niter[0]
            drift = max(drift, float(np.max(np.abs(datas[0].qpos - datas[1].qpos), initial=0.0)))
    return Accuracy(drift, steps * float(m.opt.timestep), tuple((niter / (seeds * steps)).tolist()))


def warn_if_costly(physics: physics_lib.Physics, who: str) -> None:
    """Warns once per model and settings (`SolverCostWarning`) when they are costly."""
    found = settings(physics)
    if not found.costly:
        return
    fast = dataclasses.replace(found, **{k: SHIPPED[k] for k in ("solver", "iterations", "ls_iterations")})
    message = (
        f"{who}: {physics.source} keeps costly solver settings for a model with contacts ({found}); "
        "batched on MJX a step lasts as long as its slowest world's solve. The shipped envs' "
        f"{', '.join(f'{k}={v!r}' for k, v in SHIPPED.items())} allow up to {fast.bound} iterations: give them "
        "as physics options (**mjzoo.solver.SHIPPED; mjzoo.solver.accuracy(physics) measures their qpos drift), "
        "or give iterations yourself"
    )
    if message not in _WARNED:
        _WARNED.add(message)
        warnings.warn(message, SolverCostWarning, stacklevel=3)


def _name(names: dict, value, enum) -> str:
    """The physics option's name of a MuJoCo enum value, else MuJoCo's ("mjINT_IMPLICIT")."""
    return next((k for k, v in names.items() if v == value), enum(value).name)


def _may_touch(m: mujoco.MjModel) -> bool:
    """Whether contacts can arise: enabled, and a geom pair of different bodies whose
    contype and conaffinity match (or an explicit <pair>)."""
    if m.opt.disableflags & (mujoco.mjtDisableBit.mjDSBL_CONSTRAINT | mujoco.mjtDisableBit.mjDSBL_CONTACT):
        return False
    if m.npair:
        return True
    ct, ca, weld = m.geom_contype, m.geom_conaffinity, m.body_weldid[m.geom_bodyid]
    match = ((ct[:, None] & ca[None, :]) | (ca[:, None] & ct[None, :])) != 0
    return bool(np.any(match & (weld[:, None] != weld[None, :])))
