"""The physics implementations (`mjzoo.physics`, impl="jax" | "warp") on a machine
without CUDA: MJX-JAX is the default and Warp's helpers are identities on it; asking
for Warp fails with one clear message (at load, through the registry, on the command
line); contacts, the capacity probe and gradients on JAX; training's physics record
and capacity check. The Warp path itself runs in benchmarks/warp_conformance.py on a
GPU (and in the last test here, with MJZOO_WARP_ON_CPU=1 on a machine with Warp)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import types

import catalog_tasks
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

import mjzoo
import mjzoo.envs
from mjzoo import batching
from mjzoo import physics
from mjzoo import running
from mjzoo.catalog import contacts as catalog_contacts
from mjzoo.harness import cli
from mjzoo.harness import training
from mjzoo.planning import realtime
from mjzoo.testing import check_task

# A 2 kg box resting on the floor: four corner contacts carrying m g between them.
BOX_MASS = 2.0
BOX = f"""
<mujoco model="box-on-floor">
  <option timestep="0.005"/>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <body name="box" pos="0 0 0.12">
      <freejoint/>
      <geom name="box" type="box" size="0.1 0.1 0.1" mass="{BOX_MASS}"/>
    </body>
  </worldbody>
</mujoco>
"""
PENDULUM = """
<mujoco model="pendulum">
  <option timestep="0.01"/>
  <worldbody>
    <body name="pole">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.05"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.02" mass="0.5" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator><motor joint="hinge"/></actuator>
