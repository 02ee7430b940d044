"""How well a joystick policy follows velocity commands: in the training simulator
(MJX, the task itself) and in C MuJoCo under another configuration. The measure of the
robot benchmarks and of `mjzoo sim2sim`.

    trained = tracking.in_task(task, apply, key, num_envs=16, seconds=20.0, obs_key="state")
    deployed = tracking.in_mujoco("policy.onnx", task, episodes=4, seconds=20.0,
                                  timestep=0.002, iterations=2, latency=1, push=0.5)
    deployed.linear_error, deployed.yaw_error, deployed.falls

Per control step the errors are |v_xy - c_xy| (m/s; v the base's linear velocity in its
own frame, as `rewards.linear_velocity_tracking` reads it) and |w_z - c_yaw| (rad/s, the
base's own yaw rate), averaged over the steps an episode lived and then over episodes.
Over a window of W steps (`velocity_errors`, `closed_loop`'s `windows`) v, w and c are
first averaged over the last W steps: over a gait cycle a walker's base sways and yaws
back and forth, and the windowed errors say whether the joystick's velocity is followed
on average. A
fall is an episode that ends early: the task's terminations in MJX; in C, the base below
the task's ``min_height`` or tilted past its ``max_tilt``.

In MJX the task runs as trained: its own commands, observation noise, physics
randomization, latency and pushes. In C the exported policy (`sim2sim.run_in_mujoco`)
builds its observation from `MjData` as a robot would (gyro and gravity in the base
frame, joint encoders, its last action and the command), on the task's model with the
options given, commands drawn from the task's ranges every 5-10 s (standing with
probability 0.1), and a horizontal velocity push of U(+-push) m/s per axis every 5-10 s.
"""

from __future__ import annotations

import copy
import dataclasses
import os
from collections.abc import Callable
from typing import Any
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjzoo import batching
from mjzoo import names
from mjzoo import params as task_params
from mjzoo.catalog import commands
from mjzoo.interop import sim2sim
from mjzoo.layers import find
from mjzoo.learning import to_controls
from mjzoo.running import reset
from mjzoo.running import transition
from mjzoo.types import Task

__all__ = [
    "Tracking",
    "base_velocities",
    "velocity_errors",
    "velocity_command",
    "closed_loop",
    "summarize",
    "in_task",
    "in_mujoco",
]

Array = jax.Array


class Tracking(NamedTuple):
    """Velocity tracking over `episodes` episodes of up to `seconds` simulated seconds.

    Attributes:
      linear_error: m/s, mean |v_xy - c_xy| (per episode over the steps it lived, then
        over episodes).
      yaw_error: rad/s, mean |w_z - c_yaw|, likewise.
      falls: episodes that ended early.
      episodes: how many ran.
      seconds: the episodes' length in simulated seconds.
      per_episode: {"linear_error", "yaw_error", "steps"} [episodes] each.
    """

    linear_error: float
    yaw_error: float
    falls: int
    episodes: int
    seconds: float
    per_episode: dict[str, np.ndarray]

    def summary(self) -> dict[str, Any]:
        """JSON-ready: the means, the falls, and the per-episode lists."""
        out = {k: getattr(self, k) for k in ("linear_error", "yaw_error", "falls", "episodes", "seconds")}
        return {**out, "per_episode": {k: np.asarray(v).tolist() for k, v in self.per_episode.items()}}


def _free_joint(mj_model: mujoco.MjModel) -> tuple[int, int]:
    """(qpos, qvel) address of the model's first free joint: the base."""
    qpos, qvel = names.free_joint_addresses(mj_model, None, "tracking")
    return int(qpos[0]), int(qvel[0])


def base_velocities(qpos: Any, qvel: Any, address: tuple[int, int]) -> tuple[Any, Any]:
    """(v_xy [..., 2] m/s in the base frame, w_z [...] rad/s) from free-joint coordinates
    (qpos [..., nq], qvel [..., nv]; MuJoCo keeps a free joint's linear velocity in the
    world frame and its angular velocity in the body's). NumPy or JAX arrays."""
    qp, qv = address
    w, x, y, z = (qpos[..., qp + 3 + i] for i in range(4))
    norm = (w * w + x * x + y * y + z * z) ** 0.5
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    v = [qvel[..., qv + i] for i in range(3)]
    # R^T v, R the rotation of the unit quaternion (w, x, y, z): its first two rows' columns
    vx = (1 - 2 * (y * y + z * z)) * v[0] + 2 * (x * y + w * z) * v[1] + 2 * (x * z - w * y) * v[2]
    vy = 2 * (x * y - w * z) * v[0] + (1 - 2 * (x * x + z * z)) * v[1] + 2 * (y * z + w * x) * v[2]
    stack = jnp.stack if isinstance(vx, jax.Array) else np.stack
    return stack([vx, vy], -1), qvel[..., qv + 5]


