"""Pushes (`mjzoo.catalog.events`) on the base-and-arm task of tests/catalog_tasks.py: a free 2 kg box
"base" in zero gravity, no contacts, semi-implicit Euler with dt = 0.02 s and one physics
step per control step, so
    qvel' = qvel + dt * F / m,   qpos' = qpos + dt * qvel'.
Left alone it keeps its velocity. With interval (0.1, 0.1) s the countdown (0.1 s) runs
out after 5 steps: pushes start at steps 6, 11, 16, ... (1-based). All runs go through
one jitted, vmapped runner.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from catalog_tasks import DT
from catalog_tasks import MASS
from catalog_tasks import B
from catalog_tasks import T
from catalog_tasks import make_task
from catalog_tasks import run

import mjzoo
import mjzoo.envs
from mjzoo.catalog import events
from mjzoo.layers import find

PUSH_STEPS = np.array([6, 11, 16, 21]) - 1  # 0-based steps at which a (0.1, 0.1) s interval pushes
KEY = jax.random.key(0)


def steps_where(flags: np.ndarray) -> list[np.ndarray]:
    return [np.flatnonzero(row) for row in np.asarray(flags)]


# --- velocity pushes ------------------------------------------------------------------


def test_velocity_pushes_on_schedule_and_integrated_by_hand():
    task = events.with_velocity_pushes(make_task(), interval=(0.1, 0.1), linear=(1.0, 0.5, 0.0))
    start, s = run(task, KEY)
    np.testing.assert_allclose(find(start, events.VelocityPushState).countdown, 0.1)
    for pushed in steps_where(s.metrics["velocity_push/applied"]):
        np.testing.assert_array_equal(pushed, PUSH_STEPS)
    # countdown after steps 1..6: 0.08, 0.06, 0.04, 0.02, 0, (pushed: 0.1 - 0.02 =) 0.08.
    countdown = find(s, events.VelocityPushState).countdown[:, :6]
    np.testing.assert_allclose(countdown, [[0.08, 0.06, 0.04, 0.02, 0.0, 0.08]] * B, atol=1e-6)
    v = np.asarray(s.data.qvel[:, :, :3])  # [B, T, 3] world linear velocity of the base
    kicks = np.diff(np.concatenate([np.zeros((B, 1, 3)), v], axis=1), axis=1)  # velocity change per step
    pushed = np.zeros(T, bool)
    pushed[PUSH_STEPS] = True
    np.testing.assert_allclose(kicks[:, ~pushed], 0.0, atol=1e-6)  # nothing else changes it
    k = kicks[:, pushed]
    assert np.all(np.abs(k[..., 0]) <= 1.0) and np.all(np.abs(k[..., 1]) <= 0.5)
    np.testing.assert_array_equal(k[..., 2], 0.0)
    assert len(np.unique(np.round(k[..., 0], 6))) == k[..., 0].size  # a new draw every push
    np.testing.assert_allclose(s.metrics["velocity_push/linear"][:, pushed], np.linalg.norm(k, axis=-1), rtol=1e-5)
    np.testing.assert_array_equal(s.metrics["velocity_push/linear"][:, ~pushed], 0.0)
    # The step integrates the kick: qpos after the first push = dt * dv.
    np.testing.assert_allclose(s.data.qpos[:, 5, :2], DT * k[:, 0, :2], rtol=1e-5, atol=1e-7)
    np.testing.assert_array_equal(s.data.qvel[:, :, 3:], 0.0)  # no angular kick asked


def test_velocity_pushes_random_intervals_and_angular_kicks():
    # Same structure: numbers are leaves, no new compile.
    task = events.with_velocity_pushes(make_task(), interval=(0.04, 0.1), linear=(0, 0, 0), angular=(0, 0, 2.0))
    _, s = run(task, KEY)
    for pushed in steps_where(s.metrics["velocity_push/applied"]):
        # First push after 2..5 steps (0.04..0.1 s), then every 2..5 steps.
        assert 2 <= pushed[0] <= 5 and np.all((np.diff(pushed) >= 2) & (np.diff(pushed) <= 5)), pushed
    assert len({tuple(p) for p in steps_where(s.metrics["velocity_push/applied"])}) > 1  # schedules differ per key
    np.testing.assert_array_equal(s.data.qvel[..., :5], 0.0)  # only the body-frame z angular velocity moves
    assert np.abs(s.data.qvel[..., 5]).max() > 0.0 and np.all(np.abs(s.metrics["velocity_push/angular"]) <= 2.0)


# --- force pushes ---------------------------------------------------------------------


def test_force_pushes_held_for_the_duration():
    # 0.04 s = two steps. Each push F changes the velocity by 2 * dt * F / m = 0.02 F.
    task = events.with_force_pushes(make_task(), "base", interval=(0.1, 0.1), force=(10, 10, 10), duration=0.04)
    _, s = run(task, KEY)
    for started in steps_where(s.metrics["force_push/started"]):
        np.testing.assert_array_equal(started, PUSH_STEPS)
    active = np.zeros(T, bool)
    active[PUSH_STEPS] = active[PUSH_STEPS + 1] = True
    np.testing.assert_array_equal(s.metrics["force_push/force"][:, ~active], 0.0)
    forces = np.asarray(find(s, events.ForcePushState).force[:, PUSH_STEPS])  # [B, 4, 3]
    assert np.all(np.abs(forces) <= 10.0) and len(np.unique(forces)) == forces.size
    size = s.metrics["force_push/force"][:, PUSH_STEPS + 1]
    np.testing.assert_allclose(size, np.linalg.norm(forces, axis=-1), rtol=1e-5)
    # Velocity after the first push's two steps: 0.02 F; after step 6 alone: 0.01 F.
    v = np.asarray(s.data.qvel[:, :, :3])
    np.testing.assert_allclose(v[:, 5], DT * forces[:, 0] / MASS, rtol=1e-4)
    np.testing.assert_allclose(v[:, 6], 2 * DT * forces[:, 0] / MASS, rtol=1e-4)
    np.testing.assert_allclose(v[:, 9], v[:, 6], rtol=1e-6)  # no force between pushes
    np.testing.assert_allclose(v[:, 11] - v[:, 9], 2 * DT * forces[:, 1] / MASS, rtol=1e-4, atol=1e-6)
    np.testing.assert_array_equal(s.data.xfrc_applied, 0.0)  # the push is taken off after each step
    np.testing.assert_allclose(find(s, events.ForcePushState).remaining[:, PUSH_STEPS], 0.02, atol=1e-6)


def test_pushes_restart_with_every_episode():
    # Episodes of 8 steps: the countdown restarts at each reset, so pushes come at steps
    # 6 and 14 (= 8 + 6) and 22, never at 11 or 16.
    task = events.with_velocity_pushes(make_task(), interval=(0.1, 0.1), linear=(1, 1, 0))
    task = events.with_force_pushes(task, "arm", interval=(0.1, 0.1), force=(1, 1, 1), duration=0.02)
    task = mjzoo.with_auto_reset(mjzoo.with_time_limit(task, 8))
    _, s = run(task, KEY)
    for flags in ("velocity_push/applied", "force_push/started"):
        for pushed in steps_where(s.metrics[flags]):
            np.testing.assert_array_equal(pushed, [5, 13, 21])


# --- errors at construction -------------------------------------------------------------


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match=r"no body named 'torso'; body names: \['world', 'base', 'arm', 'hand'"):
        events.with_force_pushes(make_task(), "torso")
    with pytest.raises(ValueError, match="'world'"):
        events.with_force_pushes(make_task(), "world")
    with pytest.raises(ValueError, match="duration"):
        events.with_force_pushes(make_task(), "base", duration=0.0)
    with pytest.raises(ValueError, match="interval"):
        events.with_velocity_pushes(make_task(), interval=(0.0, 1.0))
    with pytest.raises(ValueError, match="interval"):
        events.with_force_pushes(make_task(), "base", interval=(2.0, 1.0))
    with pytest.raises(ValueError, match="force"):
        events.with_force_pushes(make_task(), "base", force=(1.0, -1.0, 0.0))
    with pytest.raises(ValueError, match="linear"):
        events.with_velocity_pushes(make_task(), linear=(1.0, 1.0))
    with pytest.raises(ValueError, match="free joint"):
        events.with_velocity_pushes(mjzoo.envs.make("pendulum_swingup"))