</mujoco>
"""


@pytest.fixture
def no_cuda(monkeypatch):
    """A machine with Warp installed and no CUDA GPU, MJZOO_WARP_ON_CPU unset."""
    monkeypatch.setattr(physics, "_has_cuda", lambda: False)
    monkeypatch.setattr(physics, "_warp_installed", lambda: True)
    monkeypatch.delenv(physics.WARP_ON_CPU, raising=False)


@pytest.fixture
def no_warp(monkeypatch):
    """A machine without MuJoCo Warp (as CI)."""
    monkeypatch.setattr(physics, "_warp_installed", lambda: False)


# --- options and the default ----------------------------------------------------------


def test_an_unknown_impl_is_a_value_error_naming_the_choices():
    with pytest.raises(ValueError, match=r"impl='bogus'.*\['jax', 'warp'\]"):
        physics.load(PENDULUM, impl="bogus")


@pytest.mark.parametrize("name", ["max_contacts", "max_constraints"])
def test_a_capacity_of_zero_is_a_value_error_naming_the_option(name):
    with pytest.raises(ValueError, match=f"{name}=0"):
        physics.load(PENDULUM, **{name: 0})


def test_the_default_on_a_machine_without_cuda_is_jax():
    assert not physics._has_cuda()
    assert physics.default_impl() == "jax"
    assert physics.load(PENDULUM).impl == "jax"


# --- asking for Warp without it ---------------------------------------------------------


def test_warp_without_cuda_says_so_and_names_impl_jax(no_cuda):
    with pytest.raises(ValueError, match="CUDA") as error:
        physics.load(PENDULUM, impl="warp")
    assert "impl='jax'" in str(error.value) and physics.WARP_ON_CPU in str(error.value)


def test_warp_not_installed_says_how_to_install_it(no_warp):
    with pytest.raises(ValueError, match=r"pip install -e '\.\[warp\]'"):
        physics.load(PENDULUM, impl="warp")


@pytest.mark.parametrize(
    "machine, words", [("no_cuda", ["CUDA", "impl='jax'"]), ("no_warp", ["pip install -e '.[warp]'"])]
)
def test_warp_through_the_registry_fails_the_same_way(request, machine, words):
    request.getfixturevalue(machine)
    with pytest.raises(ValueError) as error:
        mjzoo.envs.make("cartpole_balance", impl="warp")
    assert all(word in str(error.value) for word in words), error.value


@pytest.mark.parametrize("machine, word", [("no_cuda", "CUDA"), ("no_warp", "pip install")])
def test_warp_on_the_command_line_is_one_line_error(request, capsys, tmp_path, monkeypatch, machine, word):
    request.getfixturevalue(machine)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["train", "ppo", "cartpole_balance", "--impl", "warp"])
    err = capsys.readouterr().err
    assert exit_info.value.code not in (0, None)
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("mjzoo train: ") and word in err and "impl='warp'" in err, err
    assert list(tmp_path.iterdir()) == []  # nothing written


# --- Warp's helpers are identities on JAX ----------------------------------------------


def _two_states() -> tuple[mjx.Data, mjx.Data]:
    data0 = physics.load(PENDULUM).data0
    return data0, data0.replace(qpos=data0.qpos + 1.0, qvel=data0.qvel - 2.0, time=jnp.float32(3.0))


def test_sized_and_own_leave_jax_data_alone():
    data, _ = _two_states()
    assert batching.sized(data, 8) is data
    assert batching.own(data) is data
    task = mjzoo.envs.make("cartpole_balance")
    for changed in (batching.sized(task, 8), batching.own(task)):
        assert all(a is b for a, b in zip(jax.tree.leaves(changed), jax.tree.leaves(task), strict=True))


def test_partition_splits_each_worlds_leaves_and_keeps_scalars_whole():
    task = mjzoo.envs.make("cartpole_balance")
    states = jax.vmap(lambda k: running.reset(task, k))(jax.random.split(jax.random.key(0), 4))
    tree = {"states": states, "count": jnp.zeros(())}
    specs = batching.partition(tree)
    split, whole = jax.sharding.PartitionSpec(batching.AXIS), jax.sharding.PartitionSpec()
    assert jax.tree.leaves(specs["count"]) == [whole]
    leaves, specs = jax.tree.leaves(states), jax.tree.leaves(specs["states"])
    assert len(leaves) == len(specs) and all(spec == split for spec in specs)


def test_vmap_transition_is_jax_vmap_on_jax_physics_under_a_mesh():
    """On MJX-JAX, XLA splits the batch by itself: no shard_map, the plain vmap's result."""
    task = mjzoo.envs.make("cartpole_balance")
    keys = jax.random.split(jax.random.key(0), 4)
    states = jax.vmap(lambda k: running.reset(task, k))(keys)
    actions = jnp.linspace(-1.0, 1.0, 4)[:, None] * jnp.ones((4, task.action_size))
    plain = jax.vmap(running.transition, in_axes=(None, 0, 0, 0))(task, states, actions, keys)
    with jax.sharding.use_abstract_mesh(jax.sharding.AbstractMesh((2,), (batching.AXIS,))):  # traced only
        jaxpr = jax.make_jaxpr(lambda s: batching.vmap_transition(running.transition, task, s, actions, keys))(states)
    assert "shard_map" not in str(jaxpr) and "dot_general" in str(jaxpr)
    mapped = batching.vmap_transition(running.transition, task, states, actions, keys)
    jax.tree.map(np.testing.assert_array_equal, mapped, plain)


@pytest.mark.parametrize("cond", [True, False])
def test_where_is_leafwise_jnp_where_on_jax(cond):
    a, b = _two_states()
    merged = batching.where(jnp.asarray(cond), a, b)
    expected = jax.tree.map(lambda x, y: jnp.where(cond, x, y), a, b)
    assert jax.tree.structure(merged) == jax.tree.structure(expected)
    for x, y in zip(jax.tree.leaves(merged), jax.tree.leaves(expected), strict=True):
        np.testing.assert_array_equal(x, y)


def test_no_overflow_on_jax():
    data, _ = _two_states()
    assert batching.overflow(data).shape == () and int(batching.overflow(data)) == 0
    assert batching.clear_overflow(data) is data


