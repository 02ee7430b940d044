"""iLQR against a Riccati solution computed here (a linear system with a quadratic cost:
one iteration is the LQR optimum), its cost falling monotonically on the pendulum, the
pendulum swung up closed loop, and the contract: a sweep of its numbers is one program,
and the native backend is refused by name."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
from mjzoo import envs
from mjzoo import planning
from mjzoo.algorithms import ilqr
from mjzoo.envs import pendulum
from mjzoo.planning import realtime

OPTIMIZED = {"xla_backend_optimization_level": 3}  # a closed-loop run: as tests/algorithms/test_planners.py

# --- a linear-quadratic problem, by hand --------------------------------------------------

H_LQ, DT, MASS, GEAR = 8, 0.05, 2.0, 3.0
Q, R = np.diag([4.0, 0.5]), 0.1
SLIDER = f"""
<mujoco>
  <option timestep="{DT}" gravity="0 0 0" integrator="Euler"/>
  <worldbody>
    <body><joint name="x" type="slide" axis="1 0 0"/><geom type="sphere" size="0.1" mass="{MASS}"/></body>
  </worldbody>
  <actuator><motor joint="x" gear="{GEAR}"/></actuator>
</mujoco>
"""


def _quadratic(p, model, state, action, next_state):
    """x' Q x' + R u^2 of the state after the step, x = (position, velocity)."""
    x = jnp.concatenate([next_state.data.qpos, next_state.data.qvel])
    return x @ jnp.asarray(Q, jnp.float32) @ x + R * jnp.sum(jnp.square(action))


def _slider_start(p, model, data, key):
    return data.replace(qpos=data.qpos.at[0].set(0.5), qvel=data.qvel.at[0].set(-0.2))


def _riccati(x0: np.ndarray) -> tuple[np.ndarray, float]:
    """([H] the optimal controls, the optimal cost) of x_{t+1} = A x_t + B u_t with cost
    sum_t x_{t+1}' Q x_{t+1} + R u_t^2: semi-implicit Euler, v' = v + h g u / m, q' = q + h v'."""
    h, b = DT, GEAR / MASS
    a_mat = np.array([[1.0, h], [0.0, 1.0]])
    b_mat = np.array([[h * h * b], [h * b]])
    p_mat, gains = Q, []  # the cost-to-go of x_H is x_H' Q x_H: x_H is a step's result
    for t in reversed(range(H_LQ)):
        k = np.linalg.solve(R + b_mat.T @ p_mat @ b_mat, b_mat.T @ p_mat @ a_mat)
        gains.append(k)
        p_mat = (Q if t > 0 else 0 * Q) + a_mat.T @ p_mat @ (a_mat - b_mat @ k)
    x, controls, cost = x0, [], 0.0
    for k in reversed(gains):
        u = -(k @ x)
        x = a_mat @ x + b_mat @ u
        controls.append(u[0])
        cost += x @ Q @ x + R * u[0] ** 2
    return np.array(controls), cost


def test_one_iteration_on_a_linear_quadratic_problem_is_the_riccati_solution():
    task = mjzoo.task(SLIDER, costs={"quadratic": (_quadratic, 1.0)}, start=_slider_start, ctrl_dt=DT)
    config = ilqr.Config(horizon_steps=H_LQ, iterations=1, line_search_steps=1)
    hyperparams = ilqr.Hyperparams(regularization=0.0, regularization_min=0.0)
    env_state = mjzoo.reset(task, jax.random.key(0))
    state, controls = jax.jit(ilqr.plan, static_argnums=0)(
        config, task, ilqr.init(config, task, hyperparams), env_state, jax.random.key(1)
    )
    expected, optimum = _riccati(np.array([0.5, -0.2]))
    np.testing.assert_allclose(controls[:, 0], expected, rtol=2e-3, atol=1e-4)
    np.testing.assert_allclose(state.cost, optimum, rtol=1e-3)
    assert float(state.iterations) == 1 and float(state.costs[0]) > float(state.costs[1])


# --- the pendulum: cost falls, the closed loop swings up ----------------------------------


@functools.cache
def _pendulum():
    return pendulum.precise_upright(envs.make("pendulum_swingup"))


SWING = ilqr.Config(horizon_steps=30, iterations=6)
PLAN = jax.jit(ilqr.plan, static_argnums=0)  # one compile for the descent and the sweep's members


def _swinging():
    """The pendulum hanging, pushed at 2 rad/s."""
    env_state = mjzoo.reset(_pendulum(), jax.random.key(0))
    return env_state.replace(data=env_state.data.replace(qvel=env_state.data.qvel.at[0].set(2.0)))


def test_cost_falls_monotonically_on_the_pendulum():
    task = _pendulum()
    state, controls = PLAN(SWING, task, ilqr.init(SWING, task), _swinging(), jax.random.key(1))
    costs = np.asarray(state.costs)
    print("costs per iteration", costs, "mu", float(state.regularization))
    assert np.all(np.isfinite(costs)) and np.all(np.diff(costs) <= 0), costs
    assert costs[-1] < costs[0] - 0.1 * abs(costs[0]), costs  # a real decrease, not a stall
    low, high = planning.control_limits(task)
    assert np.all((np.asarray(controls) >= low) & (np.asarray(controls) <= high))


def test_a_vmapped_sweep_is_one_program_with_each_members_own_plan():
    task, env_state, key = _pendulum(), _swinging(), jax.random.key(1)
    members = [ilqr.Hyperparams(step_decay=d, regularization=r) for d, r in [(0.5, 1e-3), (0.1, 1.0), (0.9, 10.0)]]
    states = [ilqr.init(SWING, task, m) for m in members]
    swept = jax.jit(jax.vmap(ilqr.plan, in_axes=(None, None, 0, None, None)), static_argnums=0)
    together = swept(SWING, task, jax.tree.map(lambda *x: jnp.stack(x), *states), env_state, key)[1]
    alone = np.stack([PLAN(SWING, task, s, env_state, key)[1] for s in states])
    np.testing.assert_allclose(together, alone, rtol=1e-4, atol=1e-5)
    assert len({a.tobytes() for a in alone}) == len(members), "the swept numbers changed nothing"


def test_linearizing_steps_in_groups_gives_the_same_derivatives():
    """`linearize` vmaps every step at once, or runs groups of them in turn (one at a time
    is the CPU's default: it keeps jaxlib's batched solves from hanging): the same numbers."""
    task, env_state = _pendulum(), _swinging()
    horizon = 5
    controls = jnp.linspace(-1.0, 1.0, horizon)[:, None]
    keys = jax.random.split(jax.random.key(2), horizon)
    low, high = planning.control_limits(task)
    no_gains, no_reference = jnp.zeros((horizon, 1, 2)), jnp.zeros((horizon, 2))
    _, states, _, _ = ilqr.rollout(task, env_state, controls, no_gains, no_reference, keys, low, high)
    ones = jnp.ones(horizon)
    grouped = [
        jax.jit(lambda t, s, c, k, n=n: ilqr.linearize(t, s, c, k, ones, ones, None, n))(task, states, controls, keys)
        for n in (None, 1, 2)
    ]
    for f_z, c_z, c_zz in grouped[1:]:
        np.testing.assert_allclose(f_z, grouped[0][0], rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(c_z, grouped[0][1], rtol=1e-5, atol=1e-6)
        # central differences of float32 gradients: ~1e-4 of rounding, against entries up to ~20
        np.testing.assert_allclose(c_zz, grouped[0][2], rtol=1e-3, atol=1e-3)
    assert float(jnp.abs(grouped[0][0]).max()) > 0.1  # real dynamics, not zeros


def test_the_closed_loop_swings_the_pendulum_up():
    config, hyperparams = planning.configure(ilqr, envs.hyperparameters("pendulum_swingup", "ilqr"))
    problem = envs.closed_loop_problem("pendulum_swingup", ilqr, config, hyperparams=hyperparams)
    assert problem.physics == "mjx"  # "auto" on a CPU: ilqr has no native backend
    result, stats = realtime.offline(problem, jax.random.key(0), OPTIMIZED)
    solved, score = problem.success(jax.device_get(result.states))
    print(f"pendulum ilqr: score {score:.4f} rad, {stats['plan_latency_ms']:.1f} ms per replan on the CPU")
    assert solved, score


# --- the contract ---------------------------------------------------------------------------


def test_native_backend_and_bad_numbers_are_refused_by_name():
    config = ilqr.Config(horizon_steps=5)
    with pytest.raises(ValueError, match="ilqr plans on mjx only"):
        realtime.Problem(ilqr, config, _pendulum(), _pendulum(), seconds=1.0, backend="native")
    with pytest.raises(TypeError, match="native C MuJoCo rollouts have no JAX derivatives"):
        ilqr.init(config, planning.native.wrap(_pendulum()))
    with pytest.raises(ValueError, match=r"ilqr\.Hyperparams: step_decay=1\.5"):
        ilqr.Hyperparams(step_decay=1.5)
    with pytest.raises(ValueError, match=r"ilqr\.Config: iterations=0"):
        ilqr.Config(iterations=0)
