"""The files a closed-loop planning run writes (`mjzoo plan`):

out/summary.json   success, score, final_cost, backend, physics, plan_hz, plan_latency_ms, ...
                   (on Warp also the simulation's physics/capacity_overflow and
                   physics/solver_limit: shares of its steps)
out/plan.png       cost and controls over time
out/plan.mp4       the run (where an OpenGL backend exists)
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jax
import numpy as np

from mjzoo.harness import rendering
from mjzoo.planning.closed_loop import Result
from mjzoo.planning.realtime import Problem
from mjzoo.types import Task

__all__ = ["write"]


def write(
    out: Path,
    problem: Problem,
    result: Result,
    stats: dict[str, float],
    video: bool = True,
    render: rendering.RenderConfig = rendering.RenderConfig(),
    **extra: Any,
) -> dict:  # noqa: B008 (frozen)
    """Writes summary.json, plan.png and (where GL exists) plan.mp4, drawn as `render`
    says, to `out`; returns the summary with `extra` in it.

    final_cost is the mean per-step cost (-reward) over the last second of the run."""
    out.mkdir(parents=True, exist_ok=True)
    states = jax.device_get(result.states)
    time_s = np.asarray(states.data.time)
    costs, controls = np.asarray(result.costs), np.asarray(result.controls)
    solved, score = problem.success(states) if problem.success else (None, None)
    summary = {
        **extra,
        "success": solved,
        "score": score,
        "final_cost": float(np.mean(costs[time_s >= time_s[-1] - 1.0 + 1e-6])),
        "physics": "c-mujoco" if problem.physics == "native" else problem.sim_task.model.impl.value,
        "backend": problem.physics,
        "world": problem.sim_physics,
        **{k: float(np.mean(v)) for k, v in states.metrics.items() if k.startswith("physics/")},
        **{k: float(v) for k, v in stats.items()},
    }
    # null, not NaN, for what was not measured (plan_physics_ms on MJX): strict JSON readers reject NaN.
    summary = {k: None if isinstance(v, float) and not np.isfinite(v) else v for k, v in summary.items()}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False))
    _plot(out / "plan.png", time_s, costs, controls, problem.sim_task)
    if video:
        mj = problem.sim_task.mj_model
        rendering.render_video(
            mj,
            np.asarray(states.data.qpos),
            out / "plan.mp4",
            dt=problem.sim_dt,
            mocap_pos=np.asarray(states.data.mocap_pos),
            mocap_quat=np.asarray(states.data.mocap_quat),
            config=rendering.with_model_camera(render, mj),
        )
    return summary


def _plot(path: Path, time_s: np.ndarray, costs: np.ndarray, controls: np.ndarray, task: Task) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nu = controls.shape[1]
    many = nu > 6  # a hand's 16 actuators, a humanoid's 29: their legend goes beside the plots, over no line
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(9 if many else 7, 5), layout="constrained")
    top.plot(time_s, costs)
    top.set_ylabel("cost per step (-reward)")
    for i in range(nu):
        bottom.plot(time_s, controls[:, i], label=task.mj_model.actuator(i).name or f"u{i}")
    bottom.set_ylabel("control")
    bottom.set_xlabel("time (s)")
    if many:
        fig.legend(loc="outside right upper", fontsize="x-small", ncols=1 + (nu - 1) // 20)
    else:
        bottom.legend(loc="upper right", fontsize="small")
    fig.savefig(path, dpi=100)
    plt.close(fig)
