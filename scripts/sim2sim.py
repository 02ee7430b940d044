"""Sim-to-sim check of a trained run: mjzoo's JAX evaluation (MJX) against the exported
policy driving plain C MuJoCo, its observations built from the contract alone.

    python scripts/sim2sim.py runs/humanoid_walk-ppo                    # 8 episodes, the task's length
    python scripts/sim2sim.py runs/cb --episodes 16 --format jax --json out.json

Exports RUN's policy (ONNX by default; into a temporary directory unless --artifact
names an existing export to use), evaluates the run in JAX (`module.evaluate`, the
deterministic policy, --episodes episodes from --seed), then runs the artifact in C
MuJoCo from the same start states and scores C's states with the task's own reward
(`mjzoo.interop.sim2sim.replay`). Prints both returns per episode and their means, the
largest difference between the contract's observation and the task's own on C's states,
and last all the numbers as one JSON object (also written to --json). Works on any PPO or
AMP run directory (the task is built on MJX's JAX physics; observation noise is off in
both simulators, as a deployment observes).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import jax
import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--steps", type=int, default=None, help="control steps per episode (default: the task's)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--format", choices=("onnx", "jax"), default="onnx")
    parser.add_argument("--artifact", type=Path, default=None, help="an existing export of RUN to run in C")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args()

    from mjzoo.harness.cli import exporting
    from mjzoo.interop import deployment
    from mjzoo.interop import export
    from mjzoo.interop import sim2sim

    trained, state = exporting.load_run(args.run)
    task = deployment.without_observation_noise(trained.task)
    if args.steps is None and task.time_limit is None:
        parser.error(f"{trained.spec} has no time limit: give --steps")
    steps = args.steps or int(task.time_limit)
    artifact = args.artifact
    if artifact is None:
        fn = exporting.policy(trained.module, trained.cfg, task, trained.module.policy_params(state))
        described = export.describe(task, fn, source=dict(run=str(args.run), env=trained.spec))
        artifact = Path(tempfile.mkdtemp(prefix="mjzoo-sim2sim-")) / f"policy{exporting.SUFFIXES[args.format]}"
        (export.write_onnx if args.format == "onnx" else export.write_jax)(fn, described, artifact)
    loaded = export.load(artifact)
    checked = loaded.contract["observation"]["checked"]["max_abs_error"]
    print(f"{trained.spec}: {artifact} (observation layout checked: max error {checked:.2g})")

    key = jax.random.key(args.seed)
    begin = time.perf_counter()
    evaluate = jax.jit(trained.module.evaluate, static_argnums=(0, 4, 5))
    jax_returns, _, trajectory = evaluate(trained.cfg, task, state, key, args.episodes, steps)
    jax_returns, jax_obs = np.asarray(jax_returns), np.asarray(trajectory.obs)  # obs: episode 0's, [steps, k]
    print(f"JAX evaluation: {time.perf_counter() - begin:.1f} s")

    starts = sim2sim.starts(task, key, args.episodes)
    rows = []  # C MuJoCo runs from the very start states of the JAX evaluation's episodes
    for i in range(args.episodes):
        start = jax.tree.map(lambda x, i=i: x[i], starts)
        begin = time.perf_counter()
        rollout = sim2sim.run_in_mujoco(
            loaded, task.mj_model, steps, qpos=np.asarray(start.data.qpos), qvel=np.asarray(start.data.qvel)
        )
        seconds = time.perf_counter() - begin
        scored = sim2sim.replay(task, start, rollout)
        if i == 0:  # how far the two simulators' states drift apart, seen through the observation
            gap = np.abs(rollout.obs[: scored.length] - jax_obs[: scored.length]).max(axis=1)
            divergence = {f"step_{t}": float(gap[t]) for t in (1, 10, 100) if t < len(gap)} | {"max": float(gap.max())}
        rows.append(
            dict(
                episode=i,
                jax_return=float(jax_returns[i]),
                c_return=scored.episode_return,
                relative_difference=scored.episode_return / float(jax_returns[i]) - 1,
                c_length=scored.length,
                obs_error=scored.obs_error,
                c_seconds=seconds,
            )
        )
        print(
            f"episode {i:3d}: JAX {jax_returns[i]:10.2f}   C MuJoCo {scored.episode_return:10.2f} "
            f"({scored.length} steps, {seconds:.1f} s)   obs error {scored.obs_error:.1e}"
        )
    c_returns = np.array([r["c_return"] for r in rows])
    summary = dict(
        env=trained.spec,
        run=str(args.run),
        artifact=str(artifact),
        episodes=args.episodes,
        steps=steps,
        jax_mean=float(jax_returns.mean()),
        jax_std=float(jax_returns.std()),
        c_mean=float(c_returns.mean()),
        c_std=float(c_returns.std()),
        relative_difference_of_means=float(c_returns.mean() / jax_returns.mean() - 1),
        max_abs_relative_difference=float(max(abs(r["relative_difference"]) for r in rows)),
        max_obs_error=float(max(r["obs_error"] for r in rows)),
        episode0_obs_divergence=divergence,
        rows=rows,
    )
    print(
        f"mean return: JAX {summary['jax_mean']:.2f} ± {summary['jax_std']:.2f}   C MuJoCo "
        f"{summary['c_mean']:.2f} ± {summary['c_std']:.2f}   (C / JAX - 1 = "
        f"{summary['relative_difference_of_means']:+.2%})"
    )
    text = json.dumps(summary, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text)


if __name__ == "__main__":
    main()
