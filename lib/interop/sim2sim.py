"""Sim-to-sim: an exported policy driving plain C MuJoCo (`mujoco.MjData`, no MJX), its
observations built from the contract alone, as a deployment would build them.

    rollout = sim2sim.run_in_mujoco("policy.onnx", mj_model, steps=1000, qpos=..., qvel=...)
    scored = sim2sim.replay(task, start_state, rollout)  # the task's own reward on C's states
    scored.episode_return, scored.obs_error

`run_in_mujoco` needs only mujoco, numpy and the artifact's runtime (onnxruntime or JAX):
the loop a robot's controller runs. A deployment has no reward, so `replay` scores C's
states with the task's own reward and terminations in JAX: the task's transitions are
replayed with their physics replaced by C's (`mjzoo.physics.StandIn`), which also gives
the observation the task itself would have computed from C's states, to compare with the
one the contract built. `check_observation` does that comparison on MJX's own states (no
C involved): the check `export.describe` runs before it writes a contract.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from typing import Any
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjzoo import batching
from mjzoo import physics
from mjzoo.interop import deployment
from mjzoo.running import reset
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Rollout", "Replayed", "run_in_mujoco", "replay"]

Array = jax.Array


class Rollout(NamedTuple):
    """A closed-loop run in C MuJoCo, T control steps. obs [T, obs_size] the policy's
    inputs; action [T, A] its outputs; task_action [T, A] (`action.to_task`); ctrl
    [T, nu] at the last substep; time [T+1], qpos [T+1, nq], qvel [T+1, nv], act
    [T+1, na] from the start; sensordata [T, ...] after each step; before_qpos [T, nq],
    before_qvel [T, nv]: the state before each step's last physics substep; command
    [T, k] the command the policy saw at each step (k = 0 without one); inputs: of an
    `export.end_to_end` artifact, each input it was given, by name, [T, ...] (else {})."""

    obs: np.ndarray
    action: np.ndarray
    task_action: np.ndarray
    ctrl: np.ndarray
    time: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    act: np.ndarray
    sensordata: np.ndarray
    before_qpos: np.ndarray
    before_qvel: np.ndarray
    command: np.ndarray
    inputs: dict[str, np.ndarray]


class Replayed(NamedTuple):
    """`replay`'s scores: rewards, terminated, truncated [T]; the return and length of the
    first episode (as `mjzoo.learning.evaluate` counts them); obs_error: max |contract's
    observation - the task's own on C's states| over that episode."""

    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    episode_return: float
    length: int
    obs_error: float


# --- C MuJoCo in a closed loop --------------------------------------------------------------------------------


def to_ctrl(action: dict[str, Any], task_action: np.ndarray, d: mujoco.MjData) -> np.ndarray:
    """ctrl [nu] from the task action, per the contract's ``action["to_ctrl"]``, at this substep."""
    c, a = action["to_ctrl"], np.asarray(task_action, float)
    if c["type"] == "direct":
        return a
    if c["type"] == "position_targets":  # the model's servos close the loop
        return np.asarray(c["default_pose"]) + np.asarray(c["action_scale"]) * np.clip(a, -1.0, 1.0)
    limit, gear = np.asarray(c["torque_limit"]), np.asarray(c["gear"])
    a = np.clip(a, -1.0, 1.0)
    if c["type"] == "torque":
        return np.clip(a * limit, -limit, limit) / gear
    nu = len(gear)
    target_q = np.asarray(c["default_pose"]) + np.asarray(c["position_scale"]) * a[:nu]
    target_qd = np.asarray(c["velocity_scale"]) * a[nu:] if c["type"] == "position_velocity" else 0.0
    force = np.asarray(c["kp"]) * (target_q - d.qpos[c["qpos_index"]]) + np.asarray(c["kd"]) * (
        target_qd - d.qvel[c["dof_index"]]
    )
    return np.clip(force, -limit, limit) / gear


