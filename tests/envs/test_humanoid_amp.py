"""The humanoid AMP tasks (envs/humanoid_amp.py): construction, the reference AMP imitates,
the style measure by hand, and the start from a reference frame.

One compile of the humanoid in this file (a jitted reset, shared by the tasks of both
reference probabilities, which differ only in leaves); everything else is host code or
`jax.eval_shape`."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo import motion
from mjzoo.algorithms import amp
from mjzoo.envs import humanoid_amp as ha


@pytest.fixture(scope="module")
def walk():
    return ha.humanoid_amp_walk()


@pytest.fixture(scope="module")
def walk_ref(walk):
    """The walk's reference as `mjzoo train amp` finds it: through the env's record."""
    return mjzoo.envs.reference("humanoid_amp_walk", walk)


@pytest.fixture(scope="module")
def joystick():
    return ha.humanoid_amp_joystick()


@pytest.fixture(scope="module")
def resets(walk):
    """Reset states of the walk task starting at a reference frame (probability 1) and at
    the default pose (0), through one compiled reset."""
    reset = jax.jit(mjzoo.reset)
    always = ha.humanoid_amp_walk(reference_probability=1.0)
    never = ha.humanoid_amp_walk(reference_probability=0.0)
    return jax.device_get(reset(always, jax.random.key(3))), jax.device_get(reset(never, jax.random.key(3)))


def _reference(qpos, dt=0.5) -> motion.Reference:
    """A one-clip Reference of positions qpos [M, nq] (velocities 0)."""
    qpos = np.asarray(qpos, np.float32)
    return motion.Reference(
        qpos=qpos,
        qvel=np.zeros_like(qpos),
        start=np.array([0]),
        length=np.array([len(qpos)]),
        weight=np.ones(1),
        loop=np.array([False]),
        dt=np.float32(dt),
        names=("c",),
    )


# --- the reference --------------------------------------------------------------------


def test_the_walks_reference_is_the_teachers_clip_at_its_control_step(walk, walk_ref, joystick):
    clip = np.load(ha.REFERENCE_PATH)
    assert "motion" not in vars(walk)  # AMP's data, not the task's
    for task, ref in ((walk, walk_ref), (joystick, mjzoo.envs.reference("humanoid_amp_joystick", joystick))):
        assert isinstance(ref, motion.Reference) and ref.names == ("walk",)
        # 601 frames at the control step already: resampling keeps them, up to the file's fps
        # (66.666664, float32) against 1 / 0.015 (a 4e-8 relative time shift).
        assert ref.qpos.shape == (601, 24)
        np.testing.assert_allclose(ref.qpos, clip["qpos"], atol=1e-4)
        assert float(ref.dt) == pytest.approx(0.015) and not bool(ref.loop[0])
        # The control step: 5 physics steps of 3 ms.
        assert float(ref.dt) == pytest.approx(5 * task.mj_model.opt.timestep)
    assert list(ha.hinge_columns(walk.mj_model)) == list(range(7, 24))
    # another control step (an override of the task) resamples it: the same overrides as the task's
    assert float(mjzoo.envs.reference("humanoid_amp_walk", walk, ctrl_dt=0.03).dt) == pytest.approx(0.03)
    with pytest.raises(KeyError, match="'humanoid_walk' has no motion reference for AMP; envs with one: "):
        mjzoo.envs.reference("humanoid_walk", walk)


def test_a_reset_with_probability_one_starts_exactly_at_a_reference_frame(walk, walk_ref, resets):
    always, never = resets
    frame = int(always.info["reference_frame"])
    assert int(always.info["reference_clip"]) == 0 and 0 <= frame < 601
    np.testing.assert_allclose(always.data.qpos, walk_ref.qpos[frame], atol=1e-6)
    np.testing.assert_allclose(always.data.qvel, walk_ref.qvel[frame], atol=1e-6)
    # The observation is recomputed from that state: base height first.
    assert always.obs[0] == pytest.approx(float(always.data.xpos[1, 2]), abs=1e-5)
    # Probability 0: the default pose (hinges at 0, or the nearest end of a range that excludes
    # 0: the knees') with U(+-0.01) noise clipped to the range; the root as in the model.
    assert int(never.info["reference_frame"]) == -1
    m = walk.mj_model
    hinge_range = m.jnt_range[1:]  # joint 0 is the root
    default = np.clip(0.0, hinge_range[:, 0], hinge_range[:, 1])
    assert np.all(np.abs(never.data.qpos[7:] - default) <= 0.01 + 1e-6) and np.any(never.data.qpos[7:] != default)
    np.testing.assert_allclose(never.data.qpos[:7], walk.mj_model.qpos0[:7], atol=1e-6)


def test_steps_observe_and_reward_without_forward_velocity(walk, joystick):
    for task, obs, terms in (
        (walk, 45, {"alive", "effort"}),
        (joystick, 48, {"alive", "effort", "tracking", "yaw_tracking"}),
    ):
        state = jax.eval_shape(mjzoo.reset, task, jax.random.key(0))
        after = jax.eval_shape(mjzoo.transition, task, state, np.zeros(task.action_size, np.float32), jax.random.key(1))
        assert state.obs.shape == after.obs.shape == (obs,) and task.action_size == 17
        assert {k.removeprefix("reward/") for k in after.metrics if k.startswith("reward/")} == terms
        assert int(task.time_limit) == 1000
    assert mjzoo.find(state, mjzoo.catalog.commands.VelocityCommandState).command.shape == (3,)


def test_bad_overrides_are_refused_at_construction():
    with pytest.raises(ValueError, match="probability"):
        ha.humanoid_amp_walk(reference_probability=1.5)
    with pytest.raises(ValueError, match="speed"):
        ha.humanoid_amp_joystick(speed=(2.0, 1.0))


# --- the style measure ------------------------------------------------------------------


def test_style_error_by_hand_on_a_small_reference():
    # nq = 9: a free root (7, ignored) and two hinges; reference hinge angles per frame:
    hinges = np.array([[0.0, 0.0], [0.1, 0.2], [0.2, 0.4], [0.3, 0.6]])
    ref = _reference(np.concatenate([np.zeros((4, 7)), hinges], axis=1))
    sim_hinges = np.array([[0.1, 0.3], [0.2, 0.4], [0.0, 0.0]])
    sim = np.concatenate([np.full((3, 7), 5.0), sim_hinges], axis=1)  # root far away: not compared
    # Windows of 2. Sim window 0 = [(0.1, 0.3), (0.2, 0.4)] vs ref window 1 = [(0.1, 0.2), (0.2, 0.4)]:
    # |errors| 0, 0.1, 0, 0 -> mean 0.025 (ref windows 0 and 2: 0.7 / 4 and 0.5 / 4).
    # Sim window 1 = [(0.2, 0.4), (0, 0)] is 0.9 / 4 = 0.225 from each of the three ref windows.
    assert ha.style_error(ref, sim, window=2) == pytest.approx((0.025 + 0.225) / 2, abs=1e-6)
    # Window 1: each frame's nearest frame: 0.05 (to (0.1, 0.2)), 0, 0.
    assert ha.style_error(ref, sim, window=1) == pytest.approx(0.05 / 3, abs=1e-6)


def test_the_teachers_own_frames_have_no_style_error_and_an_offset_costs_at_most_itself(walk_ref):
    qpos = np.asarray(walk_ref.qpos[100:160], np.float64)
    assert ha.style_error(walk_ref, qpos) == pytest.approx(0.0, abs=1e-6)
    moved = qpos.copy()
    moved[:, :7] += 3.0  # the root is not compared
    assert ha.style_error(walk_ref, moved) == pytest.approx(0.0, abs=1e-6)
    bent = qpos.copy()
    bent[:, 7:] += 0.2
    assert 0.0 < ha.style_error(walk_ref, bent) <= 0.2 + 1e-6  # its own window is 0.2 off; a nearer one may exist


def test_forward_speed_and_the_walk_criterion():
    qpos = np.zeros((101, 24))
    qpos[:, 0] = np.linspace(1.0, 4.0, 101)  # 3 m in 100 steps of 15 ms
    assert ha.forward_speed(qpos, 0.015) == pytest.approx(2.0)
    t = ha.STYLE_THRESHOLD
    assert ha.walks_like_teacher(t - 0.01, 1.5, fell=False)
    assert not ha.walks_like_teacher(t - 0.01, 1.5, fell=True)
    assert not ha.walks_like_teacher(t, 1.5, fell=False)  # strictly below the threshold
    assert not ha.walks_like_teacher(0.0, ha.MIN_SPEED - 0.01, fell=False)  # marching in place


def test_style_measure_errors_name_the_argument(walk, walk_ref):
    with pytest.raises(TypeError, match="reference must be a motion.Reference"):
        ha.style_error(walk, np.zeros((20, 24)))
    with pytest.raises(ValueError, match="qpos"):
        ha.style_error(walk_ref, np.zeros((20, 23)))
    with pytest.raises(ValueError, match="window"):
        ha.style_error(walk_ref, np.zeros((5, 24)))  # shorter than a window of 10
    with pytest.raises(ValueError, match="qpos"):
        ha.forward_speed(np.zeros((1, 24)), 0.015)
    with pytest.raises(ValueError, match="dt"):
        ha.forward_speed(np.zeros((3, 24)), 0.0)


# --- AMP hyperparameters ----------------------------------------------------------------


def test_amp_hyperparameters_make_valid_configs_on_the_models_bodies(walk):
    (walk_config, walk_hp), (_, joystick_hp) = amp.configure(**ha.AMP), amp.configure(**ha.JOYSTICK_AMP)
    assert walk_config.num_envs == 2048 and walk_hp.style_weight == 1.0
    assert 0.0 <= walk_hp.task_weight < walk_hp.style_weight
    assert joystick_hp.task_weight > 0 and joystick_hp.style_weight > 0
    bodies = {walk.mj_model.body(i).name for i in range(walk.mj_model.nbody)}
    assert set(walk_config.key_bodies) <= bodies and len(walk_config.key_bodies) == 4
