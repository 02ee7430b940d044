"""Native rollouts (`mjzoo.planning.native`): C MuJoCo's physics behind the same Task.

For the same controls from the same state, native and MJX give the same trajectories,
rewards and costs on every planning env (float32 MJX against float64 C: agreement to
1e-4, measured 1e-6); the quantities a reward reads are MJX's (sensors computed before
the step integrates, poses from the state before the last physics step, mocap sent as
a control); what C cannot give is refused at construction, by name.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.tree_util import Partial

import mjzoo
import mjzoo.envs
from mjzoo import physics
from mjzoo import planning
from mjzoo.algorithms import cma_es
from mjzoo.algorithms import dial
from mjzoo.algorithms import mppi
from mjzoo.catalog import actuators
from mjzoo.planning import closed_loop
from mjzoo.planning import native
from mjzoo.types import State
from mjzoo.types import Task

PLANNING_ENVS = ["pendulum_swingup", "cartpole_swingup", "cylinder_push", "point_mass"]
SAMPLES, HORIZON = 8, 25


def _both(task: Task, nat: native.Native, state: State, controls: jax.Array):
    """Costs [N] of `controls` [N, H, nu] and sample 0's qpos, rewards, sensordata and
    poses [H, ...] along the way: by MJX transitions (one compile of MJX's step), and by
    the native planner's costs and native transitions."""
    key = jax.random.key(2)

    def path(step, t, actions):
        def body(s, a):
            s = step(t, s, a, key)
            return s, (s.data.qpos, s.reward, s.data.sensordata, s.data.site_xpos, s.data.xpos, s.data.subtree_com)

        return jax.lax.scan(body, mjzoo.fill_transition_entries(task, state), actions)[1]

    paths = jax.jit(jax.vmap(lambda a: path(mjzoo.transition, task, a)))(controls)
    mjx_side = (-np.sum(np.asarray(paths[1]), axis=1), jax.tree.map(lambda x: x[0], paths))
    c_side = jax.jit(
        lambda: (
            native.rollout_costs(nat, state, controls, key)[0][0],
            path(native.transition_native, nat, controls[0]),
        )
    )()
    return jax.device_get(mjx_side), jax.device_get(c_side)


def _assert_agree(mjx_side, c_side) -> None:
    (costs_m, path_m), (costs_c, path_c) = mjx_side, c_side
    np.testing.assert_allclose(costs_c, costs_m, rtol=1e-4, atol=1e-4)
    for name, a, b in zip(("qpos", "reward", "sensordata", "site_xpos", "xpos", "subtree_com"), path_m, path_c):
        np.testing.assert_allclose(b, a, atol=1e-4, err_msg=name)


@pytest.mark.parametrize("env", PLANNING_ENVS)
def test_native_rollouts_match_mjx_on_every_planning_env(env):
    task = mjzoo.envs.make(env, episode_steps=10**9)
    nat = native.wrap(task)
    assert nat.engine.direct  # these envs apply their action as ctrl: no step runs before C
    state = mjzoo.reset(task, jax.random.key(3))
    controls = jax.random.uniform(jax.random.key(1), (SAMPLES, HORIZON, task.action_size), minval=-1, maxval=1)
    _assert_agree(*_both(task, nat, state, controls))


# A two-link arm with sensors of every stage (position, velocity, acceleration/force), a
# tip site, and a mocap target that a weld pulls a free box towards.
ARM = """
<mujoco>
  <option timestep="0.005"/>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.04" mass="1"/>
      <body name="lower" pos="0.4 0 0">
        <joint name="elbow" type="hinge" axis="0 1 0" damping="0.1"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="0.5"/>
        <site name="tip" pos="0.3 0 0"/>
      </body>
    </body>
    <body name="target" mocap="true" pos="0 0.5 1"><geom type="sphere" size="0.02" contype="0" conaffinity="0"/></body>
    <body name="box" pos="0 0.5 1"><freejoint/><geom type="box" size="0.05 0.05 0.05" mass="0.2" contype="0" conaffinity="0"/></body>
  </worldbody>
  <equality><weld body1="box" body2="target" solref="0.05 1"/></equality>
  <actuator>
    <motor name="shoulder" joint="shoulder" gear="5" ctrlrange="-1 1" ctrllimited="true"/>
    <motor name="elbow" joint="elbow" gear="3" ctrlrange="-1 1" ctrllimited="true"/>
  </actuator>
  <sensor>
    <framepos objtype="site" objname="tip"/>
    <jointvel joint="elbow"/>
    <actuatorfrc actuator="shoulder"/>
    <subtreecom body="upper"/>
  </sensor>
</mujoco>
"""


def _tip_height(p, model, state, action, next_state):
    return next_state.data.site_xpos[0, 2] + 0.1 * next_state.data.sensordata[2] + next_state.data.subtree_com[1, 0]


def _arm(**options) -> Task:
    return mjzoo.task(ARM, rewards={"tip": (_tip_height, 1.0)}, ctrl_dt=0.02, **options)


def _mocap_step(inner_step, model, state: State, action: jax.Array, key: jax.Array) -> State:
    """The first two action entries drive the motors, the last two move the mocap target."""
    target = state.data.mocap_pos.at[0, 0].add(0.01 * action[0]).at[0, 2].add(0.01 * action[1])
    return inner_step(model, state.replace(data=state.data.replace(mocap_pos=target)), action, key)


def test_sensors_poses_and_mocap_are_what_mjx_gives():
    """Sensors are computed before the step integrates, in C as in MJX; poses come from
    the state before the last physics step; a step that moves a mocap body sends it to
    C as a control at every physics step (the weld then pulls the box in both)."""
    task = _arm()
    task = task.replace(step=Partial(_mocap_step, task.step))
    nat = native.wrap(task)
    assert "mocap_pos" in nat.engine.fields and not nat.engine.direct
    state = jax.jit(mjzoo.reset)(task, jax.random.key(0))
    controls = jax.random.uniform(jax.random.key(1), (4, 40, 2), minval=-1, maxval=1)
    mjx_side, c_side = _both(task, nat, state, controls)
    _assert_agree(mjx_side, c_side)
    assert np.ptp(c_side[1][2][:, 0]) > 0.05  # the sensors do move


def _reads_contacts(p, model, state, action, next_state):
    return -jnp.sum(next_state.data._impl.contact.dist)


def _rest(data0, model, key) -> State:
    return State.create(data0, data0.qpos)


def _pd_step(actuator, model, state: State, action: jax.Array, key: jax.Array) -> State:
    data = actuators.step(model, state.data, actuator, action, 4, key)
    return state.replace(data=data, obs=data.qpos)


def _pd_arm() -> Task:
    """The arm under PD control evaluated at each of 4 physics steps per control step."""
    arm = physics.load(ARM, ctrl_dt=0.02)
    pd = actuators.pd(arm.mj_model, kp=20.0, kd=1.0)
    return Task(
        model=arm.model,
        start=Partial(_rest, arm.data0),
        step=Partial(_pd_step, pd),
        reward=Partial(_tip_reward),
        terminate=Partial(_never),
        mj_model=arm.mj_model,
    )


def _tip_reward(model, state, action, next_state) -> dict:
    return {"tip": next_state.data.site_xpos[0, 2]}


def _never(model, state):
    return jnp.zeros((), bool), jnp.zeros((), bool)


def test_what_c_cannot_give_is_refused_by_name():
    floor = ARM.replace("<worldbody>", '<worldbody><geom type="plane" size="2 2 0.1"/>')
    with pytest.raises(ValueError, match=r"reads data\.contact,.*contact sensor"):
        native.wrap(mjzoo.task(floor, rewards={"contact": (_reads_contacts, 1.0)}, ctrl_dt=0.02))
    with pytest.raises(ValueError, match="depend on the physics state"):
        native.wrap(_pd_arm())


def test_a_diverging_rollout_is_nan_in_c_and_caught_by_the_guard():
    """C MuJoCo resets a simulation whose acceleration explodes (to qpos0, time 0); the
    replay sees NaN from there on, so the task's divergence guard ends the episode and
    keeps the last good state, as it does for MJX's NaN."""
    task = mjzoo.task(ARM.replace('gear="5"', 'gear="1e13"'), rewards={"tip": (_tip_height, 1.0)}, ctrl_dt=0.02)
    nat = native.wrap(task)
    state = mjzoo.fill_transition_entries(task, jax.jit(mjzoo.reset)(task, jax.random.key(0)))
    actions = jnp.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]])  # the middle one explodes

    def run(s):
        def body(s, a):
            s = native.transition_native(nat, s, a, jax.random.key(0))
            return s, (s.metrics["diverged"], s.terminated, s.data.qpos)

        return jax.lax.scan(body, s, actions)[1]

    diverged, terminated, qpos = jax.device_get(jax.jit(run)(state))
    np.testing.assert_array_equal(diverged, [0.0, 1.0, 0.0])  # from the kept state, no force: fine again
    np.testing.assert_array_equal(terminated, [False, True, False])
    assert np.all(np.isfinite(qpos)) and np.array_equal(qpos[1], qpos[0])  # the last good state is kept


