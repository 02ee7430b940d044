"""`mjzoo.physics`: loading with validated options, clear load-time errors, the cache, and
`physics.step` against repeated `mjx.step`."""

from __future__ import annotations

import inspect
import math
import os

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from mjzoo import physics

# A damped pendulum hanging off a slider: gravity, damping and two motors, so several
# substeps do non-trivial (nonlinear) work. No constraints, to keep MJX compiles short.
# The <option> attributes are filled per test.
XML = """
<mujoco model="slider_pendulum">
  <option timestep="0.01" {option}/>
  <worldbody>
    <body name="cart">
      <joint name="slide" type="slide" axis="1 0 0" damping="0.1"/>
      <geom name="cart" type="box" size="0.1 0.05 0.05" mass="1"/>
      <body name="pole" pos="0 0 0">
        <joint name="hinge" type="hinge" axis="0 1 0" damping="0.05"/>
        <geom name="pole" type="capsule" fromto="0 0 0 0 0 -0.5" size="0.02" mass="0.2"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="push" joint="slide" gear="1"/>
    <motor name="twist" joint="hinge" gear="1"/>
  </actuator>
</mujoco>
"""


def xml(option: str = "") -> str:
    return XML.format(option=option)


EULERDAMP = int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)


# --- sources --------------------------------------------------------------------------


def test_load_from_xml_string():
    p = physics.load(xml())
    assert isinstance(p, physics.Physics)
    assert isinstance(p.model, mjx.Model)
    assert isinstance(p.mj_model, mujoco.MjModel)
    assert p.source == "<xml string>"
    assert p.n_substeps == 1
    assert math.isclose(p.dt, 0.01) and math.isclose(p.ctrl_dt, 0.01)
    assert (p.mj_model.nq, p.mj_model.nv, p.mj_model.nu, p.mj_model.nbody) == (2, 2, 2, 3)
    assert p.names("body") == ["world", "cart", "pole"]
    assert p.names("actuator") == ["push", "twist"]


def test_load_from_file(tmp_path):
    path = tmp_path / "model.xml"
    path.write_text(xml())
    for source in (path, str(path)):  # a PathLike and a str path
        p = physics.load(source, ctrl_dt=0.03)
        assert p.source == str(path)
        assert p.n_substeps == 3
        assert p.names("joint") == ["slide", "hinge"]
        assert p.id("joint", "hinge") == 1
        assert p.qpos_address("hinge") == 1 and p.dof_address("hinge") == 1
        np.testing.assert_allclose(float(p.model.opt.timestep), 0.01)


def test_missing_file_raises_file_not_found_naming_the_path(tmp_path):
    path = tmp_path / "does_not_exist.xml"
    with pytest.raises(FileNotFoundError) as info:
        physics.load(path)
    assert str(path) in str(info.value)


def test_malformed_xml_file_raises_value_error_naming_the_file(tmp_path):
    path = tmp_path / "broken.xml"
    path.write_text("<mujoco><worldbody><body></mujoco>")  # unclosed elements
    with pytest.raises(ValueError) as info:
        physics.load(path)
    assert str(path) in str(info.value)


def test_schema_violation_in_file_raises_value_error_naming_the_file(tmp_path):
    path = tmp_path / "bad_attribute.xml"
    path.write_text('<mujoco><worldbody><geom type="sphere" size="0.1" colour="red"/></worldbody></mujoco>')
    with pytest.raises(ValueError) as info:
        physics.load(path)
    assert str(path) in str(info.value)
    assert "colour" in str(info.value)  # MuJoCo's own reason is kept


def test_malformed_xml_string_raises_value_error():
    with pytest.raises(ValueError, match="<xml string>"):
        physics.load("<mujoco><worldbody><body></mujoco>")


# --- valid options are applied --------------------------------------------------------


