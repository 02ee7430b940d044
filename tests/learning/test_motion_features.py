"""`mjzoo.learning.motion_features` on a toy robot: a free box with a two-hinge arm
(shoulder, elbow: pitch about the box's y axis) ending in a `hand`, and a tail on a ball
joint (`hip`) ending in a `tip`. At rest, in the box's frame, the hand is at (0.8, 0, 0)
and the tip at (-0.5, 0, 0). Features: 13 of the base, qpos 1 + 1 + 6, qvel 1 + 1 + 3,
key bodies 3 + 3: 32. Hand-computed poses, yaw invariance, the fixed base, per-second
velocities, a C MuJoCo trajectory replayed through mjx.forward, through reference frames
and through a task that replays it under the window combinator (no MJX step to compile)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo.learning.motion_features import feature_layout  # the module: mjzoo.learning may export the function
from mjzoo.learning.motion_features import feature_size  # the module: mjzoo.learning may export the function
from mjzoo.learning.motion_features import frames_features  # the module: mjzoo.learning may export the function
from mjzoo.learning.motion_features import motion_features  # the module: mjzoo.learning may export the function
from mjzoo.learning.motion_features import with_feature_window  # the module: mjzoo.learning may export the function
from mjzoo.types import State
from mjzoo.types import Task

TOY = """
<mujoco model="toy">
  <option timestep="0.005" gravity="0 0 -2"><flag contact="disable"/></option>
  <worldbody>
    <body name="root" pos="0 0 1">
      <freejoint name="root"/>
      <geom type="box" size="0.2 0.1 0.05" mass="2"/>
      <body name="upper" pos="0.2 0 0">
        <joint name="shoulder" axis="0 1 0" damping="0.05"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04"/>
        <body name="lower" pos="0.3 0 0">
          <joint name="elbow" axis="0 1 0" damping="0.05"/>
          <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04"/>
          <body name="hand" pos="0.3 0 0"/>
        </body>
      </body>
      <body name="tail" pos="-0.2 0 0">
        <joint name="hip" type="ball" damping="0.05"/>
        <geom type="capsule" fromto="0 0 0 -0.3 0 0" size="0.04"/>
        <body name="tip" pos="-0.3 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor joint="shoulder" gear="2"/><motor joint="elbow" gear="2"/></actuator>
</mujoco>
"""
ARM = """
<mujoco model="arm">
  <option><flag contact="disable"/></option>
  <worldbody>
    <body name="base" pos="0 0 0.5">
      <joint name="shoulder" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.03"/>
      <body name="link" pos="0.4 0 0">
        <joint name="wrist" type="ball"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
        <body name="hand" pos="0.3 0 0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
TOY_MJ = mujoco.MjModel.from_xml_string(TOY)
TOY_MODEL = mjx.put_model(TOY_MJ)
TOY_DATA = mjx.make_data(TOY_MODEL)
FEATURES = motion_features(TOY_MJ, key_bodies=("hand", "tip"))
compute = jax.jit(jax.vmap(lambda f, model, data: f(model, data), in_axes=(None, None, 0)))
frames = jax.jit(frames_features)


def quat(axis: str, angle: float) -> np.ndarray:
    q = np.zeros(4)
    q[0], q["xyz".index(axis) + 1] = math.cos(angle / 2), math.sin(angle / 2)
    return q


def rot(axis: str, angle: float) -> np.ndarray:
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, quat(axis, angle))
    return m.reshape(3, 3)


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_mulQuat(out, a, b)
    return out


def toy_state(pos, root_quat, shoulder=0.0, hip=(1.0, 0, 0, 0), linear=(0, 0, 0), angular=(0, 0, 0)):
    qpos = np.concatenate([pos, root_quat, [shoulder, 0.0], hip])
    qvel = np.concatenate([linear, angular, np.zeros(5)])
    return qpos, qvel


def reference(qpos, qvel, features=FEATURES, model=TOY_MODEL, data=TOY_DATA) -> np.ndarray:
    """`frames_features` of n <= 64 frames [n, nq], [n, nv]: [n, F]. Padded to 64 frames,
    so that one compile per model serves every test."""
    qpos, qvel = np.atleast_2d(qpos), np.atleast_2d(qvel)
    pad = [(0, 64 - len(qpos)), (0, 0)]
    out = frames(features, model, data, np.pad(qpos, pad, mode="edge"), np.pad(qvel, pad, mode="edge"))
    return np.asarray(out)[: len(qpos)]


