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
    tracking       following motion clips      start_sampling  reference starts, adaptive
    gait           a stepping clock and its feet-height reward
"""

from mjzoo.catalog import actuators
from mjzoo.catalog import commands
from mjzoo.catalog import contacts
from mjzoo.catalog import curriculum
from mjzoo.catalog import events
from mjzoo.catalog import gait
from mjzoo.catalog import observations
from mjzoo.catalog import randomizers
from mjzoo.catalog import resets
from mjzoo.catalog import rewards
from mjzoo.catalog import shaping
from mjzoo.catalog import start_sampling
from mjzoo.catalog import terminations
from mjzoo.catalog import trackers
from mjzoo.catalog import tracking
from mjzoo.catalog.shaping import tolerance
from mjzoo.catalog.shaping import wrap_angle

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
    "tracking",
    "start_sampling",
    "gait",
    "tolerance",
    "wrap_angle",
]
