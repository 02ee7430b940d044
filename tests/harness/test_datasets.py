"""mjzoo.harness.datasets: recorded episodes of a hand-written policy on the cart-pole
(one physics step per control step, a pole that ends the episode past 0.2 rad), checked
against C MuJoCo's kinematics, the task's own reward formula and termination rule, and
written to disk and read back. One recording (one compile) serves every test."""

from __future__ import annotations

import dataclasses
import json

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo import motion
from mjzoo.harness import datasets

EPISODES, STEPS, EPISODE_STEPS, FALL = 6, 40, 30, 0.2
TERMS = ("centered", "effort", "upright", "velocity")


def _act(scale, obs, key):
    """Random pushes, often beyond the [-1, 1] ctrlrange (so clamping shows)."""
    return scale * jax.random.normal(key, (1,))


@pytest.fixture(scope="module")
def task() -> mjzoo.Task:
    return mjzoo.envs.make("cartpole_balance", episode_steps=EPISODE_STEPS, ctrl_dt=0.01, fall_angle=FALL)


@pytest.fixture(scope="module")
def data(task) -> datasets.Dataset:
    return datasets.record_policy(
        task, _act, jnp.float32(2.0), 0, EPISODES, STEPS, deterministic=False, source={"policy": "random pushes"}
    )


def test_shapes_names_and_meta(data):
    n, t = EPISODES, STEPS
    shapes = {k: v.shape for k, v in data.arrays().items()}
    assert shapes == {
        "qpos": (n, t + 1, 2),
        "qvel": (n, t + 1, 2),
        "time": (n, t + 1),
        "xpos": (n, t + 1, 3, 3),
        "xquat": (n, t + 1, 3, 4),
        "obs": (n, t + 1, 5),
        "action": (n, t, 1),
        "ctrl": (n, t, 1),
        "reward": (n, t),
        **{f"reward/{k}": (n, t) for k in TERMS},
        "terminated": (n, t),
        "truncated": (n, t),
        "length": (n,),
    }
    assert (data.num_episodes, data.num_steps) == (n, t)
    assert data.joint_names == ("slider", "hinge") and data.body_names == ("world", "cart", "pole")
    assert data.actuator_names == ("slide",) and tuple(data.reward_terms) == TERMS
    assert data.dt == pytest.approx(0.01) and data.seed == 0 and data.deterministic is False
    np.testing.assert_allclose(np.diff(data.time, axis=1), 0.01, atol=1e-6)
    cart, angle = data.qpos[..., 0], data.qpos[..., 1]  # the cart-pole's observation, by hand
    expected = np.stack([cart, np.cos(angle), np.sin(angle), data.qvel[..., 0], data.qvel[..., 1]], -1)
    np.testing.assert_allclose(data.obs, expected, atol=1e-5)