def _to_task(action: dict[str, Any], a: np.ndarray) -> np.ndarray:
    t = action["to_task"]
    if t["type"] == "identity":
        return a
    low, high = np.asarray(t["low"]), np.asarray(t["high"])
    return np.where(t["limited"], low + (a + 1.0) * 0.5 * (high - low), a)


def _substeps(contract: dict[str, Any], m: mujoco.MjModel) -> int:
    """Physics steps per control step on `m`: the contract's control rate at `m`'s
    timestep; a ValueError when the model differs from the contract's or its timestep
    does not divide the control step."""
    want = contract["model"]
    have = deployment.model_section(m)
    for field in ("nq", "nv", "nu", "joint_names", "actuator_names"):
        if have[field] != want[field]:
            raise ValueError(
                f"run_in_mujoco: the model's {field} is {have[field]}; the policy was exported for {want[field]}"
            )
    control_dt, dt = contract["physics"]["control_dt"], float(m.opt.timestep)
    substeps = max(1, round(control_dt / dt))
    if not np.isclose(substeps * dt, control_dt, rtol=1e-4):
        raise ValueError(
            f"run_in_mujoco: the model's timestep {dt} s does not divide the policy's control step "
            f"{control_dt} s (the contract's physics step is {contract['physics']['physics_dt']} s)"
        )
    return substeps


Command = np.ndarray | Callable[[int, mujoco.MjData], np.ndarray] | None
Entries = dict[str, Any] | Callable[[int, mujoco.MjData], dict[str, Any]] | None


def _end_to_end_inputs(contract: dict[str, Any], d: mujoco.MjData, known: dict[str, Any]) -> dict[str, np.ndarray]:
    """An `end_to_end` artifact's inputs: `known` ones (the previous action, the carry, the
    task's state entries), the rest MjData's fields of those names, in MJX's shapes."""
    inputs = {}
    for spec in contract["inputs"]:
        name = spec["name"]
        if name in known:
            inputs[name] = np.asarray(known[name])
        elif not name.startswith("_") and hasattr(d, name):
            inputs[name] = np.array(getattr(d, name)).reshape(spec["shape"][1:])  # a copy: MjData changes
        else:
            raise ValueError(
                f"run_in_mujoco: the policy reads {name} ({spec['source']}), which C MuJoCo's MjData does not "
                "hold; pass entries={name: value} (the episode start's) or entries(step, mj_data) -> {name: value}"
            )
    return inputs