def test_the_divergence_guard_adds_no_physics_metrics_on_jax():
    task = mjzoo.with_divergence_guard(catalog_tasks.make_task())
    key = jax.random.key(0)
    action = jnp.zeros(task.action_size)
    after = jax.eval_shape(lambda k: running.transition(task, running.reset(task, k), action, k), key)
    assert "diverged" in after.metrics
    assert not [name for name in after.metrics if name.startswith("physics/")], sorted(after.metrics)


# --- contacts and capacities on JAX ----------------------------------------------------


@pytest.fixture(scope="module")
def settled_box():
    """(physics, C MuJoCo data after 2 s of settling, the MJX Data forwarded from it)."""
    box = physics.load(BOX)
    mj_data = mujoco.MjData(box.mj_model)
    for _ in range(400):
        mujoco.mj_step(box.mj_model, mj_data)
    data = jax.jit(mjx.forward)(box.model, mjx.put_data(box.mj_model, mj_data, impl="jax"))
    return box, mj_data, data


def test_contacts_of_a_resting_box_carry_its_weight(settled_box):
    box, _, data = settled_box
    found = batching.contacts(data, box.model)
    floor, body = box.id("geom", "floor"), box.id("geom", "box")
    between = ((found.geom1 == floor) & (found.geom2 == body)) | ((found.geom1 == body) & (found.geom2 == floor))
    assert bool(jnp.any(found.active & between))
    assert not bool(jnp.any(found.active & ~between))  # nothing else touches
    assert float(jnp.sum(jnp.where(found.active, 0.0, jnp.abs(found.normal_force)))) == 0.0
    weight = BOX_MASS * -float(box.mj_model.opt.gravity[2])
    np.testing.assert_allclose(float(jnp.sum(found.normal_force)), weight, rtol=0.02)
    assert batching.contacts(data).normal_force is None  # no model: no forces


def test_catalog_contacts_read_what_they_read_before(settled_box):
    """touching / forces through batching.contacts equal the direct read of MJX-JAX's
    contact slots and constraint forces (the catalog's code before batching.contacts)."""
    box, _, data = settled_box
    geoms, others = catalog_contacts.geom_sets(box.mj_model, ["box"], ["floor"], "test")
    contact = data._impl.contact
    pairs = ((contact.geom1 == geoms[:, None]) & jnp.isin(contact.geom2, others)) | (
        (contact.geom2 == geoms[:, None]) & jnp.isin(contact.geom1, others)
    )
    active = contact.dist < contact.includemargin
    rows = 2 * (np.asarray(contact.dim) - 1)  # pyramidal cones (the default): the edge forces add up
    address = np.asarray(contact.efc_address)
    normal = jnp.stack([jnp.sum(data._impl.efc_force[a : a + r]) if a >= 0 else 0.0 for a, r in zip(address, rows)])
    np.testing.assert_array_equal(catalog_contacts.touching(data, geoms, others), jnp.any(pairs & active, axis=1))
    np.testing.assert_allclose(
        catalog_contacts.forces(box.model, data, geoms, others), jnp.sum(pairs * normal[None, :], axis=1), rtol=1e-6
    )
    assert bool(catalog_contacts.touching(data, geoms, others)[0])


def test_probe_capacity_leaves_room_for_twice_what_c_mujoco_sees(settled_box):
    box, mj_data, _ = settled_box
    assert mj_data.ncon >= 4  # the box's corners
    most_contacts, most_rows = batching.probe_capacity(box.mj_model)
    assert most_contacts >= max(2 * mj_data.ncon, 8)
    assert most_rows >= 2 * mj_data.nefc


# --- derivatives ------------------------------------------------------------------------


def test_gradients_flow_through_physics_step_on_jax():
    pendulum = physics.load(PENDULUM)
    data = pendulum.data0.replace(qpos=jnp.array([0.3]))

    def final_angle(ctrl: jax.Array) -> jax.Array:
        return physics.step(pendulum.model, data, ctrl, 1).qpos[0]  # a substep: compiles in seconds

    grad = jax.jit(jax.grad(final_angle))(jnp.array([0.5]))
    assert bool(jnp.all(jnp.isfinite(grad))) and float(grad[0]) > 0.0  # pushing the hinge turns it


