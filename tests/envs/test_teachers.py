"""envs/teachers.py: MPPI's cart-pole swing-up as a motion clip, the AMP task built on it,
and its style measure."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo import motion
from mjzoo.envs import cartpole
from mjzoo.envs import teachers


@pytest.fixture(scope="module")
def task():
    return teachers.cartpole_amp_swingup()


@pytest.fixture(scope="module")
def reference(task):
    """AMP's reference, through the env's record, as `mjzoo train amp` finds it."""
    return mjzoo.envs.reference("cartpole_amp_swingup", task)


@pytest.fixture(scope="module")
def clip(task):
    return teachers.cartpole_clip(task.mj_model)


def test_committed_clip_loads_on_the_cartpole_model(task, clip):
    assert motion.load(teachers.CARTPOLE_CLIP, task.mj_model) is not None
    assert clip.joint_names == ("slider", "hinge")
    assert clip.fps == pytest.approx(50.0) and clip.qpos.shape == (401, 2) and clip.qvel.shape == (401, 2)


def test_clip_is_a_swing_up_that_balances(clip):
    cart, angle = clip.qpos[:, 0], clip.qpos[:, 1]
    assert np.cos(angle[0]) < -0.99 and abs(cart[0]) < 0.1  # starts hanging, centred
    assert np.all(np.cos(angle[-200:]) > 0.97)  # upright over its last 4 s
    assert np.all(np.abs(cart) < 1.81)  # on the rail
    assert np.max(np.abs(np.diff(angle))) < 0.5  # a continuous angle: no wrapping jumps


def test_the_reference_is_the_clip_at_the_tasks_control_step(task, reference, clip):
    ref = motion.check_reference(task, reference)  # it measures the control step and the widths
    assert isinstance(ref, motion.Reference) and ref.names == ("cartpole_swingup_mppi",)
    assert float(ref.dt) == pytest.approx(0.02)
    assert not bool(ref.loop[0])
    np.testing.assert_allclose(ref.qpos, clip.qpos, atol=1e-6)  # 50 fps = one frame per 0.02 s step


def test_resets_hang_or_start_at_a_clip_frame(reference):
    half = teachers.cartpole_amp_swingup(reference_init=0.5)
    states = jax.jit(jax.vmap(lambda k: mjzoo.reset(half, k)))(jax.random.split(jax.random.key(0), 16))
    ref, frames = np.asarray(reference.qpos), np.asarray(states.info["reference_frame"])
    qpos, obs = np.asarray(states.data.qpos), np.asarray(states.obs)
    from_clip = frames >= 0
    assert 0 < from_clip.sum() < 16 and len(set(frames[from_clip].tolist())) > 1
    np.testing.assert_allclose(qpos[from_clip], ref[frames[from_clip]], atol=1e-6)
    np.testing.assert_allclose(obs[:, 1], np.cos(qpos[:, 1]), atol=1e-5)  # observed after the reset
    assert np.all(np.cos(qpos[~from_clip, 1]) < -0.99)  # the others hang, as cartpole_swingup's own
    with pytest.raises(ValueError, match="probability"):
        teachers.cartpole_amp_swingup(reference_init=1.5)


def _reference_of_qpos(qpos):
    qpos = jnp.asarray(qpos, jnp.float32)
    ref = motion.Reference(
        qpos=qpos,
        qvel=jnp.zeros_like(qpos),
        start=jnp.zeros(1, jnp.int32),
        length=jnp.array([len(qpos)], jnp.int32),
        weight=jnp.ones(1),
        loop=jnp.zeros(1, bool),
        dt=jnp.float32(0.02),
        names=("tiny",),
    )
    return ref


def test_style_error_by_hand(task):
    tiny = _reference_of_qpos([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    sim = np.array([[1.0, 1.5], [2.0, 2.5]])
    # window 2, run -> reference: frames 1-2 are nearest, errors (0 + 0.5) per frame over 2 columns
    assert teachers.style_error(task, tiny, sim, window=2, both_ways=False) == pytest.approx(0.25)
    # reference -> run: window 0-1 is (1 + 1.5) x 2 / 4 = 1.25 off, window 1-2 0.25: mean 0.75
    assert teachers.style_error(task, tiny, sim, window=2) == pytest.approx((0.25 + 0.75) / 2)
    # window 1: each run frame 0.25 from its nearest; reference frames 1.25, 0.25, 0.25 from theirs
    assert teachers.style_error(task, tiny, sim, window=1) == pytest.approx((0.25 + 1.75 / 3) / 2)
    spun = sim + [0.0, 2 * np.pi - 0.5]  # frames (1, 1 + 2 pi), (2, 2 + 2 pi): a whole turn more
    assert teachers.style_error(task, tiny, spun, window=2, both_ways=False) == pytest.approx(np.pi)
    assert teachers.style_error(task, tiny, spun, window=2) == pytest.approx((np.pi + np.pi + 0.5) / 2)


def test_style_error_of_the_clip_and_of_hanging_still(task, reference, clip):
    assert teachers.style_error(task, reference, clip.qpos) == pytest.approx(0.0, abs=1e-6)
    hanging = np.tile([0.0, np.pi], (500, 1))  # near the clip's first second only
    assert teachers.style_error(task, reference, hanging, both_ways=False) < 0.2
    assert teachers.style_error(task, reference, hanging) > 0.8  # the clip's balancing, 3 rad away, is missing


def test_style_error_rejects_bad_input(task, reference):
    with pytest.raises(ValueError, match=r"qpos has shape \(10, 3\)"):
        teachers.style_error(task, reference, np.zeros((10, 3)))
    with pytest.raises(TypeError, match="reference must be a motion.Reference"):
        teachers.style_error(cartpole.swingup(), None, np.zeros((30, 2)))


def test_amp_hyperparameters_make_a_style_only_config():
    from mjzoo.algorithms import amp

    _, config = amp.configure(**teachers.AMP)  # the numbers: (Config, Hyperparams)
    assert config.task_weight == 0.0 and config.style_weight > 0
