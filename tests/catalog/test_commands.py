"""Commands (`mjzoo.catalog.commands`) on the base-and-arm task of tests/catalog_tasks.py, worked out
by hand: with a body-frame angular velocity (0, 0, w) the base's heading after n steps
is w * 0.02 * n. The task observes [qpos, qvel] (19,), and its step reports the size of
the observation it was given in ``metrics["inner_obs_size"]``.
With resample_interval (0.1, 0.1) s the countdown runs out at the end of step 5 (1-based).
All runs go through two jitted, vmapped functions (a rollout and a batch of resets).
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from catalog_tasks import DT
from catalog_tasks import QPOS0
from catalog_tasks import B
from catalog_tasks import T
from catalog_tasks import make_task
from catalog_tasks import resets_of
from catalog_tasks import run

import mjzoo
import mjzoo.envs
from mjzoo.catalog import commands
from mjzoo.layers import find
from mjzoo.types import Task


def base_task(yaw: float = 0.0, spin: float = 0.0) -> Task:
    """The base turned by `yaw` rad and spinning at `spin` rad/s about its z axis."""
    qpos = np.concatenate([QPOS0[:3], [np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)], QPOS0[7:]])
    return make_task(qpos, np.array([0, 0, 0, 0, 0, spin, 0, 0, 0]))


KEY = jax.random.key(0)


def velocity(**overrides) -> Task:
    args = dict(vx=(-1, 1), vy=(-0.5, 0.5), yaw_rate=(-2, 2), resample_interval=(0.1, 0.1))
    return commands.with_velocity_command(make_task(), **{**args, **overrides})


# --- velocity command -------------------------------------------------------------------


def test_velocity_command_redrawn_on_schedule_and_every_episode_and_observed():
    # Episodes of 8 steps: redraws at the end of steps 5, 13, 21 (the countdown) and a
    # new command from each reset, after steps 8, 16, 24.
    task = mjzoo.with_auto_reset(mjzoo.with_time_limit(velocity(), 8))
    start, s = run(task, KEY)
    c = np.asarray(find(s, commands.VelocityCommandState).command)  # [B, T, 3]
    assert c.dtype == np.float32 and c.shape == (B, T, 3)
    for row in np.asarray(s.metrics["velocity_command/resampled"]):
        np.testing.assert_array_equal(np.flatnonzero(row), [4, 12, 20])
    # Constant in between: the command changes exactly there.
    full = np.concatenate(
        [np.asarray(find(start, commands.VelocityCommandState).command)[:, None], c], axis=1
    )  # [B, T + 1, 3]
    changed = np.any(full[:, 1:] != full[:, :-1], axis=-1)
    np.testing.assert_array_equal(changed, np.broadcast_to(np.isin(np.arange(T), [4, 7, 12, 15, 20, 23]), (B, T)))
    assert np.all(np.abs(full) <= [1.0, 0.5, 2.0]) and np.abs(full[..., 2]).max() > 1.0
    # The observation is [inner observation (19), command (3)]; the inner step got its own 19.
    np.testing.assert_array_equal(s.obs[..., 19:], c)
    np.testing.assert_array_equal(s.obs[..., :19], np.concatenate([s.data.qpos, s.data.qvel], axis=-1))
    np.testing.assert_array_equal(start.obs[:, 19:], find(start, commands.VelocityCommandState).command)
    np.testing.assert_array_equal(s.metrics["inner_obs_size"], 19.0)


def test_zero_and_stand_probabilities():
    keys = jax.random.split(KEY, 4000)
    c = np.asarray(find(resets_of(velocity(zero_probability=0.5), keys), commands.VelocityCommandState).command)
    np.testing.assert_allclose(np.mean(c == 0, axis=0), 0.5, atol=0.03)  # each component alone
    np.testing.assert_allclose(np.mean(np.all(c == 0, axis=1)), 0.125, atol=0.02)  # all three: 0.5^3
    c = np.asarray(find(resets_of(velocity(stand_probability=0.25), keys), commands.VelocityCommandState).command)
    np.testing.assert_allclose(np.mean(np.all(c == 0, axis=1)), 0.25, atol=0.03)  # together
    np.testing.assert_allclose(np.mean(c == 0), 0.25, atol=0.03)  # never alone
    c = np.asarray(
        find(resets_of(velocity(vx=(0.3, 0.3), zero_probability=0.0), keys), commands.VelocityCommandState).command
    )
    np.testing.assert_array_equal(c[:, 0], np.float32(0.3))
    assert not np.any(c == 0)


# --- heading command --------------------------------------------------------------------


def test_heading_command_steers_by_the_heading_error():
    # Target heading 1 rad; the base turns at 1 rad/s, so after n steps its heading is
    # 0.02 n and the yaw rate is clip(0.5 (1 - 0.02 n), +-0.3): 0.3 up to n = 20, then
    # 0.5 * 0.58 = 0.29 at n = 21, 0.28, 0.27, 0.26.
    task = commands.with_heading_command(
        base_task(spin=1.0),
        vx=(0.5, 0.5),
        vy=(-0.2, -0.2),
        heading=(1.0, 1.0),
        gain=0.5,
        max_yaw_rate=0.3,
        resample_interval=(0.1, 0.1),
    )
    start, s = run(task, KEY)
    n = np.arange(1, T + 1)
    expected = np.clip(0.5 * (1.0 - DT * n), -0.3, 0.3)
    np.testing.assert_allclose(
        find(s, commands.VelocityCommandState).command[..., 2], np.broadcast_to(expected, (B, T)), atol=1e-5
    )
    np.testing.assert_allclose(
        find(s, commands.VelocityCommandState).command[..., :2], np.broadcast_to([0.5, -0.2], (B, T, 2)), atol=1e-7
    )
    np.testing.assert_allclose(
        find(start, commands.VelocityCommandState).command, np.broadcast_to([0.5, -0.2, 0.3], (B, 3)), atol=1e-7
    )
    np.testing.assert_allclose(find(s, commands.VelocityCommandState).target[..., 2], 1.0)
    np.testing.assert_array_equal(s.obs[..., 19:], find(s, commands.VelocityCommandState).command)


def test_heading_command_turns_the_short_way():
    # Heading -3 rad, target 3 rad: the error is 6 - 2 pi = -0.283 rad, not +6.
    task = commands.with_heading_command(
        base_task(yaw=-3.0),
        vx=(0.5, 0.5),
        vy=(-0.2, -0.2),
        heading=(3.0, 3.0),
        gain=0.5,
        max_yaw_rate=1.0,
        resample_interval=(0.1, 0.1),
    )
    start, _ = run(task, KEY)
    np.testing.assert_allclose(
        find(start, commands.VelocityCommandState).command[:, 2], 0.5 * (6.0 - 2 * np.pi), atol=1e-5
    )


# --- joint position command -------------------------------------------------------------


def test_joint_position_command_within_the_joint_ranges():
    task = commands.with_joint_position_command(make_task(), ["hip", "wrist"], resample_interval=(0.1, 0.1))
    keys = jax.random.split(KEY, 2000)
    c = np.asarray(find(resets_of(task, keys), commands.JointCommandState).command)
    assert c.shape == (2000, 2) and c.dtype == np.float32
    assert c[:, 0].min() >= -1 and c[:, 0].max() <= 0.5 and c[:, 0].min() < -0.99 and c[:, 0].max() > 0.49
    assert c[:, 1].min() >= -0.1 and c[:, 1].max() <= 0.2 and c[:, 1].min() < -0.09 and c[:, 1].max() > 0.19
    start = resets_of(task, keys)
    np.testing.assert_array_equal(start.obs[:, 19:], find(start, commands.JointCommandState).command)  # observed too
    # An unlimited joint needs explicit ranges (same structure: no new compile).
    task = commands.with_joint_position_command(make_task(), ["spin", "hip"], ranges=[(2.0, 3.0), (-0.5, 0.0)])
    c = np.asarray(find(resets_of(task, keys), commands.JointCommandState).command)
    assert c[:, 0].min() >= 2.0 and c[:, 0].max() <= 3.0 and c[:, 1].min() >= -0.5 and c[:, 1].max() <= 0.0


# --- errors at construction ---------------------------------------------------------------


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="vx"):
        velocity(vx=(1.0, -1.0))
    with pytest.raises(ValueError, match="zero_probability"):
        velocity(zero_probability=1.5)
    with pytest.raises(ValueError, match="resample_interval"):
        velocity(resample_interval=(0.0, 1.0))
    with pytest.raises(ValueError, match="free joint"):
        commands.with_heading_command(mjzoo.envs.make("pendulum_swingup"))
    with pytest.raises(ValueError, match="gain"):
        commands.with_heading_command(make_task(), gain=-1.0)
    with pytest.raises(ValueError, match="'spin' has no range"):
        commands.with_joint_position_command(make_task(), ["spin"])
    with pytest.raises(ValueError, match=r"no joint named 'knee'; joint names: \['root', 'hip', 'wrist', 'spin'\]"):
        commands.with_joint_position_command(make_task(), ["knee"])
    with pytest.raises(ValueError, match="one .* range per joint"):
        commands.with_joint_position_command(make_task(), ["hip"], ranges=[(0, 1), (0, 1)])
    dict_obs = mjzoo.with_observation(make_task(), lambda obs: {"x": obs})
    with pytest.raises(ValueError, match="1-D array observation"):
        commands.with_velocity_command(dict_obs)
    commands.with_velocity_command(dict_obs, observe=False)  # reading the command from its record only is fine
