"""AMP learns a reference's motion from the style reward alone.

The pendulum (which hangs at rest and whose task reward asks for a swing-up) is shown a
slow sway 0.2-0.4 rad off hanging (`test_amp.sway_clip`): a motion that needs torque
all the time and that the task reward does not ask for. With `task_weight=0` and no
reference-state starts, AMP must find it from the hanging pose. The style measure is
the mean joint-angle error to the nearest 10-frame reference window
(`mjzoo.motion.nearest_window_error`), over the last 300 of 400 steps of deterministic
episodes. Measured (CPU, 164k steps): AMP 0.006 rad, no torque 0.20 rad (it hangs).
The gradient penalty is 1, not the paper's 5: on these 4 normalized inputs 5 flattened
the discriminator (style reward std 0.001) and the error stayed at 0.13 rad.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo import motion
from mjzoo.algorithms import amp
from mjzoo.algorithms import ppo
from mjzoo.harness import training
from tests.algorithms.test_amp import sway_clip

STEPS = 64 * 32 * 80  # 164k env steps
AMP, AMP_HP = amp.configure(
    num_envs=64,
    unroll_length=32,
    num_minibatches=4,
    num_epochs=4,
    learning_rate=1e-3,
    entropy_coef=1e-3,
    task_weight=0.0,
    style_weight=1.0,
    disc_hidden_sizes=(64, 64),
    disc_learning_rate=1e-3,
    disc_minibatches=4,
    replay_size=10_000,
    gradient_penalty_weight=1.0,
    total_steps=STEPS,
)
PPO, PPO_HP = ppo.configure(
    num_envs=64,
    unroll_length=32,
    num_minibatches=4,
    num_epochs=4,
    learning_rate=1e-3,
    entropy_coef=1e-3,
    total_steps=STEPS,
)


def style_errors(task: mjzoo.Task, reference: motion.Reference, act, params, seed: int = 1) -> list[float]:
    """The style measure of 4 deterministic episodes of `act(params, obs, key)`."""

    def episode(key):
        _, trajectory = mjzoo.rollout(task, lambda obs, k: act(params, obs, k), mjzoo.reset(task, key), key, 400)
        return trajectory.next_state.data.qpos

    qpos = np.asarray(jax.jit(jax.vmap(episode))(jax.random.split(jax.random.key(seed), 4)))
    return [motion.nearest_window_error(np.asarray(reference.qpos), q[100:], [0], 10) for q in qpos]


@pytest.mark.filterwarnings("ignore::mjzoo.learning.TrainingWarning")
def test_style_alone_teaches_the_reference_motion():
    task = mjzoo.envs.make("pendulum_swingup")
    reference = motion.reference(sway_clip(task), task.mj_model, mjzoo.control_dt(task))

    settings = training.Settings(updates_per_chunk=20, eval_envs=2, eval_steps=10, video=False, progress=False)
    state, _ = training.run(amp.make(AMP, reference), task, settings, AMP_HP)
    learned = style_errors(task, reference, amp.policy(AMP, task), amp.policy_params(state))
    hanging = style_errors(task, reference, lambda params, obs, key: jnp.zeros(1), None)
    state, _ = training.run(ppo.make(PPO), task, settings, PPO_HP)
    task_reward = style_errors(task, reference, ppo.policy(PPO, task), ppo.policy_params(state))

    assert max(hanging) > 0.15  # hanging is ~0.2 rad from every reference window
    assert max(learned) < 0.5 * min(hanging), (learned, hanging)
    assert max(learned) < 0.5 * min(task_reward), (learned, task_reward)