def test_dt_sets_the_timestep():
    p = physics.load(xml(), dt=0.005)
    assert math.isclose(p.mj_model.opt.timestep, 0.005)
    np.testing.assert_allclose(float(p.model.opt.timestep), 0.005)
    assert p.n_substeps == 1 and math.isclose(p.ctrl_dt, 0.005)


@pytest.mark.parametrize(
    "dt, ctrl_dt, n_substeps",
    [(0.01, 0.01, 1), (0.01, 0.04, 4), (0.002, 0.02, 10), (0.001, 0.003, 3), (0.005, 0.1, 20)],
)
def test_ctrl_dt_gives_n_substeps(dt, ctrl_dt, n_substeps):
    # 0.02 / 0.002 and 0.003 / 0.001 are not exact in binary floating point: rounding must
    # still give the whole number.
    p = physics.load(xml(), dt=dt, ctrl_dt=ctrl_dt)
    assert p.n_substeps == n_substeps
    assert math.isclose(p.dt, dt) and math.isclose(p.ctrl_dt, ctrl_dt, rel_tol=1e-9)


def test_ctrl_dt_alone_uses_the_model_timestep():
    p = physics.load(xml(), ctrl_dt=0.05)  # the XML's timestep is 0.01
    assert p.n_substeps == 5 and math.isclose(p.dt, 0.01)


@pytest.mark.parametrize("dt, ctrl_dt", [(0.01, 0.025), (0.01, 0.004), (0.003, 0.01), (0.01, 0.0149)])
def test_ctrl_dt_not_a_multiple_raises(dt, ctrl_dt):
    with pytest.raises(ValueError, match="ctrl_dt"):
        physics.load(xml(), dt=dt, ctrl_dt=ctrl_dt)


@pytest.mark.parametrize(
    "default, value, expected",
    [
        ('solver="Newton"', "cg", mujoco.mjtSolver.mjSOL_CG),
        ('solver="CG"', "newton", mujoco.mjtSolver.mjSOL_NEWTON),
    ],
)
def test_solver_applied(default, value, expected):
    p = physics.load(xml(default), solver=value)
    assert p.mj_model.opt.solver == expected
    assert int(p.model.opt.solver) == int(expected)
    assert physics.load(xml(default)).mj_model.opt.solver != expected  # the option changed it


@pytest.mark.parametrize(
    "default, value, expected",
    [
        ('integrator="RK4"', "euler", mujoco.mjtIntegrator.mjINT_EULER),
        ('integrator="Euler"', "implicitfast", mujoco.mjtIntegrator.mjINT_IMPLICITFAST),
        ('integrator="Euler"', "rk4", mujoco.mjtIntegrator.mjINT_RK4),
    ],
)
def test_integrator_applied(default, value, expected):
    p = physics.load(xml(default), integrator=value)
    assert p.mj_model.opt.integrator == expected
    assert int(p.model.opt.integrator) == int(expected)
    assert physics.load(xml(default)).mj_model.opt.integrator != expected


def test_iterations_ls_iterations_tolerance_applied():
    base = physics.load(xml())
    assert (base.mj_model.opt.iterations, base.mj_model.opt.ls_iterations) != (7, 3)
    p = physics.load(xml(), iterations=7, ls_iterations=3, tolerance=1e-5)
    assert p.mj_model.opt.iterations == 7
    assert p.mj_model.opt.ls_iterations == 3
    assert math.isclose(p.mj_model.opt.tolerance, 1e-5)
    assert int(p.model.opt.iterations) == 7 and int(p.model.opt.ls_iterations) == 3
    np.testing.assert_allclose(float(p.model.opt.tolerance), 1e-5)
    assert physics.load(xml(), tolerance=0.0).mj_model.opt.tolerance == 0.0  # 0 is allowed


