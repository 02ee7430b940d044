"""Planners open to learned pieces (`mjzoo.planning.learned`): a terminal value passed at
run time as a `jax.tree_util.Partial` whose weights are leaves, so new weights reuse the
compiled planner; and planner states committed by `init`, so a host loop of a jitted
`plan` traces it once. On the point mass: the rollout cost is minus the return minus the
final state's value (against an explicit rollout), and a value rewarding a place makes
the planner head there, in one replan and closed loop, without compiling again."""

from __future__ import annotations

import functools
import types

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
from mjzoo import envs
from mjzoo import planning
from mjzoo.algorithms import cem
from mjzoo.algorithms import mppi
from mjzoo.algorithms import predictive_sampling
from mjzoo.planning import closed_loop
from mjzoo.planning import learned
from mjzoo.planning import realtime

H, K = 6, 3  # 6 planning steps of 0.05 s: a full push moves the 0.3 kg mass ~0.15 m
CONFIG = mppi.Config(num_samples=16, horizon_steps=H, num_knots=K)
HYPERPARAMS = mppi.Hyperparams(temperature=0.05)
WEIGHT = 1000.0  # the value dominates the task's own reward (in [-0.01, 1] per step)


@functools.cache
def _task():
    return envs.make("point_mass", iterations=1, ls_iterations=1, ctrl_dt=0.05)


def _env_state():
    return mjzoo.reset(_task(), jax.random.key(0))


def _linear(weights, model, state):
    """The value weights . qpos."""
    return jnp.dot(weights, state.data.qpos)


def _quadratic(weight, target, model, state):
    """The value -weight |qpos - target|^2: highest at `target`."""
    return -weight * jnp.sum(jnp.square(state.data.qpos - target))


def _critic(target, weight=WEIGHT) -> jax.tree_util.Partial:
    return planning.as_terminal_value(jax.tree_util.Partial(_quadratic, jnp.float32(weight), jnp.asarray(target)))


def _critic_linear(weights) -> jax.tree_util.Partial:
    return planning.as_terminal_value(jax.tree_util.Partial(_linear, jnp.asarray(weights, jnp.float32)))


def _committed_leaves(tree) -> list[bool]:
    return [leaf.committed for leaf in jax.tree.leaves(tree)]


# --- committed, as_terminal_value ----------------------------------------------------------


def test_committed_places_every_leaf_where_it_is_and_keeps_its_value():
    tree = {"array": jnp.arange(3.0), "numpy": np.ones(2, np.float32), "number": 2.0}
    assert not tree["array"].committed
    out = learned.committed(tree)
    assert all(_committed_leaves(out))
    chex.assert_trees_all_equal(out, {"array": jnp.arange(3.0), "numpy": jnp.ones(2), "number": jnp.asarray(2.0)})
    assert out["array"].device == tree["array"].device
    # Under jit placement is the compiler's: the traced tree passes through unchanged.
    np.testing.assert_array_equal(jax.jit(learned.committed)(tree["array"]), tree["array"])


def test_as_terminal_value_wraps_functions_and_commits_a_partials_weights():
    assert planning.as_terminal_value(None) is None
    wrapped = planning.as_terminal_value(_linear)
    assert isinstance(wrapped, jax.tree_util.Partial) and jax.tree.leaves(wrapped) == []
    critic = planning.as_terminal_value(jax.tree_util.Partial(_linear, jnp.array([1.0, 2.0])))
    assert _committed_leaves(critic) == [True]
    state = _env_state()
    np.testing.assert_allclose(critic(None, state), state.data.qpos[0] + 2 * state.data.qpos[1], rtol=1e-6)


@pytest.mark.parametrize("value", [1.0, "critic", jnp.zeros(2)])
def test_a_terminal_value_that_is_not_callable_is_rejected_by_name(value):
    with pytest.raises(TypeError, match="terminal_value must be a callable"):
        planning.as_terminal_value(value)
    with pytest.raises(TypeError, match="terminal_value must be a callable"):
        planning.rollout_costs(_task(), _env_state(), jnp.zeros((2, H, 2)), jax.random.key(0), value)
    with pytest.raises(TypeError, match="terminal_value must be a callable"):
        realtime.Problem(mppi, CONFIG, _task(), _task(), seconds=1.0, terminal_value=value)


