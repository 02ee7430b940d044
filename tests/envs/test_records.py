"""Every shipped env is one `mjzoo.task` with named numbers, and a typed record
(`EnvSpec`) in the registry holds its factory, hyperparameters and planning setup."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo.envs import base
from mjzoo.envs import cartpole
from mjzoo.envs import humanoid_amp
from mjzoo.envs import locomotion
from mjzoo.envs import pendulum
from mjzoo.envs import point_mass

# The reward weights and limits each registered env must expose by name (mjzoo.params).
NAMED = {
    "pendulum_swingup": {"upright_weight", "velocity_weight", "effort_weight", "init_noise", "velocity_bound"},
    "cartpole_balance": {"upright_weight", "centered_weight", "effort_weight", "fall_angle", "init_noise"},
    "cartpole_swingup": {"upright_weight", "velocity_weight", "centered_margin", "init_angle", "init_noise"},
    "point_mass": {"reach_weight", "effort_weight", "target_radius", "reach_margin", "spawn_range"},
    "cylinder_push": {"goal_weight", "approach_weight", "effort_weight", "margin", "spawn_range"},
    "hopper": {"forward_weight", "alive_weight", "effort_weight", "min_height", "max_tilt", "reset_noise"},
    "walker": {"forward_weight", "alive_weight", "effort_weight", "min_height", "max_tilt", "reset_noise"},
    "cheetah": {"forward_weight", "effort_weight", "reset_noise", "qpos0"},
    "ant": {"forward_weight", "alive_weight", "effort_weight", "min_height", "max_height", "reset_noise"},
    "humanoid_walk": {"forward_weight", "max_speed", "alive_weight", "effort_weight", "min_height", "reset_noise"},
    "humanoid_run": {"forward_weight", "alive_weight", "effort_weight", "min_height", "reset_noise"},
    "humanoid_standup": {"height_weight", "effort_weight", "reset_noise"},
    "ant_joystick": {"tracking_weight", "progress_weight", "action_rate_weight", "tracking_sigma", "max_tilt"},
    "humanoid_amp_walk": {"alive_weight", "effort_weight", "min_height", "reset_noise"},
    "humanoid_amp_joystick": {"tracking_weight", "yaw_tracking_weight", "tracking_sigma", "alive_weight"},
    "cartpole_amp_swingup": {"upright_weight", "centered_weight", "velocity_weight", "effort_weight"},
}
# The robot joysticks are one factory (envs/robot_joystick.py) on four models (and the G1 AMP one on it): one
# name stands for all in the parameter check (building a robot task takes ~7 s here).
ROBOT_JOYSTICK = {"tracking_weight", "yaw_tracking_weight", "air_time_weight", "foot_slip_weight", "stand_still_weight"}
ROBOTS = (
    "g1_joystick",
    "t1_joystick",
    "berkeley_humanoid_joystick",
    "go1_joystick",
    "g1_amp_joystick",
    "g1_track",
    "g1_standup",
    "go1_trot",
    "leap_cube_rotate",
    "panda_pick",
)


def test_every_registered_env_has_a_record_and_a_listed_expectation():
    assert set(NAMED) | set(ROBOTS) == set(mjzoo.envs.names())
    for name in mjzoo.envs.names():
        record = mjzoo.envs.record(name)
        assert isinstance(record, base.EnvSpec) and record.description
        assert mjzoo.envs.factory(name) is record.make


@pytest.mark.parametrize("name", [*sorted(NAMED), "go1_joystick"])
def test_params_name_every_weight_and_limit(name):
    task = mjzoo.envs.make(name)
    params = mjzoo.params(task)
    expected = NAMED.get(name, ROBOT_JOYSTICK)
    assert expected <= set(params), sorted(expected - set(params))
    # The factory's numeric defaults are the task's parameters, with the same values.
    for key, default in mjzoo.envs.defaults(name).items():
        if key in params and isinstance(default, float) and params[key].shape == ():
            np.testing.assert_allclose(params[key], default, rtol=1e-6, err_msg=key)


@jax.jit
def _transition(task, key):
    """One transition from a reset with every action at half its range."""
    return mjzoo.transition(task, mjzoo.reset(task, key), jnp.full(task.action_size, 0.5), key)


@pytest.mark.parametrize(
    ("name", "change", "term"),
    [("pendulum_swingup", dict(upright_weight=3.0), "upright"), ("hopper", dict(forward_weight=-2.0), "forward")],
)
def test_with_params_changes_the_reward_without_recompiling(name, change, term):
    task, key = mjzoo.envs.make(name), jax.random.key(1)
    before = mjzoo.reward_terms(_transition(task, key))[term]
    compiled = _transition._cache_size()
    after = mjzoo.reward_terms(_transition(task.with_params(**change), key))[term]
    assert _transition._cache_size() == compiled, "with_params recompiled the transition"
    parameter, weight = next(iter(change.items()))
    old = float(mjzoo.params(task)[parameter])
    assert float(before) != 0.0
    np.testing.assert_allclose(after, before * weight / old, rtol=1e-5)


def test_with_params_moves_a_catalog_item_s_limit():
    """`builder.named` makes a catalog termination's number a parameter: a hopper one step
    from its start pose ends when min_height is raised above its torso, and the metric
    names the termination."""
    task, key = mjzoo.envs.make("hopper"), jax.random.key(1)
    assert not bool(_transition(task, key).terminated)
    compiled = _transition._cache_size()
    raised = _transition(task.with_params(min_height=5.0), key)
    assert bool(raised.terminated) and float(raised.metrics["termination/too_low"]) == 1.0
    assert float(raised.metrics["termination/tilted"]) == 0.0
    assert _transition._cache_size() == compiled


def test_hyperparameters_and_planning_come_from_the_records():
    assert mjzoo.envs.hyperparameters("pendulum_swingup", "ppo") == pendulum.PPO
    assert mjzoo.envs.hyperparameters("pendulum_swingup", "mppi") == pendulum.PLANNING.configs["mppi"]
    assert mjzoo.envs.hyperparameters("cartpole_balance", "ppo") == cartpole.BALANCE_PPO
    assert mjzoo.envs.hyperparameters("cartpole_balance", "mppi") == {}
    assert mjzoo.envs.hyperparameters("humanoid_walk", "ppo") == locomotion.PPO["humanoid_walk"]
    assert mjzoo.envs.hyperparameters("humanoid_amp_walk", "amp") == humanoid_amp.AMP
    assert mjzoo.envs.hyperparameters("humanoid_amp_walk", "ppo") == {}
    assert mjzoo.envs.planning("point_mass") is point_mass.PLANNING
    with pytest.raises(KeyError, match="has no planning setup; envs with one: .*'point_mass'"):
        mjzoo.envs.planning("hopper")


def test_amps_reference_comes_from_the_record_or_the_factorys_module():
    """Every env with AMP hyperparameters names its reference; a user's factory module
    its ``REFERENCE``; the CLI hands it to algorithms whose `make` takes one."""
    from mjzoo.algorithms import amp
    from mjzoo.algorithms import ppo
    from mjzoo.harness.cli.arguments import imitated

    with_amp = [name for name in mjzoo.envs.names() if mjzoo.envs.record(name).amp is not None]
    assert with_amp and all(mjzoo.envs.record(name).reference is not None for name in with_amp)
    task = mjzoo.envs.make("cartpole_amp_swingup")
    ref = mjzoo.envs.reference("cartpole_amp_swingup", task, ctrl_dt=0.02)
    assert isinstance(ref, mjzoo.motion.Reference) and ref.qpos.shape[1] == task.mj_model.nq
    assert imitated(ppo, "cartpole_amp_swingup", task, {}) == ()
    (given,) = imitated(amp, "cartpole_amp_swingup", task, {})
    np.testing.assert_array_equal(given.qpos, ref.qpos)
    user = "tests.harness.test_distributed:block_amp_task"
    assert mjzoo.envs.reference(user, mjzoo.envs.make(user)).names == ("slide",)
    with pytest.raises(ValueError, match="defines no REFERENCE, the function \\(task, \\*\\*overrides\\)"):
        mjzoo.envs.reference("mjzoo.envs.cartpole:swingup", task)
    with pytest.raises(KeyError, match="has no motion reference for AMP; envs with one: .*'humanoid_amp_walk'"):
        mjzoo.envs.reference("cartpole_swingup", task)


def test_register_takes_a_record_or_a_factory(monkeypatch):
    monkeypatch.setattr(mjzoo.envs, "_REGISTRY", dict(mjzoo.envs._REGISTRY))
    mjzoo.envs.register("my_pendulum", base.EnvSpec(make=pendulum.swingup, description="mine", ppo={"num_envs": 8}))
    assert mjzoo.envs.hyperparameters("my_pendulum", "ppo") == {"num_envs": 8}
    mjzoo.envs.register("my_cartpole", cartpole.swingup, {"ppo": {"num_envs": 4}}, cartpole.SWINGUP_PLANNING)
    assert mjzoo.envs.record("my_cartpole").planning is cartpole.SWINGUP_PLANNING
    with pytest.raises(ValueError, match=r"hyperparameters for \['mppi'\] belong in the planning setup"):
        mjzoo.envs.register("my_other", cartpole.swingup, {"mppi": {}})
    with pytest.raises(TypeError, match="make must be a function"):
        base.EnvSpec(make=3, description="x")


@pytest.mark.parametrize("module", ["__init__", "base", "pendulum", "point_mass", "cylinder_push", "locomotion"])
def test_the_registry_imports_nothing_from_planning_realtime_at_load(module):
    """Only `closed_loop_problem` imports the real-time runner, when it is called (and
    type annotations, under TYPE_CHECKING)."""
    tree = ast.parse((Path(mjzoo.envs.__file__).parent / f"{module}.py").read_text())
    for node in tree.body:  # module level: imports inside `if TYPE_CHECKING:` are not run
        if isinstance(node, ast.ImportFrom):
            assert "realtime" not in (node.module or ""), ast.unparse(node)
            assert all(alias.name != "realtime" for alias in node.names), ast.unparse(node)


def test_importing_the_registry_loads_no_real_time_runner():
    """What `import mjzoo.envs` loads, in a fresh process: the closed loop's hooks that the
    planning setups name, but not `planning.realtime` (nor its clock)."""
    script = "import sys, mjzoo.envs; print('mjzoo.planning.realtime' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
