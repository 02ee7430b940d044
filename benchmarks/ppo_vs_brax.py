"""mjzoo PPO against Brax PPO on the same task, same hyperparameters, one process.

For each env: (a) raw batched stepping of the task's physics at the same number of envs,
(b) mjzoo PPO (`mjzoo.algorithms.ppo.train`), (c) Brax PPO (`brax.training.agents.ppo.train`)
through `mjzoo.interop.brax`. Hyperparameters: MuJoCo Playground's DM Control defaults
(2048 envs, batch 1024, unroll 30, 32 minibatches, 16 updates per batch, lr 1e-3,
entropy 1e-2, discount 0.995, reward scaling 10, normalized observations, clip 0.3, no
gradient clipping, Brax's default networks: policy 4x32, value 5x256, swish).

Prints a table (training steps/s, ratio to raw stepping, wall-clock time to a return
threshold, final return) and writes JSON.

    python benchmarks/ppo_vs_brax.py --envs cartpole_balance cylinder_push --steps 20000000
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from brax_peer import train_brax_ppo  # noqa: E402
from task_overhead import inputs, raw_steps_per_s  # noqa: E402

import mjzoo  # noqa: E402
import mjzoo.envs  # noqa: E402
from mjzoo.harness import metrics, training  # noqa: E402
from mjzoo.algorithms import ppo  # noqa: E402

HYPER = dict(num_envs=2048, batch_size=1024, unroll_length=30, num_minibatches=32, num_updates_per_batch=16,
             learning_rate=1e-3, entropy_cost=1e-2, discounting=0.995, reward_scaling=10.0)  # fmt: skip


def mjzoo_config(total_steps: int) -> ppo.Config:
    """The same algorithm in mjzoo's terms: Brax collects batch*minibatches/envs = 16
    unrolls of 30 steps per env per update; mjzoo collects one unroll of 480."""
    h = HYPER
    unrolls = h["batch_size"] * h["num_minibatches"] // h["num_envs"]
    return ppo.Config(
        num_envs=h["num_envs"], unroll_length=h["unroll_length"] * unrolls, num_minibatches=h["num_minibatches"],
        num_epochs=h["num_updates_per_batch"], learning_rate=h["learning_rate"], entropy_coef=h["entropy_cost"],
        discount=h["discounting"], reward_scaling=h["reward_scaling"], gae_lambda=0.95, clip_epsilon=0.3,
        max_grad_norm=None, normalize_observations=True, policy_hidden_sizes=(32,) * 4,
        value_hidden_sizes=(256,) * 5, activation="swish", total_steps=total_steps,
    )  # fmt: skip


def train_mjzoo(task: mjzoo.Task, total_steps: int, episode_length: int) -> dict:
    config = mjzoo_config(total_steps)
    with tempfile.TemporaryDirectory() as out:
        # Evaluate about as often as Brax does with num_evals=20 (every ~2M steps); Brax
        # writes no checkpoints, so neither do we here.
        settings = training.Settings(out_dir=Path(out), updates_per_chunk=2, eval_envs=128, eval_steps=episode_length,
                                     video=False, progress=False, checkpoint_every=0)  # fmt: skip
        start = time.perf_counter()
        training.run(ppo, config, task, settings)
        curve, steps_per_s = training_curve(Path(out) / "metrics.jsonl", time.perf_counter() - start)
    return {"steps_per_s": steps_per_s, "curve": curve, "final_return": curve[-1][2],
            "compile_s": curve[0][1] - config.steps_per_update / steps_per_s}  # fmt: skip


def training_curve(metrics_path: Path, total_s: float) -> tuple[list, float]:
    """([(step, wall-clock s since training started, eval return)], median steps/s after
    the first chunk) of a harness run that took `total_s` in all."""
    lines = metrics.read_metrics(metrics_path)
    offset = total_s - lines[-1]["perf/elapsed_s"]  # init before the loop's clock started
    curve = [(line["step"], line["perf/elapsed_s"] + offset, line["eval/return"]) for line in lines]
    steady = [line["perf/steps_per_s"] for line in lines[1:]] or [lines[0]["perf/steps_per_s"]]
    return curve, float(np.median(steady))


def time_to(curve: list, threshold: float) -> float | None:
    return next((seconds for _, seconds, ret in curve if ret >= threshold), None)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="*", default=["cartpole_balance", "cylinder_push"])
    parser.add_argument("--steps", type=int, default=20_000_000)
    parser.add_argument("--threshold", type=float, default=0.9, help="fraction of the best final return of the two")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes, to check the script on a CPU")
    args = parser.parse_args()
    if args.smoke:
        HYPER.update(num_envs=16, batch_size=16, num_minibatches=4, num_updates_per_batch=2)
    device = jax.devices()[0].device_kind
    print(f"device: {device}, jax {jax.__version__}, {args.steps:,} env steps per run", flush=True)
    rows = []
    for env in args.envs:
        task = mjzoo.envs.make(env)
        episode_length = mjzoo.envs.defaults(env)["episode_steps"]
        raw = raw_steps_per_s(task, env, *inputs(task, HYPER["num_envs"], 100), repeats=3)
        ours = train_mjzoo(task, args.steps, episode_length)
        print(f"{env}: mjzoo done {ours['steps_per_s']:,.0f} steps/s final {ours['final_return']:.1f}", flush=True)
        peer = train_brax_ppo(task, num_timesteps=args.steps, episode_length=episode_length, num_evals=20, **HYPER)
        print(f"{env}: brax done {peer['steps_per_s']:,.0f} steps/s final {peer['final_return']:.1f}", flush=True)
        threshold = args.threshold * max(ours["final_return"], peer["final_return"])
        rows.append({"env": env, "raw_steps_per_s": raw, "threshold": threshold, "mjzoo": ours, "brax": peer,
                     "mjzoo_time_to_threshold_s": time_to(ours["curve"], threshold),
                     "brax_time_to_threshold_s": time_to(peer["curve"], threshold)})  # fmt: skip
    print(f"\n{'env':<18} {'trainer':<7} {'steps/s':>11} {'/raw':>6} {'to thr (s)':>10} {'final':>8} {'compile s':>9}")
    for r in rows:
        for name in ("mjzoo", "brax"):
            res, ttt = r[name], r[f"{name}_time_to_threshold_s"]
            print(f"{r['env']:<18} {name:<7} {res['steps_per_s']:>11,.0f} {res['steps_per_s'] / r['raw_steps_per_s']:>6.2f} "
                  f"{'never' if ttt is None else f'{ttt:.1f}':>10} {res['final_return']:>8.1f} {res['compile_s']:>9.1f}")  # fmt: skip
        print(f"{'':<18} raw     {r['raw_steps_per_s']:>11,.0f}   threshold {r['threshold']:.1f}; "
              f"mjzoo/brax steps/s = {r['mjzoo']['steps_per_s'] / r['brax']['steps_per_s']:.2f}x")
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"ppo_vs_brax_{jax.default_backend()}.json"
    path.write_text(json.dumps({"device": device, "jax": jax.__version__, "hyper": HYPER, "rows": rows}, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
