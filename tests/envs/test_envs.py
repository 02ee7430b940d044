"""The env registry and what each env promises in its docstring."""

from __future__ import annotations

import functools
import importlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo import checks


def test_names_and_unknown_name():
    assert set(mjzoo.envs.names()) >= {
        "pendulum_swingup",
        "cartpole_balance",
        "cartpole_swingup",
        "point_mass",
        "cylinder_push",
    }
    with pytest.raises(
        KeyError, match=r"unknown env 'cartpole_balanse' \(did you mean 'cartpole_balance'\?\).*point_mass"
    ):
        mjzoo.envs.make("cartpole_balanse")


def test_unknown_override_lists_allowed():
    with pytest.raises(
        TypeError,
        match=r"unknown override\(s\) \['upright_wieght'\] \(did you mean 'upright_weight'\?\); allowed: .*'ctrl_dt'.*'upright_weight'",
    ):
        mjzoo.envs.make("cartpole_swingup", upright_wieght=2.0)


def test_bad_physics_override_is_named():
    with pytest.raises(ValueError, match=r"cartpole.xml: physics option solver='pgs'"):
        mjzoo.envs.make("cartpole_swingup", solver="pgs")
    with pytest.raises(ValueError, match=r"ctrl_dt=0.025 must be a whole multiple of the physics dt=0.01"):
        mjzoo.envs.make("cartpole_swingup", ctrl_dt=0.025)


def test_register_rejects_duplicates():
    with pytest.raises(ValueError, match="already registered"):
        mjzoo.envs.register("point_mass", mjzoo.envs.point_mass.reach)


@functools.cache
def _run(name: str, steps: int, **overrides):
    task = mjzoo.envs.make(name, **dict(overrides))
    nu = task.action_size

    def policy(obs, key):
        return jax.random.uniform(key, (nu,), minval=-1.0, maxval=1.0)

    @jax.jit
    def run(task, key):
        state = mjzoo.reset(task, key)
        return state, mjzoo.rollout(task, policy, state, key, steps)[1]

    return task, run(task, jax.random.key(3))


@pytest.mark.parametrize(
    "name", ["pendulum_swingup", "cartpole_balance", "cartpole_swingup", "point_mass", "cylinder_push"]
)
def test_reward_terms_are_bounded_by_their_weights(name):
    task, (_, trajectory) = _run(name, 40)
    weights = {k[: -len("_weight")]: v for k, v in mjzoo.envs.defaults(name).items() if k.endswith("_weight")}
    terms = mjzoo.reward_terms(trajectory.next_state)
    assert set(terms) == set(weights)
    for term, values in terms.items():
        assert np.all(np.abs(values) <= weights[term] + 1e-6), term


def test_pendulum_starts_hanging_and_observes_angle():
    _, (first, _) = _run("pendulum_swingup", 2)
    np.testing.assert_allclose(first.obs[0], -1.0, atol=0.01)  # cos(pi)
    assert abs(float(first.data.qpos[0]) - np.pi) <= 0.1


def test_cartpole_balance_terminates_when_the_pole_falls():
    task, (first, trajectory) = _run("cartpole_balance", 200)
    assert abs(float(first.data.qpos[1])) <= 0.1  # starts near upright
    angles = np.asarray(trajectory.next_state.data.qpos[:, 1])
    leaning = np.abs(np.arctan2(np.sin(angles), np.cos(angles)))
    np.testing.assert_array_equal(trajectory.next_state.terminated, leaning > 0.5)
    assert trajectory.next_state.terminated.any()  # random pushes topple it within 4 s


def test_cartpole_swingup_starts_down_and_never_terminates():
    _, (first, trajectory) = _run("cartpole_swingup", 50)
    assert float(first.obs[1]) < -0.99
    assert not trajectory.next_state.terminated.any()


def test_point_mass_goal_is_in_info_obs_and_marker():
    _, (first, _) = _run("point_mass", 2)
    goal = np.asarray(first.info["goal"])
    assert np.all(np.abs(goal) <= 0.4)
    np.testing.assert_allclose(first.obs[4:6], goal - np.asarray(first.data.qpos), atol=1e-6)
    np.testing.assert_allclose(first.data.mocap_pos[0, :2], goal)


def test_point_mass_reach_is_one_on_the_target_and_falls_to_a_tenth_at_the_margin():
    pm = mjzoo.envs.point_mass
    task = mjzoo.envs.make("point_mass")
    p = mjzoo.params(task)  # the task's own numbers, as its functions get them
    state = mjzoo.reset(task, jax.random.key(0))
    goal = state.info["goal"]
    at = lambda xy: state.replace(data=state.data.replace(qpos=xy))  # noqa: E731
    np.testing.assert_allclose(pm.reached(p, task.model, state, jnp.zeros(2), at(goal)), 1.0)
    np.testing.assert_allclose(pm.effort(p, task.model, state, jnp.zeros(2), at(goal)), 0.0)
    # 0.03 m radius + 0.5 m margin away: the gaussian tolerance's value at the margin, 0.1.
    far = at(goal + jnp.array([0.53, 0.0]))
    np.testing.assert_allclose(pm.reached(p, task.model, state, jnp.ones(2), far), 0.1, rtol=1e-4)
    np.testing.assert_allclose(pm.effort(p, task.model, state, jnp.ones(2), far), 1.0)


