"""`mjzoo.planning`, the pieces of the sampling planners, against hand-computed numbers
(MPPI weights, the CEM step, risk measures, knot sampling, receding-horizon shift,
spline controls, initial state, config validation), then on the point-mass task:
rollout costs against an explicit `mjzoo.rollout`, ensembles, and one jitted replan of
each planner (`predictive_sampling`, `cem`, `mppi`) with no retracing.

MJX compiles are slow on the CPU, so every physics function is jitted once per module
(`functools.cache`) and called with one config per planner and one batch shape."""

from __future__ import annotations

import copy
import functools
import math

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
from mjzoo.catalog import randomizers
from mjzoo.planning import PlannerState
from mjzoo.planning import splines

# --- helpers --------------------------------------------------------------------------------

H, K, NU = 5, 3, 2  # planning horizon, knots, point-mass controls
ROLLOUTS = 2  # control sequences per `rollout_costs` call: one batch shape, one compile
CONFIGS = {
    predictive_sampling: predictive_sampling.Config(num_samples=8, horizon_steps=H, num_knots=K),
    cem: cem.Config(num_samples=8, horizon_steps=H, num_knots=K, num_elites=2),
    mppi: mppi.Config(num_samples=8, horizon_steps=H, num_knots=K),
}


@functools.cache
def _task():
    # One solver iteration and one line-search step: a third less compile time, and the
    # tests compare the planners with the same task's own rollouts.
    return envs.make("point_mass", iterations=1, ls_iterations=1)


@functools.cache
def _env_state(seed: int):
    return mjzoo.reset(_task(), jax.random.key(seed))


def _committed(*trees):
    """Arguments placed on the device: jit compiles again when an argument changes from
    uncommitted (fresh from an eager op) to committed (a jit output)."""
    return jax.device_put(trees, jax.devices()[0])


@functools.cache
def _jitted_rollout_costs():
    return jax.jit(planning.rollout_costs)


def _rollout_costs(task, state, controls, key=None):
    key = jax.random.key(0) if key is None else key
    return _jitted_rollout_costs()(*_committed(task, state, jnp.asarray(controls, jnp.float32), key))


@functools.cache
def _jitted_rollout():
    return jax.jit(mjzoo.rollout, static_argnums=4)


@functools.cache
def _jitted_plan(planner):
    # At most one trace per planner in this whole module: every call below shares it.
    return jax.jit(chex.assert_max_traces(planner.plan, n=1), static_argnums=0)


def _plan(planner, planner_state, env_state, key):
    return _jitted_plan(planner)(CONFIGS[planner], *_committed(_task(), planner_state, env_state, key))


def _line_state(time=1.0, dt=0.25, knots=((0.0,), (2.0,), (4.0,))) -> PlannerState:
    """The line y = s as a plan with K = 3 knots at steps [0, 2, 4] (H = 5); times and
    dt are exact in binary, so elapsed steps are exact."""
    knots = jnp.asarray(knots, jnp.float32)
    f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    return PlannerState(knots, jnp.ones_like(knots), f32(time), f32(dt), f32(0.0))


LINEAR = predictive_sampling.Config(horizon_steps=H, num_knots=K, interpolation="linear")


# --- mppi_weights -------------------------------------------------------------------------


@pytest.mark.parametrize("temperature", [0.1, 2.0])
def test_mppi_weights_hand_computed(temperature):
    # exp(-0) : exp(-ln 2) = 1 : 1/2  ->  [2/3, 1/3].
    weights = planning.mppi_weights(jnp.array([0.0, math.log(2) * temperature]), temperature)
    np.testing.assert_allclose(weights, [2 / 3, 1 / 3], rtol=1e-6)
    # Three samples: 1 : 1/2 : 1/4  ->  [4/7, 2/7, 1/7].
    costs = jnp.array([0.0, 1.0, 2.0]) * math.log(2) * temperature
    np.testing.assert_allclose(planning.mppi_weights(costs, temperature), [4 / 7, 2 / 7, 1 / 7], rtol=1e-6)


def test_mppi_weights_give_infinite_costs_weight_zero():
    np.testing.assert_allclose(planning.mppi_weights(jnp.array([1.0, jnp.inf, 1.0]), 0.5), [0.5, 0.0, 0.5])


