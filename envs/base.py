"""What every shipped env shares: where its model files live, and its record in the
registry (`EnvSpec`: the factory, hyperparameters per algorithm, the planning setup).

Every env is built the one public way, `mjzoo.task` (lib/builder.py); this module holds
nothing a user's own task would need but the model files."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any
from typing import Callable

import numpy as np

from mjzoo import physics as physics_lib
from mjzoo.motion import Reference
from mjzoo.planning.closed_loop import Hooks
from mjzoo.types import Task

__all__ = [
    "ASSETS",
    "load",
    "brax_asset",
    "EnvSpec",
    "PlanningSetup",
    "sampling_setup",
    "elite_count",
    "held_near",
]

ASSETS = Path(__file__).parent / "assets"


def load(asset: str, **physics_options: Any) -> physics_lib.Physics:
    """Loads one of the bundled model files (``envs/assets/<asset>``) with physics options."""
    return physics_lib.load(ASSETS / asset, **physics_options)


def brax_asset(asset: str, **physics_options: Any) -> physics_lib.Physics:
    """Loads a model file bundled with the installed brax package
    (``brax/envs/assets/<asset>``), found at run time, with physics options."""
    import brax  # a dependency; imported here so envs without its models do not pay for it

    return physics_lib.load(Path(brax.__file__).parent / "envs" / "assets" / asset, **physics_options)


@dataclasses.dataclass(frozen=True)
class PlanningSetup:
    """How the sampling planners solve a task closed loop (`mjzoo plan`, the tests).

    Attributes:
      seconds: length of the closed-loop run; None: one episode (the task's time limit).
      replan_every: simulation control steps per replan.
      plan_overrides: the planning task is ``plan_view(make(name, **plan_overrides))``
        (e.g. a coarser control step); the simulation is ``make(name)``.
      configs: config fields per planner module name ("mppi", "cem", ...).
      success: ``states -> (solved, score)`` over the run's simulated states [T]
        (numpy leaves), with the score the criterion thresholds; None: no criterion
        (a user's task without one: the report gives the final cost).
      hooks: the task's planner hooks (`mjzoo.planning.closed_loop.Hooks`).
      plan_view: ``Task -> Task`` applied to the planning task, e.g. a sharper reward
        term: a planner only sees the cost differences its samples can resolve.
    """

    seconds: float | None
    replan_every: int
    plan_overrides: dict[str, Any]
    configs: dict[str, dict[str, Any]]
    success: Callable[[Any], tuple[bool, float]] | None
    hooks: Hooks = Hooks()
    plan_view: Callable[[Task], Task] | None = None

    def plan_task(self, make: Callable[..., Task], **overrides: Any) -> Task:
        """The planning task, from the env factory `make`."""
        task = make(**self.plan_overrides, **overrides)
        return self.plan_view(task) if self.plan_view else task


def elite_count(num_samples: int) -> int:
    """The elites CEM and CMA-ES keep on the real robots: 1/16 of the samples, at least 2."""
    return max(2, num_samples // 16)


def sampling_setup(
    seconds: float,
    success: Callable[[Any], tuple[bool, float]],
    *,
    horizon_steps: int,
    num_knots: int,
    noise_scale: float,
    num_samples: int = 1024,
    noise_ramp: float = 0.0,
    dial_iterations: int = 2,
    plan_overrides: dict[str, Any] | None = None,
) -> PlanningSetup:
    """The real robots' setup: every sampling planner at `num_samples` over `horizon_steps`
    control steps, replanning every step, its noise widening by `noise_ramp` along the
    horizon (CMA-ES, which adapts its own spread, without); MPPI at temperature 0.1, CEM
    and CMA-ES keeping 1/16 of the samples (64 of 1024) as elites, DIAL annealing over
    `dial_iterations`."""
    sampling = dict(num_samples=num_samples, horizon_steps=horizon_steps, num_knots=num_knots, noise_scale=noise_scale)
    ramped = dict(sampling, noise_ramp=noise_ramp) if noise_ramp else sampling
    elites = elite_count(num_samples)
    return PlanningSetup(
        seconds=seconds,
        replan_every=1,
        plan_overrides=plan_overrides or {},
        success=success,
        configs={
            "predictive_sampling": ramped,
            "mppi": dict(ramped, temperature=0.1),
            "cem": dict(ramped, num_elites=elites),
            "dial": dict(ramped, iterations=dial_iterations),
            "cma_es": dict(sampling, num_elites=elites),
        },
    )


def held_near(
    states, value_fn: Callable[[Any], np.ndarray], tolerance: float, seconds: float = 1.0
) -> tuple[bool, float]:
    """(max |value| over the last `seconds` of the run < tolerance, that max) for a
    per-step value computed from the stacked states."""
    time = np.asarray(states.data.time)
    worst = float(np.max(np.abs(value_fn(states)[time >= time[-1] - seconds + 1e-6])))
    return worst < tolerance, worst


@dataclasses.dataclass(frozen=True, kw_only=True)
class EnvSpec:
    """A registered env's record: how to build it and how each algorithm solves it.

    Attributes:
      make: the factory, keyword-only arguments (each an override, `mjzoo.envs.make`).
      description: one line, for listings.
      ppo: PPO's config fields that solve it (`mjzoo train ppo NAME`); None: none tuned.
      amp: AMP's config fields (the envs with a motion reference).
      sac, fast_td3: the off-policy learners' config fields; None: their Configs' defaults.
      planning: how the sampling planners solve it closed loop; None: not set up.
      reference: for an env AMP imitates with: ``reference(task, **overrides) ->
        mjzoo.motion.Reference``, called with the task `make(**overrides)` built and
        those overrides (it ignores the ones it does not read); `mjzoo.envs.reference`
        calls it. None: the env has no motion to imitate.
    """

    make: Callable[..., Task]
    description: str
    ppo: dict[str, Any] | None = None
    amp: dict[str, Any] | None = None
    sac: dict[str, Any] | None = None
    fast_td3: dict[str, Any] | None = None
    planning: PlanningSetup | None = None
    reference: Callable[..., Reference] | None = None

    def __post_init__(self):
        if not callable(self.make):
            raise TypeError(f"EnvSpec: make must be a function returning a Task, got {type(self.make).__name__}")
        if self.planning is not None and not isinstance(self.planning, PlanningSetup):
            raise TypeError(f"EnvSpec: planning must be a PlanningSetup, got {type(self.planning).__name__}")
        if self.reference is not None and not callable(self.reference):
            raise TypeError(f"EnvSpec: reference must be a function of the task, got {type(self.reference).__name__}")

    def hyperparameters(self, algorithm: str) -> dict[str, Any]:
        """Config fields for `algorithm` ("ppo", "amp", "sac", "fast_td3", or a planner
        module's name: its planning config); empty if it has none."""
        learned = {"ppo": self.ppo, "amp": self.amp, "sac": self.sac, "fast_td3": self.fast_td3}.get(algorithm)
        if learned is not None:
            return dict(learned)
        return dict(self.planning.configs.get(algorithm, {})) if self.planning else {}