def run_in_mujoco(
    artifact: str | os.PathLike | Any,
    mj_model: mujoco.MjModel,
    steps: int,
    *,
    qpos: np.ndarray | None = None,
    qvel: np.ndarray | None = None,
    command: Command = None,
    entries: Entries = None,
    latency: int = 0,
    perturb: Callable[[int, mujoco.MjModel, mujoco.MjData], None] | None = None,
) -> Rollout:
    """Runs the exported policy for `steps` control steps on `mj_model` in C MuJoCo.

    Each step: build the observation from the contract's terms and history, run the
    policy (carrying its recurrent state), map its action to ctrl (`to_task`, then
    `to_ctrl` at every physics substep), `mj_step` until the control step has passed.
    An `export.end_to_end` artifact observes inside: it is given the MjData fields it
    reads (and `entries`) and returns the task's action. Nothing here knows the task:
    only the artifact.

    Args:
      artifact: a path to an exported policy, or `export.load`'s result.
      mj_model: the robot's model; names and sizes must match the contract. Its
        options may differ from training's (another solver, fewer iterations, another
        timestep that divides the control step): the control rate stays the contract's.
      steps: control steps to run (>= 1).
      qpos, qvel: the start state (default the model's qpos0, zero velocity).
      command: for a policy whose observation holds a command (a ``command`` term): one
        [k] array, or ``command(step, mj_data) -> [k]`` asked before every step.
      entries: for an `export.end_to_end` artifact whose observation reads the task's
        state entries (``info['goal']``): their values at the start, ``{name: value}``
        (then the artifact's ``next <name>`` outputs carry them on), or
        ``entries(step, mj_data) -> {name: value}`` asked before every step.
      latency: control steps each action waits before reaching the motors (zeros until
        the first arrives), as `actuators.with_action_latency` delays it in training.
      perturb: ``perturb(step, mj_model, mj_data)`` before every step: pushes, or any
        edit of the state a test wants.
    """
    from mjzoo.interop import export

    loaded = artifact if isinstance(artifact, export.Loaded) else export.load(artifact)
    contract = loaded.contract
    substeps = _substeps(contract, mj_model)
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"run_in_mujoco: steps={steps!r} must be an integer >= 1")
    if isinstance(latency, bool) or not isinstance(latency, (int, np.integer)) or latency < 0:
        raise ValueError(f"run_in_mujoco: latency={latency!r} must be an integer >= 0")
    obs_spec, action_spec = contract["observation"], contract["action"]
    end_to_end = contract.get("format") == export.END_TO_END
    if end_to_end and action_spec["to_ctrl"]["type"] == "own":
        raise ValueError(f"run_in_mujoco: the policy's action is not ctrl: {action_spec['to_ctrl']['formula']}")
    wants_command = any(t["source"] == "command" for t in obs_spec.get("terms", ()))
    if wants_command and command is None:
        term = next(t for t in obs_spec["terms"] if t["source"] == "command")
        raise ValueError(
            f"run_in_mujoco: the policy observes a command ({term['name']}: {term['meaning']}); pass command="
        )
    m, d = mj_model, mujoco.MjData(mj_model)
    if qpos is not None:
        d.qpos[:] = qpos
    if qvel is not None:
        d.qvel[:] = qvel
    mujoco.mj_forward(m, d)
    recurrent = contract["policy"]["recurrent"]
    carry = np.zeros(contract["policy"]["carry_size"], np.float32) if recurrent else None
    previous, frames = np.zeros(action_spec["size"]), []
    known = {} if callable(entries) else dict(entries or {})  # an end-to-end artifact's state entries
    pending = [np.zeros(action_spec["size"])] * latency  # actions on their way to the motors
    log: dict[str, list] = {k: [] for k in Rollout._fields}
    for name in ("time", "qpos", "qvel", "act"):
        log[name].append(np.array(getattr(d, name)))
    for step in range(steps):
        if perturb is not None:
            perturb(step, m, d)
        now = np.zeros(0) if not wants_command else np.asarray(command(step, d) if callable(command) else command)
        if end_to_end:
            known.update({export.PREVIOUS_ACTION: previous, export.CARRY: carry})
            known.update(entries(step, d) if callable(entries) else {})
            inputs = _end_to_end_inputs(contract, d, known)
            out = loaded.act(inputs)
            known.update({k.removeprefix(export.NEXT): v for k, v in out.items() if k.startswith(export.NEXT)})
            obs, action, carry = out["obs"], out["action"], out.get("next_carry")
            task_action = np.asarray(action, float)
            log["inputs"].append(inputs)
        else:
            frames = (frames + [deployment.frame(obs_spec["terms"], m, d, previous, now)])[-obs_spec["history"] :]
            obs = deployment.stacked(frames, obs_spec["history"])
            if recurrent:
                action, carry = loaded.act(obs, carry)
            else:
                action = loaded.act(obs)
            task_action = _to_task(action_spec, np.asarray(action, float))
        pending.append(task_action)
        applied = pending.pop(0)
        for i in range(substeps):
            d.ctrl[:] = to_ctrl(action_spec, applied, d)
            if i == substeps - 1:
                log["before_qpos"].append(np.array(d.qpos))
                log["before_qvel"].append(np.array(d.qvel))
            mujoco.mj_step(m, d)
        previous = task_action
        for name, value in (
            ("obs", obs),
            ("action", action),
            ("task_action", task_action),
            ("ctrl", d.ctrl),
            ("time", d.time),
            ("qpos", d.qpos),
            ("qvel", d.qvel),
            ("act", d.act),
            ("sensordata", d.sensordata),
            ("command", now),
        ):
            log[name].append(np.array(value))
    inputs = log.pop("inputs")
    stacked = {k: np.stack([step[k] for step in inputs]) for k in (inputs[0] if inputs else {})}
    return Rollout(**{k: np.asarray(v) for k, v in log.items()}, inputs=stacked)


