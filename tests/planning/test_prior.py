"""A trained policy as a planner's prior (`mjzoo.planning.prior`): the planner plans
offsets to the policy's actions in closed loop, so a zero offset is the policy exactly, in
every rollout and in the world; on the point mass a briefly trained PPO policy and critic
make MPPI with 2 samples over 0.2 s reach its goals better than the same MPPI without them."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
from mjzoo import envs
from mjzoo.algorithms import mppi
from mjzoo.algorithms import ppo
from mjzoo.planning import closed_loop
from mjzoo.planning import native
from mjzoo.planning import prior
from mjzoo.planning import realtime
from mjzoo.running import transition


@functools.cache
def _task():
    return envs.make("point_mass", iterations=1, ls_iterations=1, ctrl_dt=0.05)


def _towards_goal(gain, obs):
    """A hand policy: push along the offset to the goal (obs[4:6])."""
    return gain * obs[4:6]


def test_the_residual_view_steps_the_policy_plus_the_offset():
    task = _task()
    guide = prior.policy_prior(jax.tree_util.Partial(_towards_goal, jnp.float32(3.0)))
    state = mjzoo.fill_transition_entries(task, mjzoo.reset(task, jax.random.key(0)))
    view, key, offset = prior.residual(task, guide), jax.random.key(1), jnp.asarray([0.1, -0.2])
    policy = 3.0 * state.obs[4:6]
    assert np.abs(np.asarray(policy)).max() > 0.1  # it pushes: not a zero action matching a zero offset
    for control, applied in ((jnp.zeros(2), policy), (offset, policy + offset)):
        got = jax.jit(transition)(view, state, control, key)
        expected = transition(task, state, applied, key)
        np.testing.assert_allclose(got.data.qpos, expected.data.qpos, rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(got.reward, expected.reward, rtol=1e-6, atol=1e-7)
    # A symmetric control range: the plan's zero offset is the zero control.
    np.testing.assert_allclose(prior.centre(task), [0.0, 0.0])


def _policy_alone(task, act, state, steps):
    """[T] states and [T, nu] actions of `act` (obs -> action) in closed loop on `task`."""

    def body(s, key):
        action = act(s.obs)
        after = transition(task, s, action, key)
        return after, (after, action)

    return jax.lax.scan(body, state, jax.random.split(jax.random.key(3), steps))[1]


def test_with_zero_noise_the_guided_closed_loop_is_the_policy():
    """Whatever the knots and the planner's model: the world applies the policy's action
    in its own state plus a zero offset."""
    world = _task()
    coarse = envs.make("point_mass", iterations=1, ls_iterations=1, ctrl_dt=0.1)  # the planner's model differs
    guide = prior.policy_prior(jax.tree_util.Partial(_towards_goal, jnp.float32(3.0)))
    config = mppi.Config(num_samples=4, horizon_steps=6, num_knots=2)  # 2 knots could not hold its actions
    state = mjzoo.fill_transition_entries(world, mjzoo.reset(world, jax.random.key(0)))
    hooks = prior.guided(closed_loop.Hooks(), guide)
    result = closed_loop.run(
        mppi, config, world, coarse, state, jax.random.key(4), 20, 1, hooks, None, mppi.Hyperparams(noise_scale=0.0)
    )
    # The world's steps take no key here, so the policy alone's keys do not matter.
    states, actions = _policy_alone(world, guide.act, state, 20)
    np.testing.assert_allclose(result.controls, actions, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(result.states.data.qpos, states.data.qpos, rtol=1e-5, atol=1e-6)
    assert np.abs(np.asarray(actions)).max() > 0.1


def test_a_policy_in_the_loop_plans_in_jax():
    """C MuJoCo's rollouts replay fixed controls: they cannot apply a policy per step."""
    task = _task()
    guide = prior.policy_prior(jax.tree_util.Partial(_towards_goal, jnp.float32(3.0)))
    hooks = prior.guided(closed_loop.Hooks(), guide)
    with pytest.raises(ValueError, match="Problem: .* plan on MJX"):
        realtime.Problem(mppi, FEW, task, task, 0.2, hooks=hooks, backend="native")
    assert realtime.Problem(mppi, FEW, task, task, 0.2, hooks=hooks).physics == "mjx"  # "auto"
    with pytest.raises(ValueError, match="closed_loop: .* plan on MJX"):
        closed_loop.replan(
            mppi,
            FEW,
            native.wrap(task),
            mppi.init(FEW, task),
            mjzoo.reset(task, jax.random.key(0)),
            jax.random.key(1),
            hooks,
        )
    with pytest.raises(ValueError, match="guide the planner already"):
        prior.guided(hooks, guide)


@functools.cache
def _trained_prior() -> prior.PolicyPrior:
    """PPO on the point mass for ~65k steps: its policy heads for the goal, roughly."""
    config = ppo.Config(num_envs=64, unroll_length=16, num_minibatches=4, num_epochs=4, total_steps=64 * 16 * 64)
    hyperparams = ppo.Hyperparams(learning_rate=3e-3, entropy_coef=1e-3, discount=0.9)
    task = _task()
    state, _ = jax.jit(ppo.train, static_argnums=0)(config, task, hyperparams, jax.random.key(0))
    return prior.from_learner(ppo, config, task, state)


# Few samples over a short horizon (0.2 s): beyond the reward's 0.5 m margin a plain
# planner sees no gradient; the prior's plan and critic point the way.
FEW = mppi.Config(num_samples=2, horizon_steps=4, num_knots=2)


def _closed_loop_return(hooks, terminal_value, seed) -> float:
    task, config = _task(), FEW
    state = mjzoo.reset(task, jax.random.key(seed))
    result = closed_loop.run(
        mppi, config, task, task, state, jax.random.key(seed + 100), 40, 1, hooks, terminal_value, mppi.Hyperparams()
    )
    return float(jnp.sum(result.states.reward))


def test_a_trained_policy_prior_makes_few_samples_do_better():
    guide = _trained_prior()
    hooks = prior.guided(closed_loop.Hooks(), guide)
    seeds = range(4)
    with_prior = [_closed_loop_return(hooks, prior.terminal_value(guide), s) for s in seeds]
    without = [_closed_loop_return(closed_loop.Hooks(), None, s) for s in seeds]
    print("returns with the prior", np.round(with_prior, 2), "without", np.round(without, 2))
    assert np.mean(with_prior) > np.mean(without) + 2.0, (with_prior, without)
