"""The G1's AMP joystick (envs/robot_amp.py): its reference is the retargeted clips at
the joystick's control step, episodes may start on them, the style measure by hand, and
AMP's registered settings are valid. Nothing here compiles the G1's physics (the
joystick's step is tested on the Go1, tests/envs/test_robot_joystick.py)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo.algorithms import amp
from mjzoo.envs import robot_amp
from mjzoo.envs import robot_joystick


@pytest.fixture(scope="module")
def task():
    return mjzoo.envs.make("g1_amp_joystick")


def test_the_reference_is_the_g1_clips_at_the_control_step(task):
    ref = mjzoo.envs.reference("g1_amp_joystick", task)
    walk = mjzoo.motion.load(robot_amp.CLIPS / "walk.npz", task.mj_model)
    run = mjzoo.motion.load(robot_amp.CLIPS / "run.npz", task.mj_model)
    # the recorded span of each, (frames - 1) / fps s, a frame every 0.02 s (the joystick's step)
    frames = [round((c.qpos.shape[0] - 1) / c.fps / 0.02) + 1 for c in (walk, run)]
    assert ref.dt == pytest.approx(0.02) and ref.qpos.shape[1:] == (task.mj_model.nq,)
    assert abs(ref.qpos.shape[0] - sum(frames)) <= 2  # a frame either way at each end
    np.testing.assert_allclose(ref.qpos[0], walk.qpos[0], atol=1e-6)  # the first clip starts as recorded
    only_walk = mjzoo.envs.reference("g1_amp_joystick", task, clips="walk")  # one name, as the CLI gives it
    assert only_walk.qpos.shape[0] < ref.qpos.shape[0]
    with pytest.raises(ValueError, match=r"clips \['crawl'\] unknown or empty; the G1's clips: \[.*'walk'"):
        robot_amp.g1_reference(task.mj_model, 0.02, ("crawl",))


def test_episodes_may_start_on_a_reference_frame(task):
    """The joystick's resets end with the reference's: its clip and frame are recorded
    (-1 where the joystick's own start was kept)."""
    info = jax.eval_shape(lambda k: mjzoo.reset(task, k), jax.random.key(0)).info
    assert info["reference_clip"].shape == () and info["reference_frame"].shape == ()
    assert mjzoo.params(task)["reference_probability"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="flat terrain only, not 'rough'"):
        robot_joystick.robot_joystick("g1", terrain="rough", reference=mjzoo.envs.reference("g1_amp_joystick", task))


def test_style_error_by_hand(task):
    ref = mjzoo.envs.reference("g1_amp_joystick", task)
    q = np.asarray(ref.qpos, np.float64)
    assert robot_amp.style_error(ref, q[10:30]) == pytest.approx(0.0, abs=1e-9)  # a stretch of the clips
    shifted = q[10:30].copy()
    shifted[:, 7:] += 0.1  # every joint 0.1 rad off: at most 0.1 from its own stretch
    error = robot_amp.style_error(ref, shifted)
    assert 0.0 < error <= 0.1 + 1e-9
    standing = np.repeat(np.asarray(task.mj_model.key_qpos[0])[None], 20, axis=0)
    assert robot_amp.style_error(ref, standing) > 0.05  # the keyframe's stance is no walk
    with pytest.raises(ValueError, match=r"expected \[T >= 8, 36\]"):
        robot_amp.style_error(ref, q[:4])


def test_amp_settings_are_valid_and_keep_the_asymmetric_critic():
    config, hp = amp.configure(**mjzoo.envs.hyperparameters("g1_amp_joystick", "amp"))
    assert (config.policy_obs_key, config.value_obs_key) == ("state", "privileged_state")
    assert config.key_bodies == robot_amp.KEY_BODIES and float(hp.task_weight) == float(hp.style_weight) == 0.5
