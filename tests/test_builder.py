"""`mjzoo.task` (the builder of one's own task) and named parameters (`mjzoo.params`,
`mjzoo.with_params`, `Task.with_params`).

The model: a 1 kg block on a frictionless slide joint along x, no gravity, a motor
(force = action, unlimited), semi-implicit Euler with dt = 0.1 s. From rest with F = 1 N
one step gives qvel = 0.1 m/s, qpos = 0.01 m. A reset item draws a goal in [0.5, 1] m
and keeps it in info; the reward term "reach" is -|goal - qpos| times its weight, and
"push" is the action, through a parameter it names.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from jax.tree_util import Partial

import mjzoo
from mjzoo.catalog import resets

XML = """
<mujoco model="block">
  <option timestep="0.1" integrator="Euler" gravity="0 0 0"/>
  <worldbody>
    <body name="block">
      <joint name="x" type="slide" axis="1 0 0"/>
      <geom type="box" size="0.1 0.1 0.1" mass="1"/>
    </body>
  </worldbody>
  <actuator><motor joint="x"/></actuator>
</mujoco>
"""
PUSH = np.ones(1, np.float32)


def goal(p, model, data, key):
    return data, {"goal": jax.random.uniform(key, minval=p["goal_low"], maxval=1.0)}


def observe(p, model, state):
    return jnp.concatenate([state.data.qpos, state.info["goal"][None]])


def reach(p, model, state, action, next_state):
    return -jnp.abs(next_state.info["goal"] - next_state.data.qpos[0])


def push(p, model, state, action, next_state):
    return action[0]


def past(p, model, state):
    return state.data.qpos[0] > p["limit"]


def make(**kwargs):
    spec = dict(
        observe=observe,
        rewards={"reach": (reach, 2.0), "push": (push, "gain")},
        terminate=past,
        resets=(goal,),
        params={"goal_low": 0.5, "gain": 0.5, "limit": 0.005},
    )
    return mjzoo.task(XML, **{**spec, **kwargs})


TRACES = []


@jax.jit
def step(task, key):
    TRACES.append(1)
    state = mjzoo.reset(task, key)
    return state, mjzoo.transition(task, state, jnp.asarray(PUSH), key)


def test_a_kit_task_resets_steps_and_rewards_as_its_functions_say():
    start, after = step(make(), jax.random.key(0))
    g = float(start.info["goal"])
    assert 0.5 <= g <= 1.0 and float(start.obs[1]) == g and float(start.obs[0]) == 0.0
    np.testing.assert_allclose(after.data.qpos, [0.01], rtol=1e-5)
    terms = mjzoo.reward_terms(after)
    np.testing.assert_allclose(terms["reach"], -2.0 * (g - 0.01), rtol=1e-5)
    np.testing.assert_allclose(terms["push"], 0.5 * 1.0)
    assert bool(after.terminated) and not bool(start.terminated)  # 0.01 m > limit 0.005 m
    assert float(after.info["goal"]) == g  # the step keeps info


def test_params_list_every_named_number_and_change_without_retracing():
    task = make()
    assert {k: float(v) for k, v in mjzoo.params(task).items()} == pytest.approx(
        {"gain": 0.5, "goal_low": 0.5, "limit": 0.005, "reach_weight": 2.0}
    )
    _, before = step(task, jax.random.key(1))
    traces = len(TRACES)
    _, after = step(task.with_params(reach_weight=4.0, gain=-1.0), jax.random.key(1))
    assert len(TRACES) == traces, "with_params retraced"
    np.testing.assert_allclose(mjzoo.reward_terms(after)["reach"], 2 * mjzoo.reward_terms(before)["reach"])
    assert float(mjzoo.reward_terms(after)["push"]) == -1.0


def test_with_params_names_an_unknown_parameter_and_a_wrong_shape():
    task = make()
    with pytest.raises(KeyError, match="no parameter named 'reach_wieght'.*reach_weight"):
        task.with_params(reach_wieght=1.0)
    with pytest.raises(ValueError, match=r"gain=\[1.0, 2.0\] has shape \(2,\).*shape \(\)"):
        mjzoo.with_params(task, gain=[1.0, 2.0])


def test_with_params_reaches_a_registered_env_s_dataclass_fields():
    import mjzoo.envs

    task = mjzoo.envs.make("point_mass")
    assert float(mjzoo.params(task)["reach_weight"]) == 1.0
    heavier = task.with_params(reach_weight=3.0)
    assert float(mjzoo.params(heavier)["reach_weight"]) == 3.0
    assert jax.tree.structure(heavier) == jax.tree.structure(task)


def test_default_observation_no_reward_and_time_limit():
    task = mjzoo.task(XML, time_limit=1)
    start, after = step(task, jax.random.key(0))
    np.testing.assert_allclose(start.obs, [0.0, 0.0])  # qpos, qvel
    np.testing.assert_allclose(after.obs, [0.01, 0.1], rtol=1e-5)
    assert mjzoo.reward_terms(after) == {} and float(after.reward) == 0.0
    assert bool(after.truncated) and not bool(after.terminated)


def test_an_mjmodel_and_a_partial_that_carries_its_own_numbers():
    task = mjzoo.task(
        mujoco.MjModel.from_xml_string(XML), ctrl_dt=0.2, rewards={"push": Partial(_scaled_push, jnp.float32(3.0))}
    )
    _, after = step(task, jax.random.key(0))
    np.testing.assert_allclose(after.data.qpos, [0.03], rtol=1e-5)  # two 0.1 s steps of 1 N
    assert float(mjzoo.reward_terms(after)["push"]) == 3.0


def _scaled_push(scale, model, state, action, next_state):
    return scale * action[0]


def _vector(p, model, state, action, next_state):
    return jnp.ones(2)


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        (dict(rewards={"push": (push, "gian")}), ValueError, "names the parameter 'gian', which params lacks"),
        (dict(rewards={"a b": push}), ValueError, "'a b' must be a Python identifier"),
        (dict(params={"reach_weight": 1.0}), ValueError, "'reach_weight' is given in params and as"),
        (dict(params={"gain": "x"}), ValueError, r"params\['gain'\]='x' must be numbers"),
        (dict(params={"gain": 0.5, "limit": [0.0, float("nan")]}), ValueError, r"params\['limit'\].*not NaN"),
        (dict(params={"gain": float("inf")}), ValueError, r"weight of reward term 'push', params\['gain'\]=inf"),
        (dict(observe=3), TypeError, "observe must be callable"),
        (dict(rewards={"reach": (reach, float("nan"))}), ValueError, "weight of 'reach'"),
        (dict(rewards={"vector": (_vector, 1.0)}), ValueError, r"reward term 'vector' has shape \(2,\)"),
    ],
)
def test_construction_names_the_mistake(kwargs, error, message):
    with pytest.raises(error, match=message):
        make(**kwargs)


def test_an_infinite_bound_is_a_parameter():
    """A published healthy range ``(0.7, inf)``: an infinite limit that never binds."""
    task = make(params={"goal_low": 0.5, "gain": 0.5, "limit": float("inf")})
    assert float(mjzoo.params(task)["limit"]) == float("inf")
    _, after = step(task, jax.random.key(0))
    assert not bool(after.terminated)
    assert bool(step(task.with_params(limit=0.005), jax.random.key(0))[1].terminated)  # the same trace


def test_a_lambda_or_nested_function_warns_of_retracing_and_a_module_function_does_not():
    with pytest.warns(mjzoo.RetraceHazardWarning, match="reward term 'reach' is a lambda"):
        make(rewards={"reach": lambda p, m, s, a, ns: 0.0})
    weight = 0.5

    def nested(model, state, action, next_state):
        return weight

    with pytest.warns(mjzoo.RetraceHazardWarning, match=r"nested function.*captures \(0.5\)"):
        mjzoo.with_reward(make(), "nested", nested)
    with warnings.catch_warnings():
        warnings.simplefilter("error", mjzoo.RetraceHazardWarning)
        mjzoo.with_reward(make(), "push2", Partial(_scaled_push, jnp.float32(1.0)))


def test_catalog_reset_items_may_write_info():
    task = mjzoo.task(XML)
    task = resets.with_resets(task, resets.joint_velocities(task.mj_model, 0.0), _marked, observe=_joint_state)
    start, after = step(task, jax.random.key(0))
    assert float(start.info["mark"]) == 7.0 and float(after.info["mark"]) == 7.0


def _joint_state(model, state):
    return mjzoo.builder.joint_state({}, model, state)


def _marked(model, data, key):
    return data, {"mark": jnp.float32(7.0)}


# --- what the shipped envs need: costs, named terminations, alive, start, catalog numbers


def _still(p, model, data, key):
    return data, {"start_key": jax.random.key_data(key)}


def _effort(model, state, action, next_state):
    return jnp.sum(jnp.square(action))


def _far(min_x, model, state):
    return state.data.qpos[0] > min_x


def test_costs_named_terminations_alive_and_a_catalog_number_made_a_parameter():
    task = mjzoo.task(
        XML,
        start=_still,
        rewards={"alive": (mjzoo.builder.alive, 2.0)},
        costs={"effort": (Partial(_effort), 0.25)},
        terminate={"far": mjzoo.builder.named(Partial(_far, 0.005), "limit")},
    )
    assert {k: float(v) for k, v in mjzoo.params(task).items()} == pytest.approx(
        {"alive_weight": 2.0, "effort_weight": 0.25, "limit": 0.005}
    )
    start, after = step(task, jax.random.key(3))
    # start gets the reset key itself; the cost is charged, the weight a magnitude.
    np.testing.assert_array_equal(start.info["start_key"], jax.random.key_data(jax.random.key(3)))
    assert float(mjzoo.reward_terms(after)["effort"]) == -0.25
    # 0.01 m > 0.005 m: terminated, named in metrics, and alive pays nothing for it.
    assert bool(after.terminated) and float(after.metrics["termination/far"]) == 1.0
    assert float(start.metrics["termination/far"]) == 0.0
    assert float(mjzoo.reward_terms(after)["alive"]) == 0.0
    _, after = step(task.with_params(limit=1.0), jax.random.key(3))
    assert not bool(after.terminated) and float(mjzoo.reward_terms(after)["alive"]) == 2.0


def test_named_needs_one_name_per_number_and_agreeing_shared_names():
    with pytest.raises(ValueError, match="binds 1 number"):
        mjzoo.builder.named(Partial(_far, 0.005), "a", "b")
    item = mjzoo.builder.named(Partial(_far, 0.005), "limit")
    other = mjzoo.builder.named(Partial(_far, 0.5), "limit")
    with pytest.raises(ValueError, match="limit=0.5.*already has limit"):
        mjzoo.task(XML, terminate={"a": item, "b": other})
    with pytest.raises(ValueError, match="'effort' is both a reward and a cost"):
        mjzoo.task(XML, rewards={"effort": push}, costs={"effort": push})


def test_combinators_run_inside_the_terms_and_a_loaded_physics_is_taken():
    physics = mjzoo.physics.load(XML, ctrl_dt=0.2)
    doubled = mjzoo.task(physics, combinators=(_double_action,), rewards={"push": push}, params={})
    _, after = step(doubled, jax.random.key(0))
    # The term sees the action the transition was given; the physics the doubled one:
    # two 0.1 s steps of 2 N from rest.
    np.testing.assert_allclose(after.data.qpos, [0.06], rtol=1e-5)
    with pytest.raises(ValueError, match="a loaded Physics takes no physics options"):
        mjzoo.task(physics, ctrl_dt=0.1)


def _double_action(task):
    return task.replace(step=Partial(_doubled_step, task.step))


def _doubled_step(step_fn, model, state, action, key):
    return step_fn(model, state, 2.0 * action, key)


def speed(p, model, state, action, next_state):  # m/s over the control step
    return (next_state.data.qpos[0] - state.data.qpos[0]) / p["ctrl_dt"]


def steps_seen(p, model, state):
    return jnp.stack([p["dt"], p["ctrl_dt"]])


def test_every_function_sees_the_model_s_timestep_and_control_step():
    # 3 substeps of 0.1 s from rest at 1 N: v = 0.1, 0.2, 0.3 m/s, x = 0.01, 0.03, 0.06 m:
    # 0.2 m/s over the 0.3 s control step. At dt = 0.05 s: x = 0.015 m over 0.15 s, 0.1 m/s.
    task = mjzoo.task(XML, ctrl_dt=0.3, observe=steps_seen, rewards={"speed": speed})
    assert "ctrl_dt" not in mjzoo.params(task)  # read from the model, not a copy to change

    def run(timestep):
        model = task.model.replace(opt=task.model.opt.replace(timestep=timestep))
        return step(task.replace(model=model), jax.random.key(0))

    start, after = run(0.1)
    np.testing.assert_allclose(start.obs, [0.1, 0.3], rtol=1e-6)
    np.testing.assert_allclose(after.obs, [0.1, 0.3], rtol=1e-6)
    np.testing.assert_allclose(mjzoo.reward_terms(after)["speed"], 0.2, rtol=1e-5)
    # A traced timestep (a randomized model, one per world) is the one each world sees.
    start, after = jax.vmap(run)(jnp.array([0.1, 0.05]))
    np.testing.assert_allclose(after.obs, [[0.1, 0.3], [0.05, 0.15]], rtol=1e-6)
    np.testing.assert_allclose(mjzoo.reward_terms(after)["speed"], [0.2, 0.1], rtol=1e-5)
    with pytest.raises(ValueError, match=r"params name 'ctrl_dt' is taken.*p\['ctrl_dt'\]"):
        mjzoo.task(XML, params={"ctrl_dt": 0.3})


def stacked(p, model, state):  # a hand-made history: the reset has no previous observation to keep
    return jnp.concatenate([state.obs, state.data.qpos, state.data.qvel])


@pytest.mark.parametrize("check", [True, False])
def test_an_observation_whose_shape_changes_is_named_before_the_guard_selects_between_them(check):
    # Unnamed, the divergence guard's select of [4] against [2] failed first ("Incompatible
    # shapes for broadcasting"): at construction, and without the check at the first trace.
    message = r"the observation differs between reset \(float32\[2\]\) and step \(float32\[4\]\)"
    with pytest.raises(ValueError, match=message):
        task = mjzoo.task(XML, observe=stacked, check=check)
        mjzoo.reset(task, jax.random.key(0))
