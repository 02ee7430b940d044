"""Every registered env opens in every viewer mode: its scene and its panel build under
zero, random and slider controls and under each sampling planner where it has a planning
setup, with no traceback (an infinite parameter, `cartpole_balance`'s fall angle made
``inf``, included).

Nothing is stepped. The tasks are built with the physics forward and step stubbed out
(their construction traces them abstractly: seconds an env, and the point here is the
viewer), and each viewer gets a stand-in source at the model's rest pose carrying what
the panel reads from the real one: the task's float parameters, the control sliders,
the planner's hyperparameters as `mjzoo view --planner` configures them.
"""

from __future__ import annotations

import jax
import mujoco
import numpy as np
import pytest

import mjzoo
from mjzoo import physics
from mjzoo.harness import viewer
from mjzoo.harness.cli.arguments import PLANNERS
from mjzoo.harness.cli.arguments import algorithm_module
from mjzoo.harness.cli.arguments import build_planner
from mjzoo.harness.viewer.sources import CONTROLS
from mjzoo.harness.viewer.sources import Frame
from mjzoo.harness.viewer.sources import action_range
from mjzoo.harness.viewer.sources import controls
from mjzoo.harness.viewer.sources import float_parameters
from mjzoo.harness.viewer.sources import host_poses

ENVS = mjzoo.envs.names()
UNBOUNDED = "cartpole_balance_unbounded"  # cartpole_balance, fall_angle=inf


@pytest.fixture(scope="module")
def tasks() -> dict[str, mjzoo.Task]:
    """Every registered env (and an unbounded cart-pole), built without tracing physics."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(physics, "_forward", _unchanged)
        patch.setattr(physics, "_jax_step", _unchanged)
        built = {name: mjzoo.envs.make(name) for name in ENVS}
        built[UNBOUNDED] = mjzoo.envs.make("cartpole_balance", fall_angle=float("inf"))
    yield built
    jax.clear_caches()  # no trace of the stubbed physics outlives the module


def _unchanged(model, data):
    return data


class Unstepped:
    """A viewer source at the model's rest pose that never advances."""

    def __init__(self, task: mjzoo.Task, control: str = "zero", num_envs: int = 1, hyperparams=None):
        self.mj_model, self.num_envs, self.dt = task.mj_model, num_envs, 0.02
        _, self.act_params = controls(control, task)  # as `viewer.env` makes them
        self.control_sliders, self.control_range = control == "sliders", action_range(task)
        self._parameters = float_parameters(task)
        if hyperparams is not None:  # as `viewer.planner`'s source: its Hyperparams become sliders
            self.hyperparams, self.set_config = hyperparams, lambda **values: None

    def parameters(self) -> dict[str, np.ndarray]:
        return self._parameters

    def frame(self) -> Frame:
        data = mujoco.MjData(self.mj_model)
        qpos, mocap_pos, mocap_quat = (
            np.repeat(x[None], self.num_envs, 0) for x in (data.qpos, data.mocap_pos, data.mocap_quat)
        )
        xpos, xquat = host_poses(self.mj_model, qpos, mocap_pos, mocap_quat)
        return Frame(qpos, mocap_pos, mocap_quat, xpos, xquat, 0.0, {"reward": np.zeros(self.num_envs)})


def _opened(source: Unstepped) -> dict:
    shown = viewer.serve(source, port=0, host="127.0.0.1", playing=False)
    try:
        return shown.controls
    finally:
        shown.stop()


@pytest.mark.parametrize("name", [*ENVS, UNBOUNDED])
def test_every_env_opens_under_every_control(tasks, name):
    task = tasks[name]
    for kind in CONTROLS:
        source = Unstepped(task, kind, num_envs=2)
        opened = _opened(source)
        scalars = {f"param/{n}" for n, value in source.parameters().items() if np.ndim(value) == 0}
        assert scalars <= set(opened)
        assert sum(k.startswith("ctrl/") for k in opened) == (task.mj_model.nu if kind == "sliders" else 0)
    if name == UNBOUNDED:
        assert opened["param/fall_angle"].value == "inf" and opened["param/upright_weight"].value == 1.0


@pytest.mark.parametrize("name", [n for n in ENVS if mjzoo.envs.record(n).planning is not None])
@pytest.mark.parametrize("planner", PLANNERS)
def test_every_planned_env_opens_under_every_planner(tasks, name, planner):
    _, hyperparams = build_planner(algorithm_module(planner, PLANNERS), name, {})
    opened = _opened(Unstepped(tasks[name], hyperparams=hyperparams))
    assert any(k.startswith("config/") for k in opened)