def _heavier(model, key):
    return {"body_mass": model.body_mass * jax.random.uniform(key, (), minval=0.5, maxval=2.0)}


def test_an_ensemble_rolls_out_one_c_model_per_member():
    task = mjzoo.envs.make("pendulum_swingup", episode_steps=10**9)
    ensemble = planning.ensemble(task, _heavier, 3, jax.random.key(0))
    nat = native.wrap(ensemble)
    assert len(nat.engine.models) == 3
    masses = [m.body_mass[1] for m in nat.engine.models]
    np.testing.assert_allclose(masses, np.asarray(ensemble.fields["body_mass"])[:, 1], rtol=1e-6)
    state = mjzoo.reset(task, jax.random.key(1))
    controls = jax.random.uniform(jax.random.key(2), (SAMPLES, HORIZON, 1), minval=-1, maxval=1)
    key = jax.random.key(3)
    costs_m = jax.jit(planning.rollout_costs)(ensemble, state, controls, key)[0]
    costs_c = jax.jit(native.rollout_costs)(nat, state, controls, key)[0]
    assert costs_c.shape == (3, SAMPLES)
    np.testing.assert_allclose(costs_c, costs_m, rtol=1e-4, atol=1e-4)
    assert np.ptp(np.asarray(costs_c)[:, 0]) > 1e-3  # the members differ