def test_disable_euler_damping_sets_only_its_bit():
    on = physics.load(xml(), disable_euler_damping=True)
    off = physics.load(xml(), disable_euler_damping=False)
    assert on.mj_model.opt.disableflags & EULERDAMP
    assert not off.mj_model.opt.disableflags & EULERDAMP
    assert on.mj_model.opt.disableflags & ~EULERDAMP == off.mj_model.opt.disableflags & ~EULERDAMP
    assert int(on.model.opt.disableflags) & EULERDAMP


def test_disable_euler_damping_keeps_other_disable_flags():
    # A model that already disables gravity keeps that flag when the option adds its own.
    gravity = int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)
    no_gravity = '<option timestep="0.01"><flag gravity="disable"/></option>'
    source = XML.replace('<option timestep="0.01" {option}/>', no_gravity)
    assert physics.load(source).mj_model.opt.disableflags & gravity
    p = physics.load(source, disable_euler_damping=True)
    assert p.mj_model.opt.disableflags & gravity
    assert p.mj_model.opt.disableflags & EULERDAMP


def test_disable_euler_damping_changes_the_dynamics():
    # The joints' damping is integrated implicitly by Euler unless disabled; stepping the
    # two models from the same moving state must differ.
    on = physics.load(xml(), integrator="euler", disable_euler_damping=True)
    off = physics.load(xml(), integrator="euler")
    results = [np.asarray(_mjx_step(p.model, _moving_data(p)).qvel) for p in (on, off)]
    assert not np.allclose(results[0], results[1], rtol=0, atol=1e-7)


# --- invalid options ------------------------------------------------------------------

INVALID = [
    ("dt", 0.0),
    ("dt", -0.01),
    ("dt", "0.01"),
    ("dt", float("nan")),
    ("dt", float("inf")),
    ("dt", True),  # a bool is not a duration (iterations already rejects bools)
    ("ctrl_dt", 0.0),
    ("ctrl_dt", -0.02),
    ("ctrl_dt", "0.02"),
    ("ctrl_dt", float("nan")),
    ("ctrl_dt", float("inf")),
    ("solver", "pgs"),  # MuJoCo has PGS, MJX does not
    ("solver", "CG"),
    ("solver", 1),
    ("iterations", 0),
    ("iterations", -3),
    ("iterations", 2.0),
    ("iterations", True),
    ("iterations", "10"),
    ("ls_iterations", 0),
    ("ls_iterations", 1.5),
    ("ls_iterations", False),
    ("integrator", "implicit"),  # not supported by MJX
    ("integrator", "verlet"),
    ("integrator", 0),
    ("tolerance", -1e-8),
    ("tolerance", "1e-8"),
    ("tolerance", float("nan")),
    ("tolerance", True),
    ("disable_euler_damping", 1),
    ("disable_euler_damping", "yes"),
    ("disable_euler_damping", None),
]


@pytest.mark.parametrize("name, value", INVALID, ids=[f"{n}={v!r}" for n, v in INVALID])
def test_invalid_option_raises_value_error_naming_it(name, value):
    with pytest.raises(ValueError) as info:
        physics.load(xml(), **{name: value})
    assert name in str(info.value)


def test_invalid_option_error_names_the_file(tmp_path):
    path = tmp_path / "model.xml"
    path.write_text(xml())
    with pytest.raises(ValueError) as info:
        physics.load(path, solver="pgs")
    assert str(path) in str(info.value) and "solver" in str(info.value)


def test_unknown_option_is_a_type_error():
    with pytest.raises(TypeError):
        physics.load(xml(), timestep=0.01)


def test_options_constant_lists_every_option():
    keywords = [p.name for p in inspect.signature(physics.load).parameters.values() if p.kind == p.KEYWORD_ONLY]
    assert list(physics.OPTIONS) == keywords


# --- names ----------------------------------------------------------------------------


def test_id_of_missing_name_raises_key_error_with_context(tmp_path):
    path = tmp_path / "model.xml"
    path.write_text(xml())
    p = physics.load(path)
    with pytest.raises(KeyError) as info:
        p.id("body", "nope")
    message = info.value.args[0]
    assert "'nope'" in message
    assert str(path) in message
    assert "'cart'" in message and "'pole'" in message  # what does exist