def test_warp_data_is_reported_as_not_differentiable():
    physics.check_differentiable(_two_states()[0], "a JAX gradient")  # no error
    stand_in = types.SimpleNamespace(impl=mjx.Impl.WARP)
    with pytest.raises(NotImplementedError, match="impl='jax'") as error:
        physics.check_differentiable(stand_in, "my gradient")
    assert str(error.value).startswith("my gradient: ") and "impl='warp'" in str(error.value)


# --- training's record and capacity check ------------------------------------------------


def test_training_records_the_jax_physics():
    assert training.physics_info(mjzoo.envs.make("cartpole_balance", impl="jax")) == {"impl": "jax"}


def test_training_stops_when_warp_outgrew_its_capacity():
    task = mjzoo.envs.make("cartpole_balance")
    training._check_capacity(task, {"env/physics/capacity_overflow": 0.0, "env/physics/solver_limit": 0.5})
    with pytest.raises(training.PhysicsCapacityError, match="max_contacts"):
        training._check_capacity(task, {"env/physics/capacity_overflow": 0.01})


def test_warp_over_several_gpus_is_refused_with_the_way_out(monkeypatch):
    """It crashed XLA's GPU compiler in one process and in one per GPU
    (benchmarks/results/scaling/): one clear error instead, naming MJX-JAX."""
    from mjzoo.harness import devices as placement

    monkeypatch.setattr(placement, "template_data", lambda tree: types.SimpleNamespace(impl=mjx.Impl.WARP))
    gpus = [types.SimpleNamespace(process_index=jax.process_index(), platform="gpu") for _ in range(2)]
    with pytest.raises(NotImplementedError, match=r"over 2 GPUs.*one process or one per GPU.*impl='jax'"):
        placement.shard_envs({"collector": jnp.zeros(4)}, ["collector"], gpus)
    other = [types.SimpleNamespace(process_index=jax.process_index() + 1, platform="gpu")]
    with pytest.raises(NotImplementedError, match="over 2 GPUs"):
        placement._check_warp_gpus({}, gpus[:1] + other)  # one GPU per process crashed too
    monkeypatch.setenv(placement.WARP_GPUS, "1")
    placement._check_warp_gpus({}, gpus)  # asked for: tried
    monkeypatch.delenv(placement.WARP_GPUS)
    monkeypatch.setattr(placement, "template_data", lambda tree: types.SimpleNamespace(impl=mjx.Impl.JAX))
    placement._check_warp_gpus({}, gpus)  # MJX-JAX on the same GPUs: allowed
    cpus = [types.SimpleNamespace(process_index=0, platform="cpu") for _ in range(2)]
    monkeypatch.setattr(placement, "template_data", lambda tree: types.SimpleNamespace(impl=mjx.Impl.WARP))
    placement._check_warp_gpus({}, cpus)  # Warp over CPU devices runs (the tests below)


# --- Warp itself (developers: Warp installed, MJZOO_WARP_ON_CPU=1) ----------------------


needs_warp = pytest.mark.skipif(
    importlib.util.find_spec("warp") is None or os.environ.get(physics.WARP_ON_CPU) != "1",
    reason=f"needs MuJoCo Warp installed and {physics.WARP_ON_CPU}=1 (Warp's slow CPU backend; "
    "benchmarks/warp_conformance.py checks every env on a GPU)",
)


@needs_warp
def test_playground_envs_on_warp_print_no_solver_warnings():
    playground = pytest.importorskip("mjzoo.interop.playground")
    env = playground.load("CartpoleBalance", impl="warp")
    assert env.mjx_model.opt._impl.warn_overflow == 0  # for Brax stepping the same env too
    assert playground.task(env).model.opt._impl.warn_overflow == 0