# --- scoring C's states with the task's reward ------------------------------------------------------------------


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class _FromC(physics.StandIn):
    """Physics that returns C's state after the control step, with the poses and
    velocities MJX's step would leave (computed from the state before its last substep)."""

    model: mjx.Model
    after: dict[str, Array]
    before: dict[str, Array]

    def substep(self, data: mjx.Data) -> mjx.Data:
        pre = data.replace(**{k: v.astype(getattr(data, k).dtype) for k, v in self.before.items()})
        pre = mjx.com_vel(self.model, mjx.com_pos(self.model, mjx.kinematics(self.model, pre)))
        return pre.replace(**{k: v.astype(getattr(data, k).dtype) for k, v in self.after.items()})


@jax.jit
def _replay(task: Task, start: State, actions: Array, keys: Array, after: dict, before: dict):
    def body(state: State, inputs):
        action, key, a, b = inputs
        state = transition(task.replace(model=_FromC(task.model, a, b)), state, action, key)
        return state, (state.reward, state.terminated, state.truncated, state.obs)

    return jax.lax.scan(body, start, (actions, keys, after, before))[1]


def replay(task: Task, start: State, rollout: Rollout, key: Array | None = None) -> Replayed:
    """Scores a C rollout with `task`'s own reward and terminations (JAX, one compile).

    Args:
      task: the task the policy was exported from (MJX's JAX implementation).
      start: the task's state the rollout started from (`starts`; its qpos and qvel
        are the rollout's first).
      rollout: `run_in_mujoco`'s result.
      key: the task's step keys (noise); default key(0).
    """
    if not np.allclose(np.asarray(start.data.qpos), rollout.qpos[0], atol=1e-5):
        raise ValueError("replay: the rollout did not start from `start` (its qpos differ)")
    steps = rollout.action.shape[0]
    keys = jax.random.split(jax.random.key(0) if key is None else key, steps)
    after = {
        "time": rollout.time[1:],
        "qpos": rollout.qpos[1:],
        "qvel": rollout.qvel[1:],
        "act": rollout.act[1:],
        "sensordata": rollout.sensordata,
    }
    before = {"qpos": rollout.before_qpos, "qvel": rollout.before_qvel}
    after, before, actions = jax.tree.map(lambda x: jnp.asarray(x, jnp.float32), (after, before, rollout.task_action))
    rewards, terminated, truncated, obs = jax.device_get(_replay(task, start, actions, keys, after, before))
    done = terminated | truncated
    alive = (np.cumsum(done) - done) == 0  # up to and including the first episode end, as evaluate counts
    length = int(alive.sum())
    # The task's observation after step t is what the policy saw at step t + 1.
    seen = rollout.obs[1:length]
    error = float(np.max(np.abs(seen - obs[: length - 1]))) if length > 1 else 0.0
    return Replayed(rewards, terminated, truncated, float(np.sum(rewards * alive)), length, error)


def starts(task: Task, key: Array, num_envs: int) -> State:
    """The start states of `mjzoo.learning.evaluate(task, policy, key, num_envs)`'s
    episodes, [num_envs] leading axis: C runs from the same states as JAX's evaluation."""
    keys = jax.random.split(key, num_envs)
    task = batching.sized(task, num_envs)  # Warp: a contact pool for every episode
    return jax.jit(jax.vmap(lambda k: reset(task, jax.random.split(k)[0])))(keys)
