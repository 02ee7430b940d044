"""Motion tracking (lib/catalog/tracking.py, start_sampling.py) on a three-body robot: each
reward and termination against hand-computed numbers under jit and vmap, the adaptive
sampler's statistics and distribution in numpy, and the tracking task (envs/motion_tracking.py's
factory) through the Task contract with the robot on its reference at reset."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import mjzoo
from mjzoo import motion
from mjzoo import physics
from mjzoo.catalog import start_sampling
from mjzoo.catalog import tracking
from mjzoo.envs import motion_tracking

ROBOT = """
<mujoco>
  <option timestep="0.01"/>
  <default><geom contype="0" conaffinity="0"/></default>
  <worldbody>
    <body name="pelvis" pos="0 0 1">
      <freejoint name="root"/>
      <geom type="box" size=".1 .1 .1" mass="5"/>
      <body name="torso" pos="0 0 .2">
        <joint name="waist" type="hinge" axis="0 1 0" range="-1 1"/>
        <geom type="capsule" fromto="0 0 0 0 0 .3" size=".05" mass="2"/>
        <body name="arm" pos="0 .1 .3">
          <joint name="shoulder" type="hinge" axis="0 1 0" range="-2 2"/>
          <geom type="capsule" fromto="0 0 0 .3 0 0" size=".03" mass="1"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position joint="waist" kp="50" kv="2" ctrlrange="-1 1"/>
    <position joint="shoulder" kp="20" kv="1" ctrlrange="-2 2"/>
  </actuator>
</mujoco>
"""
BODIES = ("pelvis", "torso", "arm")


@functools.cache
def robot() -> physics.Physics:
    return physics.load(ROBOT, ctrl_dt=0.02)


def clip(name: str = "sway", frames: int = 20, speed: float = 0.5) -> motion.Clip:
    """The pelvis moving forward at `speed` m/s, the waist and shoulder swaying, 50 fps."""
    m = robot().mj_model
    t = np.arange(frames) / 50.0
    qpos = np.zeros((frames, m.nq))
    qpos[:, 0], qpos[:, 2], qpos[:, 3] = speed * t, 1.0, 1.0
    qpos[:, 7], qpos[:, 8] = 0.3 * np.sin(4 * t), 0.5 * np.sin(3 * t)
    qvel = motion.velocities_from_positions(qpos, 50.0, m)
    return motion.Clip(name=name, fps=50.0, qpos=qpos, qvel=qvel, joint_names=tuple(m.joint(i).name for i in range(3)))


@functools.cache
def reference() -> tracking.Motion:
    m = robot().mj_model
    return tracking.motion(motion.reference([clip()], m, dt=0.02, loop=False), m, BODIES, anchor="torso")


def state_at(frame: int, shift=(0.0, 0.0, 0.0), yaw: float = 0.0, tilt: float = 0.0, joints=(0.0, 0.0), kick=None):
    """The robot at `frame` of the clip (on the clock), its base moved by `shift` (m),
    turned about world z by `yaw` and about its x axis by `tilt` (rad), its joints offset
    by `joints`, its base's world linear velocity raised by `kick` (m/s)."""
    p, ref = robot(), reference()
    data = mujoco.MjData(p.mj_model)
    data.qpos, data.qvel = np.asarray(ref.clips.qpos[frame]), np.asarray(ref.clips.qvel[frame])
    turn, bend = np.zeros(4), np.zeros(4)
    mujoco.mju_axisAngle2Quat(turn, [0, 0, 1], yaw)
    mujoco.mju_axisAngle2Quat(bend, [1, 0, 0], tilt)
    quat = np.zeros(4)
    mujoco.mju_mulQuat(quat, turn, data.qpos[3:7].copy())
    mujoco.mju_mulQuat(quat, quat.copy(), bend)
    position = np.zeros(3)
    mujoco.mju_rotVecQuat(position, data.qpos[:3].copy(), turn)  # the whole robot turned about the origin
    data.qpos[:3], data.qpos[3:7] = position + shift, quat
    linear = np.zeros(3)
    mujoco.mju_rotVecQuat(linear, data.qvel[:3].copy(), turn)  # world-frame linear velocity turns too
    data.qvel[:3] = linear + (np.zeros(3) if kick is None else kick)
    data.qpos[7:] += joints
    data.time = frame * 0.02
    mujoco.mj_forward(p.mj_model, data)
    info = {"reference_clip": jnp.int32(0), "reference_frame": jnp.int32(0)}
    return mjzoo.State.create(mujoco.mjx.put_data(p.mj_model, data), jnp.zeros(1), info)