def test_body_poses_are_those_of_the_stored_qpos(task, data):
    """C MuJoCo's mj_kinematics on a state's qpos gives the recorded xpos and xquat (after
    mjx.step the Data's own poses lag one integration behind)."""
    mj_data = mujoco.MjData(task.mj_model)
    for episode, t in ((0, 0), (1, 1), (2, STEPS // 2), (EPISODES - 1, STEPS)):
        mj_data.qpos[:] = data.qpos[episode, t]
        mujoco.mj_kinematics(task.mj_model, mj_data)
        np.testing.assert_allclose(data.xpos[episode, t], mj_data.xpos, atol=1e-5)
        np.testing.assert_allclose(data.xquat[episode, t], mj_data.xquat, atol=1e-5)
    assert not np.allclose(data.xpos[:, 1:, 2], data.xpos[:, :1, 2])  # the pole moved


def test_reward_terms_sum_to_the_reward_and_follow_the_formula(data):
    np.testing.assert_allclose(sum(data.reward_terms.values()), data.reward, atol=1e-5)
    angle_after = data.qpos[:, 1:, 1]  # the upright term reads the state after the step
    np.testing.assert_allclose(data.reward_terms["upright"], (1.0 + np.cos(angle_after)) / 2.0, atol=1e-5)
    clipped = np.clip(data.action[..., 0], -1.0, 1.0)
    np.testing.assert_allclose(data.reward_terms["effort"], -0.01 * clipped**2, atol=1e-6)


def test_ctrl_is_the_action_clamped_to_the_ctrlrange(data):
    assert np.any(np.abs(data.action) > 1.0)  # the clamp is exercised
    np.testing.assert_allclose(data.ctrl, np.clip(data.action, -1.0, 1.0), rtol=1e-6)  # XLA may round an ulp apart


def test_length_ends_at_the_first_fall_or_the_time_limit(data):
    """By hand: the first step after which |pole angle| > 0.2 rad, or step 30."""
    leaning = np.abs(np.arctan2(np.sin(data.qpos[:, 1:, 1]), np.cos(data.qpos[:, 1:, 1]))) > FALL
    steps = np.arange(1, STEPS + 1)
    ends = np.where(leaning | (steps == EPISODE_STEPS), steps, STEPS + 1)
    np.testing.assert_array_equal(data.length, ends.min(axis=1))
    assert set(data.length) - {EPISODE_STEPS} and EPISODE_STEPS in data.length  # a fall and a timeout
    fell = data.length < EPISODE_STEPS
    assert data.terminated[fell, data.length[fell] - 1].all()
    np.testing.assert_allclose(data.returns(), [r[:n].sum() for r, n in zip(data.reward, data.length)], rtol=1e-6)


def test_episode_lengths_by_hand():
    terminated = np.array([[0, 0, 1, 0], [0, 0, 0, 0], [1, 1, 1, 1]], bool)
    truncated = np.array([[0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]], bool)
    np.testing.assert_array_equal(datasets.episode_lengths(terminated, truncated), [2, 4, 1])


def test_a_clip_is_an_episode_cut_at_its_length(data):
    episode = int(np.argmin(data.length))
    clip = datasets.clip(data, episode)
    frames = data.length[episode] + 1
    assert clip.name == f"episode_{episode:03d}" and clip.num_frames == frames and clip.fps == pytest.approx(100.0)
    assert clip.joint_names == data.joint_names and clip.body_names == data.body_names
    np.testing.assert_array_equal(clip.body_pos, data.xpos[episode, :frames])
    # One Euler step per frame: q[t+1] = q[t] + dt * v[t+1], so differences are velocities.
    np.testing.assert_allclose(np.diff(clip.qpos, axis=0) * clip.fps, clip.qvel[1:], rtol=1e-3, atol=1e-4)
    assert datasets.clip(data, 0, name="walk").name == "walk"
    with pytest.raises(IndexError, match="episode 6 is out of range; the dataset has 6"):
        datasets.clip(data, EPISODES)


def test_save_load_round_trip_and_meta(data, tmp_path):
    written = datasets.save(tmp_path / "d", data)
    names = sorted(str(p.relative_to(tmp_path / "d")) for p in written)
    assert names == sorted(["dataset.npz", "meta.json", *(f"motions/episode_{i:03d}.npz" for i in range(EPISODES))])
    assert sorted(p.name for p in (tmp_path / "d").rglob("*") if p.is_file()) == sorted(p.name for p in written)
    back = datasets.load(tmp_path / "d")
    assert {k: v.tolist() for k, v in back.arrays().items()} == {k: v.tolist() for k, v in data.arrays().items()}
    assert back.meta() == data.meta()
    meta = json.loads((tmp_path / "d" / "meta.json").read_text())
    assert meta["format"] == "mjzoo.dataset/1" and (meta["episodes"], meta["steps"]) == (EPISODES, STEPS)
    assert meta["dt"] == pytest.approx(0.01) and meta["seed"] == 0 and meta["deterministic"] is False
    assert meta["source"] == {"policy": "random pushes"} and meta["reward_terms"] == list(TERMS)
    assert meta["joint_names"] == ["slider", "hinge"] and meta["actuator_names"] == ["slide"]
    assert meta["arrays"]["xquat"] == {"shape": [EPISODES, STEPS + 1, 3, 4], "dtype": "float32"}
    assert meta["arrays"]["terminated"]["dtype"] == "bool"
    clip = motion.load_file(tmp_path / "d" / "motions" / "episode_003.npz")
    np.testing.assert_allclose(clip.qpos, datasets.clip(data, 3).qpos)
    assert clip.fps == pytest.approx(100.0) and clip.body_names == data.body_names


def _first(data: datasets.Dataset, n: int) -> datasets.Dataset:
    """The first `n` episodes."""
    fields = (
        "qpos",
        "qvel",
        "time",
        "xpos",
        "xquat",
        "obs",
        "action",
        "ctrl",
        "reward",
        "terminated",
        "truncated",
        "length",
    )
    return dataclasses.replace(
        data, **{f: getattr(data, f)[:n] for f in fields}, reward_terms={k: v[:n] for k, v in data.reward_terms.items()}
    )


def test_overwrite_is_refused_unless_asked_and_keeps_other_files(data, tmp_path):
    datasets.save(tmp_path, data)
    (tmp_path / "notes.txt").write_text("mine")
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    with pytest.raises(FileExistsError, match="already holds a dataset .*overwrite=True"):
        datasets.save(tmp_path, data)
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before
    datasets.save(tmp_path, _first(data, 2), overwrite=True)
    assert (tmp_path / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in (tmp_path / "motions").iterdir()) == ["episode_000.npz", "episode_001.npz"]
    assert datasets.load(tmp_path).num_episodes == 2 and not list(tmp_path.glob(".*tmp*"))
    with pytest.raises(NotADirectoryError, match="is a file, not a directory"):
        datasets.save(tmp_path / "notes.txt", data)


def test_a_structured_observation_round_trips_by_key_path(data, tmp_path):
    obs = {"joints/pos": data.qpos, "joints/vel": data.qvel}
    nested = dataclasses.replace(data, obs=obs)
    assert {"obs/joints/pos", "obs/joints/vel"} <= set(nested.arrays()) and "obs" not in nested.arrays()
    datasets.save(tmp_path, nested)
    back = datasets.load(tmp_path)
    assert set(back.obs) == set(obs) and np.array_equal(back.obs["joints/vel"], data.qvel)


def test_the_same_policy_records_other_seeds_without_compiling_again(task, data):
    compiled = datasets._policy_episodes._cache_size()
    other = datasets.record_policy(task, _act, jnp.float32(2.0), jax.random.key(1), EPISODES, STEPS)
    assert datasets._policy_episodes._cache_size() == compiled
    assert not np.array_equal(other.qpos, data.qpos)
    assert isinstance(other.seed, list) and other.deterministic is None


def test_mistakes_are_named(task, data, tmp_path):
    with pytest.raises(ValueError, match="episodes must be an int >= 1, got 0"):
        datasets.record_policy(task, _act, 2.0, 0, 0, STEPS)
    with pytest.raises(TypeError, match="act must be a function"):
        datasets.record_policy(task, "ppo", 2.0, 0, 1, STEPS)
    with pytest.raises(FileNotFoundError, match="holds no meta.json"):
        datasets.load(tmp_path)
    with pytest.raises(ValueError, match=r"Dataset: ctrl has shape \(6, 39, 1\); expected \[6, 40\] leading"):
        dataclasses.replace(data, ctrl=data.ctrl[:, 1:])
    datasets.save(tmp_path, data)
    np.savez(tmp_path / "dataset.npz", **{**data.arrays(), "qpos": data.qpos[:, :3]})
    with pytest.raises(ValueError, match=r"dataset.npz's qpos is float32\[6, 3, 2\]; meta.json says float32"):
        datasets.load(tmp_path)
