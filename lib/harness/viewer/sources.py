"""What a viewer shows: a simulated task under some controller, or a recording.

A source is a small stateful object the viewer's loop drives:

    source.advance() -> int       one jitted call: steps a batch of control steps
    source.frame()   -> Frame     host arrays of what to draw now
    source.reset(seed)
    source.parameters()           the task's named floats (sliders), `set_parameters`

`Simulation` runs a task for E environments (vmapped) under ``act(params, obs, key) ->
action``: zero, uniform random or slider controls (`controls`), or a trained policy.
`Planning` (planning.py) runs a sampling planner closed loop; `Recording` (recording.py)
plays recorded states back. A task's numbers reach the jitted step as arguments
(`Task.with_params`), so changing one does not compile again: `traces` counts compiles.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any
from typing import Callable

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjzoo import batching
from mjzoo.combinators import with_auto_reset
from mjzoo.parameters import params as task_params
from mjzoo.planning.sampling import control_limits
from mjzoo.running import control_dt
from mjzoo.running import fill_transition_entries
from mjzoo.running import reset
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Frame", "Simulation", "controls", "host_poses", "float_parameters", "CONTROLS"]

Act = Callable[[Any, Any, jax.Array], jax.Array]  # (params, obs, key) -> action [nu]
CONTROLS = ("zero", "random", "sliders")


@dataclasses.dataclass
class Frame:
    """What one displayed frame draws (host arrays, E environments shown; for models side
    by side, `recording.SideBySide`, each per-environment field is a list of E arrays).

    Attributes:
      qpos: [E, nq]; mocap_pos [E, nmocap, 3], mocap_quat [E, nmocap, 4].
      xpos: [E, nbody, 3] and xquat: [E, nbody, 4] (wxyz) body poses in the world.
      time: [] simulated seconds of environment 0.
      terms: {name: [E]} the last step's weighted reward terms (``reward/<name>``).
      traces: None, or [S + 1, H, P, 3] a planner's sampled rollouts' P points, its chosen plan last.
    """

    qpos: np.ndarray
    mocap_pos: np.ndarray
    mocap_quat: np.ndarray
    xpos: np.ndarray
    xquat: np.ndarray
    time: float
    terms: dict[str, np.ndarray]
    traces: np.ndarray | None = None


def host_poses(
    mj_model: mujoco.MjModel, qpos: np.ndarray, mocap_pos: np.ndarray, mocap_quat: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """([E, nbody, 3], [E, nbody, 4]) body poses of qpos [E, nq] by native forward
    kinematics: cheap on the host, and the same for every physics backend."""
    data = mujoco.MjData(mj_model)
    xpos = np.empty((len(qpos), mj_model.nbody, 3))
    xquat = np.empty((len(qpos), mj_model.nbody, 4))
    for e in range(len(qpos)):
        data.qpos[:], data.mocap_pos[:], data.mocap_quat[:] = qpos[e], mocap_pos[e], mocap_quat[e]
        mujoco.mj_kinematics(mj_model, data)
        xpos[e], xquat[e] = data.xpos, data.xquat
    return xpos, xquat


def float_parameters(task: Task) -> dict[str, np.ndarray]:
    """The task's named floating-point parameters (`mjzoo.params`) with at most 8
    entries each, as host arrays: the ones a slider can set."""
    found = {}
    for name, value in task_params(task).items():
        value = np.asarray(value)
        if np.issubdtype(value.dtype, np.floating) and value.size <= 8:
            found[name] = value
    return found


def controls(kind: str, task: Task) -> tuple[Act, np.ndarray]:
    """(act, params) for the controls `kind`: "zero", "random" (uniform in each
    action's range, `action_range`) or "sliders" (params: [nu] the slider values, set by the viewer)."""
    if kind not in CONTROLS:
        raise ValueError(f"controls: unknown {kind!r}; choose one of {', '.join(CONTROLS)}")
    low, high = action_range(task)
    if kind == "random":
        return jax.tree_util.Partial(_uniform, jnp.asarray(low), jnp.asarray(high)), np.zeros(0, np.float32)
    start = np.clip(np.zeros_like(low), low, high)
    return jax.tree_util.Partial(_given if kind == "sliders" else _zero, jnp.asarray(start)), start


def action_range(task: Task) -> tuple[np.ndarray, np.ndarray]:
    """([A], [A]) the range of each of `task`'s actions: [-1, 1] where they are its
    actuator's own (``task.action_dim`` set, e.g. `actuators.position_targets`), else each
    actuator's control range, [-1, 1] where unlimited: the planners' `control_limits`, made
    finite for a slider."""
    low, high = control_limits(task)
    return np.where(np.isfinite(low), low, -1.0), np.where(np.isfinite(high), high, 1.0)


def _uniform(low, high, params, obs, key):
    return jax.random.uniform(key, low.shape, minval=low, maxval=high)


def _zero(start, params, obs, key):
    return start


def _given(start, params, obs, key):
    return params


class Simulation:
    """E environments of `task` under `act(params, obs, key)`, auto-reset at episode end.

    `advance()` runs `chunk` control steps of all environments in one jitted `lax.scan`
    (the task and `act_params` are arguments: new numbers, no compile)."""

    def __init__(self, task: Task, act: Act, act_params: Any, num_envs: int = 1, seed: int = 0, chunk: int = 0):
        self.task, self.act, self.act_params, self.num_envs = task, act, act_params, num_envs
        self.mj_model, self.dt = task.mj_model, control_dt(task)
        self.chunk = chunk or max(1, round(1 / (30 * self.dt)))  # about one displayed frame at 1x
        self.traces, self.steps = 0, 0
        self._reset = jax.jit(self._reset_all)
        self._advance = jax.jit(self._advance_all)
        self.reset(seed)
        jax.block_until_ready(self._advance(task, act_params, self.states, self.key))  # compile before serving

    def reset(self, seed: int = 0) -> None:
        reset_key, self.key = jax.random.split(jax.random.key(seed))
        self.states = self._reset(self.task, jax.random.split(reset_key, self.num_envs))

    def advance(self) -> int:
        """Steps every environment `chunk` control steps; returns how many."""
        self.key, key = jax.random.split(self.key)
        self.states = self._advance(self.task, self.act_params, self.states, key)
        self.steps += self.chunk
        return self.chunk

    @property
    def control_range(self) -> tuple[np.ndarray, np.ndarray]:
        """([A], [A]) the range of each action, for the viewer's control sliders."""
        return action_range(self.task)

    def parameters(self) -> dict[str, np.ndarray]:
        return float_parameters(self.task)

    def set_parameters(self, **values: Any) -> None:
        """New task numbers for the next step (same structure and dtype: no compile)."""
        self.task = self.task.with_params(**values)

    def frame(self) -> Frame:
        data = jax.device_get(
            (
                self.states.data.qpos,
                self.states.data.mocap_pos,
                self.states.data.mocap_quat,
                self.states.data.time,
                self.states.metrics,
            )
        )
        qpos, mocap_pos, mocap_quat, time, metrics = data
        xpos, xquat = host_poses(self.mj_model, qpos, mocap_pos, mocap_quat)
        terms = {k[len("reward/") :]: np.asarray(v) for k, v in metrics.items() if k.startswith("reward/")}
        return Frame(qpos, mocap_pos, mocap_quat, xpos, xquat, float(time[0]), terms)

    def _reset_all(self, task: Task, keys: jax.Array) -> State:
        sized = with_auto_reset(batching.sized(task, keys.shape[0]))  # Warp: a contact pool for every env
        return jax.vmap(lambda k: fill_transition_entries(sized, reset(sized, k)))(keys)

    def _advance_all(self, task: Task, act_params: Any, states: State, key: jax.Array) -> State:
        self.traces += 1  # Python runs only while tracing: counts compiles
        sized = with_auto_reset(batching.sized(task, self.num_envs))  # Warp: a contact pool for every env

        def one(state: State, key: jax.Array) -> State:
            act_key, step_key = jax.random.split(key)
            return transition(sized, state, self.act(act_params, state.obs, act_key), step_key)

        def body(states: State, key: jax.Array) -> tuple[State, None]:
            return jax.vmap(one)(states, jax.random.split(key, self.num_envs)), None

        return jax.lax.scan(body, states, jax.random.split(key, self.chunk))[0]


def slider_range(value: float) -> tuple[float, float, float]:
    """(min, max, step) of a slider for a parameter now at `value`: 0 to twice it (its
    sign kept), or -1 to 1 for 0; 200 steps."""
    if value == 0 or not math.isfinite(value):
        low, high = -1.0, 1.0
    else:
        low, high = sorted((0.0, 2.0 * value))
    return low, high, (high - low) / 200
