"""DIAL-MPC and CMA-ES against hand-computed numbers and a numpy reference, converging on
quadratics (pure JAX, no physics), then on the point mass: one jit per `plan` (no
retrace), a vmapped sweep of their numbers. Their closed loops on the pendulum are in
tests/algorithms/test_planners.py, beside the other planners'."""

from __future__ import annotations

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
from mjzoo.algorithms import cma_es
from mjzoo.algorithms import dial

# --- DIAL: the schedule and the weights, by hand -----------------------------------------


def test_dial_noise_schedule_hand_computed():
    # sigma_0 exp(-j / (beta_1 N) - (K-1-k) / (beta_2 (K-1))), N = 2, K = 3, beta_1 = 1, beta_2 = 2.
    got = dial.noise_schedule(0.5, 1.0, 2.0, iterations=2, num_knots=3)
    e = math.exp
    expected = [
        [0.5 * e(-1 / 2), 0.5 * e(-1 / 4), 0.5],  # j = 0: only the horizon's annealing
        [0.5 * e(-1 / 2 - 1 / 2), 0.5 * e(-1 / 2 - 1 / 4), 0.5 * e(-1 / 2)],  # j = 1: x exp(-1/2)
    ]
    np.testing.assert_allclose(got, expected, rtol=1e-6)
    # One knot: no horizon to anneal along; one iteration: sigma_0.
    np.testing.assert_allclose(dial.noise_schedule(0.3, 1.0, 1.0, iterations=1, num_knots=1), [[0.3]], rtol=1e-6)


def test_dial_weights_are_in_units_of_the_cost_spread():
    costs = jnp.array([0.0, 1.0, 2.0])  # std sqrt(2/3): lambda std = 1 / ln 2 gives 1 : 1/2 : 1/4
    temperature = 1 / (math.log(2) * math.sqrt(2 / 3))
    np.testing.assert_allclose(dial.normalized_weights(costs, temperature), [4 / 7, 2 / 7, 1 / 7], rtol=1e-5)
    # Scale-free: the same weights for costs 100x larger and shifted; an infinite cost gets 0.
    np.testing.assert_allclose(dial.normalized_weights(100 * costs + 7, temperature), [4 / 7, 2 / 7, 1 / 7], rtol=1e-4)
    with_inf = dial.normalized_weights(jnp.array([0.0, 1.0, 2.0, jnp.inf]), temperature)
    np.testing.assert_allclose(with_inf, [4 / 7, 2 / 7, 1 / 7, 0.0], rtol=1e-5)
    np.testing.assert_allclose(dial.normalized_weights(jnp.ones(4), 0.1), np.full(4, 0.25), rtol=1e-6)


def _quadratic(target):
    return lambda samples, key: (jnp.sum(jnp.square(samples - target), axis=(1, 2)), jnp.float32(0))


