"""The catalog: building blocks of tasks, one module per kind.

Each module holds small items a task is assembled from: functions of the physics state
(observations, reward terms, terminations, reset items, randomizers) and combinators
that add state-carrying behaviour (commands, events, curricula, actuator models,
trackers, observation history). Items take the host `mujoco.MjModel` at construction to
resolve names and return `jax.tree_util.Partial`s whose numbers are pytree leaves.
docs/catalog.md lists every item and how they nest.

    observations   what a policy sees          rewards       reward terms, `tolerance`
    terminations   when an episode ends        resets        how an episode starts
    events         pushes during an episode    commands      velocity / joint targets
    curriculum     difficulty levels           randomizers   per-episode physics draws
    actuators      torque, PD, latency, drops  trackers      action history, feet
    contacts       contact queries             shaping       `tolerance`, `wrap_angle`
"""

from mjzoo.catalog import (
    actuators,
    commands,
    contacts,
    curriculum,
    events,
    observations,
    randomizers,
    resets,
    rewards,
    shaping,
    terminations,
    trackers,
)
from mjzoo.catalog.shaping import tolerance, wrap_angle

__all__ = [
    "observations",
    "rewards",
    "shaping",
    "terminations",
    "resets",
    "events",
    "commands",
    "curriculum",
    "randomizers",
    "actuators",
    "trackers",
    "contacts",
    "tolerance",
    "wrap_angle",
]
