"""What every concrete task shares: where its model files live, how its numbers become
pytree leaves, and how its four functions become a `Task` with an episode limit and a
divergence guard."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from mjzoo import physics as physics_lib
from mjzoo.combinators import with_divergence_guard, with_time_limit
from mjzoo.planning.closed_loop import Hooks
from mjzoo.types import State, Task, bind

__all__ = [
    "ASSETS",
    "load",
    "brax_asset",
    "floats",
    "build",
    "advance",
    "never_terminate",
    "PlanningSetup",
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


def floats(**values: Any) -> dict[str, jax.Array]:
    """Numbers as float32 leaves, so tasks built with different values share a trace."""
    return {k: jnp.asarray(v, jnp.float32) for k, v in values.items()}


def build(
    physics: physics_lib.Physics,
    params: Any,
    reset: Callable,
    step: Callable,
    reward: Callable,
    terminate: Callable,
    *,
    episode_steps: int,
) -> Task:
    """A Task of module-level functions bound to `params`, guarded against divergence
    and truncated after `episode_steps` control steps."""
    task = Task(
        model=physics.model,
        start=bind(reset, params),
        step=bind(step, params),
        reward=bind(reward, params),
        terminate=bind(terminate, params),
        mj_model=physics.mj_model,
    )
    return with_time_limit(with_divergence_guard(task), episode_steps)


def advance(model: mjx.Model, state: State, action: jax.Array, n_substeps: int) -> mjx.Data:
    """Physics of one control step: `action` as the controls (MuJoCo clamps them to
    ctrlrange), held for `n_substeps` physics steps."""
    return physics_lib.step(model, state.data, jnp.asarray(action, jnp.float32), n_substeps)


def never_terminate(params: Any, model: mjx.Model, state: State) -> tuple[jax.Array, jax.Array]:
    """For tasks that end only by their time limit."""
    return jnp.zeros((), bool), jnp.zeros((), bool)


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


def held_near(
    states, value_fn: Callable[[Any], np.ndarray], tolerance: float, seconds: float = 1.0
) -> tuple[bool, float]:
    """(max |value| over the last `seconds` of the run < tolerance, that max) for a
    per-step value computed from the stacked states."""
    time = np.asarray(states.data.time)
    worst = float(np.max(np.abs(value_fn(states)[time >= time[-1] - seconds + 1e-6])))
    return worst < tolerance, worst


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles in (-pi, pi]."""
    return np.arctan2(np.sin(angle), np.cos(angle))
