"""mjzoo: tasks are data, algorithms are functions.

A `Task` is an immutable pytree of a MuJoCo MJX model and four pure functions (reset,
step, reward, terminate); combinators turn tasks into tasks; `transition` and `rollout`
run one environment, and `jax.vmap` runs many. The locomotion catalog (observations,
rewards, terminations, resets, events, commands, curricula, randomizers, actuators and
the trackers they share) is a set of modules of small items: see docs/catalog.md.
"""

import contextlib
import io

with contextlib.redirect_stdout(io.StringIO()):  # mjx prints a notice when its optional warp backend is absent
    from mujoco import mjx  # noqa: F401

from mjzoo import (  # the core, then the locomotion catalog (docs/catalog.md)
    actuators,
    checks,
    commands,
    contacts,
    curriculum,
    events,
    names,
    observations,
    physics,
    randomizers,
    resets,
    rewards,
    terminations,
    trackers,
    tree,
)
from mjzoo.combinators import (
    with_action_repeat,
    with_auto_reset,
    with_divergence_guard,
    with_observation,
    with_reward,
    with_reward_clip,
    with_time_limit,
)
from mjzoo.perturbations import with_action_noise, with_domain_randomization, with_observation_noise
from mjzoo.running import Policy, complete, reset, reward_terms, rollout, transition, transition_with_terms
from mjzoo.types import State, Task, Trajectory, bind

__version__ = "0.1.0"

__all__ = [
    "Task",
    "State",
    "Trajectory",
    "Policy",
    "bind",
    "reset",
    "complete",
    "transition",
    "transition_with_terms",
    "rollout",
    "reward_terms",
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
    "tree",
    "names",
    "checks",
    "contacts",
    "observations",
    "rewards",
    "terminations",
    "trackers",
    "resets",
    "events",
    "commands",
    "curriculum",
    "randomizers",
    "actuators",
]