def test_id_of_missing_joint_lists_joints():
    p = physics.load(xml())
    with pytest.raises(KeyError) as info:
        p.id("joint", "elbow")
    message = info.value.args[0]
    assert "'elbow'" in message and "'slide'" in message and "'hinge'" in message
    assert "<xml string>" in message


def test_id_of_existing_names():
    p = physics.load(xml())
    assert p.id("body", "world") == 0 and p.id("body", "cart") == 1 and p.id("body", "pole") == 2
    assert p.id("geom", "pole") == 1
    assert p.id("actuator", "twist") == 1


def test_unknown_element_kind_raises():
    with pytest.raises(ValueError, match="tendon"):
        physics.load(xml()).id("tendon", "x")


# --- stepping -------------------------------------------------------------------------


_mjx_step = jax.jit(mjx.step)
_physics_step = jax.jit(physics.step, static_argnums=3)


def _moving_data(p):
    data = mjx.make_data(p.model)
    return data.replace(qpos=jnp.array([0.2, 0.7]), qvel=jnp.array([-0.5, 2.0]))


def test_step_with_substeps_equals_repeated_mjx_step():
    p = physics.load(xml(), ctrl_dt=0.03, integrator="euler")
    assert p.n_substeps == 3
    data, ctrl = _moving_data(p), jnp.array([0.8, -0.3])
    expected, d = [], data.replace(ctrl=ctrl)
    for _ in range(3):
        d = _mjx_step(p.model, d)
        expected.append(d)
    for k in (1, 3):
        got = _physics_step(p.model, data, ctrl, k)
        for field in ("qpos", "qvel", "qacc", "ctrl", "time"):
            np.testing.assert_allclose(getattr(got, field), getattr(expected[k - 1], field), rtol=1e-5, atol=1e-6)
    # The substeps did something: the state moved and time advanced by 3 dt.
    assert not np.allclose(expected[2].qpos, data.qpos)
    assert not np.allclose(expected[2].qvel, expected[0].qvel)
    np.testing.assert_allclose(float(expected[2].time), 0.03, rtol=1e-5)


def test_step_applies_ctrl():
    p = physics.load(xml())
    data = mjx.make_data(p.model)
    out = _physics_step(p.model, data, jnp.array([1.0, 0.0]), 1)
    np.testing.assert_array_equal(out.ctrl, [1.0, 0.0])
    assert float(out.qvel[0]) > 0.0  # the slider is pushed forward


# --- cache ----------------------------------------------------------------------------


def test_identical_string_loads_are_cached():
    a = physics.load(xml(), dt=0.005, ctrl_dt=0.01, solver="cg")
    b = physics.load(xml(), solver="cg", ctrl_dt=0.01, dt=0.005)  # keyword order is irrelevant
    assert a is b
    assert physics.load(xml(), dt=0.005, ctrl_dt=0.01, solver="newton") is not a
    assert physics.load(xml(), dt=0.005, ctrl_dt=0.02, solver="cg") is not a


def test_identical_file_loads_are_cached(tmp_path):
    path = tmp_path / "model.xml"
    path.write_text(xml())
    a = physics.load(path, iterations=5)
    assert physics.load(path, iterations=5) is a
    assert physics.load(str(path), iterations=5) is a
    assert physics.load(path, iterations=6) is not a


def test_edited_file_is_reloaded(tmp_path):
    # The cache must not serve a stale model once the file changed on disk.
    path = tmp_path / "model.xml"
    path.write_text(xml())
    a = physics.load(path)
    path.write_text(xml().replace('timestep="0.01"', 'timestep="0.004"'))
    stat = os.stat(path)
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))  # mtime resolution
    b = physics.load(path)
    assert b is not a
    assert math.isclose(b.dt, 0.004)