def velocity_errors(v_xy: Array, w_z: Array, command: Array, window: int = 1) -> tuple[Array, Array]:
    """(|v_xy - c_xy| [T] m/s, |w_z - c_yaw| [T] rad/s) of one episode's base velocities
    (v_xy [T, 2], w_z [T]) against its command [T, 3], each of the three averaged first over
    the last `window` steps (the first steps: over those so far)."""
    if not (isinstance(window, int) and window >= 1):
        raise ValueError(f"tracking.velocity_errors: window={window!r} must be an integer >= 1")
    gap = jnp.concatenate([v_xy, w_z[:, None]], -1) - command  # [T, 3]
    total = jnp.cumsum(gap, 0)
    steps = gap.shape[0]
    before = jnp.concatenate([jnp.zeros((window, 3)), total])[:steps]  # the sum `window` steps back
    mean = (total - before) / jnp.minimum(jnp.arange(1, steps + 1), window)[:, None]
    return jnp.linalg.norm(mean[:, :2], axis=-1), jnp.abs(mean[:, 2])


def _summarize(linear: np.ndarray, yaw: np.ndarray, lived: np.ndarray, fell: np.ndarray, seconds: float) -> Tracking:
    """linear, yaw [E, T] errors; lived [E, T] bool; fell [E] bool."""
    steps = np.maximum(lived.sum(1), 1)
    per_linear, per_yaw = (np.where(lived, e, 0.0).sum(1) / steps for e in (linear, yaw))
    return Tracking(
        linear_error=float(per_linear.mean()),
        yaw_error=float(per_yaw.mean()),
        falls=int(fell.sum()),
        episodes=int(fell.shape[0]),
        seconds=float(seconds),
        per_episode={"linear_error": per_linear, "yaw_error": per_yaw, "steps": lived.sum(1)},
    )


def closed_loop(
    task: Task,
    act: Callable[[Any], Array],
    key: Array,
    num_envs: int,
    steps: int,
    obs_key: str | None = None,
    windows: tuple[int, ...] = (1,),
) -> tuple[Array, ...]:
    """`num_envs` episodes of `steps` steps of ``act(obs) -> action [A] in [-1, 1]`` in
    `task` (traceable: jit it, or call it inside a program of one's own), each from
    ``reset(task, split(key_i)[0])`` as `sim2sim.starts` draws them. `act` sees
    ``obs[obs_key]``, or the whole observation when `obs_key` is None.

    Returns:
      (linear error [E, T] m/s, yaw error [E, T] rad/s, lived [E, T] bool: the step
      began before the episode ended, fell [E, T] bool: it ended there by a termination),
      then for each further entry of `windows` its pair of errors (`velocity_errors`: the
      velocities and command averaged over that many steps; the first entry's lead).
    """
    if not windows:
        raise ValueError("tracking.closed_loop: windows must name at least one window (1: per step)")
    address = _free_joint(task.mj_model)
    task = batching.sized(task, num_envs)  # Warp: a contact pool for every episode

    def one(key):
        state = reset(task, jax.random.split(key)[0])

        def body(carry, key):
            state, done = carry
            obs = state.obs[obs_key] if obs_key is not None else state.obs
            after = transition(task, state, to_controls(task, act(obs)), key)
            v_xy, w_z = base_velocities(after.data.qpos, after.data.qvel, address)
            command = find(state, commands.VelocityCommandState).command
            lived = ~done
            return (after, done | after.terminated | after.truncated), (
                v_xy,
                w_z,
                command,
                lived,
                lived & after.terminated,
            )

        keys = jax.random.split(jax.random.split(key)[1], steps)
        v_xy, w_z, command, lived, fell = jax.lax.scan(body, (state, jnp.zeros((), bool)), keys)[1]
        errors = [velocity_errors(v_xy, w_z, command, w) for w in windows]
        return (*errors[0], lived, fell, *(e for pair in errors[1:] for e in pair))

    return jax.vmap(one)(jax.random.split(key, num_envs))


def summarize(linear: Any, yaw: Any, lived: Any, fell: Any, seconds: float) -> Tracking:
    """A `Tracking` of `closed_loop`'s arrays ([E, T] each; `fell` may be [E])."""
    fell = np.asarray(fell)
    return _summarize(
        np.asarray(linear), np.asarray(yaw), np.asarray(lived), fell.any(-1) if fell.ndim == 2 else fell, seconds
    )


_closed_loop = jax.jit(closed_loop, static_argnames=("act", "num_envs", "steps", "obs_key", "windows"))


def in_task(
    task: Task,
    apply: Callable[[Array], Array],
    key: Array,
    *,
    num_envs: int = 16,
    seconds: float = 20.0,
    control_dt: float = 0.02,
    obs_key: str | None = None,
) -> Tracking:
    """`num_envs` episodes of `seconds` (of `control_dt` s steps) in `task` itself (one
    compile), the policy ``apply(obs [k]) -> action [A] in [-1, 1]`` deterministic,
    reading ``obs[obs_key]`` of a dict observation. The task must hold a velocity
    command (`commands.with_velocity_command`)."""
    steps = max(1, round(seconds / control_dt))
    return summarize(*jax.device_get(_closed_loop(task, apply, key, num_envs, steps, obs_key)), seconds)


