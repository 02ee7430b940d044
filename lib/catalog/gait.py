"""A stepping clock for legged robots: the policy observes it, and is paid for lifting each
foot along the height curve it prescribes (MuJoCo Playground's humanoid ``phase`` and
``feet_phase``).

Each foot has a phase that advances at `frequency` Hz from episode time 0, offset from
the others' (a biped's feet half a cycle apart: offsets (0, pi); a trotting
quadruped's diagonal pairs together). The clock needs no state: it reads
``data.time``, which every reset sets to 0.

    observe = observations.concat(..., gait.clock(1.375, (0.0, jnp.pi)))
    rewards = {"feet_phase": (gait.feet_phase(mj_model, ("left_foot", "right_foot"), 1.375, (0.0, jnp.pi)), 1.0)}
"""

from __future__ import annotations

import math
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import names
from mjzoo.catalog.commands import VelocityCommandState
from mjzoo.layers import find
from mjzoo.types import State

__all__ = ["BIPED", "TROT", "phases", "clock", "swing_height", "feet_phase"]

Array = jax.Array
BIPED = (0.0, math.pi)  # left, right: half a cycle apart
TROT = (0.0, math.pi, math.pi, 0.0)  # FR, FL, RR, RL: the diagonal pairs together


def phases(frequency: float | Array, offsets: Array, time: Array) -> Array:
    """[n] rad in [-pi, pi): each foot's phase at `time` (s), `frequency` Hz, `offsets` [n] rad."""
    phase = 2 * jnp.pi * frequency * time + offsets
    return jnp.mod(phase + jnp.pi, 2 * jnp.pi) - jnp.pi


def _check(frequency: float, offsets: Sequence[float], who: str) -> tuple[Array, Array]:
    if not (math.isfinite(frequency) and frequency > 0):
        raise ValueError(f"{who}: frequency={frequency!r} must be a finite number of Hz > 0")
    if not offsets or not all(math.isfinite(o) for o in offsets):
        raise ValueError(f"{who}: offsets={tuple(offsets)!r} must be one finite phase (rad) per foot")
    return jnp.float32(frequency), jnp.asarray(offsets, jnp.float32)


def clock(frequency: float, offsets: Sequence[float] = BIPED) -> Partial:
    """Observation [2n]: cos then sin of the `n` feet's phases."""
    return Partial(_clock, *_check(frequency, offsets, "gait.clock"))


def _clock(frequency, offsets, model: mjx.Model, state: State) -> Array:
    phase = phases(frequency, offsets, state.data.time)
    return jnp.concatenate([jnp.cos(phase), jnp.sin(phase)]).astype(jnp.float32)


def swing_height(phase: Array, height: float | Array) -> Array:
    """The foot height (m) the clock asks for at `phase` (any shape): 0 at -pi, rising
    to `height` at 0 and back to 0 at pi along cubic Bezier pieces (Playground's ``get_rz``)."""
    x = 2 * (phase + jnp.pi) / (2 * jnp.pi)  # 0 -> 2 over a cycle
    rise = lambda u: u**3 + 3 * u**2 * (1 - u)  # noqa: E731  0 -> 1, flat at both ends
    return jnp.where(x <= 1, height * rise(x), height * (1 - rise(x - 1)))


def feet_phase(
    mj_model: mujoco.MjModel,
    feet: Sequence[str],
    frequency: float,
    offsets: Sequence[float] = BIPED,
    height: float = 0.15,
    width: float = 0.01,
) -> Partial:
    """Reward in [0, 1]: exp(-sum_feet (h - swing_height(phase))^2 / `width`), where h is
    each foot geom's height above where it rests in the model's first keyframe, at the
    phase the step started in; 0 while the base stands still (|v_xy| and |w_z| <= 0.1)
    under a zero command (the `with_velocity_command` state's). Flat ground: the heights
    are the world's."""
    frequency, offsets = _check(frequency, offsets, "gait.feet_phase")
    ids = names.ids(mj_model, "geom", feet, "gait.feet_phase")
    if len(ids) != offsets.shape[0]:
        raise ValueError(f"gait.feet_phase: {len(ids)} feet {tuple(feet)} need as many offsets, got {offsets.shape[0]}")
    if not (math.isfinite(height) and math.isfinite(width) and width > 0):
        raise ValueError(f"gait.feet_phase: height={height!r} must be finite and width={width!r} finite and > 0")
    data = mujoco.MjData(mj_model)
    if mj_model.nkey:
        mujoco.mj_resetDataKeyframe(mj_model, data, 0)
    mujoco.mj_kinematics(mj_model, data)
    rest = jnp.asarray(data.geom_xpos[np.asarray(ids), 2], jnp.float32)
    return Partial(_feet_phase, jnp.asarray(ids), rest, frequency, offsets, jnp.float32(height), jnp.float32(width))


def _feet_phase(ids, rest, frequency, offsets, height, width, model, state, action, next_state) -> Array:
    lift = next_state.data.geom_xpos[ids, 2] - rest
    target = swing_height(phases(frequency, offsets, state.data.time), height)
    qvel = next_state.data.qvel
    command = find(state, VelocityCommandState).command
    moving = (jnp.linalg.norm(qvel[:2]) > 0.1) | (jnp.abs(qvel[5]) > 0.1) | (jnp.linalg.norm(command) > 0.01)
    return jnp.exp(-jnp.sum(jnp.square(lift - target)) / width) * moving