def test_cylinder_push_moves_the_cylinder_when_pushed():
    task = mjzoo.envs.make("cylinder_push")
    state = mjzoo.reset(task, jax.random.key(0))
    # Pusher 20 cm left of the cylinder, both at rest; push right for 1 s.
    qpos = jnp.array([-0.2, 0.0, 0.0, 0.0])
    state = state.replace(data=state.data.replace(qpos=qpos, qvel=jnp.zeros(4)))

    @jax.jit
    def push(task, state):
        return mjzoo.rollout(task, lambda obs, key: jnp.array([1.0, 0.0]), state, jax.random.key(0), 50)[0]

    final = push(task, state)
    pusher_x, cylinder_x = float(final.data.qpos[0]), float(final.data.qpos[2])
    assert cylinder_x > 0.1  # pushed along +x
    assert abs(float(final.data.qpos[3])) < 0.02  # no sideways drift
    assert cylinder_x - pusher_x >= 0.14  # they touch but never interpenetrate (radii 5 + 10 cm)


def test_an_override_of_the_wrong_type_is_named_with_the_expected_type():
    cases = [
        (dict(episode_steps="abc"), "cartpole_balance: override episode_steps='abc' must be an int"),
        (dict(episode_steps=2.5), "override episode_steps=2.5 must be an int"),
        (dict(episode_steps=True), "override episode_steps=True must be an int"),  # bool is not an int
        (dict(upright_weight=[1, 2]), r"override upright_weight=\[1, 2\] must be a number"),
        (dict(upright_weight="heavy"), "override upright_weight='heavy' must be a number"),
        (dict(fall_angle=None), "override fall_angle=None must be a number"),
    ]
    for overrides, message in cases:
        with pytest.raises(TypeError, match=message):
            mjzoo.envs.make("cartpole_balance", **overrides)
    with pytest.raises(TypeError, match="ant: override max_height='top' must be a number or None"):
        mjzoo.envs.make("ant", max_height="top")
    with pytest.raises(TypeError, match="ant_joystick: override actuator=3 must be callable or None"):
        mjzoo.envs.make("ant_joystick", actuator=3)
    with pytest.raises(ValueError, match=r"physics option iterations='many' is invalid; expected an integer >= 1"):
        mjzoo.envs.make("cartpole_balance", iterations="many")  # physics options: physics.load's check


def test_an_override_of_a_compatible_type_is_accepted(monkeypatch):
    """Floats take ints and 0-d arrays (a swept weight), tuples lists (JSON gives lists
    back), None where the annotation allows it; a default of None judges only callables."""
    from typing import Callable

    task, received = mjzoo.envs.make("cartpole_balance"), []

    def typed(
        *,
        steps: int = 5,
        weight: float = 1.0,
        height: float | None = 1.0,
        sizes: tuple = (64,),
        flag: bool = False,
        hook: Callable | None = None,
        extra=None,
        **physics_options,
    ):
        received.append(dict(steps=steps, weight=weight, height=height, sizes=sizes, flag=flag, hook=hook, extra=extra))
        return task  # a factory returns a Task: make refuses anything else

    monkeypatch.setitem(mjzoo.envs._REGISTRY, "typed", mjzoo.envs.EnvSpec(make=typed, description="typed factory"))
    accepted = dict(
        steps=np.int64(7), weight=2, height=None, sizes=[32, 32], flag=np.bool_(True), hook=print, extra="x"
    )
    assert mjzoo.envs.make("typed", **accepted) is task and received == [accepted]
    mjzoo.envs.make("typed", weight=np.float32(0.5))
    mjzoo.envs.make("typed", weight=jnp.asarray(0.02))
    for overrides, message in [
        (dict(sizes=64), "sizes=64 must be a tuple or list"),
        (dict(flag=1), "flag=1 must be True or False"),
        (dict(weight=jnp.zeros(2)), "must be a number"),
        (dict(steps=None), "steps=None must be an int"),
    ]:
        with pytest.raises(TypeError, match=message):
            mjzoo.envs.make("typed", **overrides)
    assert mjzoo.envs.make("cartpole_balance", upright_weight=2).action_size == 1


def test_a_misspelled_name_gets_the_nearest_known_one():
    assert checks.did_you_mean(["num_env"], ["num_envs", "num_epochs", "seed"]) == " (did you mean 'num_envs'?)"
    assert checks.did_you_mean(["zzz", "lerning_rate"], ["learning_rate"]) == " (did you mean 'learning_rate'?)"
    assert checks.did_you_mean(["nonsense"], ["num_envs", "seed"]) == ""
    with pytest.raises(KeyError, match=r"unknown env 'cartpole_balanse' \(did you mean 'cartpole_balance'\?\)"):
        mjzoo.envs.make("cartpole_balanse")


def test_the_robots_sampling_setup_ramps_every_planner_but_cma_es():
    from mjzoo.envs import base

    setup = base.sampling_setup(
        5.0, lambda states: (True, 0.0), num_samples=32, horizon_steps=20, num_knots=4, noise_scale=0.2, noise_ramp=4.0
    )
    configs = setup.configs
    assert {name: c["noise_ramp"] for name, c in configs.items() if "noise_ramp" in c} == {
        "predictive_sampling": 4.0,
        "mppi": 4.0,
        "cem": 4.0,
        "dial": 4.0,
    }
    # CMA-ES adapts its own spread (it refuses a ramp); elites are 1/16 of the samples, at least 2.
    assert configs["cma_es"]["num_elites"] == configs["cem"]["num_elites"] == 2
    assert {c["num_samples"] for c in configs.values()} == {32}
    for name, fields in configs.items():  # every planner takes its fields as they are
        module = importlib.import_module(f"mjzoo.algorithms.{name}")
        mjzoo.planning.configure(module, fields)
    default = base.sampling_setup(5.0, None, horizon_steps=25, num_knots=4, noise_scale=0.5).configs
    assert "noise_ramp" not in default["mppi"] and default["cem"]["num_elites"] == 64
