"""Sampling planners closed loop on the CPU, with each env's documented planning setup
(`mjzoo.envs.planning`): the pendulum swung up and held, the cart-pole balanced after
its swing-up, the cylinder pushed onto its goal, point-mass goals
reached one after another. Plus the task hooks one by one, and robust planning over an ensemble."""

from __future__ import annotations

import dataclasses
import functools
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from mujoco import mjx

import mjzoo
import mjzoo.envs
from mjzoo import planning
from mjzoo.algorithms import cem
from mjzoo.algorithms import cma_es
from mjzoo.algorithms import dial
from mjzoo.algorithms import mppi
from mjzoo.algorithms import predictive_sampling
from mjzoo.envs import cylinder_push
from mjzoo.envs import point_mass
from mjzoo.planning import closed_loop
from mjzoo.planning import realtime

# The suite compiles at XLA -O0 (conftest) for short tests; a closed-loop run is long,
# and at -O3 it runs about 6x faster for the same compile time.
OPTIMIZED = {"xla_backend_optimization_level": 3}
PLANNERS = {"predictive_sampling": predictive_sampling, "cem": cem, "mppi": mppi, "dial": dial, "cma_es": cma_es}


def setup_for(env: str, planner: str, backend: str = "auto") -> realtime.Problem:
    """The env's documented closed-loop problem for `planner`."""
    module = PLANNERS[planner]
    config, hyperparams = planning.configure(module, mjzoo.envs.hyperparameters(env, planner))
    return mjzoo.envs.closed_loop_problem(env, module, config, backend=backend, hyperparams=hyperparams)


# With C MuJoCo's rollouts (the default on a CPU): one planner on each env, so each planner
# and each env runs (the planners and envs share everything above the rollouts, contacts
# included: the push's contacts live in the rollouts, which every planner calls alike; each
# run compiles its own closed loop, about a minute of the suite's CPU, so the push runs
# one planner, not all three; benchmarks/planner_cpu.py runs every planner on the
# cart-pole and the push, over seeds). MJX's own physics with one planner on the pendulum
# (its contact rollouts match C MuJoCo's in tests/planning/test_native.py).
CASES = [("cylinder_push", "cem", "native"), ("pendulum_swingup", "predictive_sampling", "native")]
CASES += [("cartpole_swingup", "cem", "native")]
CASES += [("point_mass", "mppi", "native"), ("pendulum_swingup", "mppi", "mjx")]
# The iterating planners on the pendulum, C MuJoCo called from inside their one jit.
CASES += [("pendulum_swingup", "dial", "native"), ("pendulum_swingup", "cma_es", "native")]


@functools.cache
def closed_loop_run(env: str, planner: str, backend: str) -> tuple[realtime.Problem, closed_loop.Result, dict]:
    """The case's problem and its run from key 0: one compile, shared with the hooks test."""
    setup = setup_for(env, planner, backend)
    return setup, *realtime.offline(setup, jax.random.key(0), OPTIMIZED)


@pytest.mark.parametrize(("env", "planner", "backend"), CASES)
def test_planner_solves_env_closed_loop(env, planner, backend):
    setup, result, stats = closed_loop_run(env, planner, backend)
    assert setup.physics == backend
    solved, score = setup.success(jax.device_get(result.states))
    print(f"{env} {planner} {backend}: score {score:.3f}, {stats['plan_latency_ms']:.1f} ms per replan on the CPU")
    assert solved, f"{env} with {planner}: score {score}"
    assert np.all(np.isfinite(np.asarray(result.controls)))
    low, high = planning.control_limits(setup.sim_task)
    assert np.all(np.asarray(result.controls) >= low - 1e-6) and np.all(np.asarray(result.controls) <= high + 1e-6)


def test_warm_start_hook_sets_the_first_plan():
    setup = setup_for("point_mass", "predictive_sampling")
    state = mjzoo.reset(setup.sim_task, jax.random.key(0))
    state = state.replace(info={**state.info, "goal": state.data.qpos + jnp.array([0.2, -0.1])})
    first = closed_loop.first_plan(setup.planner, setup.config, setup.plan_task, state, setup.hooks)
    np.testing.assert_allclose(first.knots, np.tile([[1.0, -0.5]], (setup.config.num_knots, 1)), atol=1e-6)
    bare = closed_loop.first_plan(setup.planner, setup.config, setup.plan_task, state)
    np.testing.assert_array_equal(bare.knots, 0.0)