@needs_warp
def test_cartpole_conforms_on_warp():
    report = check_task(mjzoo.envs.make("cartpole_balance", impl="warp", episode_steps=6), num_steps=10)
    assert report.skipped == {}


@needs_warp
def test_a_warp_batch_resets_as_each_env_would(monkeypatch):
    """The batched auto-reset (one branch for the batch, Warp's shared contact pool passed
    through unbatched) gives the same states as choosing per env, bit for bit."""
    from mjzoo import combinators

    def rollout() -> tuple:
        task = batching.sized(
            mjzoo.with_auto_reset(mjzoo.envs.make("cartpole_balance", impl="warp", episode_steps=6)), 4
        )
        states = jax.vmap(lambda k: running.reset(task, k))(jax.random.split(jax.random.key(0), 4))
        actions = jnp.linspace(-1.0, 1.0, 4)[:, None] * jnp.ones((4, task.action_size))

        def body(states, key):
            states = jax.vmap(lambda s, a, k: running.transition(task, s, a, k))(
                states, actions, jax.random.split(key, 4)
            )
            return states, (states.obs, states.data.qpos, states.truncated)

        return jax.jit(lambda s: jax.lax.scan(body, s, jax.random.split(jax.random.key(1), 14))[1])(states)

    batched = rollout()
    monkeypatch.setattr(combinators, "_restarted", combinators._restarted_select)
    chosen_per_env = rollout()
    assert int(batched[2].sum()) == 2 * 4  # every env restarted twice in 14 steps
    jax.tree.map(np.testing.assert_array_equal, batched, chosen_per_env)


def _upright(p, model, state, action, next_state):
    return jnp.cos(next_state.data.qpos[0])


@needs_warp
def test_a_warp_task_of_one_substep_per_control_step_evaluates():
    """MJX's Warp step called bare under the evaluation's vmap inside its scan leaked its
    tracers (UnexpectedTracerError); a run of such a task failed at its first evaluation."""
    from mjzoo import learning

    task = mjzoo.task(PENDULUM, rewards={"upright": _upright}, time_limit=20, impl="warp", ctrl_dt=0.01)
    assert mjzoo.control_dt(task) == pytest.approx(task.mj_model.opt.timestep)  # one substep
    policy = learning.feed_forward(lambda obs, key: (jnp.zeros(task.action_size), ()))
    returns = jax.jit(lambda t, k: learning.evaluate(t, policy, k, 2, 20).returns)(task, jax.random.key(0))
    np.testing.assert_allclose(returns, 20.0, rtol=1e-4)  # hanging still: cos 0 = 1 a step


@needs_warp
def test_a_warp_tracking_evaluation_gives_every_episode_its_contacts():
    """`tracking.closed_loop` sizes Warp's contact pool for its episodes: before, one
    world's pool served them all, and the episodes without contacts fell through the floor
    (a G1's tracking and joystick evaluations on a GPU counted nearly every one as a fall)."""
    from mjzoo.interop import tracking

    def falls(impl: str) -> np.ndarray:
        task = mjzoo.envs.make("ant_joystick", impl=impl)
        act = lambda obs: jnp.zeros(task.action_size)  # noqa: E731
        return np.asarray(jax.jit(lambda k: tracking.closed_loop(task, act, k, 16, 20))(jax.random.key(0))[3])

    warp, jax_ = falls("warp"), falls("jax")
    assert not jax_.any()  # resting ants stand for a second (unsized, Warp had 12 of 16 fall)
    np.testing.assert_array_equal(warp, jax_)