def rewards(ref):
    return {
        "anchor_position": tracking.anchor_position_tracking(ref, 0.3),
        "anchor_orientation": tracking.anchor_orientation_tracking(ref, 0.4),
        "body_position": tracking.body_position_tracking(ref, 0.3),
        "body_orientation": tracking.body_orientation_tracking(ref, 0.4),
        "body_linear_velocity": tracking.body_linear_velocity_tracking(ref, 1.0),
        "body_angular_velocity": tracking.body_angular_velocity_tracking(ref, 3.14),
        "joint_position": tracking.joint_position_tracking(ref, 0.5),
    }


@jax.jit
def evaluate(model, ref, state):
    """Every term, termination and the MPJPE of a batch of states (vmapped)."""

    def one(state):
        out = {k: fn(model, state, None, state) for k, fn in rewards(ref).items()}
        out["height"] = tracking.anchor_height_deviation(ref, 0.25)(model, state)
        out["tilt"] = tracking.anchor_orientation_deviation(ref, 0.8)(model, state)
        out["mpjpe"] = tracking.mpjpe(ref, state)
        return out

    return jax.vmap(one)(state)


def stacked(*states):
    return jax.tree.map(lambda *x: jnp.stack(x), *states)


def test_tracking_terms_by_hand_under_jit_and_vmap():
    ref, model = reference(), robot().model
    cases = dict(
        on=state_at(5),
        shifted=state_at(5, shift=(0.1, 0.0, 0.0)),
        turned=state_at(5, yaw=np.pi / 2),
        lifted=state_at(5, shift=(0.0, 0.0, 0.3)),
        bent=state_at(5, joints=(0.2, 0.0)),
        kicked=state_at(5, kick=(0.3, 0.0, 0.0)),
        tilted=state_at(5, tilt=1.4),
    )
    out = {k: np.asarray(v) for k, v in evaluate(model, ref, stacked(*cases.values())).items()}
    row = {name: {k: v[i] for k, v in out.items()} for i, name in enumerate(cases)}
    on = row["on"]  # on the reference: every reward 1, nothing ends, no error
    for name in rewards(ref):
        assert on[name] == pytest.approx(1.0, abs=1e-4), name
    assert not on["height"] and not on["tilt"] and on["mpjpe"] < 1e-3
    # 10 cm off in x: the anchor pays exp(-0.01 / 0.09); anchored bodies and MPJPE do not see it.
    shifted = row["shifted"]
    assert shifted["anchor_position"] == pytest.approx(np.exp(-0.01 / 0.09), rel=1e-4)
    assert shifted["body_position"] == pytest.approx(1.0, abs=1e-4) and shifted["mpjpe"] < 1e-3
    # Turned a quarter about z (with its velocities): the anchor's orientation pays
    # exp(-(pi/2)^2 / 0.16), the anchored bodies, their velocities and the joints match.
    turned = row["turned"]
    assert turned["anchor_orientation"] == pytest.approx(np.exp(-((np.pi / 2) ** 2) / 0.16), rel=1e-3)
    for name in ("body_position", "body_orientation", "body_linear_velocity", "body_angular_velocity"):
        assert turned[name] == pytest.approx(1.0, abs=1e-4), name
    # 0.3 m up: beyond 0.25 m of height error; the anchor pays exp(-0.09 / 0.09).
    lifted = row["lifted"]
    assert lifted["height"] and not lifted["tilt"]
    assert lifted["anchor_position"] == pytest.approx(np.exp(-1.0), rel=1e-4)
    # The waist 0.2 rad off: the joints' mean squared error 0.02 -> exp(-0.02 / 0.25);
    # the torso and arm turn with it, so MPJPE grows, the anchor (torso) stays the origin.
    bent = row["bent"]
    assert bent["joint_position"] == pytest.approx(np.exp(-0.02 / 0.25), rel=1e-4)
    assert bent["mpjpe"] > 10.0
    # Every body 0.3 m/s faster in x: exp(-0.09 / 1).
    assert row["kicked"]["body_linear_velocity"] == pytest.approx(np.exp(-0.09), rel=1e-3)
    # Tilted 1.4 rad about x: |cos(1.4) - 1| = 0.83 > 0.8.
    assert row["tilted"]["tilt"] and not row["tilted"]["height"]