def test_phase_view_charges_the_approach_only_until_in_position():
    task = mjzoo.envs.make("cylinder_push", approach_weight=0.0)
    state = mjzoo.reset(task, jax.random.key(3))
    pusher, cylinder = cylinder_push.positions(state.data)
    behind = cylinder_push._behind(state.data, state.info["goal"])
    action = jnp.zeros(2)

    def phase_term(start):
        view = cylinder_push.phase_view(np.float32(0.05), np.float32(1.0), task, start)
        return float(mjzoo.transition_with_terms(view, start, action, jax.random.key(0))[1]["approach_phase"])

    far = float(jnp.linalg.norm(behind - pusher))
    assert far > 0.05 and phase_term(state) < -0.5 * far  # charged about the distance
    qpos = state.data.qpos.at[0:2].set(behind)
    in_position = state.replace(data=state.data.replace(qpos=qpos))
    assert phase_term(in_position) == 0.0


def test_goal_resampling_hook_moves_only_a_reached_goal():
    task = mjzoo.envs.make("point_mass")
    state = mjzoo.reset(task, jax.random.key(0))
    hook = functools.partial(point_mass.new_goal_when_reached, np.float32(0.05), np.float32(0.3), task)
    away = hook(state, jax.random.key(1))
    np.testing.assert_array_equal(away.info["goal"], state.info["goal"])
    there = state.replace(data=state.data.replace(qpos=state.info["goal"]))
    moved = hook(there, jax.random.key(1))
    assert float(jnp.linalg.norm(moved.info["goal"] - state.info["goal"])) > 0
    np.testing.assert_allclose(moved.data.mocap_pos[0, :2], moved.info["goal"])
    np.testing.assert_allclose(moved.obs[4:], moved.info["goal"] - moved.data.qpos, atol=1e-6)


def _heavier(scale_low, scale_high, model, key):
    return {"body_mass": model.body_mass * jax.random.uniform(key, minval=scale_low, maxval=scale_high)}


def test_robust_planning_over_an_ensemble_swings_up_a_heavier_pendulum():
    """The world's pendulum is 30% heavier than the nominal model; the planner plans over
    4 models with masses 0.9-1.5x and aggregates their costs by CVaR (8 s: the heavier
    pendulum needs more swings). The risk measures' numbers are tested in
    tests/planning/test_sampling.py."""
    risk = "cvar"
    setup = setup_for("pendulum_swingup", "predictive_sampling")
    sim_task = setup.sim_task.replace(
        model=setup.sim_task.model.replace(body_mass=setup.sim_task.model.body_mass * 1.3)
    )
    models = planning.ensemble(setup.plan_task, jax.tree_util.Partial(_heavier, 0.9, 1.5), 4, jax.random.key(7))
    config = dataclasses.replace(setup.config, risk=risk)
    hyperparams = dataclasses.replace(setup.hyperparams, cvar_alpha=0.5)
    robust = dataclasses.replace(
        setup, sim_task=sim_task, plan_task=models, config=config, hyperparams=hyperparams, seconds=8.0
    )
    result, _ = realtime.offline(robust, jax.random.key(0), OPTIMIZED)
    solved, score = robust.success(jax.device_get(result.states))
    assert solved, f"{risk}: |angle| over the last second up to {score:.3f} rad"


def test_plan_cli_runs_in_real_time_and_writes_its_files(tmp_path):
    from mjzoo.harness import cli

    cli.main(
        ["plan", "predictive_sampling", "pendulum_swingup", "--seconds", "0.5", "--out", str(tmp_path), "--no-video"]
    )
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert {"success", "final_cost", "plan_hz", "plan_latency_ms"} <= set(summary)
    assert summary["mode"] == "realtime" and summary["plan_hz"] > 0 and summary["plan_latency_ms"] > 0
    assert (tmp_path / "plan.png").stat().st_size > 0