def test_dial_one_iteration_is_the_weighted_mean_of_its_samples():
    target = jnp.array([[0.5, -0.2], [0.1, 0.3]])
    knots, std, key = jnp.zeros((2, 2)), jnp.full((1, 2, 2), 0.4), jax.random.key(0)
    mean, cost, _ = dial.anneal(_quadratic(target), knots, std, -1.0, 1.0, 16, 0.5, key)
    # By hand: the samples `anneal` draws (its key split), costed and weighted.
    sample_key, _ = jax.random.split(jax.random.split(key, 1)[0])
    samples = np.asarray(planning.sample_knots(sample_key, knots, std[0], 16, -1.0, 1.0))
    costs = np.sum((samples - np.asarray(target)) ** 2, axis=(1, 2))
    logits = -(costs - costs.min()) / (0.5 * costs.std())
    weights = np.exp(logits) / np.exp(logits).sum()
    np.testing.assert_allclose(mean, np.tensordot(weights, samples, axes=1), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(cost, weights @ costs, rtol=1e-5)


def test_dial_converges_on_a_quadratic_and_annealing_refines_it():
    target = jnp.array([[0.6, -0.4], [0.2, 0.7], [-0.5, 0.1]])
    errors = {}
    for iterations in (1, 8):
        stds = dial.noise_schedule(0.5, 0.5, 1.0, iterations, 3)[:, :, None] * jnp.ones(2)
        run = jax.jit(
            lambda key, s=stds: dial.anneal(_quadratic(target), jnp.zeros((3, 2)), s, -1.0, 1.0, 32, 0.1, key)
        )
        errors[iterations] = np.mean([float(jnp.abs(run(jax.random.key(s))[0] - target).max()) for s in range(4)])
    assert errors[8] < 0.1 and errors[8] < 0.5 * errors[1], errors


# --- CMA-ES: one update against numpy, and convergence --------------------------------------


def _numpy_update(samples, costs, mean, sigma, cov, ps, pc, g, lam, mu):
    """Hansen's tutorial, written out in float64 numpy."""
    n = mean.size
    w = np.array([np.log((lam + 1) / 2 / i) for i in range(1, mu + 1)])
    w, mueff = w / w.sum(), w.sum() ** 2 / np.sum(w**2)
    cs, c1 = (mueff + 2) / (n + mueff + 5), 2 / ((n + 1.3) ** 2 + mueff)
    ds, cc = 1 + cs + 2 * max(0, np.sqrt((mueff - 1) / (n + 1)) - 1), (4 + mueff / n) / (n + 4 + 2 * mueff / n)
    cmu, chin = (
        min(1 - c1, 2 * (mueff - 2 + 1 / mueff) / ((n + 2) ** 2 + mueff)),
        np.sqrt(n) * (1 - 1 / (4 * n) + 1 / (21 * n**2)),
    )
    ys = (samples[np.argsort(costs)[:mu]] - mean) / sigma
    yw = w @ ys
    vals, vecs = np.linalg.eigh(cov)
    ps = (1 - cs) * ps + np.sqrt(cs * (2 - cs) * mueff) * (vecs @ np.diag(vals**-0.5) @ vecs.T @ yw)
    hs = np.linalg.norm(ps) / np.sqrt(1 - (1 - cs) ** (2 * (g + 1))) < (1.4 + 2 / (n + 1)) * chin
    pc = (1 - cc) * pc + hs * np.sqrt(cc * (2 - cc) * mueff) * yw
    cov = (1 - c1 - cmu + (1 - hs) * c1 * cc * (2 - cc)) * cov + c1 * np.outer(pc, pc) + cmu * (ys.T * w) @ ys
    return mean + sigma * yw, sigma * np.exp(cs / ds * (np.linalg.norm(ps) / chin - 1)), cov, ps, pc


@pytest.mark.parametrize("generation", [0, 5])
def test_cma_update_matches_a_numpy_reference_on_a_quadratic(generation):
    rng = np.random.default_rng(generation)
    dim, lam, mu = 3, 6, 3
    a = rng.normal(size=(dim, dim))
    cov = a @ a.T / dim + np.eye(dim)  # not the identity: C^{-1/2} matters
    mean, sigma = rng.normal(size=dim), 0.7
    ps, pc = rng.normal(size=dim) * 0.5, rng.normal(size=dim) * 0.5
    samples = mean + sigma * rng.normal(size=(lam, dim)) @ np.linalg.cholesky(cov).T
    costs = np.sum(samples**2, axis=1)  # the quadratic |x|^2
    expected = _numpy_update(samples, costs, mean, sigma, cov, ps, pc, generation, lam, mu)
    c = cma_es.constants(dim, lam, mu)
    args = [jnp.asarray(v, jnp.float32) for v in (samples, costs, mean, sigma, cov, ps, pc, generation)]
    got = jax.jit(cma_es.update, static_argnums=0)(c, *args)
    for name, g, e in zip(["mean", "sigma", "cov", "path_sigma", "path_c"], got, expected):
        np.testing.assert_allclose(g, e, rtol=2e-4, atol=2e-5, err_msg=name)
    # The best sample moves the mean towards it: the quadratic's value falls.
    assert np.sum(np.asarray(got[0]) ** 2) < np.sum(mean**2)


def test_cma_es_converges_on_an_ill_conditioned_quadratic():
    """f(x) = sum_i 10^(2 i / (D-1)) (x_i - t_i)^2, D = 6: 100x between its axes, which
    the covariance learns; the step size shrinks as the search closes in."""
    dim, lam = 6, 12
    scales = jnp.asarray(10.0 ** (2 * np.arange(dim) / (dim - 1)), jnp.float32)
    target = jnp.linspace(-0.5, 0.5, dim)
    c = cma_es.constants(dim, lam, lam // 2)
    low, high = jnp.full(dim, -2.0), jnp.full(dim, 2.0)

    def generation(carry, key):
        mean, sigma, cov, ps, pc, g = carry
        x = cma_es.sample(key, mean, sigma, cov, lam, low, high)
        costs = jnp.sum(scales * jnp.square(x - target), axis=1)
        return (*cma_es.update(c, x, costs, mean, sigma, cov, ps, pc, g), g + 1), None

    zeros = jnp.zeros(dim)
    start = (zeros, jnp.float32(0.5), jnp.eye(dim), zeros, zeros, jnp.float32(0))
    (mean, sigma, cov, *_), _ = jax.jit(lambda k: jax.lax.scan(generation, start, jax.random.split(k, 150)))(
        jax.random.key(0)
    )
    np.testing.assert_allclose(mean, target, atol=1e-3)
    assert float(sigma) < 0.05
    variances = np.diag(np.asarray(cov))
    assert variances[0] > 10 * variances[-1], variances  # wider along the flat axis


# --- on the point mass: one jit per plan, sweeps ---------------------------------------------

H, K = 5, 3
CONFIGS = {
    dial: dial.Config(num_samples=8, horizon_steps=H, num_knots=K, iterations=2),
    cma_es: cma_es.Config(num_samples=8, horizon_steps=H, num_knots=K, iterations=2),
}
SWEEPS = {
    dial: ("temperature", [0.01, 0.1, 1.0, 10.0]),
    cma_es: ("noise_scale", [0.05, 0.2, 0.5, 1.0]),
}
NAMES = lambda m: m.__name__.rsplit(".", 1)[-1]  # noqa: E731


@functools.cache
def _task():
    return envs.make("point_mass", iterations=1, ls_iterations=1)


@functools.cache
def _jitted_plan(planner):
    return jax.jit(chex.assert_max_traces(planner.plan, n=1), static_argnums=0)


@pytest.mark.parametrize("planner", list(CONFIGS), ids=NAMES)
def test_plan_is_one_jit_within_limits_warm_started(planner):
    config, task = CONFIGS[planner], _task()
    low, high = planning.control_limits(task)
    states = [mjzoo.reset(task, jax.random.key(s)) for s in (0, 1)]
    state = jax.device_put(planner.init(config, task))
    costs = []
    for env_state, seed in [(states[0], 10), (states[1], 11), (states[0], 12)]:
        args = jax.device_put((task, state, env_state, jax.random.key(seed)))
        state, controls = _jitted_plan(planner)(config, *args)
        chex.assert_shape(controls, (H, 2))
        assert np.all((np.asarray(controls) >= low) & (np.asarray(controls) <= high))
        np.testing.assert_allclose(controls, planning.controls(config, state.knots, low, high), rtol=1e-6)
        np.testing.assert_allclose(state.dt, 0.02, rtol=1e-5)
        costs.append(float(state.cost))
    assert np.all(np.isfinite(costs))
    if planner is cma_es:  # generations carried over replans: 3 replans x 2
        assert float(state.generation) == 6 and float(state.sigma) != 0.3


@pytest.mark.parametrize("planner", list(SWEEPS), ids=NAMES)
def test_a_vmapped_sweep_is_one_program_with_each_members_own_plan(planner):
    field, values = SWEEPS[planner]
    config, task = CONFIGS[planner], _task()
    env_state, key = mjzoo.reset(task, jax.random.key(0)), jax.random.key(1)

    def replan(hyperparams):
        return planner.plan(config, task, planner.init(config, task, hyperparams), env_state, key)[1]

    chex.clear_trace_counter()  # each parametrized case counts its own traces
    members = [planner.Hyperparams(**{field: v}) for v in values]
    batch = jax.tree.map(lambda *x: jnp.stack(x), *members)
    together = jax.jit(jax.vmap(replan))(batch)
    chex.assert_shape(together, (len(values), H, 2))
    alone_fn = jax.jit(chex.assert_max_traces(replan, n=1))
    alone = np.stack([alone_fn(jax.tree.map(jnp.asarray, m)) for m in members])
    np.testing.assert_allclose(together, alone, rtol=1e-4, atol=1e-5)
    assert len({a.tobytes() for a in alone}) == len(values), "the swept field changed nothing"


def test_configs_and_hyperparams_name_a_bad_field():
    with pytest.raises(ValueError, match=r"dial\.Config: iterations=0"):
        dial.Config(iterations=0)
    with pytest.raises(ValueError, match=r"beta_horizon"):
        dial.Hyperparams(beta_horizon=0.0)
    with pytest.raises(ValueError, match=r"cma_es\.Config: num_elites=9"):
        cma_es.Config(num_samples=8, num_elites=9)
    with pytest.raises(ValueError, match=r"sigma_max"):
        cma_es.Hyperparams(sigma_min=0.5, sigma_max=0.1)
    with pytest.raises(ValueError, match=r"cma_es\.Hyperparams: noise_ramp=1\.0 is invalid; expected 0"):
        cma_es.Hyperparams(noise_ramp=1.0)  # its covariance shapes the noise along the horizon
    assert cma_es.Config(num_samples=10).parents == 5


def test_every_env_planning_setup_configures_both():
    for name in ("pendulum_swingup", "cartpole_swingup", "point_mass", "cylinder_push"):
        for planner in (dial, cma_es):
            config, hyperparams = planning.configure(planner, envs.hyperparameters(name, NAMES(planner)))
            assert isinstance(config, planner.Config) and isinstance(hyperparams, planner.Hyperparams)
