"""Datasets of recorded episodes: a teacher's motion, written where imitation reads it.

Any trained policy or sampling planner can be the teacher. `record_policy` and
`record_planner` run it on a task for N episodes of T control steps (one jit each,
vmapped over episodes, a `lax.scan` over time) and return a `Dataset` of host arrays:
the states (qpos, qvel, time, body poses, observations) [N, T+1, ...], first state
included, and the steps (the policy's action, the controls applied, the reward and
each reward term, the end flags) [N, T, ...]. Episodes are not reset: each runs on
past an early end, and `length` [N] says where it ended.

`save` writes a directory: ``dataset.npz`` (every array), ``meta.json`` (names, shapes,
dtypes, the control step, where the data came from) and ``motions/episode_000.npz``,
one `mjzoo.motion.Clip` per episode cut at its length, so that AMP can take any
episode as a reference motion.

    data = datasets.record_policy(task, ppo.policy(config, task), params, seed, episodes=16, steps=500)
    datasets.save("data/walk", data)
    data = datasets.load("data/walk")
    reference = datasets.clip(data, episode=3)  # or mjzoo.motion.load_file("data/walk/motions/episode_003.npz")
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
from pathlib import Path
from types import ModuleType
from typing import Any
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from mjzoo import batching
from mjzoo import motion
from mjzoo import names
from mjzoo.planning import closed_loop
from mjzoo.planning.realtime import Problem
from mjzoo.running import reset
from mjzoo.running import reward_terms
from mjzoo.running import rollout
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Dataset", "record_policy", "record_planner", "save", "load", "clip"]

FORMAT = "mjzoo.dataset/1"
ARRAYS, META, MOTIONS = "dataset.npz", "meta.json", "motions"
Act = Callable[[Any, Any, jax.Array], jax.Array]  # (params, obs, key) -> action


@dataclasses.dataclass(frozen=True)
class Dataset:
    """N recorded episodes of T control steps (host numpy arrays).

    States, first (reset) state included: qpos [N, T+1, nq], qvel [N, T+1, nv], time
    [N, T+1] (s), xpos [N, T+1, nbody, 3] and xquat [N, T+1, nbody, 4] (world poses of
    every body, world body first, computed from that state's qpos), obs [N, T+1, ...]
    (a dict of such arrays by key path, "a/b", for a structured observation).
    Steps t = 0..T-1, from state t to state t+1: action [N, T, A] (what the policy or
    planner output), ctrl [N, T, nu] (the controls the physics applied: ``data.ctrl``
    after the step, clamped to the actuators' ctrlrange as MuJoCo clamps it), reward
    [N, T], reward_terms {name: [N, T]} (the weighted terms summing to reward),
    terminated and truncated [N, T]. length [N]: steps up to and including the first
    terminated or truncated one, else T; the steps after it are not part of the episode.
    dt: the control step (s). source: JSON-able description of the teacher; seed: the
    seed (an int) or the key's data; deterministic: whether the actions were the
    policy's deterministic ones (None: a planner).
    """

    qpos: np.ndarray
    qvel: np.ndarray
    time: np.ndarray
    xpos: np.ndarray
    xquat: np.ndarray
    obs: np.ndarray | dict[str, np.ndarray]
    action: np.ndarray
    ctrl: np.ndarray
    reward: np.ndarray
    reward_terms: dict[str, np.ndarray]
    terminated: np.ndarray
    truncated: np.ndarray
    length: np.ndarray
    dt: float
    joint_names: tuple[str, ...]
    body_names: tuple[str, ...]
    actuator_names: tuple[str, ...]
    source: dict[str, Any] = dataclasses.field(default_factory=dict)
    seed: int | list[int] | None = None
    deterministic: bool | None = None

    def __post_init__(self) -> None:
        n, t = self.qpos.shape[0], self.qpos.shape[1] - 1
        for name, array in self.arrays().items():
            lead = (n,) if name == "length" else (n, t + 1) if _is_state(name) else (n, t)
            if array.shape[: len(lead)] != lead:
                raise ValueError(
                    f"Dataset: {name} has shape {array.shape}; expected {list(lead)} leading "
                    f"(N={n} episodes, T={t} steps)"
                )

    @property
    def num_episodes(self) -> int:
        return int(self.qpos.shape[0])

    @property
    def num_steps(self) -> int:
        """T, the control steps recorded per episode."""
        return int(self.qpos.shape[1]) - 1

    def returns(self) -> np.ndarray:
        """[N] each episode's summed reward over its `length` steps."""
        within = np.arange(self.num_steps)[None, :] < self.length[:, None]
        return np.sum(self.reward * within, axis=1)

    def arrays(self) -> dict[str, np.ndarray]:
        """Every array under its name in dataset.npz: obs or obs/KEY, reward/NAME."""
        obs = self.obs if isinstance(self.obs, dict) else {"": self.obs}
        fields = ("qpos", "qvel", "time", "xpos", "xquat", "action", "ctrl", "reward")
        return {
            **{f: getattr(self, f) for f in fields},
            **{f"obs/{k}" if k else "obs": v for k, v in obs.items()},
            **{f"reward/{k}": v for k, v in self.reward_terms.items()},
            "terminated": self.terminated,
            "truncated": self.truncated,
            "length": self.length,
        }

    def meta(self) -> dict[str, Any]:
        """What meta.json holds: everything but the arrays, and each array's shape and dtype."""
        shapes = {k: {"shape": list(v.shape), "dtype": str(v.dtype)} for k, v in self.arrays().items()}
        return {
            "format": FORMAT,
            "episodes": self.num_episodes,
            "steps": self.num_steps,
            "dt": self.dt,
            "source": self.source,
            "seed": self.seed,
            "deterministic": self.deterministic,
            "joint_names": list(self.joint_names),
            "body_names": list(self.body_names),
            "actuator_names": list(self.actuator_names),
            "reward_terms": list(self.reward_terms),
            "arrays": shapes,
        }


def _is_state(name: str) -> bool:
    """Whether the array `name` holds states [N, T+1, ...] (else steps [N, T, ...])."""
    return name in ("qpos", "qvel", "time", "xpos", "xquat", "obs") or name.startswith("obs/")


def episode_lengths(terminated: np.ndarray, truncated: np.ndarray) -> np.ndarray:
    """[N, T] end flags -> [N] int: steps up to and including the first end, else T."""
    done = np.asarray(terminated, bool) | np.asarray(truncated, bool)
    return np.where(done.any(axis=1), np.argmax(done, axis=1) + 1, done.shape[1]).astype(np.int32)


# --- recording ------------------------------------------------------------------------


def record_policy(
    task: Task,
    act: Act,
    params: Any,
    key: jax.Array | int,
    episodes: int,
    steps: int,
    *,
    deterministic: bool | None = None,
    source: dict[str, Any] | None = None,
) -> Dataset:
    """Runs ``act(params, obs, key) -> action`` (e.g. ``ppo.policy(config, task,
    deterministic)``) on `task` from `episodes` resets for `steps` control steps each.

    One jit, vmapped over episodes; `act` and the counts are static (the same `act`
    object reuses the compile), `task` and `params` are arguments. `key`: a PRNG key
    or an int seed. `deterministic` and `source` are recorded as given.
    Returns a `Dataset` of N = `episodes`, T = `steps`.
    """
    episodes, steps = _count("record_policy", "episodes", episodes), _count("record_policy", "steps", steps)
    if not callable(act):
        raise TypeError(f"record_policy: act must be a function (params, obs, key) -> action, got {type(act).__name__}")
    key, seed = _key(key)
    limited = _ctrl_limited(task)
    raw = _policy_episodes(act, steps, task, params, jax.random.split(key, episodes), limited)
    return _assemble(task, raw, seed, deterministic, source)


def record_planner(
    problem: Problem,
    key: jax.Array | int,
    episodes: int,
    steps: int | None = None,
    *,
    source: dict[str, Any] | None = None,
) -> Dataset:
    """Runs `problem`'s planner closed loop (`closed_loop.run`: the planner plans on
    `problem.plan_task`, the world is `problem.sim_task`) from `episodes` resets.

    `steps`: control steps per episode; None: the problem's length (`num_replans x
    replan_every`). The run goes on in whole replans and is cut at `steps`. One jit,
    vmapped over episodes. The action is the control the planner commanded.
    """
    episodes = _count("record_planner", "episodes", episodes)
    every = problem.replan_every
    total = problem.num_replans * every if steps is None else _count("record_planner", "steps", steps)
    key, seed = _key(key)
    limited = _ctrl_limited(problem.sim_task)
    raw = _planner_episodes(
        problem.planner,
        problem.config,
        math.ceil(total / every),
        every,
        total,
        problem.sim_task,
        problem.plan_task,
        problem.hooks,
        problem.terminal_value,
        problem.hyperparams,
        jax.random.split(key, episodes),
        limited,
    )
    return _assemble(problem.sim_task, raw, seed, None, source)


def _count(who: str, name: str, value: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{who}: {name} must be an int >= 1, got {value!r}")
    return int(value)


def _key(key: jax.Array | int) -> tuple[jax.Array, int | list[int]]:
    """(a typed PRNG key, what meta.json records of it)."""
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        return jax.random.key(int(key)), int(key)
    if not isinstance(key, jax.Array):
        raise TypeError(f"key must be a jax PRNG key or an int seed, got {type(key).__name__}")
    typed = key if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key) else jax.random.wrap_key_data(key)
    return typed, np.asarray(jax.random.key_data(typed)).ravel().tolist()


def _ctrl_limited(task: Task) -> np.ndarray:
    """[nu] bool: which controls MuJoCo clamps to their ctrlrange (none if the model
    disables clamping)."""
    mj = task.mj_model
    clamps = not mj.opt.disableflags & int(mjx.DisableBit.CLAMPCTRL)
    return np.asarray(mj.actuator_ctrllimited, bool) & clamps


@functools.partial(jax.jit, static_argnums=(0, 1))
def _policy_episodes(act: Act, steps: int, task: Task, params: Any, keys: jax.Array, limited: jax.Array):
    """keys [N] -> the raw record (see `_record`) of N episodes of `act`."""

    def one(key):
        reset_key, run_key = jax.random.split(key)
        first = reset(task, reset_key)
        _, trajectory = rollout(task, lambda obs, k: act(params, obs, k), first, run_key, steps)
        return _record(task, first, trajectory.next_state, trajectory.action, limited)

    task = batching.sized(task, keys.shape[0])  # Warp: a contact pool for every episode
    return jax.vmap(one)(keys)


@functools.partial(jax.jit, static_argnums=(0, 1, 2, 3, 4))
def _planner_episodes(
    planner: ModuleType,
    config: Any,
    num_replans: int,
    every: int,
    steps: int,
    sim_task: Task,
    plan_task: Any,
    hooks: closed_loop.Hooks,
    value: Any,
    hyperparams: Any,
    keys: jax.Array,
    limited: jax.Array,
):
    """keys [N] -> the raw record of N closed-loop episodes, cut at `steps`."""

    def one(key):
        reset_key, run_key = jax.random.split(key)
        first = reset(sim_task, reset_key)
        result = closed_loop.run(
            planner, config, sim_task, plan_task, first, run_key, num_replans, every, hooks, value, hyperparams
        )
        cut = jax.tree.map(lambda x: x[:steps], (result.states, result.controls))
        return _record(sim_task, first, *cut, limited)

    if sim_task.model.impl == mjx.Impl.WARP:  # Warp pools are sized per call: each planner sizes its own
        return jax.lax.map(one, keys)
    return jax.vmap(one)(keys)


def _poses(task: Task, data: mjx.Data) -> mjx.Data:
    """Body poses of the stacked states [T] by `mjx.kinematics`; on Warp through MJX-JAX
    from the host model (kinematics needs only qpos and mocap; a Warp call would need
    contact pools for the stack)."""
    if data.impl != mjx.Impl.WARP:
        return jax.vmap(lambda d: mjx.kinematics(task.model, d))(data)
    model, template = mjx.put_model(task.mj_model, impl="jax"), mjx.make_data(task.mj_model, impl="jax")
    pose = lambda q, p, r: mjx.kinematics(model, template.replace(qpos=q, mocap_pos=p, mocap_quat=r))  # noqa: E731
    return jax.vmap(pose)(data.qpos, data.mocap_pos, data.mocap_quat)


def _record(task: Task, first: State, after: State, actions: jax.Array, limited: jax.Array) -> dict[str, Any]:
    """One episode's arrays from its first state, the states after each step [T] and the
    actions [T, A] (traced, inside the jit; nothing else of the states is kept)."""

    def stack(a, b):  # [] and [T] -> [T+1]
        return jnp.concatenate([a[None], b])

    data = jax.tree.map(stack, batching.own(first.data), batching.own(after.data))
    # After mjx.step, a Data's poses belong to the qpos before the step's integration:
    # recompute them from each stored state.
    posed = _poses(task, data)
    low, high = task.model.actuator_ctrlrange[:, 0], task.model.actuator_ctrlrange[:, 1]
    ctrl = jnp.where(limited, jnp.clip(after.data.ctrl, low, high), after.data.ctrl)
    obs = jax.tree.map(stack, first.obs, after.obs)
    return {
        "qpos": data.qpos,
        "qvel": data.qvel,
        "time": data.time,
        "xpos": posed.xpos,
        "xquat": posed.xquat,
        "obs": obs,
        "action": actions,
        "ctrl": ctrl,
        "reward": after.reward,
        "terms": reward_terms(after),
        "terminated": after.terminated,
        "truncated": after.truncated,
    }


def _assemble(
    task: Task, raw: dict[str, Any], seed: Any, deterministic: bool | None, source: dict[str, Any] | None
) -> Dataset:
    """The host `Dataset` of a raw record, with the task's names and control step."""
    raw = jax.device_get(raw)
    obs_leaves = jax.tree_util.tree_leaves_with_path(raw["obs"])
    obs = {jax.tree_util.keystr(p, simple=True, separator="/"): np.asarray(v) for p, v in obs_leaves}
    arrays = {k: np.asarray(v) for k, v in raw.items() if k not in ("obs", "terms")}
    return Dataset(
        **arrays,
        obs=obs[""] if list(obs) == [""] else obs,
        reward_terms={k: np.asarray(v) for k, v in raw["terms"].items()},
        length=episode_lengths(raw["terminated"], raw["truncated"]),
        dt=_control_dt(arrays["time"]),
        joint_names=_names(task, "joint"),
        body_names=_names(task, "body"),
        actuator_names=_names(task, "actuator"),
        source=dict(source or {}),
        seed=seed,
        deterministic=deterministic,
    )


def _control_dt(time: np.ndarray) -> float:
    """The control step from the recorded times [N, T+1], as `mjzoo.control_dt` measures it
    (one transition from a reset) without compiling a step again."""
    # max: an auto-reset in step 0 restarts its clock; 7 digits: what float32 times hold.
    return float(f"{np.max(time[:, 1] - time[:, 0]):.7g}")


def _names(task: Task, kind: str) -> tuple[str, ...]:
    return tuple(names.all_names(task.mj_model, kind))


# --- files ----------------------------------------------------------------------------


def existing(directory: str | Path) -> tuple[str, ...]:
    """The files of a saved dataset that `directory` holds (relative names; empty if none)."""
    directory = Path(directory)
    found = [name for name in (ARRAYS, META) if (directory / name).exists()]
    return (*found, *sorted(f"{MOTIONS}/{p.name}" for p in (directory / MOTIONS).glob("episode_*.npz")))


def save(directory: str | Path, dataset: Dataset, overwrite: bool = False) -> list[Path]:
    """Writes `dataset` to `directory`: dataset.npz, meta.json and motions/episode_NNN.npz
    (one `mjzoo.motion.Clip` per episode, `clip`). Returns the paths written.

    A directory that holds a dataset is refused (FileExistsError) unless `overwrite`;
    other files in it are left alone. Each file is written under a temporary name and
    renamed, dataset.npz last, after the old one is removed: a crash never leaves a
    dataset.npz that `load` would take for complete with the wrong meta or clips.
    """
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise NotADirectoryError(f"datasets.save: {directory} is a file, not a directory")
    found = existing(directory)
    if found and not overwrite:
        raise FileExistsError(
            f"datasets.save: {directory} already holds a dataset ({', '.join(found[:3])}"
            f"{', ...' if len(found) > 3 else ''}); pass overwrite=True to replace it"
        )
    (directory / ARRAYS).unlink(missing_ok=True)  # gone until the new one is complete
    keep = {f"{MOTIONS}/{_clip_name(i)}.npz" for i in range(dataset.num_episodes)}
    for stale in (f for f in found if f.startswith(f"{MOTIONS}/") and f not in keep):
        (directory / stale).unlink()  # the old dataset's clips beyond this one's episodes
    written = [
        _atomic(directory / MOTIONS / f"{_clip_name(i)}.npz", functools.partial(_save_clip, dataset, i))
        for i in range(dataset.num_episodes)
    ]
    text = json.dumps(dataset.meta(), indent=2, default=str) + "\n"
    written.append(_atomic(directory / META, lambda path: path.write_text(text)))
    written.append(_atomic(directory / ARRAYS, lambda path: np.savez(path, **dataset.arrays())))
    return written


def _clip_name(episode: int) -> str:
    return f"episode_{episode:03d}"


def _save_clip(dataset: Dataset, episode: int, path: Path) -> None:
    motion.save(path, clip(dataset, episode))


def _atomic(path: Path, write: Callable[[Path], None]) -> Path:
    """Writes `path` through `write(temporary path)` (same suffix), then renames it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        write(temporary)
        with open(temporary, "rb+") as f:  # on disk before the rename makes it visible
            os.fsync(f.fileno())
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)
    return path


def load(directory: str | Path) -> Dataset:
    """The dataset `save` wrote to `directory`, checked against its meta.json."""
    directory = Path(directory)
    for name in (META, ARRAYS):
        if not (directory / name).is_file():
            raise FileNotFoundError(f"datasets.load: {directory} holds no {name} (not a complete dataset)")
    meta = json.loads((directory / META).read_text())
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ValueError(f"datasets.load: {directory / META} is not an {FORMAT} meta file")
    with np.load(directory / ARRAYS, allow_pickle=False) as f:
        arrays = {k: np.asarray(f[k]) for k in f.files}
    for name, spec in meta["arrays"].items():
        if name not in arrays or list(arrays[name].shape) != spec["shape"] or str(arrays[name].dtype) != spec["dtype"]:
            got = "missing" if name not in arrays else f"{arrays[name].dtype}{list(arrays[name].shape)}"
            raise ValueError(f"datasets.load: {ARRAYS}'s {name} is {got}; {META} says {spec['dtype']}{spec['shape']}")
    obs = {k[len("obs/") :]: v for k, v in arrays.items() if k.startswith("obs/")}
    plain = ("qpos", "qvel", "time", "xpos", "xquat", "action", "ctrl", "reward", "terminated", "truncated", "length")
    return Dataset(
        **{k: arrays[k] for k in plain},
        obs=arrays.get("obs", obs),
        reward_terms={k: arrays[f"reward/{k}"] for k in meta["reward_terms"]},
        dt=float(meta["dt"]),
        joint_names=tuple(meta["joint_names"]),
        body_names=tuple(meta["body_names"]),
        actuator_names=tuple(meta["actuator_names"]),
        source=meta["source"],
        seed=meta["seed"],
        deterministic=meta["deterministic"],
    )


def clip(dataset: Dataset, episode: int, name: str | None = None) -> motion.Clip:
    """Episode `episode` as a motion clip: its first ``length + 1`` states' qpos, qvel
    and body poses, at fps = 1 / dt, named `name` (default "episode_NNN")."""
    if not 0 <= episode < dataset.num_episodes:
        raise IndexError(f"datasets.clip: episode {episode} is out of range; the dataset has {dataset.num_episodes}")
    frames = int(dataset.length[episode]) + 1
    return motion.Clip(
        name=name or _clip_name(episode),
        fps=1.0 / dataset.dt,
        qpos=dataset.qpos[episode, :frames],
        qvel=dataset.qvel[episode, :frames],
        joint_names=dataset.joint_names,
        body_names=dataset.body_names,
        body_pos=dataset.xpos[episode, :frames],
        body_quat=dataset.xquat[episode, :frames],
    )
