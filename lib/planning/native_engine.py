"""C MuJoCo's side of the native backend (`mjzoo.planning.native`): host models, a
persistent `mujoco.rollout` thread pool, preallocated buffers, and the conversions
between C's state vectors and the arrays JAX replays."""

from __future__ import annotations

import os
import time as time_lib
from typing import Any

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

__all__ = ["APPLIED", "Engine", "physical_cores"]

# What a task's step applies to the physics, in mjtState order: C takes them as controls.
APPLIED = ("ctrl", "qfrc_applied", "xfrc_applied", "mocap_pos", "mocap_quat")
_SPEC = {f: int(getattr(mujoco.mjtState, f"mjSTATE_{f.upper()}")) for f in APPLIED}


def physical_cores() -> int:
    """CPU cores this process may run on, counting hyperthread siblings once."""
    cpus = sorted(os.sched_getaffinity(0))
    seen = set()
    for cpu in cpus:
        try:
            with open(f"/sys/devices/system/cpu/cpu{cpu}/topology/thread_siblings_list") as f:
                seen.add(f.read().strip())
        except OSError:
            return len(cpus)
    return max(1, len(seen))


class Engine:
    """One host model per ensemble member, a persistent `mujoco.rollout` thread pool with
    its per-thread `MjData`, and the layout of states and controls. Compared by identity:
    a jitted planner compiles once per engine.

    Attributes:
      n_substeps: physics steps per control step of the task.
      fields: the applied inputs (`APPLIED`) the task's step sets: computed in JAX for
        every physics step. The others (`held`) keep the start state's values over a
        rollout, sent to C only where they differ from a reset's (C resets them).
      direct: the step applies its action as ctrl and sets nothing else: a rollout's
        controls are its actions.
      seconds: the wall time of each call's C rollouts.
    """

    def __init__(self, models: list[mujoco.MjModel], n_substeps: int, num_threads: int, chunk_size: int | None):
        first = models[0]
        self.models, self.n_substeps, self.chunk_size, self.num_threads = models, n_substeps, chunk_size, num_threads
        self.dt = float(first.opt.timestep)
        blank = mujoco.MjData(first)
        self.present = [f for f in APPLIED if getattr(blank, f).size > 0]
        self._defaults = {f: np.array(getattr(blank, f)) for f in self.present}  # what C resets them to
        self.sizes = {f: int(getattr(blank, f).size) for f in ("qpos", "qvel", "act", "sensordata")}
        self.width = 1 + first.nq + first.nv + first.na  # time, qpos, qvel, act: the head of C's full state
        self.full = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
        self.vary(self.present)
        self.direct = False
        self._scratch = mujoco.MjData(first)
        self._datas = [mujoco.MjData(first) for _ in range(max(1, num_threads))]
        self._pool = mj_rollout.Rollout(nthread=num_threads)  # 0: on the calling thread
        self._batches: dict[tuple, dict[str, Any]] = {}  # preallocated per batch shape and control spec
        self.seconds: list[float] = []

    def vary(self, fields: list[str]) -> None:
        """Computes `fields` (and ctrl) per physics step; holds the other applied inputs."""
        self.fields = [f for f in self.present if f in fields or f == "ctrl"]
        self.held = [f for f in self.present if f not in self.fields]

    def __call__(self, time, qpos, qvel, act, history, warmstart, held, controls) -> tuple[np.ndarray, ...]:
        """Rolls out [M, N, T, size] per-step `controls` (of `fields`) from one state, with
        the `held` inputs fixed; returns float32 states [M, N, T, `width`] (time, qpos,
        qvel, act; NaN but time after C reset a diverging rollout) and sensordata
        [M, N, T, nsensordata]."""
        num_models, num_samples, steps, _ = controls.shape
        batch = num_models * num_samples
        kept = [(f, np.ravel(v)) for f, v in zip(self.held, held) if not np.array_equal(v, self._defaults[f])]
        sent = sorted(self.fields + [f for f, _ in kept], key=APPLIED.index)
        spec = sum(_SPEC[f] for f in sent)
        buffers = self._buffers(num_models, num_samples, steps, spec)
        d = self._scratch
        d.time, d.qpos[:], d.qvel[:], d.act[:] = time, qpos, qvel, act
        if d.history.size:
            d.history[:] = history
        mujoco.mj_getState(self.models[0], d, buffers["start"][0], self.full)
        buffers["start"][1:] = buffers["start"][0]
        buffers["warmstart"][:] = warmstart
        per_step = controls.reshape(batch, steps, -1)
        columns, offset = dict(kept), 0
        for f in sent:  # C's control vector: the fields in mjtState order
            size = np.size(self._defaults[f])
            if f in columns:
                buffers["controls"][..., offset : offset + size] = columns[f]
            else:
                start = sum(np.size(self._defaults[g]) for g in self.fields[: self.fields.index(f)])
                buffers["controls"][..., offset : offset + size] = per_step[..., start : start + size]
            offset += size
        tick = time_lib.perf_counter()
        # Every array already has rollout's exact shape and dtype: its Python checks are skipped.
        self._pool.rollout(
            buffers["models"],
            self._datas,
            buffers["start"],
            buffers["controls"],
            control_spec=spec,
            skip_checks=True,
            nstep=steps,
            initial_warmstart=buffers["warmstart"],
            state=buffers["states"],
            sensordata=buffers["sensors"],
            chunk_size=self.chunk_size or max(1, -(-batch // max(1, self.num_threads))),
        )
        self.seconds.append(time_lib.perf_counter() - tick)
        return self._split(buffers, float(time), (num_models, num_samples, steps))

    def _split(self, buffers: dict, time: float, shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
        states = buffers["states"][..., : self.width]
        times = states[..., 0]
        # C resets a diverging simulation (time back to 0): NaN from there on, as MJX's would be.
        earlier = np.concatenate([np.full((times.shape[0], 1), time), times[:, :-1]], axis=1)
        reset = np.maximum.accumulate(times < earlier - 0.5 * self.dt, axis=1)
        states = states.astype(np.float32)  # copies: the buffers are reused
        states[..., 1:][reset] = np.nan
        return states.reshape(*shape, -1), buffers["sensors"].astype(np.float32).reshape(*shape, -1)

    def _buffers(self, num_models: int, num_samples: int, steps: int, spec: int) -> dict[str, Any]:
        key = (num_models, num_samples, steps, spec)
        if key not in self._batches:
            batch, first = num_models * num_samples, self.models[0]
            nstate = mujoco.mj_stateSize(first, self.full)
            self._batches[key] = {
                "models": [m for m in self.models[:num_models] for _ in range(num_samples)],
                "start": np.zeros((batch, nstate)),
                "warmstart": np.zeros((batch, first.nv)),
                "controls": np.zeros((batch, steps, mujoco.mj_stateSize(first, spec))),
                "states": np.zeros((batch, steps, nstate)),
                "sensors": np.zeros((batch, steps, first.nsensordata)),
            }
        return self._batches[key]

    def close(self) -> None:
        self._pool.close()