def velocity_command(node: Any, depth: int = 0) -> Any:
    """The settings (ranges ``low``/``high`` [3], ``stand_probability``, ...) of the task's
    `commands.with_velocity_command`, or None when it has none."""
    if depth > 64:
        return None
    if isinstance(node, Task):
        return velocity_command(node.step, depth + 1)
    if dataclasses.is_dataclass(node) and type(node).__name__ == "_Command":
        return node if node.name == "velocity_command" else None  # a heading command draws headings
    for child in getattr(node, "args", ()):
        found = velocity_command(child, depth + 1)
        if found is not None:
            return found
    return None


def _tilted(qpos: np.ndarray, address: int) -> np.ndarray:
    """Angle (rad) between the base's z axis and the world's, per row of qpos [T, nq]."""
    w, x, y, z = (qpos[:, address + 3 + i] for i in range(4))
    cos = (w * w - x * x - y * y + z * z) / (w * w + x * x + y * y + z * z)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def in_mujoco(
    artifact: str | os.PathLike | Any,
    task: Task,
    *,
    episodes: int = 4,
    seconds: float = 20.0,
    seed: int = 0,
    timestep: float | None = None,
    iterations: int | None = None,
    ls_iterations: int | None = None,
    latency: int = 0,
    push: float = 0.0,
) -> Tracking:
    """`episodes` episodes of `seconds` of the exported policy in C MuJoCo on `task`'s
    model (the options given changed), from `task`'s own start states."""
    from mjzoo.interop import export

    loaded = artifact if isinstance(artifact, export.Loaded) else export.load(artifact)
    command = velocity_command(task)
    if command is None:
        raise ValueError("tracking.in_mujoco: the task has no velocity command (commands.with_velocity_command)")
    m = copy.deepcopy(task.mj_model)
    for field, value in (("timestep", timestep), ("iterations", iterations), ("ls_iterations", ls_iterations)):
        if value is not None:
            setattr(m.opt, field, value)
    named = task_params(task)
    min_height = float(named["min_height"]) if "min_height" in named else -np.inf
    max_tilt = float(named["max_tilt"]) if "max_tilt" in named else np.pi
    low, high = np.asarray(command.low, float), np.asarray(command.high, float)
    stand, zero = float(command.stand_probability), float(command.zero_probability)
    control_dt = loaded.contract["physics"]["control_dt"]
    steps = max(1, round(seconds / control_dt))
    address = _free_joint(m)
    starts = sim2sim.starts(task, jax.random.key(seed), episodes)
    rng = np.random.default_rng(seed)
    errors: dict[str, list] = {"linear": [], "yaw": [], "lived": [], "fell": []}
    for e in range(episodes):
        schedule = _schedule(rng, steps, control_dt, low, high, stand, zero)
        kicks = _schedule(rng, steps, control_dt, -np.full(2, push), np.full(2, push), 0.0, 0.0, changes_only=True)

        def perturb(step: int, m: mujoco.MjModel, d: mujoco.MjData, kicks=kicks) -> None:
            if push > 0 and step in kicks:
                d.qvel[address[1] : address[1] + 2] += kicks[step]

        rollout = sim2sim.run_in_mujoco(
            loaded,
            m,
            steps,
            qpos=np.asarray(starts.data.qpos[e]),
            qvel=np.asarray(starts.data.qvel[e]),
            command=lambda step, d, schedule=schedule: schedule[step],
            latency=latency,
            perturb=perturb,
        )
        v_xy, w_z = base_velocities(rollout.qpos[1:], rollout.qvel[1:], address)
        down = (rollout.qpos[1:, address[0] + 2] < min_height) | (_tilted(rollout.qpos[1:], address[0]) > max_tilt)
        lived = np.cumsum(down) - down == 0  # up to and including the fall
        errors["linear"].append(np.linalg.norm(v_xy - rollout.command[:, :2], axis=-1))
        errors["yaw"].append(np.abs(w_z - rollout.command[:, 2]))
        errors["lived"].append(lived)
        errors["fell"].append(down.any())
    return summarize(errors["linear"], errors["yaw"], errors["lived"], errors["fell"], seconds)


def _schedule(rng, steps, dt, low, high, stand, zero, changes_only=False):
    """A value drawn from U(low, high) every U(5, 10) s (all zero with probability
    `stand`, each component with `zero`): [steps, k] the value at each step, or with
    `changes_only` {step: value} at the draws alone (the first after the first interval)."""
    values, draws, step, value = np.zeros((steps, low.size)), {}, 0, None
    while step < steps:
        if changes_only:
            step += max(1, round(rng.uniform(5.0, 10.0) / dt))
            if step < steps:
                draws[step] = rng.uniform(low, high)
            continue
        value = rng.uniform(low, high) * (rng.uniform(size=low.size) >= zero) * (rng.uniform() >= stand)
        span = max(1, round(rng.uniform(5.0, 10.0) / dt))
        values[step : step + span] = value
        step += span
    return draws if changes_only else values
