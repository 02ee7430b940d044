"""mjzoo: tasks are data, algorithms are functions.

A `Task` is an immutable pytree of a MuJoCo MJX model and four pure functions (reset,
step, reward, terminate); combinators turn tasks into tasks; `transition` and `rollout`
run one environment, and `jax.vmap` runs many. This package's root is that core; the
rest is grouped by concern, each subpackage importing only what sits below it:

    mjzoo               the core: Task and State, running a task, physics and its batches of worlds, combinators
    mjzoo.catalog       building blocks of tasks (observations, rewards, terminations, ...)
    mjzoo.learning      pure pieces RL algorithms are composed from (gae, losses, networks)
    mjzoo.planning      pieces sampling planners are composed from, the closed loop
    mjzoo.harness       running experiments: training loop, metrics, checkpoints, CLI
    mjzoo.interop       other ecosystems (Brax, MuJoCo Playground)
    mjzoo.algorithms    PPO, MPPI, CEM, predictive sampling
    mjzoo.envs          concrete tasks and their registry
    mjzoo.testing       check_task: the Task contract's properties, checked on any task
    mjzoo.motion        motion references: clips, their file format, reference-state starts
    mjzoo.robots        real robot models (Menagerie, Playground scenes) and terrain

The subpackages load on first use (``mjzoo.learning.gae`` works after ``import mjzoo``),
so importing the core does not pay for the harness's or Brax's imports. See
docs/design.md.
"""

import contextlib
import io

with contextlib.redirect_stdout(io.StringIO()):  # mjx prints a notice when its optional warp backend is absent
    from mujoco import mjx  # noqa: F401

from mjzoo import batching
from mjzoo import checks
from mjzoo import layers
from mjzoo import lazy
from mjzoo import names
from mjzoo import physics
from mjzoo import solver
from mjzoo import tree
from mjzoo.builder import task
from mjzoo.checks import RetraceHazardWarning
from mjzoo.combinators import AutoResetState
from mjzoo.combinators import ObservationState
from mjzoo.combinators import TimeLimitState
from mjzoo.combinators import with_action_repeat
from mjzoo.combinators import with_auto_reset
from mjzoo.combinators import with_divergence_guard
from mjzoo.combinators import with_observation
from mjzoo.combinators import with_reward
from mjzoo.combinators import with_reward_clip
from mjzoo.combinators import with_time_limit
from mjzoo.layers import find
from mjzoo.parameters import params
from mjzoo.parameters import with_params
from mjzoo.perturbations import DomainRandomizationState
from mjzoo.perturbations import with_action_noise
from mjzoo.perturbations import with_domain_randomization
from mjzoo.perturbations import with_observation_noise
from mjzoo.running import Policy
from mjzoo.running import control_dt
from mjzoo.running import episode_steps
from mjzoo.running import fill_transition_entries
from mjzoo.running import reset
from mjzoo.running import reward_terms
from mjzoo.running import rollout
from mjzoo.running import transition
from mjzoo.running import transition_with_terms
from mjzoo.types import Outcome
from mjzoo.types import State
from mjzoo.types import Task
from mjzoo.types import Trajectory

__version__ = "0.1.0"

SUBPACKAGES = (
    "catalog",
    "learning",
    "planning",
    "harness",
    "interop",
    "algorithms",
    "envs",
    "testing",
    "motion",
    "robots",
)

__all__ = [
    "Task",
    "State",
    "Trajectory",
    "Outcome",
    "Policy",
    "find",
    "ObservationState",
    "TimeLimitState",
    "AutoResetState",
    "DomainRandomizationState",
    "reset",
    "fill_transition_entries",
    "transition",
    "transition_with_terms",
    "rollout",
    "reward_terms",
    "control_dt",
    "episode_steps",
    "task",
    "params",
    "with_params",
    "RetraceHazardWarning",
    "with_observation",
    "with_time_limit",
    "with_auto_reset",
    "with_action_repeat",
    "with_reward",
    "with_reward_clip",
    "with_divergence_guard",
    "with_observation_noise",
    "with_action_noise",
    "with_domain_randomization",
    "physics",
    "solver",
    "batching",
    "tree",
    "layers",
    "names",
    "checks",
    *SUBPACKAGES,
]


__getattr__, __dir__ = lazy.submodules(__name__, SUBPACKAGES)
