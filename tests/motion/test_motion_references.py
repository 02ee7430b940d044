"""`motion.Reference` and its functions under jit and vmap, with hand-checked indices:
two TORSO clips at 50 fps resampled to dt = 0.02 s (unchanged), "long" 50 frames
looping (qpos rows 0..49), "short" 20 frames not looping (rows 50..69)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from catalog_tasks import BASE_AND_ARM
from catalog_tasks import MJ as ARM
from jax.tree_util import Partial
from motion_models import TORSO
from motion_models import analytic
from mujoco import mjx

from mjzoo import motion
from mjzoo.types import State
from mjzoo.types import Task

LONG, SHORT = analytic(50.0, 50, name="long"), analytic(50.0, 20, name="short")


@pytest.fixture(scope="module")
def ref() -> motion.Reference:
    return motion.reference([LONG, SHORT], TORSO, dt=0.02, weights=[4.0, 1.0], loop=[True, False])


def test_reference_concatenates_the_clips(ref):
    assert ref.names == ("long", "short") and ref.num_clips == 2
    assert ref.qpos.shape == (70, 9) and ref.qvel.shape == (70, 8) and ref.qpos.dtype == jnp.float32
    np.testing.assert_array_equal(ref.start, [0, 50])
    np.testing.assert_array_equal(ref.length, [50, 20])
    np.testing.assert_allclose(ref.weight, [0.8, 0.2])
    np.testing.assert_array_equal(ref.loop, [True, False])
    np.testing.assert_allclose(ref.qpos[50:], SHORT.qpos, atol=1e-6)
    assert float(ref.dt) == pytest.approx(0.02)
    # A clip at another rate is resampled to 1/dt: 1 s at 25 fps -> 51 frames at 50 fps.
    slow = motion.reference(analytic(25.0, 26), TORSO, dt=0.02)
    np.testing.assert_array_equal(slow.length, [51])
    np.testing.assert_array_equal(slow.weight, [1.0])


def test_frame_index_loops_or_clamps_under_jit_and_vmap(ref):
    clip = jnp.array([0, 0, 0, 1, 1, 1])
    t = jnp.array([3, 53, -1, 25, -3, 7])
    # long loops: 53 -> 3, -1 -> 49; short clamps: 25 -> 19 (row 69), -3 -> 0 (row 50).
    index = jax.jit(jax.vmap(motion.frame_index, in_axes=(None, 0, 0)))(ref, clip, t)
    np.testing.assert_array_equal(index, [3, 3, 49, 69, 50, 57])


def test_frames_are_consecutive_through_frame_index(ref):
    qpos, qvel = jax.jit(motion.frames, static_argnums=3)(ref, jnp.int32(1), jnp.int32(18), 4)
    assert qpos.shape == (4, 9) and qvel.shape == (4, 8)
    np.testing.assert_array_equal(qpos, ref.qpos[jnp.array([68, 69, 69, 69])])
    qpos, _ = jax.jit(motion.frames, static_argnums=3)(ref, jnp.int32(0), jnp.int32(48), 4)
    np.testing.assert_array_equal(qpos, ref.qpos[jnp.array([48, 49, 0, 1])])


def test_sample_frame_respects_weights_and_the_remaining_frames(ref):
    keys = jax.random.split(jax.random.key(3), 4000)
    clip, t = jax.jit(jax.vmap(lambda k: motion.sample_frame(ref, k, min_remaining=5)))(keys)
    clip, t = np.asarray(clip), np.asarray(t)
    assert clip.dtype == np.int32 and t.dtype == np.int32
    assert abs(np.mean(clip == 0) - 0.8) < 0.03
    # Frames uniform in [0, length - 5]: every one of them drawn, none past.
    assert set(t[clip == 0]) == set(range(46)) and set(t[clip == 1]) == set(range(16))
    # A weight of 0 never draws its clip.
    never = motion.reference([LONG, SHORT], TORSO, dt=0.02, weights=[1.0, 0.0])
    drawn, _ = jax.vmap(lambda k: motion.sample_frame(never, k))(keys[:500])
    assert not np.any(np.asarray(drawn) == 1)


def test_reference_rejects_bad_arguments():
    with pytest.raises(ValueError, match="weights=.* must be 2 finite numbers >= 0, not all 0"):
        motion.reference([LONG, SHORT], TORSO, dt=0.02, weights=[1.0, -1.0])
    with pytest.raises(ValueError, match="loop=.* must be one bool or 2 of them"):
        motion.reference([LONG, SHORT], TORSO, dt=0.02, loop=[True])
    with pytest.raises(ValueError, match="dt=0 must be"):
        motion.reference(LONG, TORSO, dt=0)
    with pytest.raises(TypeError, match="clips must be a Clip"):
        motion.reference([], TORSO, dt=0.02)
    with pytest.raises(ValueError, match="motion clip 'bad': joint 1 is 'h2'"):
        motion.reference(LONG.replace(name="bad", joint_names=("root", "h2", "h1")), TORSO, dt=0.02)


def arm_clip(fps: float = 50.0) -> motion.Clip:
    """A clip of catalog_tasks' base-and-arm model (root, hip, wrist, spin; nq 10, nv 9)."""
    t = np.arange(30) / fps
    qpos = np.zeros((30, 10))
    qpos[:, 0], qpos[:, 2], qpos[:, 3], qpos[:, 7] = 0.3 * t, 0.5, 1.0, 0.2 * np.sin(t)
    qvel = motion.velocities_from_positions(qpos, fps, ARM)
    return motion.Clip(name="arm", fps=fps, qpos=qpos, qvel=qvel, joint_names=("root", "hip", "wrist", "spin"))


def _start(model, key):
    return State.create(mjx.make_data(model), jnp.zeros(1))


def _tick(seconds, model, state, action, key):
    """A step that only advances time (what control_dt measures), cheap to compile."""
    return state.replace(data=state.data.replace(time=state.data.time + seconds))


def _nothing(model, *args):
    return {} if len(args) == 3 else (jnp.zeros((), bool), jnp.zeros((), bool))


def test_check_reference_checks_the_control_step_and_the_widths(ref):
    task = Task(
        model=BASE_AND_ARM.model,
        start=Partial(_start),
        step=Partial(_tick, jnp.float32(0.02)),
        reward=Partial(_nothing),
        terminate=Partial(_nothing),
        mj_model=ARM,
    )
    arm_ref = motion.reference(arm_clip(), ARM, dt=0.02)
    assert motion.check_reference(task, arm_ref) is arm_ref  # the task is only read
    with pytest.raises(ValueError, match=r"a frame every 0.01 s but the task's control step is 0.02 s"):
        motion.check_reference(task, motion.reference(arm_clip(), ARM, dt=0.01))
    with pytest.raises(ValueError, match="the reference has nq=9, nv=8 but the task's model nq=10, nv=9"):
        motion.check_reference(task, ref)
    with pytest.raises(TypeError, match="ref must be a motion.Reference"):
        motion.check_reference(task, arm_clip())
