"""Hand-checked behaviour of the combinators (`mjzoo.combinators`, `mjzoo.perturbations`).

Every test runs a tiny hand-made Task whose numbers can be worked out on paper:

  a 1 kg block on a frictionless slide joint along x, no gravity, pushed by a motor
  (force = action, unlimited), MuJoCo's semi-implicit Euler with dt = 0.1 s:
      qvel' = qvel + dt * F / m,   qpos' = qpos + dt * qvel'.
  From rest with F = 1 N the n-th step gives
      qvel_n = 0.1 n,   qpos_n = 0.01 * n (n + 1) / 2 = 0.01, 0.03, 0.06, 0.10, 0.15, 0.21, ...
  obs = [qpos, qvel]; one reward term "x" = qpos after the step; terminated once
  qpos > threshold, never truncated; metrics["qpos"] = qpos after the step.
  The step writes NaN into qvel when action > nan_above (to provoke divergence), and the
  reset puts qpos at spawn * U(0, 1) (spawn = 0 unless a test needs a random reset).

All runs go through a few module-level jitted functions that take the task as an
argument, so tasks of one structure share one compile.
"""

from __future__ import annotations

import dataclasses
import re

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.tree_util import Partial
from mujoco import mjx

import mjzoo
from mjzoo import physics as physics_lib
from mjzoo.combinators import AutoResetState
from mjzoo.combinators import ObservationState
from mjzoo.combinators import TimeLimitState
from mjzoo.perturbations import DomainRandomizationState
from mjzoo.types import State
from mjzoo.types import Task

DT = 0.1
XML = f"""
<mujoco model="block">
  <option timestep="{DT}" integrator="Euler" gravity="0 0 0"/>
  <worldbody>
    <body name="block">
      <joint name="x" type="slide" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
    </body>
  </worldbody>
  <actuator><motor name="push" joint="x" gear="1"/></actuator>
</mujoco>
"""

# qpos_n and qvel_n after n steps from rest under a constant 1 N push (n = 1..8).
QPOS = np.array([0.01 * n * (n + 1) / 2 for n in range(1, 9)], np.float32)  # .01 .03 .06 .10 .15 .21 .28 .36
QVEL = np.array([0.1 * n for n in range(1, 9)], np.float32)
NEVER = 1e9  # a threshold never reached


# --- the tiny task --------------------------------------------------------------------


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Params:
    threshold: jax.Array  # terminated once qpos > threshold
    nan_above: jax.Array  # the step writes NaN into qvel when action > nan_above
    spawn: jax.Array  # reset: qpos = spawn * U(0, 1)


def _observe(data: mjx.Data) -> jax.Array:
    return jnp.concatenate([data.qpos, data.qvel])


def _reset(p: Params, model, key):
    data = mjx.make_data(model)
    data = data.replace(qpos=p.spawn * jax.random.uniform(key, (1,)))
    return State.create(data, _observe(data))


def _step(p: Params, model, state, action, key):
    data = physics_lib.step(model, state.data, action, 1)
    data = data.replace(qvel=jnp.where(action[0] > p.nan_above, jnp.nan, data.qvel))
    return state.replace(data=data, obs=_observe(data), metrics={"qpos": data.qpos[0]})


def _reward(p: Params, model, state, action, next_state):
    return {"x": next_state.data.qpos[0]}


def _terminate(p: Params, model, state):
    return state.data.qpos[0] > p.threshold, jnp.zeros((), bool)


PHYSICS = physics_lib.load(XML)


def make_task(threshold=NEVER, nan_above=1e30, spawn=0.0) -> Task:
    p = Params(jnp.float32(threshold), jnp.float32(nan_above), jnp.float32(spawn))
    return Task(
        model=PHYSICS.model,
        start=Partial(_reset, p),
        step=Partial(_step, p),
        reward=Partial(_reward, p),
        terminate=Partial(_terminate, p),
        mj_model=PHYSICS.mj_model,
    )


# --- shared jitted runners --------------------------------------------------------------

KEY = jax.random.key(0)
reset = jax.jit(mjzoo.reset)


@jax.jit
def run(task: Task, state: State, actions: jax.Array, key: jax.Array):
    """Transitions for each row of `actions` [T, 1]; returns (final, stacked states [T])."""

    def body(state, xs):
        action, key = xs
        next_state = mjzoo.transition(task, state, action, key)
        return next_state, next_state

    return jax.lax.scan(body, state, (actions, jax.random.split(key, actions.shape[0])))


def pushes(*forces: float) -> jax.Array:
    return jnp.asarray(forces, jnp.float32)[:, None]


T = 6  # every episode runs T transitions (one compile per task structure), padded with 0 N


def episode(task: Task, *forces: float, key=KEY):
    """Reset, then run the given pushes: (initial state, stacked next states [len(forces)])."""
    assert len(forces) <= T
    reset_key, run_key = jax.random.split(key)
    state = reset(task, reset_key)
    _, states = run(task, state, pushes(*forces, *[0.0] * (T - len(forces))), run_key)
    return state, jax.tree.map(lambda x: x[: len(forces)], states)


def test_the_tiny_task_follows_the_hand_computed_dynamics():
    state, states = episode(make_task(), *[1.0] * 6)
    np.testing.assert_array_equal(state.obs, [0.0, 0.0])
    np.testing.assert_allclose(states.data.qpos[:, 0], QPOS[:6], rtol=1e-5)
    np.testing.assert_allclose(states.data.qvel[:, 0], QVEL[:6], rtol=1e-5)
    np.testing.assert_allclose(states.reward, QPOS[:6], rtol=1e-5)
    np.testing.assert_allclose(states.metrics["reward/x"], QPOS[:6], rtol=1e-5)
    assert not states.terminated.any() and not states.truncated.any()
    # threshold 0.05: qpos 0.01, 0.03 stay below, 0.06 is above.
    _, states = episode(make_task(threshold=0.05), 1.0, 1.0, 1.0)
    np.testing.assert_array_equal(states.terminated, [False, False, True])


