"""AMP: config validation, the algorithm contract (one jit, no retracing, vmapped seeds,
the harness), the style reward wiring, reference windows through the simulation's own
feature function, the discriminator-has-won warning, and sharding over devices.

The task throughout is the pendulum with a reference of a slow sway 0.2-0.4 rad off
hanging (`sway_clip`), recorded in C MuJoCo; the two-device check, which holds of any
task, runs the block on a rail of tests/harness/test_distributed.py, quicker to compile.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import textwrap

import jax
import mujoco
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo import learning
from mjzoo import motion
from mjzoo import names
from mjzoo.algorithms import amp
from mjzoo.harness import training
from mjzoo.learning import motion_features

SMALL, HP = amp.configure(
    num_envs=8,
    unroll_length=8,
    num_minibatches=2,
    num_epochs=1,
    disc_minibatches=2,
    disc_hidden_sizes=(16,),
    replay_size=64,
    total_steps=8 * 8 * 4,
    task_weight=0.0,
    style_weight=1.0,
)


def sway_clip(
    task: mjzoo.Task, tilt: float = 0.3, amplitude: float = 0.1, hz: float = 0.5, seconds: float = 8.0
) -> motion.Clip:
    """The pendulum held `tilt` rad off hanging, swaying `amplitude` rad at `hz`: tracked
    in C MuJoCo by feedforward (inertia, damping, gravity) plus PD, recorded every
    control step. Without torque the pendulum falls back to hanging; the task's own
    reward asks for upright: the motion is neither."""
    m = task.mj_model
    data = mujoco.MjData(m)
    dt, omega = mjzoo.control_dt(task), 2 * np.pi * hz
    angle = lambda t: np.pi - tilt - amplitude * np.sin(omega * t)  # noqa: E731 (0 is upright)
    rate = lambda t: -amplitude * omega * np.cos(omega * t)  # noqa: E731
    data.qpos[0], data.qvel[0] = angle(0.0), rate(0.0)
    qpos, qvel = [], []
    for _ in range(int(seconds / dt) + 1):
        qpos.append(data.qpos.copy())
        qvel.append(data.qvel.copy())
        for _ in range(round(dt / m.opt.timestep)):
            t = data.time
            torque = (
                0.25 * amplitude * omega**2 * np.sin(omega * t)
                + 0.05 * rate(t)
                - 4.905 * np.sin(data.qpos[0])
                + 20.0 * (angle(t) - data.qpos[0])
                + 2.0 * (rate(t) - data.qvel[0])
            )
            data.ctrl[0] = np.clip(torque / 2.5, -1.0, 1.0)
            mujoco.mj_step(m, data)
    return motion.Clip(
        name="sway",
        fps=1.0 / dt,
        qpos=np.array(qpos),
        qvel=np.array(qvel),
        joint_names=tuple(names.all_names(m, "joint")),
    )


@pytest.fixture(scope="module")
def swing():
    """The pendulum task AMP learns on."""
    return mjzoo.envs.make("pendulum_swingup")


@pytest.fixture(scope="module")
def sway(swing):
    """The sway as AMP's reference, at the task's control step."""
    return motion.check_reference(swing, motion.reference(sway_clip(swing), swing.mj_model, mjzoo.control_dt(swing)))


@pytest.mark.parametrize(
    "fields,message",
    [
        (dict(num_frames=1), "num_frames=1 is invalid; expected >= 2"),
        (dict(disc_minibatches=3), "disc_minibatches=3 is invalid; expected a divisor of num_envs \\* unroll_length"),
        (dict(task_weight=0.0, style_weight=0.0), "style_weight=0.0 is invalid; expected > 0 where task_weight is 0"),
        (dict(disc_loss="wasserstein"), "disc_loss='wasserstein' is invalid"),
        (dict(replay_keep_probability=1.5), "replay_keep_probability=1.5 is invalid; expected in \\[0.0, 1.0\\]"),
        (dict(policy_obs_key="policy/state"), "policy_obs_key='policy/state' is invalid"),
        (dict(num_envs=0), "num_envs=0 is invalid"),  # PPO's own checks hold too
        (dict(discount=2.0), "ppo.Hyperparams: discount=2.0 is invalid"),
        (dict(disc_learning_rate=0.0), "amp.Hyperparams: disc_learning_rate=0.0 is invalid"),
        (
            dict(style_wieght=1.0),
            "amp.configure: unknown field\\(s\\) \\['style_wieght'\\] \\(did you mean 'style_weight'\\?\\); fields: \\[.*'style_weight'",
        ),
    ],
)
def test_config_errors_name_the_field(fields, message):
    with pytest.raises(ValueError, match=message):
        amp.configure(**{**dict(num_envs=8, unroll_length=8, num_minibatches=2, disc_minibatches=2), **fields})


def test_configure_puts_each_number_where_it_belongs():
    config, hp = amp.configure(num_frames=3, learning_rate=1e-3, style_weight=2.0, disc_max_grad_norm=None)
    assert config.num_frames == 3 and hp.ppo.learning_rate == 1e-3 and hp.style_weight == 2.0
    assert hp.disc_max_grad_norm == float("inf") and hp.ppo.max_grad_norm == 1.0


def test_the_reference_is_amps_not_the_tasks():
    """`Task` has no motion field; AMP without a reference says how to give it one."""
    assert "motion" not in {f.name for f in dataclasses.fields(mjzoo.Task)}
    task = mjzoo.envs.make("pendulum_swingup")
    how = "AMP needs a motion reference to imitate, got NoneType; give one: amp.make\\(config, reference\\)"
    with pytest.raises(TypeError, match=how):
        amp.init(SMALL, task, None, HP, jax.random.key(0))
    with pytest.raises(TypeError, match=how):
        amp.make(SMALL, None)


def test_a_reference_of_another_model_is_refused(swing, sway):
    cartpole = mjzoo.envs.make("cartpole_swingup")
    with pytest.raises(ValueError, match="the reference has nq=1, nv=1 but the task's model nq=2, nv=2"):
        amp.init(SMALL, cartpole, sway, HP, jax.random.key(0))


@pytest.fixture(scope="module")
def started(swing, sway):
    return amp.init(SMALL, swing, sway, HP, jax.random.key(0))


@pytest.fixture(scope="module")
def small_update():
    traces = []

    def update(task, state):
        traces.append(None)
        return amp.update(SMALL, task, state)

    return jax.jit(update), traces


def test_update_is_one_jit_that_does_not_retrace(swing, started, small_update):
    update, traces = small_update
    state, metrics = update(swing, started)
    state, metrics = update(swing, state)
    other = swing.with_params(upright_weight=2.0)  # a changed number is a leaf: no retrace
    state, metrics = update(other, state)
    # another clip of the same shape is a leaf of the state too: no retrace
    update(other, state.replace(reference=dataclasses.replace(state.reference, qpos=0.5 * state.reference.qpos)))
    assert len(traces) == 1
    assert int(state.updates) == 3
    for name in (
        "disc/accuracy_reference",
        "disc/accuracy_policy",
        "disc/logit_reference",
        "disc/logit_policy",
        "disc/gradient_penalty",
        "disc/loss",
        "amp/style_reward",
        "amp/style_reward_std",
        "loss/policy",
        "loss/value",
    ):
        assert np.isfinite(float(metrics[name])), name
    # 3 updates of 64 windows kept with probability 0.05, and the rest of the replay empty
    assert 0 < float(metrics["amp/replay_size"]) <= 3 * 64


def test_the_policy_sees_the_tasks_observation_and_the_discriminator_the_window(swing, started):
    obs = started.ppo.collector.env_state.obs
    assert set(obs) == {"policy", "motion"}
    assert obs["policy"].shape == (8, 3)  # the pendulum's own observation
    # fixed base, one hinge: its angle and velocity per frame, two frames
    assert obs["motion"].shape == (8, 2, 2)
    assert started.ppo.params["policy"][0]["kernel"].shape[0] == 3
    assert started.disc_params[0]["kernel"].shape[0] == 4
    act = amp.policy(SMALL, swing)  # deployable on the task's own observation
    action = act(amp.policy_params(started), mjzoo.reset(swing, jax.random.key(1)).obs, jax.random.key(2))
    assert action.shape == (1,) and -1.0 <= float(action[0]) <= 1.0


def test_an_asymmetric_observation_feeds_each_network_its_entry(swing, sway):
    """A task observing {"state", "privileged_state"} (a robot's joystick): the policy sees
    the state, the critic the privileged view, the discriminator the window, and the
    deployable policy acts on the task's own dict observation."""
    asymmetric = mjzoo.catalog.observations.with_privileged_observation(
        swing, mjzoo.catalog.observations.joint_velocities
    )
    config = dataclasses.replace(SMALL, policy_obs_key="state", value_obs_key="privileged_state")
    state = amp.init(config, asymmetric, sway, HP, jax.random.key(0))
    obs = state.ppo.collector.env_state.obs
    assert set(obs) == {"policy", "motion"} and set(obs["policy"]) == {"state", "privileged_state"}
    assert state.ppo.params["policy"][0]["kernel"].shape[0] == 3  # the pendulum's own 3
    assert state.ppo.params["value"][0]["kernel"].shape[0] == 4  # and its joint velocity
    state, metrics = jax.jit(amp.update, static_argnums=0)(config, asymmetric, state)
    assert np.isfinite(float(metrics["loss/value"]))
    act = amp.policy(config, asymmetric)
    action = act(amp.policy_params(state), mjzoo.reset(asymmetric, jax.random.key(1)).obs, jax.random.key(2))
    assert action.shape == (1,) and np.isfinite(float(action[0]))


def test_reference_windows_are_consecutive_frames_featurized_like_the_simulation(swing, sway, started):
    template = jax.tree.map(lambda x: x[0], started.ppo.collector.env_state.data)
    windows = jax.jit(amp.reference_windows, static_argnums=(0, 5))(
        SMALL, swing, sway, template, jax.random.key(3), 256
    )
    ref = sway
    assert windows.shape == (256, 2, 2)
    # every window is (angle, velocity) of two consecutive reference frames, velocity per second
    frames = np.stack([np.asarray(ref.qpos[:, 0]), np.asarray(ref.qvel[:, 0])], axis=-1)
    starts = [int(np.argmin(np.abs(frames[:-1] - w[0]).sum(-1))) for w in np.asarray(windows)]
    np.testing.assert_allclose(np.asarray(windows), np.stack([frames[starts], frames[np.add(starts, 1)]], 1), atol=1e-5)
    # and they match the features the simulation computes on the same states
    features = motion_features.motion_features(swing.mj_model)
    qpos, qvel = np.asarray(ref.qpos[5:7]), np.asarray(ref.qvel[5:7])
    simulated = [
        features(swing.model, mjzoo.mjx.forward(swing.model, template.replace(qpos=q, qvel=v)))
        for q, v in zip(qpos, qvel)
    ]
    np.testing.assert_allclose(np.stack(simulated), frames[5:7], atol=1e-6)


def test_seeds_vmap(swing, sway):
    """Several seeds train in one program: init and update vmapped over keys."""
    keys = jax.random.split(jax.random.key(0), 2)
    states = jax.vmap(lambda k: amp.init(SMALL, swing, sway, HP, k))(keys)
    states, metrics = jax.jit(jax.vmap(lambda s: amp.update(SMALL, swing, s)))(states)
    assert metrics["disc/loss"].shape == (2,)
    assert not np.allclose(states.disc_params[0]["kernel"][0], states.disc_params[0]["kernel"][1])


def test_diagnose_warns_when_the_discriminator_has_won():
    won = [{"disc/accuracy_reference": 0.995, "disc/accuracy_policy": 0.999}] * 3
    assert amp.diagnose(won) is not None and "has won" in amp.diagnose(won)
    assert amp.diagnose(won[:2]) is None  # not yet for long
    assert amp.diagnose([*won[:2], {"disc/accuracy_reference": 0.9, "disc/accuracy_policy": 0.999}]) is None
    # reference windows all right but policy windows mostly called reference: not won
    assert amp.diagnose([{"disc/accuracy_reference": 1.0, "disc/accuracy_policy": 0.2}] * 3) is None


def test_train_writes_the_discriminators_diagnostics_and_warns_once(swing, sway, tmp_path):
    algorithm = amp.make(SMALL, sway)._replace(
        diagnose=lambda history: "amp: the discriminator has won" if len(history) >= 1 else None
    )
    settings = training.Settings(
        out_dir=tmp_path / "run",
        updates_per_chunk=2,
        eval_count=0,  # two chunks of 2 updates: two metrics lines
        eval_envs=2,
        eval_steps=20,
        video=False,
        progress=False,
    )
    with pytest.warns(learning.TrainingWarning, match="the discriminator has won") as caught:
        training.run(algorithm, swing, settings, HP.replace(disc_learning_rate=3e-4))
    assert len([w for w in caught if issubclass(w.category, learning.TrainingWarning)]) == 1  # not once per chunk
    lines = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert [line["step"] for line in lines] == [128, 256]
    for name in (
        "disc/accuracy_reference",
        "disc/accuracy_policy",
        "disc/logit_reference",
        "disc/logit_policy",
        "disc/gradient_penalty",
        "amp/style_reward",
        "amp/style_reward_std",
        "eval/return",
    ):
        assert name in lines[-1], name
    saved = json.loads((tmp_path / "run" / "config.json").read_text())
    assert saved["algorithm"] == "amp" and saved["config"]["disc_hidden_sizes"] == [16]
    assert (
        saved["hyperparams"]["disc_learning_rate"] == pytest.approx(3e-4) and saved["hyperparams"]["style_weight"] == 1
    )
    assert saved["config"] == training.config_dict(SMALL)
    assert saved["hyperparams"] == pytest.approx(training.hyperparams_dict(HP.replace(disc_learning_rate=3e-4)))


@pytest.mark.skipif(sys.platform != "linux", reason="forces host devices with XLA_FLAGS")
def test_two_devices_give_one_devices_result(cpu_devices_env):
    """Sharded over 2 CPU devices (the env batch split, the rest replicated), an update
    gives the parameters one device gives, each device computing its share of every
    minibatch step (PPO's two-device test also runs the unsplit steps)."""
    code = textwrap.dedent(
        """
        import jax, numpy as np
        from mjzoo.algorithms import amp
        from mjzoo.harness import devices
        from tests.algorithms.test_amp import HP, SMALL
        from tests.harness.test_distributed import REFERENCE, block_task
        task = block_task()  # any task shards alike: the block on a rail compiles fastest
        ref = REFERENCE(task)
        state = amp.init(SMALL, task, ref, HP, jax.random.key(0))
        one = jax.jit(amp.update, static_argnums=0)(SMALL, task, jax.device_put(state, jax.devices()[0]))[0]
        sharded = devices.shard_envs(state, amp.PER_ENV_FIELDS)
        assert len(sharded.ppo.collector.start.sharding.device_set) == 2
        assert len(sharded.disc_params[0]["kernel"].sharding.device_set) == 2  # replicated
        def split_update(config, task, state):  # each device its share of every step, under the env mesh
            with devices.env_mesh_scope():
                return amp.update(config, task, state)
        three = jax.jit(split_update, static_argnums=0)(SMALL, devices.replicate(task), sharded)[0]
        for a, b in zip(jax.tree.leaves((one.ppo.params, one.disc_params)), jax.tree.leaves((three.ppo.params, three.disc_params))):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=2e-4, atol=2e-5)
        print("ok")
        """
    )
    env = cpu_devices_env(2)
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=root, capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-3000:]