WARP_TWO_DEVICES = """
import os, sys
import jax, numpy as np
import mjzoo.envs
from mjzoo.algorithms import ppo
from mjzoo.harness import devices as placement
assert jax.device_count() == 2
config = ppo.Config(num_envs=8, unroll_length=4, num_minibatches=2, num_epochs=1, total_steps=64)
task = mjzoo.envs.make("hopper", impl="warp")
init, update = jax.jit(ppo.init, static_argnums=0), jax.jit(lambda t, s: ppo.update(config, t, s))
states = []
for devices in (jax.devices()[:1], jax.devices()):
    state = placement.shard_envs(init(config, task, ppo.Hyperparams(), jax.random.key(0)), ppo.PER_ENV_FIELDS, devices)
    with jax.set_mesh(placement.env_mesh(devices)):  # Warp's physics splits over it
        for _ in range(2):
            state, _ = update(placement.replicate(task, devices), state)
    states.append(state)
assert len(states[1].collector.env_state.data.qpos.sharding.device_set) == 2
one, two = (jax.device_get(s.collector.env_state.data) for s in states)
print("max qpos difference", np.max(np.abs(one.qpos - two.qpos)), "contacts", one._impl.nacon, two._impl.nacon)
np.testing.assert_allclose(one.qpos, two.qpos, atol=1e-5)
assert int(one._impl.nacon[0]) == int(two._impl.nacon[0]) > 0  # each device's count, summed
sys.stdout.flush()
os._exit(0)  # Warp's CPU backend can keep the interpreter from exiting
"""


@needs_warp
def test_warp_training_on_two_devices_matches_one_device(cpu_devices_env):
    """Each device steps its own worlds with its share of Warp's contact pool
    (`batching.vmap_transition` under the mesh): two updates of PPO on the hopper give one
    device's states, and the devices' contact counts add up to one device's."""
    result = subprocess.run(
        [sys.executable, "-c", WARP_TWO_DEVICES], env=cpu_devices_env(2), capture_output=True, text=True, timeout=900
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert "max qpos difference" in result.stdout


@needs_warp
def test_a_warp_planner_plans_from_a_natively_stepped_world():
    """A planner on MuJoCo Warp beside a world in C MuJoCo (whose states are MJX-JAX's):
    the world's state is carried onto Warp's data (`physics.switch_impl`) at each replan,
    so from the same start and key its first plan is the one it makes beside a world on
    Warp; the closed loop then runs on."""
    from mjzoo.algorithms import mppi

    fields = dict(num_samples=8, horizon_steps=5, num_knots=3)
    config, hyperparams = mjzoo.planning.configure(
        mppi, {**mjzoo.envs.hyperparameters("pendulum_swingup", "mppi"), **fields}
    )
    runs, problems = {}, {}
    for world in ("native", "mjx"):
        problem = mjzoo.envs.closed_loop_problem(
            "pendulum_swingup",
            mppi,
            config,
            seconds=0.2,
            backend="mjx",
            hyperparams=hyperparams,
            sim_backend=world,
            impl="warp",
        )
        assert problem.plan_task.model.impl == mjx.Impl.WARP
        runs[world] = realtime.realtime(problem, jax.random.key(0), clock="simulated")[0]
        problems[world] = problem
    with pytest.raises(ValueError, match="clock='simulated'"):  # one jitted scan, one implementation
        realtime.offline(problems["native"], jax.random.key(0))
    assert runs["native"].controls.shape[0] == 10 and np.isfinite(runs["native"].costs).all()
    np.testing.assert_allclose(runs["native"].controls[0], runs["mjx"].controls[0], atol=1e-5)

    jax_data = mjzoo.reset(mjzoo.envs.make("pendulum_swingup", impl="jax"), jax.random.key(1)).data
    warp_data = mjzoo.reset(mjzoo.envs.make("pendulum_swingup", impl="warp"), jax.random.key(2)).data
    moved = physics.switch_impl(jax_data, warp_data)
    assert moved.impl == mjx.Impl.WARP and physics.switch_impl(jax_data, jax_data) is jax_data
    np.testing.assert_array_equal(moved.qpos, jax_data.qpos)
    np.testing.assert_array_equal(moved.xpos, jax_data.xpos)