def test_anchored_and_quaternions_by_hand():
    quarter = jnp.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])  # +90 deg about z
    np.testing.assert_allclose(tracking.quat_rotate(quarter, jnp.array([1.0, 0.0, 0.0])), [0, 1, 0], atol=1e-6)
    np.testing.assert_allclose(tracking.quat_angle(jnp.array([1.0, 0, 0, 0]), quarter), np.pi / 2, rtol=1e-6)
    tilted_turn = tracking.quat_multiply(quarter, jnp.array([np.cos(0.2), np.sin(0.2), 0.0, 0.0]))
    np.testing.assert_allclose(tracking.yaw_only(tilted_turn), quarter, atol=1e-6)
    # Reference: anchor at (1, 0, 0.9) facing +x, a body 0.5 m ahead of it. Robot's anchor at
    # (0, 2, 0.7) facing +y: the body goes 0.5 m along +y, at the reference anchor's height.
    ref_pos = jnp.array([[1.0, 0.0, 0.9], [1.5, 0.0, 1.0]])
    ref_quat = jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0]), (2, 1))
    pos, quat, turn = tracking.anchored(ref_pos, ref_quat, 0, jnp.array([0.0, 2.0, 0.7]), quarter)
    np.testing.assert_allclose(pos, [[0.0, 2.0, 0.9], [0.0, 2.5, 1.0]], atol=1e-6)
    np.testing.assert_allclose(quat, jnp.tile(quarter, (2, 1)), atol=1e-6)
    np.testing.assert_allclose(turn, quarter, atol=1e-6)


# --- the adaptive sampler -----------------------------------------------------------------


def test_bins_and_uniform_floor():
    valid = start_sampling.bins([10, 4], frames_per_bin=4)  # start frames 0..8 -> 3 bins; 0..2 -> 1
    np.testing.assert_array_equal(valid, [[True, True, True], [True, False, False]])
    p = np.asarray(start_sampling.uniform_probabilities(valid, jnp.array([0.75, 0.25])))
    np.testing.assert_allclose(p, [[0.25, 0.25, 0.25], [0.25, 0.0, 0.0]])


def test_start_probabilities_by_hand():
    valid = np.array([[True, True, True], [True, True, False]])
    weight = jnp.array([0.5, 0.5])
    failures = jnp.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    p = np.asarray(start_probabilities(failures, valid, weight))
    # Smoothed with 0.8 one bin back: (0, 0.8, 1) / 1.8 takes 0.9, the floor 0.1 of
    # (1/6, 1/6, 1/6; 1/4, 1/4, 0).
    floor = np.array([[1 / 6, 1 / 6, 1 / 6], [1 / 4, 1 / 4, 0.0]])
    expected = 0.9 * np.array([[0.0, 0.8, 1.0], [0.0, 0.0, 0.0]]) / 1.8 + 0.1 * floor
    np.testing.assert_allclose(p, expected, rtol=1e-6)
    assert p.sum() == pytest.approx(1.0, rel=1e-6)
    # Nothing failed: the floor alone; a failure in a cell the clip lacks counts nowhere.
    np.testing.assert_allclose(start_probabilities(jnp.zeros((2, 3)), valid, weight), floor, rtol=1e-6)
    masked = jnp.zeros((2, 3)).at[1, 2].set(1.0)
    np.testing.assert_allclose(start_probabilities(masked, valid, weight)[1], [0.1 / 4, 0.1 / 4 + 0.9, 0], rtol=1e-5)


def start_probabilities(failures, valid, weight):
    return jax.jit(start_sampling.start_probabilities, static_argnums=5)(failures, valid, weight, 0.1, 0.8, 1)


def test_record_failure_averages_over_episode_ends():
    update = jax.jit(start_sampling.record_failure)
    failures = jnp.array([[0.2, 0.0], [0.0, 0.4]])
    kept = update(failures, 0, 1, False, True, 0.5)  # the episode goes on: unchanged
    np.testing.assert_allclose(kept, failures)
    failed = update(failures, 0, 1, True, True, 0.5)  # ended by a failure in (0, 1)
    np.testing.assert_allclose(failed, [[0.1, 0.5], [0.0, 0.2]])
    finished = update(failures, 0, 1, True, False, 0.5)  # played to the end: decay only
    np.testing.assert_allclose(finished, [[0.1, 0.0], [0.0, 0.2]])