def test_mppi_weights_are_invariant_to_a_constant_and_do_not_underflow():
    costs = jnp.array([0.0, math.log(2) * 0.5, 30.0])
    base = planning.mppi_weights(costs, 0.5)
    np.testing.assert_allclose(base, [2 / 3, 1 / 3, 0.0], rtol=1e-5, atol=1e-12)
    # exp(-1000 / 0.5) underflows to 0 in float32 without the minimum subtracted.
    # (1000 + c is rounded to float32's 6e-5 steps at 1000: hence rtol 1e-3.)
    shifted = planning.mppi_weights(costs + 1000.0, 0.5)
    np.testing.assert_allclose(shifted, base, rtol=1e-3, atol=1e-12)
    np.testing.assert_allclose(planning.mppi_weights(costs - 7.0, 0.5), base, rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(float(jnp.sum(shifted)), 1.0, rtol=1e-6)


def test_mppi_weights_under_jit_with_traced_temperature_and_vmap():
    costs = jnp.array([0.0, math.log(2)])
    np.testing.assert_allclose(jax.jit(planning.mppi_weights)(costs, jnp.float32(1.0)), [2 / 3, 1 / 3], rtol=1e-6)
    # Temperatures 1 and ln 2 / ln 3: ratios 1/2 and 1/3.
    temps = jnp.array([1.0, math.log(2) / math.log(3)])
    per_temperature = jax.vmap(planning.mppi_weights, (None, 0))(costs, temps)
    np.testing.assert_allclose(per_temperature, [[2 / 3, 1 / 3], [3 / 4, 1 / 4]], rtol=1e-5)
    per_batch = jax.vmap(planning.mppi_weights, (0, None))(jnp.stack([costs, costs[::-1]]), 1.0)
    np.testing.assert_allclose(per_batch, [[2 / 3, 1 / 3], [1 / 3, 2 / 3]], rtol=1e-6)


# --- cem_update ---------------------------------------------------------------------------


def test_cem_update_hand_computed_elites():
    # Costs [3, 1, 2, 0]: the 2 elites are samples 3 (value 10) and 1 (value 1).
    # mean 5.5, population std |10 - 1| / 2 = 4.5.
    samples = jnp.array([[0.0], [1.0], [2.0], [10.0]])
    costs = jnp.array([3.0, 1.0, 2.0, 0.0])
    mean, std = planning.cem_update(samples, costs, 2, 0.0, 100.0)
    np.testing.assert_allclose(mean, [5.5], rtol=1e-6)
    np.testing.assert_allclose(std, [4.5], rtol=1e-6)
    # Three elites (10, 1, 2): mean 13/3, std sqrt(((10-13/3)^2 + (1-13/3)^2 + (2-13/3)^2)/3).
    mean, std = planning.cem_update(samples, costs, 3, 0.0, 100.0)
    np.testing.assert_allclose(mean, [13 / 3], rtol=1e-6)
    np.testing.assert_allclose(std, [np.std([10.0, 1.0, 2.0])], rtol=1e-6)


def test_cem_update_clips_std_per_element():
    # [N=3, K=2, nu=1] plans; elites = samples 0 and 2 (costs 0 and 1).
    # Knot 0 elites [1, 1]: std 0 -> sigma_min 0.2. Knot 1 elites [-4, 4]: std 4 -> sigma_max.
    samples = jnp.array([[[1.0], [-4.0]], [[9.0], [9.0]], [[1.0], [4.0]]])
    costs = jnp.array([0.0, 5.0, 1.0])
    sigma_min = jnp.array([[0.2], [0.2]])
    sigma_max = jnp.array([[1.0], [3.0]])
    mean, std = planning.cem_update(samples, costs, 2, sigma_min, sigma_max)
    chex.assert_shape([mean, std], (2, 1))
    np.testing.assert_allclose(mean, [[1.0], [0.0]])
    np.testing.assert_allclose(std, [[0.2], [3.0]])


def test_cem_update_under_jit_and_vmap():
    samples = jnp.array([[0.0], [1.0], [2.0], [10.0]])
    costs = jnp.array([3.0, 1.0, 2.0, 0.0])
    update = jax.jit(planning.cem_update, static_argnums=2)
    np.testing.assert_allclose(update(samples, costs, 2, 0.0, 3.0)[1], [3.0])  # 4.5 clipped to 3
    # A batch of problems: reversed costs [0, 2, 1, 3] pick samples 0 and 2 (values 0, 2).
    means, stds = jax.vmap(planning.cem_update, (None, 0, None, None, None))(
        samples, jnp.stack([costs, costs[::-1]]), 2, 0.0, 100.0
    )
    np.testing.assert_allclose(means[:, 0], [5.5, 1.0], rtol=1e-6)
    np.testing.assert_allclose(stds[:, 0], [4.5, 1.0], rtol=1e-6)


# --- aggregate ----------------------------------------------------------------------------

# [M=4 models, N=2 samples]
COSTS = np.array([[1.0, 10.0], [4.0, 20.0], [2.0, 40.0], [3.0, 30.0]], np.float32)


@pytest.mark.parametrize(
    "risk,alpha,expected",
    [
        ("mean", 0.25, [2.5, 25.0]),
        ("worst", 0.25, [4.0, 40.0]),
        ("cvar", 0.5, [3.5, 35.0]),  # mean of the 2 largest: (4 + 3)/2, (40 + 30)/2
        ("cvar", 0.25, [4.0, 40.0]),  # ceil(0.25 * 4) = 1: the worst
        ("cvar", 0.3, [3.5, 35.0]),  # ceil(1.2) = 2
        ("cvar", 0.01, [4.0, 40.0]),  # at least one model
        ("cvar", 1.0, [2.5, 25.0]),
    ],  # every model: the mean
)
def test_aggregate_hand_computed(risk, alpha, expected):
    np.testing.assert_allclose(planning.aggregate(jnp.asarray(COSTS), risk, alpha), expected, rtol=1e-6)
    jitted = jax.jit(planning.aggregate, static_argnums=(1, 2))(jnp.asarray(COSTS), risk, alpha)
    np.testing.assert_allclose(jitted, expected, rtol=1e-6)


def test_aggregate_one_model_is_that_model():
    for risk in planning.RISKS:
        np.testing.assert_allclose(planning.aggregate(jnp.asarray(COSTS[:1]), risk, 0.5), COSTS[0])


def test_aggregate_vmaps_over_batches_of_cost_tables():
    batch = jnp.stack([jnp.asarray(COSTS), -jnp.asarray(COSTS)])
    out = jax.vmap(lambda c: planning.aggregate(c, "cvar", 0.5))(batch)
    np.testing.assert_allclose(out, [[3.5, 35.0], [-1.5, -15.0]], rtol=1e-6)  # (-1 - 2)/2, (-10 - 20)/2


def test_aggregate_cvar_tail_size_is_exact_for_decimal_alpha():
    # BUG (library): the tail is ceil(alpha * M) in floating point, and 0.28 * 25 =
    # 7.000000000000001, so CVaR at alpha = 0.28 over 25 models averages the worst 8
    # rather than the worst 7 (= 28% of 25). Costs 0..24: worst 7 are 18..24, mean 21.
    costs = jnp.arange(25.0)[:, None]
    np.testing.assert_allclose(planning.aggregate(costs, "cvar", 0.28), [21.0], rtol=1e-6)


def test_aggregate_rejects_an_unknown_risk():
    with pytest.raises(ValueError, match=r"unknown risk 'median'.*mean.*worst.*cvar"):
        planning.aggregate(jnp.asarray(COSTS), "median")


# --- sample_knots -------------------------------------------------------------------------

MEAN = jnp.array([[0.0, 0.25], [0.5, -0.5]])  # [K=2, nu=2]
STD = jnp.array([[0.1, 0.2], [0.3, 0.4]])
LOW, HIGH = jnp.array([-1.0, -1.0]), jnp.array([1.0, 0.5])


def test_sample_knots_keeps_the_mean_first_and_perturbs_the_rest():
    key = jax.random.key(3)
    samples = planning.sample_knots(key, MEAN, STD, 6, LOW, HIGH)
    chex.assert_shape(samples, (6, 2, 2))
    np.testing.assert_array_equal(samples[0], MEAN)
    eps = jax.random.normal(key, (6, 2, 2))
    np.testing.assert_allclose(samples[1:], jnp.clip(MEAN + STD * eps[1:], LOW, HIGH), rtol=1e-6)
    assert not np.any(np.all(np.asarray(samples[1:]) == np.asarray(MEAN), axis=(1, 2)))
    without = planning.sample_knots(key, MEAN, STD, 6, LOW, HIGH, include_mean=False)
    np.testing.assert_allclose(without, jnp.clip(MEAN + STD * eps, LOW, HIGH), rtol=1e-6)


def test_sample_knots_clips_to_the_limits_per_actuator():
    samples = np.asarray(planning.sample_knots(jax.random.key(0), MEAN, 100 * STD, 64, LOW, HIGH))
    assert samples.min(axis=(0, 1)).tolist() == [-1.0, -1.0]
    assert samples.max(axis=(0, 1)).tolist() == [1.0, 0.5]
    np.testing.assert_array_equal(samples[0], MEAN)  # the mean survives any std


def test_sample_knots_takes_a_std_per_sample_under_jit():
    # CEM's explore samples: one [N, K, nu] std; zero std reproduces the mean.
    stds = jnp.stack([STD, jnp.zeros_like(STD), STD])
    sample = jax.jit(planning.sample_knots, static_argnums=(3, 6))
    out = sample(jax.random.key(1), MEAN, stds, 3, LOW, HIGH, True)
    chex.assert_shape(out, (3, 2, 2))
    np.testing.assert_array_equal(out[:2], jnp.stack([MEAN, MEAN]))
    assert not np.allclose(out[2], MEAN)


# --- controls, control_at, shift ----------------------------------------------------------


def test_controls_shape_and_values():
    knots = jax.random.normal(jax.random.key(0), (4, K, NU))  # [N, K, nu]
    out = planning.controls(CONFIGS[predictive_sampling], knots)
    chex.assert_shape(out, (4, H, NU))
    positions, steps = splines.knot_positions(K, H), jnp.arange(H, dtype=jnp.float32)
    for n in range(4):
        np.testing.assert_allclose(out[n], splines.interpolate(knots[n], positions, steps, "cubic"), rtol=1e-6)
    chex.assert_shape(planning.controls(LINEAR, knots[0]), (H, NU))  # one plan [K, nu]
    chex.assert_shape(planning.controls(LINEAR, jnp.stack([knots, knots])), (2, 4, H, NU))  # [B, N, K, nu]
    # The line y = s at knot steps [0, 2, 4]: the controls are the steps themselves.
    np.testing.assert_allclose(planning.controls(LINEAR, _line_state().knots)[:, 0], [0, 1, 2, 3, 4])


def test_controls_of_knots_within_limits_stay_within_limits():
    # A cubic spline overshoots: knots [-1, 1, 1] at steps [0, 2, 4] have Catmull-Rom
    # tangents [1, 0.5, 0] per step; on [2, 4] the Hermite piece at step 3 is
    # 1/2*1 + 1/8*(0.5*2) + 1/2*1 = 1.125 > 1, so `controls` clips to the limits.
    knots = jnp.array([[-1.0, -1.0], [1.0, 1.0], [1.0, -1.0]])
    low, high = planning.control_limits(_task())
    unclipped = np.asarray(planning.controls(CONFIGS[predictive_sampling], knots))
    assert unclipped[:, 0].max() > 1.1  # the overshoot the clip removes
    out = np.asarray(planning.controls(CONFIGS[predictive_sampling], knots, low, high))
    assert np.all((out >= low) & (out <= high)), f"controls {out[:, 0]} leave [{low[0]}, {high[0]}]"


def test_control_at_reads_the_plan_in_environment_time():
    state = _line_state(time=1.0, dt=0.25)  # step s at time 1 + 0.25 s
    times = jnp.array([1.0, 1.125, 1.25, 1.5, 2.0, 9.0, 0.0])
    expected = [0.0, 0.5, 1.0, 2.0, 4.0, 4.0, 0.0]  # held at both ends
    for t, e in zip(times, expected):
        np.testing.assert_allclose(planning.control_at(LINEAR, state, t), [e], rtol=1e-6)
    vmapped = jax.jit(jax.vmap(functools.partial(planning.control_at, LINEAR), (None, 0)))(state, times)
    np.testing.assert_allclose(vmapped[:, 0], expected, rtol=1e-6)
    # Before the first replan dt = 0: the first knot, whatever the time.
    np.testing.assert_allclose(planning.control_at(LINEAR, _line_state(dt=0.0), 1.5), [0.0])


def test_shift_by_one_step_reads_the_old_plan_one_step_ahead():
    # Knots at steps [0, 2, 4] move to [1, 3, 5]: y = [1, 3, 4], the last knot held.
    shifted = planning.shift(LINEAR, _line_state(time=1.0, dt=0.25), jnp.float32(1.25))
    np.testing.assert_allclose(shifted.knots[:, 0], [1.0, 3.0, 4.0], rtol=1e-6)
    assert float(shifted.time) == 1.25
    chex.assert_trees_all_equal(shifted.std, _line_state().std)
    # By one knot spacing (2 steps) the new plan is the old one two steps later, held.
    shifted = planning.shift(LINEAR, _line_state(time=1.0, dt=0.25), jnp.float32(1.5))
    np.testing.assert_allclose(planning.controls(LINEAR, shifted.knots)[:, 0], [2, 3, 4, 4, 4], rtol=1e-6)
    # Past the whole horizon: every knot is the old last knot.
    shifted = planning.shift(LINEAR, _line_state(time=1.0, dt=0.25), jnp.float32(10.0))
    np.testing.assert_allclose(shifted.knots[:, 0], [4.0, 4.0, 4.0])


@pytest.mark.parametrize("method", splines.METHODS)
def test_shift_with_a_knot_per_step_drops_the_first_control(method):
    # K = H: knots at every step, so a one-step shift is exactly the old controls one
    # step later, the last one held past the horizon, for every interpolation.
    config = predictive_sampling.Config(horizon_steps=H, num_knots=H, interpolation=method)
    knots = jax.random.normal(jax.random.key(5), (H, NU))
    state = PlannerState(knots, jnp.ones_like(knots), jnp.float32(0.5), jnp.float32(0.25), jnp.float32(0.0))
    old = planning.controls(config, knots)
    new = planning.controls(config, jax.jit(planning.shift, static_argnums=0)(config, state, jnp.float32(0.75)).knots)
    np.testing.assert_allclose(new, jnp.concatenate([old[1:], old[-1:]]), rtol=1e-6, atol=1e-6)


def test_shift_without_a_measured_dt_or_backwards_in_time_keeps_the_knots():
    for state, now in [(_line_state(dt=0.0), 3.0), (_line_state(time=1.0), 0.5)]:
        shifted = planning.shift(LINEAR, state, jnp.float32(now))
        np.testing.assert_array_equal(shifted.knots, state.knots)
        assert float(shifted.time) == now


# --- initial_state ------------------------------------------------------------------------


def test_initial_state_on_point_mass():
    config = predictive_sampling.Config(horizon_steps=H, num_knots=K)
    state = planning.initial_state(config, _task(), predictive_sampling.Hyperparams(noise_scale=0.3))
    chex.assert_shape([state.knots, state.std], (K, NU))
    np.testing.assert_array_equal(state.knots, np.zeros((K, NU)))
    np.testing.assert_allclose(state.std, 0.3, rtol=1e-6)  # ctrlrange [-1, 1]: half range 1
    assert float(state.time) == 0.0 and float(state.dt) == 0.0 and float(state.cost) == np.inf
    chex.assert_type([state.knots, state.std, state.time, state.dt, state.cost], jnp.float32)
    # The hyperparameters are kept as float32 [] leaves: a sweep vmaps over them.
    chex.assert_trees_all_equal(state.hyperparams, predictive_sampling.Hyperparams(noise_scale=jnp.float32(0.3)))
    chex.assert_type(jax.tree.leaves(state.hyperparams), jnp.float32)
    warm = jnp.full((K, NU), 0.5)
    np.testing.assert_array_equal(planning.initial_state(config, _task(), knots=warm).knots, warm)


def test_initial_state_std_is_noise_scale_times_half_range():
    # Actuator 0 unlimited (unit 1), actuator 1 in [0.5, 1.5] (half range 0.5): the
    # zero plan is clipped into the limits, to 0.5 for actuator 1.
    mj_model = copy.copy(_task().mj_model)
    mj_model.actuator_ctrllimited[0] = 0
    mj_model.actuator_ctrlrange[1] = [0.5, 1.5]
    task = _task().replace(mj_model=mj_model)
    low, high = planning.control_limits(task)
    np.testing.assert_array_equal(low, [-np.inf, 0.5])
    np.testing.assert_array_equal(high, [np.inf, 1.5])
    np.testing.assert_array_equal(planning.half_range(task), [1.0, 0.5])
    state = cem.init(cem.Config(horizon_steps=H, num_knots=K), task, cem.Hyperparams(noise_scale=0.4))
    np.testing.assert_allclose(state.std, np.broadcast_to([0.4, 0.2], (K, NU)), rtol=1e-6)
    np.testing.assert_array_equal(state.knots, np.broadcast_to([0.0, 0.5], (K, NU)))


def test_noise_ramp_profile_hand_computed_under_jit_and_vmap():
    # 1 + r k / (K - 1): K = 4 knots, r = 3 -> [1, 2, 3, 4]; r = 0 is flat; one knot is 1.
    profile = jax.jit(planning.noise_ramp_profile, static_argnums=1)
    np.testing.assert_allclose(profile(3.0, 4), [1.0, 2.0, 3.0, 4.0], rtol=1e-6)
    np.testing.assert_allclose(profile(0.0, 4), np.ones(4))
    np.testing.assert_allclose(profile(5.0, 1), [1.0])
    swept = jax.vmap(lambda r: planning.noise_ramp_profile(r, 3))(jnp.array([0.0, 1.0, 4.0]))
    np.testing.assert_allclose(swept, [[1.0, 1.0, 1.0], [1.0, 1.5, 2.0], [1.0, 3.0, 5.0]], rtol=1e-6)


def test_noise_std_grows_along_the_horizon_by_the_ramp_per_actuator():
    # Half ranges [1, 0.5]: knot k's std is noise_scale (1 + r k / 2) x half range.
    mj_model = copy.copy(_task().mj_model)
    mj_model.actuator_ctrlrange[1] = [0.5, 1.5]
    task = _task().replace(mj_model=mj_model)
    std = jax.jit(lambda scale, ramp: planning.noise_std(scale, task, (K, NU), ramp))(0.2, 2.0)
    np.testing.assert_allclose(std, [[0.2, 0.1], [0.4, 0.2], [0.6, 0.3]], rtol=1e-6)
    np.testing.assert_allclose(planning.noise_std(0.2, task, (K, NU)), [[0.2, 0.1]] * K, rtol=1e-6)


@pytest.mark.parametrize("planner", [predictive_sampling, mppi, cem])
def test_plans_sample_with_the_ramped_noise(planner, monkeypatch):
    # Each planner draws its samples with std noise_scale (1 + r k / (K - 1)) = 0.05 x
    # [1, 3, 5] (CEM: its initial fit, 0.05, widened by the ramp; sigma_min is 0.05).
    seen = []
    draw = planning.sampling.sample_knots

    def recording(key, mean, std, *args, **kwargs):
        jax.debug.callback(lambda s: seen.append(np.asarray(s)), std)
        return draw(key, mean, std, *args, **kwargs)

    monkeypatch.setattr(planning.sampling, "sample_knots", recording)
    state = planner.init(CONFIGS[planner], _task(), planner.Hyperparams(noise_scale=0.05, noise_ramp=4.0))
    jax.jit(planner.plan, static_argnums=0)(CONFIGS[planner], _task(), state, _env_state(0), jax.random.key(1))
    std = np.broadcast_to(seen[-1], (CONFIGS[planner].num_samples, K, NU))
    np.testing.assert_allclose(std, np.broadcast_to([[0.05], [0.15], [0.25]], std.shape), rtol=1e-6)


def test_initial_state_rejects_warm_start_knots_of_the_wrong_shape():
    config = predictive_sampling.Config(horizon_steps=H, num_knots=K)
    with pytest.raises(ValueError, match=r"warm-start knots must have shape \(3, 2\).*got \(2, 3\)"):
        planning.initial_state(config, _task(), knots=jnp.zeros((2, 3)))
    with pytest.raises(ValueError, match="warm-start knots"):
        mppi.init(CONFIGS[mppi], _task(), knots=jnp.zeros((K,)))


def test_init_refuses_another_planners_hyperparams_or_knots_in_their_place():
    with pytest.raises(TypeError, match=r"mppi.init: hyperparams must be a Hyperparams.*cem.Hyperparams"):
        mppi.init(CONFIGS[mppi], _task(), cem.Hyperparams())
    with pytest.raises(TypeError, match="warm-start knots go by knots="):
        cem.init(CONFIGS[cem], _task(), jnp.zeros((K, NU)))


# --- Config validation --------------------------------------------------------------------


@pytest.mark.parametrize(
    "module,kwargs,field",
    [
        (cem, dict(num_samples=8, num_elites=9), "num_elites"),
        (cem, dict(num_elites=0), "num_elites"),
        (predictive_sampling, dict(interpolation="quadratic"), "interpolation"),
        (mppi, dict(risk="median"), "risk"),
        (predictive_sampling, dict(num_samples=1), "num_samples"),
        (predictive_sampling, dict(horizon_steps=0), "horizon_steps"),
        (mppi, dict(horizon_steps=5, num_knots=6), "num_knots"),
        (cem, dict(num_knots=0), "num_knots"),
        (predictive_sampling, dict(unroll=0), "unroll"),
    ],
)
def test_config_rejects_out_of_range_values_naming_the_field(module, kwargs, field):
    name = module.__name__.rsplit(".", 1)[-1]
    with pytest.raises(ValueError, match=rf"^{name}\.Config: {field}=\S+ is invalid; expected "):
        module.Config(**kwargs)


HYPERPARAMS_OUT_OF_RANGE = [
    (mppi, dict(temperature=0.0), "temperature"),
    (mppi, dict(temperature=-1.0), "temperature"),
    (cem, dict(sigma_min=0.5, sigma_max=0.1), "sigma_max"),
    (cem, dict(sigma_min=-0.1), "sigma_min"),
    (cem, dict(explore_fraction=1.0), "explore_fraction"),
    (cem, dict(cvar_alpha=0.0), "cvar_alpha"),
    (predictive_sampling, dict(cvar_alpha=1.5), "cvar_alpha"),
    (mppi, dict(noise_scale=-0.1), "noise_scale"),
    (predictive_sampling, dict(noise_ramp=-1.0), "noise_ramp"),
]


@pytest.mark.parametrize("module,kwargs,field", HYPERPARAMS_OUT_OF_RANGE)
def test_hyperparams_reject_out_of_range_values_naming_the_field(module, kwargs, field):
    name = module.__name__.rsplit(".", 1)[-1]
    with pytest.raises(ValueError, match=rf"^{name}\.Hyperparams: {field}=\S+ is invalid; expected "):
        module.Hyperparams(**kwargs)
    # A batch for a sweep is checked elementwise; traced values are not checked.
    batch = {k: np.array([v, v]) for k, v in kwargs.items()}
    with pytest.raises(ValueError, match=rf"{field}=\[.*\] is invalid; expected "):
        module.Hyperparams(**batch)
    jax.jit(lambda values: jax.tree.leaves(module.Hyperparams(**values)))(batch)


def test_hyperparams_refuse_a_string_or_a_bool_naming_the_field():
    with pytest.raises(ValueError, match=r"^mppi\.Hyperparams: temperature='hot' is invalid; expected a number"):
        mppi.Hyperparams(temperature="hot")
    with pytest.raises(ValueError, match=r"^cem\.Hyperparams: sigma_min=True is invalid; expected a number"):
        cem.Hyperparams(sigma_min=True)


def test_configs_are_hashable_static_arguments():
    for module, config in CONFIGS.items():
        assert hash(config) == hash(module.Config(**{f: getattr(config, f) for f in config.__dataclass_fields__}))


# --- configure: one flat dict of fields -> (Config, Hyperparams) -------------------------


def test_configure_splits_a_flat_dict_into_structure_and_numbers():
    fields = {"num_samples": 64, "horizon_steps": 1e1, "temperature": 1, "noise_scale": 0.2, "risk": "worst"}
    config, hyperparams = planning.configure(mppi, fields)
    assert config == mppi.Config(num_samples=64, horizon_steps=10, risk="worst")
    assert hyperparams == mppi.Hyperparams(temperature=1.0, noise_scale=0.2)
    assert type(config.horizon_steps) is int and type(hyperparams.temperature) is float
    config, hyperparams = planning.configure(cem, {"num_elites": 4, "sigma_min": 0.2})
    assert (config.num_elites, hyperparams.sigma_min) == (4, 0.2)
    assert planning.configure(predictive_sampling, {}) == (
        predictive_sampling.Config(),
        predictive_sampling.Hyperparams(),
    )
    # Arrays pass through as they are: a batch of hyperparameters for a sweep.
    temps = np.array([0.1, 0.2])
    assert planning.configure(mppi, {"temperature": temps})[1].temperature is temps


@pytest.mark.parametrize(
    "module,fields,message",
    [
        (
            mppi,
            {"temprature": 0.1},
            r"^mppi: unknown field\(s\) \['temprature'\] \(did you mean 'temperature'\?\); fields: .*'temperature'",
        ),
        (cem, {"temperature": 0.1}, r"^cem: unknown field\(s\) \['temperature'\]"),
        (mppi, {"num_samples": "many"}, r"^mppi: num_samples='many' is invalid; expected an int"),
        (mppi, {"num_samples": 1.5}, r"num_samples=1.5 is invalid; expected an int"),
        (mppi, {"num_samples": True}, r"num_samples=True is invalid; expected an int"),
        (mppi, {"temperature": "hot"}, r"^mppi: temperature='hot' is invalid; expected a number"),
        (mppi, {"interpolation": 3}, r"interpolation=3 is invalid; expected a string"),
        (mppi, {"temperature": 0.0}, r"^mppi\.Hyperparams: temperature=0.0 is invalid; expected > 0"),
        (cem, {"num_elites": 0}, r"^cem\.Config: num_elites=0 is invalid; expected in \[1, num_samples = 128\]"),
    ],
)
def test_configure_names_an_unknown_field_or_a_bad_value(module, fields, message):
    with pytest.raises(ValueError, match=message):
        planning.configure(module, fields)


def test_every_env_planning_setup_configures():
    for name in ("pendulum_swingup", "cartpole_swingup", "point_mass", "cylinder_push"):
        for module in CONFIGS:
            planning.configure(module, envs.hyperparameters(name, module.__name__.rsplit(".", 1)[-1]))


# --- rollout_costs on point_mass ----------------------------------------------------------


def _open_loop(controls, policy_keys, obs, key):
    """The control of the step whose policy key `key` is: `rollout` hands its policy only
    (obs, key), with key = split(split(rollout_key, T)[t])[0]. NaN if no key matches, so a
    change in how `rollout` derives keys fails loudly."""
    match = jnp.all(jax.random.key_data(policy_keys) == jax.random.key_data(key), axis=-1)
    return jnp.where(jnp.any(match), controls[jnp.argmax(match)], jnp.nan)


def _random_controls(seed):
    return jax.random.uniform(jax.random.key(seed), (ROLLOUTS, H, NU), minval=-1.0, maxval=1.0)


def test_rollout_costs_equal_minus_the_return_of_an_explicit_rollout():
    task, state = _task(), _env_state(0)
    controls = _random_controls(1)
    costs, dt = _rollout_costs(task, state, controls, jax.random.key(2))
    chex.assert_shape(costs, (1, ROLLOUTS))
    # The task's control step ctrl_dt = 0.02 s, measured from the rollouts' data.time.
    np.testing.assert_allclose(dt, 0.02, rtol=1e-5)
    rollout_key = jax.random.key(9)
    policy_keys = jax.vmap(lambda k: jax.random.split(k)[0])(jax.random.split(rollout_key, H))
    for n in range(ROLLOUTS):
        policy = jax.tree_util.Partial(_open_loop, controls[n], policy_keys)
        _, trajectory = _jitted_rollout()(*_committed(task, policy, state, rollout_key), H)
        np.testing.assert_array_equal(trajectory.action, controls[n])
        np.testing.assert_allclose(costs[0, n], -jnp.sum(trajectory.next_state.reward), atol=1e-5)
        np.testing.assert_allclose(trajectory.next_state.data.time[-1] - state.data.time, H * 0.02, rtol=1e-5)
    assert costs[0, 0] != costs[0, 1]


def test_rollout_costs_over_an_ensemble_are_per_model():
    task, state = _task(), _env_state(0)
    controls = _random_controls(3)
    ensemble = planning.ensemble(task, randomizers.scale_masses(task.mj_model, 0.5, 2.0), 3, jax.random.key(4))
    chex.assert_shape(ensemble.fields["body_mass"], (3, task.mj_model.nbody))
    costs, dt = _rollout_costs(ensemble, state, controls)
    chex.assert_shape(costs, (3, ROLLOUTS))
    np.testing.assert_allclose(dt, 0.02, rtol=1e-5)
    # Row m is the plain task with model m's masses (same batch shape: no new compile).
    for m in range(3):
        model = task.model.replace(**{k: v[m] for k, v in ensemble.fields.items()})
        expected, _ = _rollout_costs(task.replace(model=model), state, controls)
        np.testing.assert_allclose(costs[m], expected[0], rtol=1e-5, atol=1e-6)
    assert len(set(np.asarray(costs[:, 0]).tolist())) == 3  # different masses, different costs
    # A zero-width randomization is the nominal model in every row.
    nominal = planning.ensemble(task, randomizers.scale_masses(task.mj_model, 1.0, 1.0), 3, jax.random.key(4))
    plain, _ = _rollout_costs(task, state, controls)
    np.testing.assert_allclose(_rollout_costs(nominal, state, controls)[0], jnp.tile(plain, (3, 1)), rtol=1e-6)


# --- one replan of each planner -----------------------------------------------------------


@pytest.mark.parametrize("planner", list(CONFIGS), ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_plan_returns_controls_within_limits_and_does_not_retrace(planner):
    config, task = CONFIGS[planner], _task()
    low, high = planning.control_limits(task)
    first, second = _env_state(0), _env_state(1)
    assert not np.allclose(first.data.qpos, second.data.qpos)
    state = planner.init(config, task)
    for env_state, seed in [(first, 10), (second, 11), (first, 12)]:  # traced once: assert_max_traces(n=1)
        state, controls = _plan(planner, state, env_state, jax.random.key(seed))
        chex.assert_shape(controls, (H, NU))
        assert np.all((np.asarray(controls) >= low) & (np.asarray(controls) <= high)), controls
        chex.assert_shape([state.knots, state.std], (K, NU))
        np.testing.assert_allclose(state.dt, 0.02, rtol=1e-5)
        assert float(state.time) == float(env_state.data.time)
        assert np.isfinite(float(state.cost))
        np.testing.assert_allclose(controls, planning.controls(config, state.knots), rtol=1e-6)


def test_predictive_sampling_never_returns_a_plan_worse_than_its_nominal():
    # Two replans from the same state: the shift is the identity (no time passes), so the
    # nominal of the second is the first's plan, kept as sample 0.
    task, env_state = _task(), _env_state(2)
    state = predictive_sampling.init(CONFIGS[predictive_sampling], task)
    first, first_controls = _plan(predictive_sampling, state, env_state, jax.random.key(20))
    second, second_controls = _plan(predictive_sampling, first, env_state, jax.random.key(21))
    zero = jnp.zeros((H, NU))
    costs_first, _ = _rollout_costs(task, env_state, jnp.stack([zero, first_controls]))
    costs_second, _ = _rollout_costs(task, env_state, jnp.stack([first_controls, second_controls]))
    # The state's cost is the chosen plan's rollout cost (point_mass ignores step keys).
    np.testing.assert_allclose(first.cost, costs_first[0, 1], atol=1e-6)
    np.testing.assert_allclose(second.cost, costs_second[0, 1], atol=1e-6)
    assert costs_first[0, 1] <= costs_first[0, 0]  # the zero plan was the first nominal
    assert costs_second[0, 1] <= costs_second[0, 0]