# --- with_time_limit --------------------------------------------------------------------


def test_time_limit_truncates_exactly_at_max_steps():
    _, states = episode(mjzoo.with_time_limit(make_task(), 4), *[1.0] * 6)
    np.testing.assert_array_equal(mjzoo.find(states, TimeLimitState).steps, [1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(states.truncated, [False, False, False, True, True, True])
    assert not states.terminated.any()  # the limit never terminates
    np.testing.assert_allclose(states.reward, QPOS[:6], rtol=1e-5)  # rewards untouched


def test_time_limit_counter_starts_at_zero_and_is_int32():
    state = reset(mjzoo.with_time_limit(make_task(), 4), KEY)
    assert (
        mjzoo.find(state, TimeLimitState).steps.dtype == jnp.int32 and int(mjzoo.find(state, TimeLimitState).steps) == 0
    )


def test_nested_time_limits_each_count_their_own_steps():
    # The known bug of one shared counter: an inner limit of 2 under an auto-reset under an
    # outer limit of 5. The inner counts its own episodes (restarted every 2 steps), the
    # outer its 6 steps; before, the outer's count overwrote the inner's, which then
    # truncated at every step from the 2nd on.
    task = mjzoo.with_time_limit(mjzoo.with_auto_reset(mjzoo.with_time_limit(make_task(), 2)), 5)
    state, states = episode(task, *[1.0] * 6)
    outer, inner = state.layers, state.layers.inner.inner
    assert isinstance(outer, TimeLimitState) and isinstance(inner, TimeLimitState)
    assert int(outer.steps) == 0 and int(inner.steps) == 0
    np.testing.assert_array_equal(states.layers.steps, [1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(states.layers.inner.inner.steps, [1, 0, 1, 0, 1, 0])  # a new episode at 0
    np.testing.assert_array_equal(states.truncated, [False, True, False, True, True, True])
    np.testing.assert_allclose(states.data.qpos[:, 0], [0.01, 0, 0.01, 0, 0.01, 0], atol=1e-7)  # restarted
    assert mjzoo.find(states, TimeLimitState) is states.layers  # the outermost: the one a reader here sees
    assert int(task.time_limit) == 2


def test_time_limits_around_action_repeat_each_count_their_own_steps():
    # Inner limit 5 of the block's steps, under 2 repeats: its 5th step is in the 3rd
    # repeated step, after which the repeat stops (the episode ended). The outer limit of
    # 4 counts repeated steps. time_limit: min(ceil(5 / 2), 4) = 3.
    task = mjzoo.with_time_limit(mjzoo.with_action_repeat(mjzoo.with_time_limit(make_task(), 5), 2), 4)
    _, states = episode(task, *[1.0] * 6)
    np.testing.assert_array_equal(states.layers.steps, [1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(states.layers.inner.steps, [2, 4, 5, 6, 7, 8])
    np.testing.assert_array_equal(states.truncated, [False, False, True, True, True, True])
    np.testing.assert_allclose(states.data.qpos[:3, 0], QPOS[[1, 3, 4]], rtol=1e-5)
    assert int(task.time_limit) == 3


def test_find_reads_a_record_by_type_and_names_what_is_missing():
    state = reset(mjzoo.with_observation_noise(mjzoo.with_auto_reset(mjzoo.with_time_limit(make_task(), 3)), 0.0), KEY)
    assert mjzoo.find(state, AutoResetState) is state.layers  # noise keeps no record
    assert mjzoo.find(state, TimeLimitState) is state.layers.inner
    assert state.outcome is None and reset(make_task(), KEY).layers == ()
    with pytest.raises(LookupError, match=r"no ObservationState .*\['AutoResetState', 'TimeLimitState'\]"):
        mjzoo.find(state, ObservationState)
    assert mjzoo.find(state, ObservationState, None) is None


def test_time_limit_terminated_wins_over_truncated():
    # threshold 0.08: qpos 0.01, 0.03, 0.06 < 0.08 < 0.10 = step 4, the last allowed step.
    _, states = episode(mjzoo.with_time_limit(make_task(threshold=0.08), 4), *[1.0] * 4)
    np.testing.assert_array_equal(states.terminated, [False, False, False, True])
    np.testing.assert_array_equal(states.truncated, [False, False, False, False])


def test_time_limit_is_a_leaf():
    # Two limits, one trace: max_steps is data, not structure.
    a, b = mjzoo.with_time_limit(make_task(), 2), mjzoo.with_time_limit(make_task(), 3)
    assert jax.tree.structure(a) == jax.tree.structure(b)
    _, states = episode(b, 1.0, 1.0, 1.0)
    np.testing.assert_array_equal(states.truncated, [False, False, True])


def test_time_limit_is_readable_from_the_task():
    # The innermost limit binds; action repeat counts it in its own (longer) steps.
    assert make_task().time_limit is None
    assert int(mjzoo.with_time_limit(mjzoo.with_time_limit(make_task(), 7), 9).time_limit) == 7
    assert int(mjzoo.with_action_repeat(mjzoo.with_time_limit(make_task(), 7), 3).time_limit) == 3  # ceil(7 / 3)
    assert int(mjzoo.with_auto_reset(mjzoo.with_time_limit(make_task(), 7)).time_limit) == 7


@pytest.mark.parametrize("max_steps", [0, -1, 2.5, True, "10", None])
def test_time_limit_invalid_max_steps(max_steps):
    with pytest.raises(ValueError, match="max_steps"):
        mjzoo.with_time_limit(make_task(), max_steps)


# --- with_auto_reset ----------------------------------------------------------------------


def test_auto_reset_after_truncation():
    task = mjzoo.with_auto_reset(mjzoo.with_time_limit(make_task(), 3))
    _, s = episode(task, *[1.0] * 5)
    # Rewards: one episode of 3 steps, then the next one starts from rest.
    np.testing.assert_allclose(s.reward, [0.01, 0.03, 0.06, 0.01, 0.03], rtol=1e-5)
    np.testing.assert_allclose(s.metrics["reward/x"], [0.01, 0.03, 0.06, 0.01, 0.03], rtol=1e-5)
    np.testing.assert_array_equal(s.truncated, [False, False, True, False, False])
    assert not s.terminated.any()
    # Step 3 ended the episode: its obs and data are the fresh episode's...
    np.testing.assert_array_equal(s.obs[2], [0.0, 0.0])
    np.testing.assert_array_equal(s.data.qpos[2], [0.0])
    np.testing.assert_array_equal(s.data.qvel[2], [0.0])
    # ... the final observation of the finished one is kept ...
    np.testing.assert_allclose(mjzoo.find(s, AutoResetState).final_obs[2], [0.06, 0.3], rtol=1e-5)
    # ... and the time limit restarts: 1, 2, (3 ->) 0, 1, 2.
    np.testing.assert_array_equal(mjzoo.find(s, TimeLimitState).steps, [1, 2, 0, 1, 2])
    # Without an episode end, final_obs is the obs itself.
    for t in (0, 1, 3, 4):
        np.testing.assert_array_equal(mjzoo.find(s, AutoResetState).final_obs[t], s.obs[t])
    np.testing.assert_allclose(s.obs[3], [0.01, 0.1], rtol=1e-5)


def test_auto_reset_after_termination():
    # Same structure as above (threshold and max_steps are leaves): no new compile.
    task = mjzoo.with_auto_reset(mjzoo.with_time_limit(make_task(threshold=0.05), 100))
    _, s = episode(task, *[1.0] * 5)
    np.testing.assert_allclose(s.reward, [0.01, 0.03, 0.06, 0.01, 0.03], rtol=1e-5)
    np.testing.assert_array_equal(s.terminated, [False, False, True, False, False])
    assert not s.truncated.any()
    np.testing.assert_array_equal(s.obs[2], [0.0, 0.0])
    np.testing.assert_allclose(mjzoo.find(s, AutoResetState).final_obs[2], [0.06, 0.3], rtol=1e-5)
    np.testing.assert_allclose(s.metrics["qpos"][2], 0.06, rtol=1e-5)  # metrics: the finished transition
    np.testing.assert_array_equal(mjzoo.find(s, TimeLimitState).steps, [1, 2, 0, 1, 2])


def test_auto_reset_state_is_a_fresh_reset():
    # With a random reset, the state after an episode end equals a reset of the inner task
    # (the data of a new episode, not of the old one), at a fresh spawn in [0, 0.5).
    task = mjzoo.with_auto_reset(mjzoo.with_time_limit(make_task(spawn=0.5), 1))
    _, s = episode(task, 1.0, 1.0, 1.0)
    assert s.truncated.all()
    assert np.all(s.data.qvel == 0.0)
    q = np.asarray(s.data.qpos[:, 0])
    assert np.all((q >= 0.0) & (q < 0.5)) and len(set(q.tolist())) == 3  # new draws every time
    np.testing.assert_allclose(s.obs[:, 0], q)
    # final_obs is one step away from the previous fresh start: q + 0.01, 0.1.
    np.testing.assert_allclose(mjzoo.find(s, AutoResetState).final_obs[1:, 0], q[:-1] + 0.01, rtol=1e-5)


_RESETS: list[int] = []


def _counted_reset(p: Params, model, key):
    jax.debug.callback(lambda: _RESETS.append(1))  # runs only where a reset is computed
    return _reset(p, model, key)


def test_a_batch_resets_only_on_steps_where_an_env_ended():
    """Under vmap the new episodes are computed only on steps where some env ended (one
    branch for the batch), and every env's states equal its own unbatched run."""
    inner = make_task(threshold=0.05)
    task = mjzoo.with_auto_reset(inner.replace(start=Partial(_counted_reset, inner.start.args[0])))
    keys = jax.random.split(KEY, 3)
    states = jax.vmap(reset, in_axes=(None, 0))(task, keys)
    calm = jnp.zeros((3, T, 1))  # no env ends
    pushed = calm.at[1].set(1.0)  # env 1 is pushed past the threshold at its 3rd step (then every 3rd)
    batched = jax.jit(jax.vmap(run, in_axes=(None, 0, 0, 0)))
    for actions, resets_expected in ((calm, False), (pushed, True)):
        jax.block_until_ready(batched(task, states, actions, keys))  # compiled (and warmed) first
        _RESETS.clear()
        _, s = jax.block_until_ready(batched(task, states, actions, keys))
        jax.effects_barrier()
        assert bool(_RESETS) == resets_expected, (len(_RESETS), resets_expected)
        for env in range(3):
            _, alone = run(task, jax.tree.map(lambda x, env=env: x[env], states), actions[env], keys[env])
            chex.assert_trees_all_equal(jax.tree.map(lambda x, env=env: x[env], s), alone)
    np.testing.assert_array_equal(s.terminated[1], [False, False, True, False, False, True])


def test_nested_batches_reset_only_on_steps_where_an_env_ended():
    """Under a vmap over seeds of a vmap over envs (PPO's seeds trained at once) the
    condition stays one for the whole batch: no new episodes are computed while no env of
    any seed ends (Playground's cheetah settles 200 steps per reset), and each seed's
    states equal its own batch's run."""
    inner = make_task(threshold=0.05)
    task = mjzoo.with_auto_reset(inner.replace(start=Partial(_counted_reset, inner.start.args[0])))
    keys = jax.random.split(KEY, (2, 3))
    states = jax.vmap(jax.vmap(reset, in_axes=(None, 0)), in_axes=(None, 0))(task, keys)
    calm = jnp.zeros((2, 3, T, 1))
    pushed = calm.at[1, 2].set(1.0)  # seed 1's env 2 ends at its 3rd step
    batched = jax.vmap(run, in_axes=(None, 0, 0, 0))
    nested = jax.jit(jax.vmap(batched, in_axes=(None, 0, 0, 0)))
    for actions, resets_expected in ((calm, False), (pushed, True)):
        jax.block_until_ready(nested(task, states, actions, keys))
        _RESETS.clear()
        _, s = jax.block_until_ready(nested(task, states, actions, keys))
        jax.effects_barrier()
        assert bool(_RESETS) == resets_expected, (len(_RESETS), resets_expected)
    for seed in range(2):
        at = lambda x, seed=seed: x[seed]  # noqa: E731
        _, alone = batched(task, jax.tree.map(at, states), pushed[seed], keys[seed])
        chex.assert_trees_all_equal(jax.tree.map(at, s), alone)
    np.testing.assert_array_equal(s.terminated[1, 2], [False, False, True, False, False, True])


# --- with_action_repeat -------------------------------------------------------------------


def test_action_repeat_sums_inner_rewards():
    task = mjzoo.with_action_repeat(make_task(), 3)
    _, s = episode(task, 1.0, 1.0)
    # Outer step 1 = inner steps 1..3: 0.01 + 0.03 + 0.06 = 0.10;
    # outer step 2 = inner steps 4..6: 0.10 + 0.15 + 0.21 = 0.46.
    np.testing.assert_allclose(s.reward, [0.10, 0.46], rtol=1e-5)
    np.testing.assert_allclose(s.metrics["reward/x"], [0.10, 0.46], rtol=1e-5)
    np.testing.assert_allclose(s.data.qpos[:, 0], [QPOS[2], QPOS[5]], rtol=1e-5)
    np.testing.assert_allclose(s.obs, [[QPOS[2], QVEL[2]], [QPOS[5], QVEL[5]]], rtol=1e-5)
    assert not s.terminated.any() and not s.truncated.any()


def test_action_repeat_equals_k_manual_transitions():
    base = make_task()
    _, manual = episode(base, 0.5, 0.5, 0.5)
    final = jax.tree.map(lambda x: x[-1], manual)
    _, repeated = episode(mjzoo.with_action_repeat(base, 3), 0.5)
    repeated = jax.tree.map(lambda x: x[0], repeated)
    chex.assert_trees_all_close(repeated.data, final.data, rtol=1e-6, atol=1e-7)
    chex.assert_trees_all_close(repeated.obs, final.obs, rtol=1e-6)
    # 0.5 N: half of the 1 N numbers.
    np.testing.assert_allclose(repeated.reward, 0.5 * (QPOS[0] + QPOS[1] + QPOS[2]), rtol=1e-5)


def test_action_repeat_stops_after_inner_termination():
    # threshold 0.02: inner step 2 (qpos 0.03) terminates; step 3 must not happen.
    task = mjzoo.with_action_repeat(make_task(threshold=0.02), 3)
    _, s = episode(task, 1.0)
    np.testing.assert_allclose(s.reward, [0.01 + 0.03], rtol=1e-5)
    np.testing.assert_array_equal(s.terminated, [True])
    np.testing.assert_array_equal(s.truncated, [False])
    np.testing.assert_allclose(s.data.qpos[0], [0.03], rtol=1e-5)  # state frozen at the end
    np.testing.assert_allclose(s.data.qvel[0], [0.2], rtol=1e-5)
    np.testing.assert_allclose(s.obs[0], [0.03, 0.2], rtol=1e-5)


def test_action_repeat_metrics_come_from_the_last_real_step():
    # After the inner episode ended, the remaining repeats "leave the state unchanged":
    # metrics included. metrics["qpos"] must describe inner step 2 (0.03), not a discarded
    # third step taken from it (0.06).
    task = mjzoo.with_action_repeat(make_task(threshold=0.02), 3)
    _, s = episode(task, 1.0)
    np.testing.assert_allclose(s.metrics["qpos"], [0.03], rtol=1e-5)


@pytest.mark.parametrize("repeats", [0, -2, 1.5, True, None])
def test_action_repeat_invalid(repeats):
    with pytest.raises(ValueError, match="repeats"):
        mjzoo.with_action_repeat(make_task(), repeats)


# --- with_reward ----------------------------------------------------------------------------


def speed(model, state, action, next_state):
    """Extra reward term: the velocity after the step."""
    return next_state.data.qvel[0]


def test_with_reward_duplicate_name_raises_at_construction():
    with pytest.raises(ValueError, match=r"already has a reward term named 'x': \['x'\]"):
        mjzoo.with_reward(make_task(), "x", speed)


def test_with_reward_invalid_arguments():
    with pytest.raises(ValueError):
        mjzoo.with_reward(make_task(), "", speed)
    with pytest.raises(TypeError, match="'v'"):
        mjzoo.with_reward(make_task(), "v", 3.0)


def test_with_reward_adds_a_weighted_term_and_the_weight_is_a_leaf():
    traces = []

    @jax.jit
    @chex.assert_max_traces(n=1)
    def step(task, state, action, key):
        traces.append(None)  # runs once per trace
        return mjzoo.transition(task, state, action, key)

    for weight in (2.0, 3.0, -0.5):
        task = mjzoo.with_reward(make_task(), "v", speed, weight=weight)
        s = step(task, reset(task, KEY), jnp.array([1.0]), KEY)
        # x = qpos_1 = 0.01, v = weight * qvel_1 = weight * 0.1.
        np.testing.assert_allclose(s.metrics["reward/x"], 0.01, rtol=1e-5)
        np.testing.assert_allclose(s.metrics["reward/v"], weight * 0.1, rtol=1e-5)
        np.testing.assert_allclose(s.reward, 0.01 + weight * 0.1, rtol=1e-5)
        assert mjzoo.reward_terms(s).keys() == {"x", "v"}
    assert len(traces) == 1  # three weights, one trace


# --- with_divergence_guard ------------------------------------------------------------------


def _finite(*trees) -> bool:
    return all(bool(jnp.all(jnp.isfinite(leaf))) for t in trees for leaf in jax.tree.leaves(t))


def test_divergence_guard_nan():
    # Push 1, then 10 (> nan_above = 5: qvel becomes NaN), then 1 again.
    task = mjzoo.with_divergence_guard(make_task(nan_above=5.0))
    _, s = episode(task, 1.0, 10.0, 1.0)
    assert _finite(s.obs, s.reward, s.metrics, s.data.qpos, s.data.qvel)
    np.testing.assert_array_equal(s.metrics["diverged"], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(s.terminated, [False, True, False])
    np.testing.assert_array_equal(s.truncated, [False, False, False])
    # The diverged transition returns the previous state (after step 1) with no reward.
    np.testing.assert_allclose(s.data.qpos[:, 0], [0.01, 0.01, 0.03], rtol=1e-5)
    np.testing.assert_allclose(s.data.qvel[:, 0], [0.1, 0.1, 0.2], rtol=1e-5)
    np.testing.assert_allclose(s.obs[1], [0.01, 0.1], rtol=1e-5)
    np.testing.assert_allclose(s.reward, [0.01, 0.0, 0.03], rtol=1e-5)
    np.testing.assert_array_equal(s.metrics["reward/x"][1], 0.0)
    # Its physics state is the previous one; the derived quantities are zeroed, not NaN.
    before, after = jax.tree.map(lambda x: x[0], s.data), jax.tree.map(lambda x: x[1], s.data)
    for field in mjzoo.combinators.INTEGRATION_STATE:
        if hasattr(after, field):
            chex.assert_trees_all_close(getattr(after, field), getattr(before, field))
    assert _finite(after)
    np.testing.assert_array_equal(after.qacc, 0.0)


def test_divergence_guard_is_transparent_when_finite():
    plain, guarded = make_task(), mjzoo.with_divergence_guard(make_task())
    _, a = episode(plain, 1.0, -2.0, 0.5)
    _, b = episode(guarded, 1.0, -2.0, 0.5)
    # (qpos after the second push is 0.01 + 0.1 * (0.1 - 0.2) = 0: compare with an atol.)
    chex.assert_trees_all_close(b.data, a.data, atol=1e-6)
    chex.assert_trees_all_close(
        (b.obs, b.reward, b.terminated, b.truncated), (a.obs, a.reward, a.terminated, a.truncated), atol=1e-6
    )
    np.testing.assert_array_equal(b.metrics["diverged"], [0.0, 0.0, 0.0])


def test_divergence_guard_qvel_explosion():
    # No NaN, but |qvel| = dt * F = 0.1 * 2e4 = 2e3 > max_qvel = 1e3 after the second push;
    # the first push gives 0.1 * 5e3 = 500 <= 1e3 and is kept.
    task = mjzoo.with_divergence_guard(make_task(), max_qvel=1e3)
    _, s = episode(task, 5e3, 1.5e4, -5e3)
    np.testing.assert_array_equal(s.metrics["diverged"], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(s.terminated, [False, True, False])
    np.testing.assert_allclose(s.data.qvel[:, 0], [500.0, 500.0, 0.0], rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(s.data.qpos[:, 0], [50.0, 50.0, 50.0], rtol=1e-5)
    np.testing.assert_allclose(s.reward, [50.0, 0.0, 50.0], rtol=1e-5)
    # max_qvel is a leaf: a looser guard keeps the same transition.
    _, loose = episode(mjzoo.with_divergence_guard(make_task(), max_qvel=1e4), 5e3, 1.5e4)
    np.testing.assert_array_equal(loose.metrics["diverged"], [0.0, 0.0])
    np.testing.assert_allclose(loose.data.qvel[:, 0], [500.0, 2000.0], rtol=1e-5)


def _counting(step_fn, model, state, action, key):
    next_state = step_fn(model, state, action, key)
    return next_state.replace(metrics={**next_state.metrics, "count": jnp.int32(1)})


def test_divergence_guard_keeps_an_integer_metric_an_integer():
    """A count in metrics (goals reached, say) stays int32: a float would change the type of
    a rollout's carry, which a scan refuses. Traced only."""
    inner = make_task()
    task = mjzoo.with_divergence_guard(inner.replace(step=Partial(_counting, inner.step)))
    state = jax.eval_shape(task.reset, task.model, KEY)
    state = state.replace(metrics={**state.metrics, "count": jax.ShapeDtypeStruct((), jnp.int32)})
    after = jax.eval_shape(lambda s: mjzoo.transition(task, s, jnp.ones(1), KEY), state)
    assert after.metrics["count"].dtype == jnp.int32


@pytest.mark.parametrize("max_qvel", [0.0, -1.0, float("nan")])
def test_divergence_guard_invalid_max_qvel(max_qvel):
    with pytest.raises(ValueError, match="max_qvel"):
        mjzoo.with_divergence_guard(make_task(), max_qvel=max_qvel)


# --- with_observation_noise -----------------------------------------------------------------

N_KEYS = 4000


@jax.jit
def reset_and_step(task: Task, keys: jax.Array):
    """For each key: reset, then one 1 N push; returns (reset states, next states)."""

    def one(key):
        reset_key, step_key = jax.random.split(key)
        state = mjzoo.reset(task, reset_key)
        return state, mjzoo.transition(task, state, jnp.array([1.0]), step_key)

    return jax.vmap(one)(keys)


KEYS = jax.random.split(jax.random.key(1), N_KEYS)


def test_observation_noise_statistics():
    scale = 0.1
    start, next_ = reset_and_step(mjzoo.with_observation_noise(make_task(), scale), KEYS)
    # The clean observations are known exactly: [0, 0] after the reset, [0.01, 0.1] after.
    noise = np.concatenate([np.asarray(start.obs), np.asarray(next_.obs) - np.array([0.01, 0.1])])
    assert noise.shape == (2 * N_KEYS, 2)
    # std of the sample std for n = 8000 is about 0.1 / sqrt(2n) = 8e-4: 5% is > 6 sigma.
    np.testing.assert_allclose(noise.std(axis=0), [scale, scale], rtol=0.05)
    np.testing.assert_allclose(noise.mean(axis=0), [0.0, 0.0], atol=0.01)  # 0.1/sqrt(8000) = 1e-3
    # Independent across leaves' entries and across reset / step.
    assert abs(np.corrcoef(noise[:, 0], noise[:, 1])[0, 1]) < 0.06
    assert abs(np.corrcoef(np.asarray(start.obs)[:, 0], np.asarray(next_.obs)[:, 0])[0, 1]) < 0.06
    # Different keys give different noise.
    assert len(np.unique(np.asarray(start.obs)[:, 0])) > N_KEYS * 0.99
    # The physics never sees it.
    np.testing.assert_allclose(next_.data.qpos[:, 0], 0.01, rtol=1e-5)
    np.testing.assert_allclose(next_.data.qvel[:, 0], 0.1, rtol=1e-5)
    np.testing.assert_allclose(next_.reward, 0.01, rtol=1e-5)


def test_observation_noise_scale_zero_is_identity():
    clean = reset_and_step(make_task(), KEYS)
    quiet = reset_and_step(mjzoo.with_observation_noise(make_task(), 0.0), KEYS)
    chex.assert_trees_all_close(quiet[0].obs, clean[0].obs)
    chex.assert_trees_all_close(quiet[1].obs, clean[1].obs)


def test_observation_noise_keeps_the_physics_of_the_same_key():
    # With a random reset, the noisy task must start the same episode as the clean task
    # for the same key and only add noise on top: same data, obs off by noise only.
    task = make_task(spawn=0.5)
    clean = reset_and_step(task, KEYS)
    noisy = reset_and_step(mjzoo.with_observation_noise(task, 0.0), KEYS)
    chex.assert_trees_all_close(noisy[0].data.qpos, clean[0].data.qpos)
    chex.assert_trees_all_close(noisy[1].data.qpos, clean[1].data.qpos)
    chex.assert_trees_all_close(noisy[1].obs, clean[1].obs)


def test_observation_noise_invalid_scale():
    with pytest.raises(ValueError, match="scale"):
        mjzoo.with_observation_noise(make_task(), -0.1)


# --- with_action_noise ----------------------------------------------------------------------


def test_action_noise_changes_the_physics():
    # qvel after one step = dt * (1 + eps) / m, eps ~ N(0, 0.5^2): mean 0.1, std 0.05.
    _, next_ = reset_and_step(mjzoo.with_action_noise(make_task(), 0.5), KEYS)
    qvel = np.asarray(next_.data.qvel[:, 0])
    np.testing.assert_allclose(qvel.std(), 0.05, rtol=0.05)
    np.testing.assert_allclose(qvel.mean(), 0.1, atol=0.005)
    # The commanded action is reported as taken: obs follow the noisy physics.
    np.testing.assert_allclose(next_.obs[:, 1], qvel)


def test_action_noise_scale_zero_is_identity():
    clean = reset_and_step(make_task(), KEYS)
    quiet = reset_and_step(mjzoo.with_action_noise(make_task(), 0.0), KEYS)
    chex.assert_trees_all_close(quiet[1].data, clean[1].data)
    chex.assert_trees_all_close((quiet[1].obs, quiet[1].reward), (clean[1].obs, clean[1].reward))


def test_action_noise_invalid_scale():
    with pytest.raises(ValueError, match="scale"):
        mjzoo.with_action_noise(make_task(), float("nan"))


# --- with_domain_randomization ------------------------------------------------------------


def random_mass(model, key):
    """The block's mass uniform in [1, 4) kg (body 0 is the world)."""
    return {"body_mass": model.body_mass.at[1].set(jax.random.uniform(key, minval=1.0, maxval=4.0))}


def test_domain_randomization_draws_and_uses_new_masses():
    task = mjzoo.with_domain_randomization(make_task(), random_mass)
    start, next_ = reset_and_step(task, KEYS)
    masses = np.asarray(mjzoo.find(start, DomainRandomizationState).fields["body_mass"])
    assert masses.shape == (N_KEYS, 2)
    np.testing.assert_array_equal(masses[:, 0], 0.0)  # the world keeps its mass
    assert np.all((masses[:, 1] >= 1.0) & (masses[:, 1] < 4.0))
    assert len(np.unique(masses[:, 1])) > 0.99 * N_KEYS  # different keys, different masses
    # The episode keeps its draw, and the step uses it: qvel = dt * F / m = 0.1 / m.
    np.testing.assert_array_equal(mjzoo.find(next_, DomainRandomizationState).fields["body_mass"], masses)
    np.testing.assert_allclose(next_.data.qvel[:, 0], 0.1 / masses[:, 1], rtol=1e-5)
    np.testing.assert_allclose(next_.data.qpos[:, 0], 0.01 / masses[:, 1], rtol=1e-5)
    # Heavier accelerates less (ties only between masses closer than float32 resolves).
    order = np.argsort(masses[:, 1])
    qvel = np.asarray(next_.data.qvel[order, 0])
    assert np.all(np.diff(qvel) <= 0) and qvel[0] > 3.5 * qvel[-1]


def test_domain_randomization_redraws_on_auto_reset():
    task = mjzoo.with_auto_reset(mjzoo.with_time_limit(mjzoo.with_domain_randomization(make_task(), random_mass), 2))
    start, s = episode(task, *[1.0] * 4)
    m = np.asarray(mjzoo.find(s, DomainRandomizationState).fields["body_mass"][:, 1])
    m0 = float(mjzoo.find(start, DomainRandomizationState).fields["body_mass"][1])
    # Episode 1 = steps 1, 2 (mass m0); the state after step 2 already holds episode 2's draw.
    assert m[0] == m0 and m[1] != m0 and m[2] == m[1] and m[3] != m[2]
    np.testing.assert_allclose(s.data.qvel[0, 0], 0.1 / m0, rtol=1e-5)
    np.testing.assert_allclose(s.data.qvel[2, 0], 0.1 / m[1], rtol=1e-5)


def test_domain_randomization_unknown_field():
    def bad(model, key):
        return {"body_weight": model.body_mass}

    with pytest.raises(KeyError, match="body_weight"):
        mjzoo.with_domain_randomization(make_task(), bad)


def test_domain_randomization_wrong_shape():
    def bad(model, key):
        return {"body_mass": jnp.ones(3)}

    with pytest.raises(ValueError, match="body_mass"):
        mjzoo.with_domain_randomization(make_task(), bad)


def test_domain_randomization_not_a_dict_or_not_callable():
    with pytest.raises(TypeError):
        mjzoo.with_domain_randomization(make_task(), lambda model, key: model.body_mass)
    with pytest.raises(TypeError):
        mjzoo.with_domain_randomization(make_task(), {"body_mass": 1.0})


# --- nested stacks: structure, rollout under jit ---------------------------------------------


def stack(task: Task, max_steps: int = 4) -> Task:
    return mjzoo.with_auto_reset(
        mjzoo.with_action_repeat(mjzoo.with_time_limit(mjzoo.with_divergence_guard(task), max_steps), 2)
    )


STACKS = {
    "auto_reset(repeat(time_limit(guard)))": lambda: stack(make_task()),
    "time_limit(auto_reset(guard(noise)))": lambda: mjzoo.with_time_limit(
        mjzoo.with_auto_reset(mjzoo.with_divergence_guard(mjzoo.with_observation_noise(make_task(), 0.1))), 5
    ),
    "auto_reset(time_limit(dr(action_noise)))": lambda: mjzoo.with_auto_reset(
        mjzoo.with_time_limit(
            mjzoo.with_domain_randomization(mjzoo.with_action_noise(make_task(), 0.1), random_mass), 3
        )
    ),
    "guard(repeat)": lambda: mjzoo.with_divergence_guard(mjzoo.with_action_repeat(make_task(), 2)),
    "guard(repeat(auto_reset(time_limit)))": lambda: mjzoo.with_divergence_guard(
        mjzoo.with_action_repeat(mjzoo.with_auto_reset(mjzoo.with_time_limit(make_task(), 3)), 3)
    ),
}


@pytest.mark.parametrize("name", list(STACKS))
def test_reset_state_has_the_structure_of_a_transition(name):
    task = STACKS[name]()
    # Abstract evaluation only: no compile.
    start = jax.eval_shape(mjzoo.reset, task, KEY)
    after = jax.eval_shape(lambda s: mjzoo.transition(task, s, jnp.ones((1,)), KEY), start)
    after2 = jax.eval_shape(lambda s: mjzoo.transition(task, s, jnp.ones((1,)), KEY), after)
    assert jax.tree.structure(start) == jax.tree.structure(after), (
        jax.tree.structure(start),
        jax.tree.structure(after),
    )
    assert [(l.shape, l.dtype) for l in jax.tree.leaves(start)] == [(l.shape, l.dtype) for l in jax.tree.leaves(after)]
    assert jax.tree.structure(after2) == jax.tree.structure(after)
    # Scalars where the State contract says so.
    assert (start.reward.shape, start.reward.dtype) == ((), jnp.float32)
    assert (start.terminated.shape, start.terminated.dtype) == ((), jnp.bool_)
    assert (start.truncated.shape, start.truncated.dtype) == ((), jnp.bool_)


@pytest.mark.parametrize("name", list(STACKS))
def test_a_tasks_own_reset_is_its_start_completed(name):
    """The Task contract: ``task.reset(model, key)``, then a scan of transitions. `start`
    alone lacks what only transitions write (the reward terms' metrics)."""
    task = STACKS[name]()
    own = jax.eval_shape(task.reset, task.model, KEY)
    after = jax.eval_shape(lambda s: mjzoo.transition(task, s, jnp.ones((1,)), KEY), own)
    assert jax.tree.structure(own) == jax.tree.structure(after)
    assert jax.tree.structure(own) == jax.tree.structure(jax.eval_shape(mjzoo.reset, task, KEY))
    assert "reward/x" not in jax.eval_shape(task.start, task.model, KEY).metrics


def test_a_scan_from_the_tasks_own_reset_runs():
    task = stack(make_task())
    _, states = run(task, task.reset(task.model, KEY), pushes(1.0, 2.0), KEY)
    assert states.reward.shape == (2,) and np.isfinite(states.reward).all()


@pytest.mark.parametrize("action", [jnp.ones((2,)), jnp.ones(()), jnp.ones((1, 1))])
def test_an_action_of_the_wrong_shape_is_named(action):
    task = make_task()
    with pytest.raises(ValueError, match=re.escape(f"action has shape {action.shape}, but the task takes (1,)")):
        mjzoo.transition(task, mjzoo.reset(task, KEY), action, KEY)


def test_reset_of_a_stack_starts_at_zero():
    s = reset(stack(make_task()), KEY)
    assert float(s.reward) == 0.0 and not bool(s.terminated) and not bool(s.truncated)
    assert int(mjzoo.find(s, TimeLimitState).steps) == 0
    assert float(s.metrics["diverged"]) == 0.0 and float(s.metrics["reward/x"]) == 0.0
    np.testing.assert_array_equal(mjzoo.find(s, AutoResetState).final_obs, np.zeros(2))


def constant(action, obs, key):
    return action


@jax.jit
@chex.assert_max_traces(n=1)  # every stack(...) below shares this one trace
def rollout6(task: Task, state: State, key: jax.Array, action: jax.Array):
    policy = jax.tree_util.Partial(constant, action)
    return mjzoo.rollout(task, policy, state, key, 6)


def test_rollout_of_a_stack_under_jit():
    # Each outer step = 2 inner steps; the inner limit of 4 steps ends an episode every
    # 2 outer steps: rewards 0.01 + 0.03 = 0.04, then 0.06 + 0.10 = 0.16, then again.
    task = stack(make_task())
    final, traj = rollout6(task, reset(task, KEY), KEY, jnp.array([1.0]))
    chex.assert_shape(traj.action, (6, 1))
    chex.assert_shape(traj.obs, (6, 2))
    np.testing.assert_allclose(traj.next_state.reward, [0.04, 0.16] * 3, rtol=1e-5)
    np.testing.assert_array_equal(traj.next_state.truncated, [False, True] * 3)
    assert not traj.next_state.terminated.any()
    np.testing.assert_array_equal(mjzoo.find(traj.next_state, TimeLimitState).steps, [2, 0] * 3)
    # obs each action was chosen from: reset, after 2 inner steps, reset, ...
    np.testing.assert_allclose(traj.obs, [[0.0, 0.0], [0.03, 0.2]] * 3, rtol=1e-5)
    np.testing.assert_allclose(
        mjzoo.find(traj.next_state, AutoResetState).final_obs[1::2], [[0.10, 0.4]] * 3, rtol=1e-5
    )
    chex.assert_trees_all_equal_structs(final, reset(task, KEY))


def test_rollout_of_a_stack_with_a_time_limit_inside_a_repeat():
    # Inner limit 3 with repeat 2: outer step 2 holds inner step 3 only; the episode ends
    # inside the repeat, whose second half must not run (final_obs after inner step 3).
    task = stack(make_task(), max_steps=3)
    _, traj = rollout6(task, reset(task, KEY), KEY, jnp.array([1.0]))
    np.testing.assert_allclose(traj.next_state.reward, [0.01 + 0.03, 0.06] * 3, rtol=1e-5)
    np.testing.assert_array_equal(traj.next_state.truncated, [False, True] * 3)
    assert not traj.next_state.terminated.any()
    np.testing.assert_allclose(
        mjzoo.find(traj.next_state, AutoResetState).final_obs[1::2], [[0.06, 0.3]] * 3, rtol=1e-5
    )
    np.testing.assert_array_equal(mjzoo.find(traj.next_state, TimeLimitState).steps, [2, 0] * 3)


def test_rollout_of_a_diverging_stack_stays_finite():
    # Same structure (nan_above is a leaf): no new compile. Every push of 10 N > 5 N makes
    # NaN; the guard ends each episode at once, nothing non-finite escapes.
    task = stack(make_task(nan_above=5.0))
    final, traj = rollout6(task, reset(task, KEY), KEY, jnp.array([10.0]))
    assert _finite(
        traj.obs, traj.next_state.obs, traj.next_state.reward, traj.next_state.metrics, final.data.qpos, final.data.qvel
    )
    np.testing.assert_array_equal(traj.next_state.terminated, [True] * 6)
    np.testing.assert_array_equal(traj.next_state.reward, [0.0] * 6)
    np.testing.assert_array_equal(traj.next_state.metrics["diverged"], [1.0] * 6)


def test_rollout_does_not_retrace():
    # rollout6 is wrapped in chex.assert_max_traces(n=1): thresholds, time limits and
    # actions are leaves, so none of these (nor the rollouts above) may retrace it.
    for threshold, max_steps, force in [(NEVER, 4, 1.0), (0.05, 7, 2.0), (1.0, 2, -1.0)]:
        task = stack(make_task(threshold=threshold), max_steps)
        _, traj = rollout6(task, reset(task, KEY), KEY, jnp.array([force]))
        assert traj.next_state.reward.shape == (6,)
    # threshold 0.05 with 2 N: inner qpos 0.02, 0.06 > 0.05 terminates in the first step.
    task = stack(make_task(threshold=0.05), 7)
    _, traj = rollout6(task, reset(task, KEY), KEY, jnp.array([2.0]))
    np.testing.assert_allclose(traj.next_state.reward[0], 0.02 + 0.06, rtol=1e-5)
    np.testing.assert_array_equal(traj.next_state.terminated, [True] * 6)


# --- with_observation -----------------------------------------------------------------------


def negated_velocity(obs):
    return -obs[1:]


def test_with_observation_transforms_what_is_seen_but_not_the_physics():
    plain = make_task()
    seen = mjzoo.with_observation(plain, negated_velocity)
    _, a = episode(plain, 1.0, 1.0)
    _, b = episode(seen, 1.0, 1.0)
    np.testing.assert_allclose(b.obs, -a.obs[:, 1:])
    np.testing.assert_allclose(mjzoo.find(b, ObservationState).obs, a.obs)  # the inner task's own
    chex.assert_trees_all_close(b.data.qpos, a.data.qpos)
    with pytest.raises(TypeError, match="fn must be callable"):
        mjzoo.with_observation(plain, 3)


@pytest.mark.parametrize("key", [0, jnp.zeros(3), jax.random.split(KEY)])
def test_reset_names_a_key_that_is_not_one_prng_key(key):
    with pytest.raises(TypeError, match=r"mjzoo.reset: key must be one JAX PRNG key such as jax.random.key\(0\)"):
        mjzoo.reset(make_task(), key)


def test_rollout_names_a_bad_step_count():
    task = make_task()
    with pytest.raises(ValueError, match=r"num_steps=2.5 must be an integer >= 1"):
        mjzoo.rollout(task, lambda obs, key: jnp.zeros(1), mjzoo.reset(task, KEY), KEY, 2.5)