def features_of(qpos, qvel, features=FEATURES, model=TOY_MODEL, data=TOY_DATA) -> dict[str, np.ndarray]:
    """`reference`, split by the layout."""
    out = reference(qpos, qvel, features, model, data)
    return {name: out[:, s] for name, s in feature_layout(features).items()}


def test_layout_names_every_slice():
    layout = feature_layout(FEATURES)
    assert feature_size(FEATURES) == 32
    assert list(layout) == [
        "root_height",
        "root_tangent",
        "root_normal",
        "root_linear_velocity",
        "root_angular_velocity",
        "qpos/shoulder",
        "qpos/elbow",
        "qpos/hip",
        "qvel/shoulder",
        "qvel/elbow",
        "qvel/hip",
        "key_body/hand",
        "key_body/tip",
    ]
    assert [s.stop - s.start for s in layout.values()] == [1, 3, 3, 3, 3, 1, 1, 6, 1, 1, 3, 3, 3]
    assert list(layout.values())[-1].stop == 32


def test_yawed_base_moving_along_world_x():
    qpos, qvel = toy_state([0.4, -0.2, 0.7], quat("z", 0.3), linear=[1, 0, 0], angular=[0, 0, 2])
    f = features_of(qpos, qvel)
    np.testing.assert_allclose(f["root_height"][0], [0.7], atol=1e-6)
    np.testing.assert_allclose(f["root_tangent"][0], [1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(f["root_normal"][0], [0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(f["root_linear_velocity"][0], [math.cos(0.3), -math.sin(0.3), 0], atol=1e-6)
    np.testing.assert_allclose(f["root_angular_velocity"][0], [0, 0, 2], atol=1e-6)
    np.testing.assert_allclose(f["key_body/hand"][0], [0.8, 0, 0], atol=1e-6)
    np.testing.assert_allclose(f["key_body/tip"][0], [-0.5, 0, 0], atol=1e-6)
    np.testing.assert_allclose(f["qpos/hip"][0], [1, 0, 0, 0, 0, 1], atol=1e-6)


def test_pitched_base_bent_arm_and_turned_tail():
    c, s = math.cos(0.2), math.sin(0.2)  # the base pitches by 0.2 about its y axis after a yaw of 0.3
    qpos, qvel = toy_state(
        [0, 0, 1],
        mul(quat("z", 0.3), quat("y", 0.2)),
        shoulder=math.pi / 2,
        hip=quat("z", 0.5),
        linear=[1, 0, 0],
        angular=[1, 0, 0],
    )
    f = features_of(qpos, qvel)
    np.testing.assert_allclose(f["root_tangent"][0], [c, 0, -s], atol=1e-6)
    np.testing.assert_allclose(f["root_normal"][0], [s, 0, c], atol=1e-6)
    np.testing.assert_allclose(f["root_linear_velocity"][0], [math.cos(0.3), -math.sin(0.3), 0], atol=1e-6)
    np.testing.assert_allclose(f["root_angular_velocity"][0], [c, 0, -s], atol=1e-6)  # body x, in the heading frame
    np.testing.assert_allclose(f["qpos/shoulder"][0], [math.pi / 2], atol=1e-6)
    np.testing.assert_allclose(f["qpos/hip"][0], [math.cos(0.5), math.sin(0.5), 0, 0, 0, 1], atol=1e-6)
    # The hand hangs 0.6 below the shoulder (0.2, 0, 0), the tip swings by 0.5 about the hip (-0.2, 0, 0);
    # then the base's pitch turns both.
    hand, tip = np.array([0.2, 0, -0.6]), np.array([-0.2 - 0.3 * math.cos(0.5), -0.3 * math.sin(0.5), 0])
    np.testing.assert_allclose(f["key_body/hand"][0], rot("y", 0.2) @ hand, atol=1e-6)
    np.testing.assert_allclose(f["key_body/tip"][0], rot("y", 0.2) @ tip, atol=1e-6)


def test_invariant_to_yaw_and_horizontal_shift():
    rng = np.random.default_rng(0)
    q = rng.normal(size=4)
    hip = rng.normal(size=4)
    qpos = np.concatenate([[0.3, -0.1, 0.8], q / np.linalg.norm(q), [0.4, -0.7], hip / np.linalg.norm(hip)])
    qvel = rng.normal(size=TOY_MJ.nv)
    moved_qpos, moved_qvel = [], []
    for yaw, shift in ((0.0, [0, 0]), (1.1, [2.0, -3.0]), (-2.5, [0.5, 0.5]), (math.pi, [-1.0, 4.0])):
        p, v = qpos.copy(), qvel.copy()
        p[:3] = rot("z", yaw) @ p[:3] + [*shift, 0]
        p[3:7] = mul(quat("z", yaw), p[3:7])
        v[:3] = rot("z", yaw) @ v[:3]  # world frame; the angular velocity is in the base frame
        moved_qpos.append(p), moved_qvel.append(v)
    out = reference(np.array(moved_qpos), np.array(moved_qvel))
    np.testing.assert_allclose(out, np.broadcast_to(out[0], out.shape), atol=2e-5)
    assert np.abs(out[0]).min() < np.abs(out[0]).max()  # not a degenerate all-equal vector


def test_fixed_base_arm():
    mj_model = mujoco.MjModel.from_xml_string(ARM)
    model = mjx.put_model(mj_model)
    features = motion_features(mj_model, key_bodies="hand")
    assert list(feature_layout(features)) == [
        "qpos/shoulder",
        "qpos/wrist",
        "qvel/shoulder",
        "qvel/wrist",
        "key_body/hand",
    ]
    qpos = np.concatenate([[0.4], quat("y", 0.3)])
    qvel = np.array([0.5, 0.1, 0.2, 0.3])
    f = features_of(qpos, qvel, features, model, mjx.make_data(model))
    hand = rot("z", 0.4) @ [0.4 + 0.3 * math.cos(0.3), 0, -0.3 * math.sin(0.3)] + [0, 0, 0.5]  # world frame
    np.testing.assert_allclose(f["key_body/hand"][0], hand, atol=1e-6)
    np.testing.assert_allclose(
        f["qpos/wrist"][0], [math.cos(0.3), 0, -math.sin(0.3), math.sin(0.3), 0, math.cos(0.3)], atol=1e-6
    )
    np.testing.assert_allclose(np.concatenate([f["qvel/shoulder"][0], f["qvel/wrist"][0]]), qvel, atol=1e-6)


def constant_motion(fps: float, seconds: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A clip of a motion with constant velocities; qvel by frame differences / dt."""
    t = np.arange(round(seconds * fps) + 1) / fps
    qpos = np.stack(
        [
            toy_state([0.5 * s, 0.2 * s, 0.9], quat("z", 1.0 * s), shoulder=0.3 + 0.8 * s, hip=quat("z", 0.6 * s))[0]
            for s in t
        ]
    )
    qvel = np.zeros((len(t) - 1, TOY_MJ.nv))
    for k in range(len(t) - 1):
        mujoco.mj_differentiatePos(TOY_MJ, qvel[k], 1.0 / fps, qpos[k], qpos[k + 1])
    return qpos[:-1], qvel


def test_velocities_are_per_second():
    slow, fast = features_of(*constant_motion(30.0)), features_of(*constant_motion(60.0))
    for name in ("root_linear_velocity", "root_angular_velocity", "qvel/shoulder", "qvel/hip"):
        np.testing.assert_allclose(slow[name], fast[name][::2], atol=1e-4, err_msg=name)
    np.testing.assert_allclose(slow["root_angular_velocity"], np.broadcast_to([0, 0, 1.0], (30, 3)), atol=1e-4)
    np.testing.assert_allclose(slow["qvel/shoulder"], np.full((30, 1), 0.8), atol=1e-4)
    np.testing.assert_allclose(slow["qvel/hip"], np.broadcast_to([0, 0, 0.6], (30, 3)), atol=1e-4)
    yaw = np.arange(30) / 30.0  # the world velocity (0.5, 0.2, 0) seen from the turning heading frame
    expected = np.stack([rot("z", -a) @ [0.5, 0.2, 0] for a in yaw])
    np.testing.assert_allclose(slow["root_linear_velocity"], expected, atol=1e-4)


@pytest.fixture(scope="module")
def recorded():
    """C MuJoCo steps of the toy with varying controls: qpos, qvel, and the key bodies'
    world positions as mj_step leaves them (stale: from before its integration) and as
    mj_kinematics recomputes them from the new qpos."""
    data = mujoco.MjData(TOY_MJ)
    data.qvel[:] = np.random.default_rng(1).normal(size=TOY_MJ.nv)
    qpos, qvel, stale, fresh = [], [], [], []
    for k in range(40):
        data.ctrl[:] = [math.sin(0.3 * k), math.cos(0.2 * k)]
        mujoco.mj_step(TOY_MJ, data)
        qpos.append(data.qpos.copy()), qvel.append(data.qvel.copy()), stale.append(data.xpos.copy())
        mujoco.mj_kinematics(TOY_MJ, data)
        fresh.append(data.xpos.copy())
    return np.array(qpos), np.array(qvel), np.array(stale), np.array(fresh)


def test_replayed_states_and_reference_frames_agree(recorded):
    qpos, qvel, stale, fresh = recorded
    forwarded = jax.jit(jax.vmap(lambda q, v: mjx.forward(TOY_MODEL, TOY_DATA.replace(qpos=q, qvel=v))))(qpos, qvel)
    replayed = np.asarray(compute(FEATURES, TOY_MODEL, forwarded))
    np.testing.assert_allclose(replayed, reference(qpos, qvel), atol=1e-6)
    # States as a step leaves them (xpos from before the integration) give the same features.
    assert np.abs(stale - fresh).max() > 1e-3
    after_step = jax.vmap(lambda q, v, x: TOY_DATA.replace(qpos=q, qvel=v, xpos=x))(qpos, qvel, stale)
    np.testing.assert_allclose(np.asarray(compute(FEATURES, TOY_MODEL, after_step)), replayed, atol=1e-6)


def test_key_bodies_match_c_mujoco(recorded):
    qpos, qvel, _, fresh = recorded
    f = features_of(qpos, qvel)
    for k in range(len(qpos)):
        matrix = np.zeros(9)
        mujoco.mju_quat2Mat(matrix, qpos[k, 3:7] / np.linalg.norm(qpos[k, 3:7]))
        heading = math.atan2(matrix[3], matrix[0])
        offsets = (fresh[k, [4, 6]] - qpos[k, :3]) @ rot("z", heading)  # rows: R_heading^T (x - root)
        np.testing.assert_allclose(f["key_body/hand"][k], offsets[0], atol=2e-5)
        np.testing.assert_allclose(f["key_body/tip"][k], offsets[1], atol=2e-5)


# --- the window combinator, on a task replaying the recorded states --------------------


def replay_start(clip_qpos, clip_qvel, template, model, key) -> State:
    data = template.replace(qpos=clip_qpos[0], qvel=clip_qvel[0])
    return State.create(data, jnp.concatenate([data.qpos, data.qvel]), {"frame": jnp.zeros((), jnp.int32)})


def replay_step(clip_qpos, clip_qvel, model, state, action, key) -> State:
    """The next recorded frame (data.xpos stays the template's: stale, as after a step)."""
    i = jnp.minimum(state.info["frame"] + 1, clip_qpos.shape[0] - 1)
    data = state.data.replace(qpos=clip_qpos[i], qvel=clip_qvel[i])
    return state.replace(data=data, obs=jnp.concatenate([data.qpos, data.qvel]), info={**state.info, "frame": i})


def no_reward(model, state, action, next_state):
    return {"none": jnp.zeros(())}


def never(model, state):
    return jnp.zeros((), bool), jnp.zeros((), bool)


def random_action(obs, key):
    return jax.random.uniform(key, (2,), minval=-1.0, maxval=1.0)


NUM_FRAMES, NUM_STEPS = 3, 8


def replay(recorded) -> Task:
    qpos, qvel = (jnp.asarray(x, jnp.float32) for x in recorded[:2])
    return Task(
        model=TOY_MODEL,
        start=Partial(replay_start, qpos, qvel, TOY_DATA),
        step=Partial(replay_step, qpos, qvel),
        reward=Partial(no_reward),
        terminate=Partial(never),
        mj_model=TOY_MJ,
    )


def run(task: Task, num_envs: int):
    """Every state of `num_envs` rollouts (jit, vmap), the reset's first: [envs, 1 + steps]."""

    def one(key):
        state = mjzoo.reset(task, key)
        _, trajectory = mjzoo.rollout(task, random_action, state, jax.random.fold_in(key, 1), NUM_STEPS)
        return jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), state, trajectory.next_state)

    return jax.jit(jax.vmap(one))(jax.random.split(jax.random.key(3), num_envs))


def reference_windows(features: np.ndarray, restart: np.ndarray) -> np.ndarray:
    """[T, NUM_FRAMES, F] windows built by hand: a (re)start fills the window with its frame."""
    windows, window = [], None
    for frame, new in zip(features, restart):
        window = np.repeat(frame[None], NUM_FRAMES, 0) if new else np.concatenate([window[1:], frame[None]])
        windows.append(window)
    return np.array(windows)


def test_window_holds_the_features_of_the_last_states(recorded):
    states = run(with_feature_window(replay(recorded), FEATURES, NUM_FRAMES), num_envs=2)
    qpos, qvel = recorded[0][: NUM_STEPS + 1], recorded[1][: NUM_STEPS + 1]
    np.testing.assert_allclose(states.data.qpos[1], qpos, atol=1e-6)  # the replay replays
    expected = reference_windows(reference(qpos, qvel), np.arange(NUM_STEPS + 1) == 0)
    for env in range(2):
        np.testing.assert_allclose(states.obs["motion"][env], expected, atol=1e-5)
        np.testing.assert_allclose(states.obs["policy"][env], np.concatenate([qpos, qvel], 1), atol=1e-6)
    assert np.abs(expected[:, 0] - expected[:, -1]).max() > 1e-2  # the window moves


def test_window_restarts_with_each_episode(recorded):
    task = mjzoo.with_auto_reset(mjzoo.with_time_limit(replay(recorded), 3))
    states = run(with_feature_window(task, FEATURES, NUM_FRAMES), num_envs=1)
    ended = np.asarray(states.truncated[0])
    assert ended.tolist() == [False, False, False, True, False, False, True, False, False]
    frame = np.asarray(states.info["frame"][0])
    assert frame.tolist() == [0, 1, 2, 0, 1, 2, 0, 1, 2]  # each episode replays the clip from its start
    features = reference(recorded[0][frame], recorded[1][frame])
    restart = (np.arange(NUM_STEPS + 1) == 0) | ended  # the state after an episode's end is a new episode's
    np.testing.assert_allclose(states.obs["motion"][0], reference_windows(features, restart), atol=1e-5)


# --- errors -----------------------------------------------------------------------------


def test_unknown_key_body_names_the_bodies():
    with pytest.raises(ValueError, match=r"no body named 'foot'.*'hand'"):
        motion_features(TOY_MJ, key_bodies=("hand", "foot"))


def test_bad_arguments(recorded):
    task = replay(recorded)
    with pytest.raises(ValueError, match="body 'upper' has no free joint"):
        motion_features(TOY_MJ, root_body="upper")
    with pytest.raises(TypeError, match="mj_model must be a mujoco.MjModel"):
        motion_features(TOY_MODEL)
    for bad in (1, 0, 2.5, True):
        with pytest.raises(ValueError, match=rf"num_frames={bad!r} must be an integer >= 2"):
            with_feature_window(task, FEATURES, bad)
    with pytest.raises(ValueError, match="features were built for a model with"):
        with_feature_window(task, motion_features(mujoco.MjModel.from_xml_string(ARM)), 2)
    with pytest.raises(TypeError, match="features must come from motion_features"):
        with_feature_window(task, jax.tree_util.Partial(len), 2)
    with pytest.raises(ValueError, match="already keeps a motion window"):
        with_feature_window(with_feature_window(task, FEATURES, 2), FEATURES, 2)
    with pytest.raises(ValueError, match=r"qvel must have shape \[k, 11\]"):
        frames_features(FEATURES, TOY_MODEL, TOY_DATA, np.zeros((4, 13)), np.zeros((4, 12)))