@pytest.mark.parametrize("planner", [predictive_sampling, cem, mppi], ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_init_returns_a_committed_state(planner):
    config, hyperparams = planner.Config(horizon_steps=H, num_knots=K), planner.Hyperparams(noise_scale=0.3)
    warm = planner.init(config, _task(), hyperparams, knots=jnp.full((K, 2), 0.5))
    for state in [planner.init(config, _task(), hyperparams), warm]:
        assert all(_committed_leaves(state))
        np.testing.assert_allclose(state.std, 0.3, rtol=1e-6)
    np.testing.assert_array_equal(state.knots, 0.5)


# --- on the point mass ---------------------------------------------------------------------


def _constant_action(action, obs, key):
    return action


def test_rollout_costs_subtract_the_value_of_the_final_state():
    # Constant pushes (+1, 0.5) and (-0.5, -1): the costs drop by weights . q_final exactly,
    # q_final from an explicit rollout; new weights reuse the one trace.
    task, state, key = _task(), _env_state(), jax.random.key(1)
    actions = jnp.array([[1.0, 0.5], [-0.5, -1.0]])
    jitted = jax.jit(chex.assert_max_traces(planning.rollout_costs, n=1))

    def costs(weights):
        return jitted(task, state, jnp.repeat(actions[:, None], H, 1), key, _critic_linear(weights))[0][0]

    bare = costs([0.0, 0.0])
    rollout = jax.jit(mjzoo.rollout, static_argnums=4)
    for n, action in enumerate(actions):
        final, trajectory = rollout(task, jax.tree_util.Partial(_constant_action, action), state, key, H)
        assert float(jnp.linalg.norm(final.data.qpos - state.data.qpos)) > 0.05  # the pushes move the mass
        np.testing.assert_allclose(bare[n], -jnp.sum(trajectory.next_state.reward), atol=1e-5)
        for weights in ([1.0, 0.0], [0.0, 1.0], [2.0, -3.0]):
            expected = bare[n] - jnp.dot(jnp.asarray(weights), final.data.qpos)
            np.testing.assert_allclose(costs(weights)[n], expected, atol=1e-5)


def test_a_host_loop_of_jitted_plan_traces_once_and_heads_where_the_value_says():
    # init's state, then plan's own outputs, then new critic weights (one set from a jit,
    # as a learner's update makes them): all one trace.
    task, env_state = _task(), _env_state()
    plan = jax.jit(chex.assert_max_traces(mppi.plan, n=1), static_argnums=0)
    start = env_state.data.qpos
    left = _critic(start - jnp.array([0.3, 0.0]))
    critics = {
        "none": _critic(start, weight=0.0),
        "right": _critic(start + jnp.array([0.3, 0.0])),
        "left": left,
        "left, from a jit": jax.tree_util.Partial(_quadratic, *jax.jit(lambda args: args)(left.args)),
    }
    pushes, costs = {}, {}
    for name, critic in critics.items():
        state = mppi.init(CONFIG, task, HYPERPARAMS)
        for seed in range(3):
            state, controls = plan(CONFIG, task, state, env_state, jax.random.key(seed), terminal_value=critic)
        pushes[name], costs[name] = float(jnp.mean(controls[:, 0])), float(state.cost)
    assert pushes["right"] > 0.5 and pushes["left"] < -0.5, pushes
    assert pushes["left, from a jit"] == pushes["left"] and costs["left, from a jit"] == costs["left"]
    # A sample's cost is its task cost, in [-H, 0.01 H], plus WEIGHT |q_final - target|^2,
    # where a full push for H steps moves the mass at most 0.15 m of the 0.3 m.
    for name in ("right", "left"):
        assert WEIGHT * 0.15**2 - 1.01 * H < costs[name] - costs["none"] < WEIGHT * 0.3**2 + 1.01 * H, costs


def test_closed_loop_runs_with_a_terminal_value_as_an_argument():
    # The planner module is static: a copy whose `plan` may be traced once fails if a
    # second critic recompiled the run.
    traced = types.ModuleType("traced_mppi")
    traced.init, traced.plan = mppi.init, chex.assert_max_traces(mppi.plan, n=1)
    task = _task()
    sim_state = mjzoo.reset(task, jax.random.key(2))
    run = functools.partial(closed_loop.run, traced, CONFIG, task, task, sim_state, jax.random.key(3), 4, 2)
    start = sim_state.data.qpos
    for sign in (1.0, -1.0):
        result = run(terminal_value=_critic(start + sign * jnp.array([0.0, 0.3])), hyperparams=HYPERPARAMS)
        _assert_moved_along_y(result.states.data.qpos[-1] - start, sign)


def test_a_problems_terminal_value_reaches_the_offline_run():
    # `offline` resets with the first half of its key: the start, to place the target.
    key = jax.random.key(4)
    start = mjzoo.reset(_task(), jax.random.split(key)[0]).data.qpos
    value = functools.partial(_quadratic, WEIGHT, start - jnp.array([0.0, 0.3]))  # a plain function: wrapped
    problem = realtime.Problem(
        mppi, CONFIG, _task(), _task(), seconds=0.4, replan_every=2, terminal_value=value, hyperparams=HYPERPARAMS
    )
    assert isinstance(problem.terminal_value, jax.tree_util.Partial) and problem.num_replans == 4
    result, _ = realtime.offline(problem, key)
    _assert_moved_along_y(result.states.data.qpos[-1] - start, -1.0)


def _assert_moved_along_y(moved, sign):
    """Pushed 0.3 m along y by the value: at least 5 cm that way in 0.4 s, less along x."""
    assert sign * float(moved[1]) > 0.05 and abs(float(moved[0])) < abs(float(moved[1])), moved