def test_sample_start_follows_the_table():
    table = jnp.array([[0.1, 0.2, 0.3], [0.4, 0.0, 0.0]])
    lengths = jnp.array([10, 4])  # clip 0: starts 0..8 in bins [0-3], [4-7], [8]; clip 1: 0..2
    draw = jax.jit(jax.vmap(start_sampling.sample_start, in_axes=(0, None, None, None)))
    clip, frame = (np.asarray(x) for x in draw(jax.random.split(jax.random.key(0), 20000), table, lengths, 4))
    cells = np.where(clip == 0, frame // 4, 3)
    share = np.bincount(cells, minlength=4) / len(cells)
    np.testing.assert_allclose(share, [0.1, 0.2, 0.3, 0.4], atol=0.015)
    assert frame[clip == 0].max() == 8 and frame[clip == 1].max() == 2  # never the last frame
    assert set(frame[(clip == 0) & (cells == 1)]) == {4, 5, 6, 7}


# --- the task -----------------------------------------------------------------------------


def sway_clips() -> list[motion.Clip]:
    return [clip(), clip("stroll", frames=30, speed=0.2)]


def test_tracking_task_starts_on_the_reference_and_adapts_where_it_fails():
    """One compile: 8 envs reset and run 24 steps of zero actions. The unsupported robot
    falls (its anchor 0.25 m under the reference's after ~0.2 s) unless its clip ends first."""
    clips = sway_clips()
    task = motion_tracking.motion_tracking(
        robot(), clips, motion_tracking.Tracked(BODIES, "torso", ("arm",)), bin_seconds=0.1
    )
    m = robot().mj_model
    ref = tracking.motion(motion.reference(clips, m, dt=0.02, loop=False), m, BODIES, anchor="torso")

    @jax.jit
    def run(task, key):
        states = jax.vmap(mjzoo.reset, in_axes=(None, 0))(task, jax.random.split(key, 8))

        def step(states, key):
            states = jax.vmap(mjzoo.transition, in_axes=(None, 0, None, 0))(
                task, states, jnp.zeros(task.action_size), jax.random.split(key, 8)
            )
            return states, states

        return (
            states,
            jax.vmap(tracking.mpjpe, in_axes=(None, 0))(ref, states),
            jax.lax.scan(step, states, jax.random.split(key, 24)),
        )

    states, mpjpe, (last, steps) = run(task, jax.random.key(1))
    clip_of, frame = np.asarray(states.info["reference_clip"]), np.asarray(states.info["reference_frame"])
    assert set(clip_of) == {0, 1} and np.all(frame >= 0) and np.all(frame <= np.array([18, 28])[clip_of])
    np.testing.assert_allclose(states.data.time, frame * 0.02, atol=1e-6)  # the clock
    index = np.asarray(ref.clips.start)[clip_of] + frame  # the state is that frame's
    np.testing.assert_allclose(states.data.qpos, np.asarray(ref.clips.qpos)[index], atol=1e-6)
    np.testing.assert_allclose(states.data.qvel, np.asarray(ref.clips.qvel)[index], atol=1e-6)
    assert np.all(np.asarray(mpjpe) < 1e-2)  # mm
    for leaf in jax.tree.leaves((steps.obs, steps.reward, steps.metrics)):
        assert np.all(np.isfinite(np.asarray(leaf)))
    terminated, truncated = np.asarray(steps.terminated), np.asarray(steps.truncated)
    assert terminated.any() and truncated.any()  # falls and clips played to their end
    # Every ended episode is counted once, under its clip; success = truncated (the clip's end).
    ended = sum(np.asarray(steps.metrics[f"tracking/{c.name}/ended"]) for c in clips)
    succeeded = sum(np.asarray(steps.metrics[f"tracking/{c.name}/succeeded"]) for c in clips)
    np.testing.assert_array_equal(ended, terminated | truncated)
    np.testing.assert_array_equal(succeeded, truncated)
    # The sampler's failures rose exactly in the envs where an episode failed.
    failures = np.asarray(mjzoo.find(last, start_sampling.AdaptiveStartState).failures)
    np.testing.assert_array_equal(failures.sum(axis=(1, 2)) > 0, terminated.any(axis=0))


def test_summary_turns_batch_means_into_per_clip_rates():
    metrics = {
        "env/tracking/walk/ended": 0.04,
        "env/tracking/walk/succeeded": 0.03,
        "env/tracking/walk/episode_mpjpe_mm": 1.2,
        "env/tracking/run/ended": 0.0,
        "env/tracking/run/succeeded": 0.0,
        "env/tracking/run/episode_mpjpe_mm": 0.0,
        "env/tracking/mpjpe_mm": 25.0,
    }
    out = start_sampling.summary(metrics)
    assert set(out) == {"walk", "run"}
    assert out["walk"] == pytest.approx({"episodes": 0.04, "success": 0.75, "mpjpe_mm": 30.0})
    assert np.isnan(out["run"]["success"]) and np.isnan(out["run"]["mpjpe_mm"])