def test_split_replan_equals_the_one_jit_replan():
    """The host-driven replan (two jits around C) computes what the one-jit replan (C
    through jax.pure_callback) does: same samples, same C states, same plan."""
    task = mjzoo.envs.make("cartpole_swingup", episode_steps=10**9)
    nat = native.wrap(task)
    config = mppi.Config(num_samples=16, horizon_steps=20, num_knots=4)
    state = mjzoo.fill_transition_entries(task, jax.jit(mjzoo.reset)(task, jax.random.key(0)))
    plan = mppi.init(config, nat)
    replan = lambda p, s, k: closed_loop.replan(mppi, config, nat, p, s, k)  # noqa: E731
    key = jax.random.key(1)
    one, two = jax.jit(replan)(plan, state, key), native.split(replan)(plan, state, key)
    np.testing.assert_array_equal(one.knots, two.knots)
    assert float(one.cost) == float(two.cost) and np.isfinite(float(one.cost))


def _no_callback(*args, **kwargs):
    raise AssertionError("split reached C through jax.pure_callback")


@pytest.mark.parametrize("planner, iterations", [(dial, 2), (cma_es, 1), (cma_es, 2)])
def test_split_runs_each_iteration_from_the_host(planner, iterations, monkeypatch):
    """DIAL's iterations and CMA-ES's generations run C once each, the next sampling
    around the last one's result: on a native task they unroll in Python, so `split`
    runs each C call from the host between jits (no `jax.pure_callback`: it used to
    raise a leaked tracer, then jit the replan whole). The plan is `jax.jit`'s."""
    task = mjzoo.envs.make("pendulum_swingup", episode_steps=10**9)
    nat = native.wrap(task)
    config = planner.Config(num_samples=8, horizon_steps=10, num_knots=3, iterations=iterations)
    state = mjzoo.fill_transition_entries(task, jax.jit(mjzoo.reset)(task, jax.random.key(0)))
    replan = lambda p, s, k: closed_loop.replan(planner, config, nat, p, s, k)  # noqa: E731
    plan, key = planner.init(config, nat), jax.random.key(1)
    one = jax.jit(replan)(plan, state, key)
    calls = []
    engine_call = type(nat.engine).__call__
    monkeypatch.setattr(type(nat.engine), "__call__", lambda self, *a: calls.append(1) or engine_call(self, *a))
    monkeypatch.setattr(jax, "pure_callback", _no_callback)
    two = native.split(replan)(plan, state, key)
    assert len(calls) == iterations  # one C call per iteration, each from the host
    np.testing.assert_allclose(one.knots, two.knots, rtol=1e-5, atol=1e-6)  # XLA fuses the stages otherwise
    np.testing.assert_allclose(float(one.cost), float(two.cost), rtol=1e-6)
    assert np.isfinite(float(one.cost))


def test_native_needs_jax_physics_and_one_model_to_simulate():
    task = mjzoo.envs.make("pendulum_swingup")
    ensemble = planning.ensemble(task, _heavier, 2, jax.random.key(0))
    with pytest.raises(TypeError, match="one model"):
        native.transition_native(
            native.wrap(ensemble), jax.jit(mjzoo.reset)(task, jax.random.key(0)), jnp.zeros(1), jax.random.key(0)
        )