def test_plan_cli_steps_the_world_where_sim_backend_says(tmp_path):
    from mjzoo.harness import cli

    argv = ["plan", "predictive_sampling", "pendulum_swingup", "--seconds", "0.2", "--no-video", "--backend", "mjx"]
    cli.main([*argv, "--sim-backend", "native", "--out", str(tmp_path), "--config", "num_samples=4"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["backend"] == "mjx" and summary["world"] == "native"


def test_pre_sim_step_and_post_rollout_hooks_reach_the_simulation():
    """point_mass's gusts push the mass before every simulation step (xfrc_applied), and
    the post-rollout hook keeps the cost the planner predicted for its chosen plan."""
    setup, windy, _ = closed_loop_run("point_mass", "mppi", "native")  # the closed-loop case's run, gusts on
    assert "xfrc_applied" in setup.tasks[0].engine.held  # held at what the hook set, for the step's C rollout
    calm = dataclasses.replace(setup, hooks=dataclasses.replace(setup.hooks, pre_sim_step=None))
    states = {"windy": jax.device_get(windy.states)}
    states["calm"] = jax.device_get(realtime.offline(calm, jax.random.key(0), OPTIMIZED)[0].states)
    assert setup.sim_task.mj_model.body(point_mass.MASS_BODY).name == "mass"
    wind = states["windy"].data.xfrc_applied[:, point_mass.MASS_BODY, :2]
    assert np.all(np.abs(wind) > 0) and np.std(wind) < 0.2  # N(0, 0.05 N), fresh every step
    assert np.abs(states["windy"].data.qpos - states["calm"].data.qpos).max() > 1e-4  # and it moves the mass
    plan_costs = states["windy"].info["plan_cost"]
    assert np.all(plan_costs[1:] < 0) and np.all(np.isfinite(plan_costs))  # predicted: rewards to come


def test_a_problems_second_real_time_episode_compiles_nothing():
    """`realtime` compiles its loop once per problem: a benchmark's episodes after the
    first start at once (a G1's replan took ~40 s to compile on a GPU, each episode)."""
    config, hyperparams = planning.configure(predictive_sampling, dict(num_samples=4, horizon_steps=3, num_knots=2))
    problem = mjzoo.envs.closed_loop_problem(
        "pendulum_swingup", predictive_sampling, config, seconds=0.1, backend="mjx", hyperparams=hyperparams
    )
    compiles = []
    listener = lambda name, *_, **__: compiles.append(name) if name.endswith("backend_compile_duration") else None  # noqa: E731
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        first, _ = realtime.realtime(problem, jax.random.key(0), clock="simulated")
        compiled = len(compiles)
        second, _ = realtime.realtime(problem, jax.random.key(1), clock="simulated")
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert compiled > 0 and len(compiles) == compiled, compiles[compiled:]
    assert first.states.data.qpos.shape == second.states.data.qpos.shape
    assert not np.allclose(first.states.data.qpos, second.states.data.qpos)  # other keys: another run


def test_the_world_steps_in_c_mujoco_beside_an_mjx_planner():
    """``sim_backend="native"``: the planner rolls out on MJX, the world steps in C
    MuJoCo, and the closed loop follows the all-MJX one (the engines agree to float
    rounding over a short run)."""
    config, hyperparams = planning.configure(predictive_sampling, dict(num_samples=4, horizon_steps=3, num_knots=2))
    problems = {
        world: mjzoo.envs.closed_loop_problem(
            "pendulum_swingup",
            predictive_sampling,
            config,
            seconds=0.2,
            backend="mjx",
            hyperparams=hyperparams,
            sim_backend=world,
        )
        for world in (None, "native")
    }
    sim, plan = problems["native"].tasks
    assert isinstance(sim, planning.native.Native) and not isinstance(plan, planning.native.Native)
    assert problems["native"].sim_physics == "native" and problems[None].sim_physics == "mjx"
    runs = {w: realtime.realtime(p, jax.random.key(0), clock="simulated")[0] for w, p in problems.items()}
    mjx_qpos, c_qpos = (np.asarray(runs[w].states.data.qpos) for w in (None, "native"))
    assert c_qpos.shape == mjx_qpos.shape == (10, 1)
    np.testing.assert_allclose(c_qpos, mjx_qpos, atol=1e-4)
    assert np.abs(c_qpos - c_qpos[0]).max() > 1e-3  # it moved
    with pytest.raises(ValueError, match="unknown sim_backend 'c'"):
        dataclasses.replace(problems[None], sim_backend="c")


def test_a_natively_stepped_model_is_built_on_mjx_jax_whatever_impl_says():
    """C MuJoCo replays MJX-JAX states, so `closed_loop_problem` builds the models it steps
    natively with ``impl="jax"``: on a GPU host, where MuJoCo Warp is the default, and
    under an explicit ``impl="warp"`` (which on this CPU would otherwise fail to load)."""
    config, hyperparams = planning.configure(predictive_sampling, dict(num_samples=4, horizon_steps=3, num_knots=2))
    problem = mjzoo.envs.closed_loop_problem(
        "pendulum_swingup", predictive_sampling, config, seconds=0.1, backend="native", impl="warp"
    )
    assert problem.sim_task.model.impl == problem.plan_task.model.impl == mjx.Impl.JAX
    auto = mjzoo.envs.closed_loop_problem("pendulum_swingup", predictive_sampling, config, seconds=0.1, impl="warp")
    assert auto.physics == "native" and auto.plan_task.model.impl == mjx.Impl.JAX  # "auto" on a CPU: native
    with pytest.raises(ValueError, match="impl='warp' needs"):  # an MJX planner keeps the asked physics
        mjzoo.envs.closed_loop_problem(
            "pendulum_swingup", predictive_sampling, config, backend="mjx", sim_backend="native", impl="warp"
        )
