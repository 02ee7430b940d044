"""`mjzoo.solver`: a model's solver settings and the work they allow per control step,
the shipped envs' settings, their accuracy against the model's own in C MuJoCo, and the
warning `mjzoo.task` gives once for a contact model that keeps MuJoCo's defaults."""

from __future__ import annotations

import warnings

import pytest

import mjzoo
from mjzoo import solver

# A 1 kg ball resting on a floor, pushed along x (friction: a contact's cone to solve).
# No <option> for the solver: MuJoCo's Newton with 100 iterations and 50 line-search
# steps; RK4 at 0.01 s.
BALL = """
<mujoco model="ball">
  <option timestep="0.01" integrator="RK4">{flags}</option>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <body name="ball" pos="0 0 0.1">
      <joint name="z" type="slide" axis="0 0 1"/><joint name="x" type="slide" axis="1 0 0"/>
      <geom type="sphere" size="0.1" mass="1"/>
    </body>
  </worldbody>
  <actuator><motor joint="x" gear="20" ctrlrange="-1 1" ctrllimited="true"/></actuator>
</mujoco>
"""
ROLLING = BALL.format(flags="")
NO_CONTACTS = BALL.format(flags='<flag contact="disable"/>')


def test_settings_name_the_solver_and_bound_the_iterations_of_a_control_step():
    physics = mjzoo.physics.load(ROLLING, ctrl_dt=0.04)
    found = solver.settings(physics)
    assert (found.solver, found.iterations, found.ls_iterations, found.integrator) == ("newton", 100, 50, "rk4")
    # 4 substeps x 4 RK4 stages = 16 solves, each up to 100 iterations.
    assert (found.n_substeps, found.stages, found.solves, found.bound) == (4, 4, 16, 1600)
    assert found.contacts and found.euler_damping and found.costly
    assert str(found).endswith("rk4 (4 solves a step), 4 substep(s): up to 1600 solver iterations per control step")

    fast = solver.shipped(physics)
    settled = solver.settings(fast)
    assert (settled.iterations, settled.ls_iterations, settled.bound) == (4, 4, 64)
    assert not settled.euler_damping and not settled.costly
    assert fast.n_substeps == 4 and fast.dt == physics.dt == 0.01
    assert physics.mj_model.opt.iterations == 100  # the loaded model is left as it was
    assert solver.settings(solver.shipped(physics, iterations=1)).bound == 16

    assert not solver.settings(mjzoo.physics.load(NO_CONTACTS)).contacts
    apart = ROLLING.replace('type="sphere"', 'type="sphere" contype="2" conaffinity="2"')  # never meets the floor
    assert not solver.settings(mjzoo.physics.load(apart)).contacts


def test_the_shipped_settings_are_the_planar_locomotion_envs():
    from mjzoo.envs import locomotion

    assert solver.SHIPPED == locomotion._PLANAR


def test_with_options_changes_solver_options_only():
    physics = mjzoo.physics.load(ROLLING, ctrl_dt=0.04)
    with pytest.raises(ValueError, match="with_options changes solver options only, not ctrl_dt"):
        mjzoo.physics.with_options(physics, ctrl_dt=0.02)
    with pytest.raises(ValueError, match=r"physics option iterations=0 is invalid; expected an integer >= 1"):
        mjzoo.physics.with_options(physics, iterations=0)


def test_accuracy_is_the_qpos_drift_from_the_model_s_own_settings_in_c_mujoco():
    physics = mjzoo.physics.load(ROLLING, ctrl_dt=0.04)
    same = solver.accuracy(physics, physics, seconds=0.5, seeds=2)
    assert same.qpos_drift == 0.0 and same.seconds == 0.5 and same.iterations[0] == same.iterations[1]
    shipped = solver.accuracy(physics, seconds=0.5, seeds=2)
    # One contact: Newton needs few iterations, so 4 cost next to nothing here.
    assert 0.0 <= shipped.qpos_drift < 1e-6 and shipped.iterations[1] <= 4.0
    # One iteration of one line-search step does not settle the contact: the ball drifts by cm.
    tight = solver.accuracy(physics, solver.shipped(physics, iterations=1, ls_iterations=1), seconds=0.5, seeds=2)
    assert tight.qpos_drift > 1e-3 and tight.iterations[1] <= 1.0
    with pytest.raises(ValueError, match=r"the two must be one model \(joints, actuators, timestep, substeps\)"):
        solver.accuracy(physics, mjzoo.physics.load(ROLLING, ctrl_dt=0.02))


def test_a_kit_task_warns_once_of_costly_settings_and_not_when_they_were_chosen(monkeypatch):
    monkeypatch.setattr(solver, "_WARNED", set())
    with pytest.warns(solver.SolverCostWarning) as caught:
        mjzoo.task(ROLLING, ctrl_dt=0.04, check=False)
    (message,) = [str(w.message) for w in caught if w.category is solver.SolverCostWarning]
    assert message.startswith("mjzoo.task: <xml string> keeps costly solver settings for a model with contacts")
    assert "up to 1600 solver iterations per control step" in message and "allow up to 64 iterations" in message
    assert "**mjzoo.solver.SHIPPED" in message and "\n" not in message
    with warnings.catch_warnings():
        warnings.simplefilter("error", solver.SolverCostWarning)
        mjzoo.task(ROLLING, ctrl_dt=0.04, check=False)  # once per model and settings
        mjzoo.task(ROLLING, ctrl_dt=0.04, check=False, **solver.SHIPPED)
        monkeypatch.setattr(solver, "_WARNED", set())
        mjzoo.task(ROLLING, ctrl_dt=0.04, check=False, iterations=100)  # chosen, not left by default
        mjzoo.task(NO_CONTACTS, ctrl_dt=0.04, check=False)
