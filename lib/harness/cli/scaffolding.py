"""`mjzoo new NAME --mjcf PATH`: a task module to start from, written from a model with
the own-task kit's skeleton (`mjzoo.task`, as docs/own-task.md builds one): observe,
rewards and costs, terminate, a start and a reset item, and a `PLANNING` setup, every
number a named parameter. It runs as written under `mjzoo.testing.check_task`,
`mjzoo train`, `mjzoo plan` and `mjzoo view`; its reward is a placeholder (hold the
model's rest pose) for the user to replace."""

from __future__ import annotations

import os
import string
from pathlib import Path
from typing import Annotated

import mujoco
import tyro

from mjzoo.harness.cli.arguments import UsageError

__all__ = ["new"]

# A control step near 0.02 s, a whole number of the model's physics steps.
_CONTROL_DT = 0.02
_EPISODE_SECONDS = 10.0

MODULE = string.Template('''\
"""$name: a task on $model_name ($mjcf), from `mjzoo new`. Replace the placeholder
reward (hold the rest pose) with what the task is for; every number is a parameter
(`mjzoo.params(task)`, `task.with_params(...)`, --env-overrides on the command line).

From this file's directory:

    python -c "import $name, mjzoo.testing; mjzoo.testing.check_task($name.make_task())"
    mjzoo train ppo $name:make_task --out runs/$name
    mjzoo plan mppi $name:make_task --offline
    mjzoo view $name:make_task --controls sliders
"""

from pathlib import Path

import jax
import jax.numpy as jnp

import mjzoo
from mjzoo.envs import base

MJCF = $path
CTRL_DT = $ctrl_dt  # s: $substeps physics step(s) of $timestep s per control step


def observe(p, model, state):  # [$nq + $nv]: joint positions and velocities
    return jnp.concatenate([state.data.qpos, state.data.qvel])


def near_rest(p, model, data, key):  # start: the rest pose (qpos0), each coordinate within +-reset_noise
    noise = jax.random.uniform(key, data.qpos.shape, minval=-p["reset_noise"], maxval=p["reset_noise"])
    return data.replace(qpos=model.qpos0 + noise)


def random_velocities(p, model, data, key):  # a reset item after the start: joint velocities within +-reset_noise
    return data.replace(qvel=jax.random.uniform(key, data.qvel.shape, minval=-p["reset_noise"], maxval=p["reset_noise"]))


def posture(p, model, state, action, next_state):  # placeholder in [0, 1]: 1 at the rest pose
    return jnp.exp(-jnp.sum(jnp.square(next_state.data.qpos - model.qpos0)) / p["posture_scale"])


def effort(p, model, state, action, next_state):  # the mean squared action
    return jnp.mean(jnp.square(action))


def too_fast(p, model, state):  # ends an episode whose joints spin faster than max_speed
    return jnp.any(jnp.abs(state.data.qvel) > p["max_speed"])


def make_task(**params):
    """The task; keyword arguments override its parameters."""
    defaults = dict(reset_noise=0.05, posture_scale=1.0, max_speed=100.0)
    return mjzoo.task(
        MJCF,
        observe=observe,
        rewards={"posture": (posture, 1.0)},
        costs={"effort": (effort, 0.01)},
        terminate={"too_fast": too_fast},
        start=near_rest,
        resets=(random_velocities,),
        time_limit=$time_limit,  # control steps: $episode_seconds s
        params={**defaults, **params},
        ctrl_dt=CTRL_DT,
    )


# How `mjzoo plan` solves it: one episode, replanning every control step, each planner's
# config over a horizon of about 0.5 s; success=None: the report gives the final cost.
_SAMPLING = dict(num_samples=64, horizon_steps=$horizon, num_knots=4, noise_scale=0.3)
PLANNING = base.PlanningSetup(
    seconds=None,
    replan_every=1,
    plan_overrides={},
    configs={
        "predictive_sampling": _SAMPLING,
        "mppi": dict(_SAMPLING, temperature=0.1),
        "cem": dict(_SAMPLING, num_elites=8, sigma_min=0.1),
        "dial": dict(_SAMPLING, iterations=2, temperature=1.0, beta_horizon=4.0),
        "cma_es": dict(_SAMPLING, num_elites=8),
        "ilqr": dict(horizon_steps=$horizon, iterations=3),
    },
    success=None,
)
''')


def new(
    name: Annotated[str, tyro.conf.Positional],
    mjcf: Path,
    out: Path = Path("."),
    force: bool = False,
) -> None:
    """Write OUT/NAME.py, a task module on the model at --mjcf built with `mjzoo.task`
    (observe, a placeholder reward and a cost, terminate, a start and a reset item, a
    PLANNING setup): it runs as written under `mjzoo.testing.check_task`, `mjzoo train
    ppo NAME:make_task`, `mjzoo plan` and `mjzoo view` (from OUT). An existing file is
    replaced only with --force.

    Args:
      name: the module's name (a Python identifier): OUT/NAME.py, the spec NAME:make_task.
      mjcf: the model's MJCF file; the module names it relative to OUT where it can.
      out: the directory to write NAME.py in.
      force: replace OUT/NAME.py if it exists.
    """
    if not name.isidentifier() or name.startswith("_"):
        raise UsageError(f"NAME {name!r}: must be a Python module name, e.g. my_task")
    path = out / f"{name}.py"
    if path.exists() and not force:
        raise UsageError(f"{path} already exists; pass --force to replace it")
    if not mjcf.is_file():
        raise UsageError(f"--mjcf {mjcf}: no such file")
    try:
        model = mujoco.MjModel.from_xml_path(str(mjcf))
    except ValueError as e:
        raise UsageError(f"--mjcf {mjcf}: MuJoCo cannot load it: {' '.join(str(e).split())}") from None
    if model.nu == 0:
        raise UsageError(f"--mjcf {mjcf}: the model has no actuators, so a policy has nothing to control")
    substeps = max(1, round(_CONTROL_DT / model.opt.timestep))
    ctrl_dt = substeps * model.opt.timestep
    time_limit = max(1, round(_EPISODE_SECONDS / ctrl_dt))
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(
        MODULE.substitute(
            name=name,
            model_name=mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_MODEL, 0) or "the model",
            mjcf=mjcf.name,
            path=_path_expression(mjcf, out),
            ctrl_dt=f"{ctrl_dt:.6g}",
            substeps=substeps,
            timestep=f"{model.opt.timestep:.6g}",
            nq=model.nq,
            nv=model.nv,
            time_limit=time_limit,
            episode_seconds=f"{time_limit * ctrl_dt:.6g}",
            horizon=max(1, round(0.5 / ctrl_dt)),
        )
    )
    print(f"wrote {path}: from {out}, `mjzoo train ppo {name}:make_task` trains it, `mjzoo plan mppi {name}:make_task`")
    print("plans on it, `mjzoo view` shows it; replace its placeholder reward (hold the rest pose) with your task's")


def _path_expression(mjcf: Path, out: Path) -> str:
    """Python for the model's path in the module: beside the module where it can be (the
    pair moves together), else absolute."""
    mjcf, out = mjcf.resolve(), out.resolve()
    try:
        relative = Path(os.path.relpath(mjcf, out))
    except ValueError:  # another drive (Windows)
        return repr(str(mjcf))
    if relative.parts and relative.parts[0] == "..":
        return repr(str(mjcf))
    return f"Path(__file__).parent / {str(relative.as_posix())!r}"
