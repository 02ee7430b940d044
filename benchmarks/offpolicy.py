"""Off-policy learners beside PPO, on one GPU: SAC and FastTD3 against PPO's return.

Per task and seed, in one process: PPO with the env's registered hyperparameters, then
each off-policy learner (the configs below: FastTD3's paper recipe, and SAC at the same
scale) for its own budget of env steps. PPO's final evaluation return (the mean over
seeds) is the bar; for each off-policy run the JSON records the env steps and the
wall-clock seconds from the start of training, compile included, to its first
evaluation at or above the bar (null: not reached), and the ratios to PPO's own
(PPO reaching 95% of its final return, so its figure is not its whole run). Curves of
the evaluation return against env steps and against seconds are written per task
(``curves_<task>.png``) and kept in the JSON.

Tasks: humanoid_walk, g1_joystick (its dict observation: the policy on "state", the
critic on "privileged_state", as PPO's registered config), and three DM Control envs
through `mjzoo.interop.playground` (CheetahRun, WalkerWalk, CartpoleSwingup). Whether a
joystick policy *tracks* its commands (the off-policy goal on the G1) is robots.py's
measure: ``robots.py --algorithm fast_td3`` trains with these settings and evaluates it.

    python benchmarks/offpolicy.py                     # all tasks, 2 seeds (one H100/H200)
    python benchmarks/offpolicy.py --tasks g1_joystick --algorithms fast_td3
    python benchmarks/offpolicy.py --smoke             # a tiny run of everything on a CPU
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from ppo_vs_brax import time_to  # noqa: E402
from ppo_vs_brax import training_curve  # noqa: E402

import mjzoo  # noqa: E402
import mjzoo.envs  # noqa: E402
from mjzoo.algorithms import fast_td3  # noqa: E402
from mjzoo.algorithms import ppo  # noqa: E402
from mjzoo.algorithms import sac  # noqa: E402
from mjzoo.harness import training  # noqa: E402

TASKS = ("humanoid_walk", "g1_joystick", "playground:CheetahRun", "playground:WalkerWalk", "playground:CartpoleSwingup")
MODULES = {"ppo": ppo, "sac": sac, "fast_td3": fast_td3}
# Off-policy budgets: far fewer env steps than PPO's (the goal is <= 10x fewer).
STEPS = {"humanoid_walk": 10_000_000, "g1_joystick": 10_000_000}
DEFAULT_STEPS = 3_000_000
# The critics' support bounds the discounted return, r_max / (1 - discount) at the most:
# DM Control pays at most 1 a step; the locomotion tasks several (the G1 joystick up to
# ~4.5: tracking 1.5, air time 1, alive 2).
SUPPORT = {"humanoid_walk": (-100.0, 1000.0), "g1_joystick": (-250.0, 500.0)}
DMC_SUPPORT = (-10.0, 110.0)
FAST_TD3 = dict(num_envs=1024, batch_size=32_768, gradient_steps=2, n_steps=3, buffer_size=1024 * 1024)
SAC = dict(
    num_envs=1024,
    batch_size=8192,
    gradient_steps=2,
    n_steps=3,
    buffer_size=1024 * 1024,
    learning_starts=10_240,
    normalize_observations=True,
    layer_norm=True,
    policy_hidden_sizes=(512, 256, 128),
    critic_hidden_sizes=(1024, 512, 256),
)
SMOKE = dict(num_envs=4, batch_size=32, buffer_size=4096, learning_starts=64, policy_hidden_sizes=(16,))
SMOKE_CRITIC = dict(critic_hidden_sizes=(16,))


def fields(algorithm: str, task_name: str, steps: int, smoke: bool) -> dict:
    """The flat Config and Hyperparams fields of `algorithm` on `task_name`."""
    if algorithm == "ppo":
        registered = mjzoo.envs.hyperparameters(task_name, "ppo")
        if smoke:
            registered = {**registered, "num_envs": 4, "unroll_length": 8, "num_minibatches": 2, "num_epochs": 1}
        return {**registered, "total_steps": steps}
    keys = mjzoo.envs.hyperparameters(task_name, "ppo")
    views = {"policy_obs_key": keys.get("policy_obs_key"), "critic_obs_key": keys.get("value_obs_key")}
    base = {"sac": SAC, "fast_td3": FAST_TD3}[algorithm]
    if smoke:
        base = {**base, **SMOKE, **SMOKE_CRITIC, **({"num_atoms": 11} if algorithm == "fast_td3" else {})}
    extra = {}
    if algorithm == "fast_td3":
        extra = dict(zip(("v_min", "v_max"), SUPPORT.get(task_name, DMC_SUPPORT)))
    return {**base, **views, **extra, "total_steps": steps}


def train_one(algorithm: str, task_name: str, task: mjzoo.Task, steps: int, seed: int, out: Path, smoke: bool) -> dict:
    """One run through the harness: its curve, final return, and time."""
    module = MODULES[algorithm]
    config, hyperparams = module.configure(**fields(algorithm, task_name, steps, smoke))
    settings = training.Settings(
        out_dir=out,
        seed=seed,
        video=False,
        progress=False,
        overwrite=True,
        checkpoint_every=0,  # a replay of a million steps is a large checkpoint: the benchmark needs none
        eval_count=4 if smoke else 20,
        eval_envs=4 if smoke else 64,
        eval_steps=50 if smoke else None,
        compile_cache=False,  # compile included, as a fresh machine pays it
    )
    start = time.perf_counter()
    _, last = training.run(module.make(config), task, settings, hyperparams)
    total = time.perf_counter() - start
    curve, rate = training_curve(out / "metrics.jsonl", total)
    return {
        "algorithm": algorithm,
        "seed": seed,
        "env_steps": config.num_updates * config.steps_per_update,
        "wall_s": total,
        "steps_per_s": rate,
        "final_return": float(last.get("eval/return", np.nan)),
        "curve": curve,  # (env steps, seconds since training started, eval return)
    }


def steps_to(curve: list, threshold: float) -> int | None:
    return next((step for step, _, ret in curve if ret >= threshold), None)


def compare(runs: list[dict]) -> dict:
    """Per off-policy algorithm: steps and seconds to PPO's mean final return, per seed
    and as ratios to PPO's time to 95% of it."""
    ppo_runs = [r for r in runs if r["algorithm"] == "ppo"]
    bar = float(np.mean([r["final_return"] for r in ppo_runs]))
    ppo_steps = [steps_to(r["curve"], 0.95 * bar) for r in ppo_runs]
    ppo_seconds = [time_to(r["curve"], 0.95 * bar) for r in ppo_runs]
    summary = {"ppo_return": bar, "ppo_steps_to_95": ppo_steps, "ppo_seconds_to_95": ppo_seconds}
    for name in sorted({r["algorithm"] for r in runs} - {"ppo"}):
        mine = [r for r in runs if r["algorithm"] == name]
        steps = [steps_to(r["curve"], bar) for r in mine]
        seconds = [time_to(r["curve"], bar) for r in mine]
        reached = [s for s in steps if s is not None]
        summary[name] = {
            "final_return": [r["final_return"] for r in mine],
            "steps_to_ppo_return": steps,
            "seconds_to_ppo_return": seconds,
            "fewer_steps_than_ppo": (
                float(np.mean([s for s in ppo_steps if s]) / np.mean(reached)) if reached and any(ppo_steps) else None
            ),
            "seconds_vs_ppo": (
                float(np.mean([s for s in seconds if s is not None]) / np.mean([s for s in ppo_seconds if s]))
                if all(s is not None for s in seconds) and any(ppo_seconds)
                else None
            ),
        }
    return summary


def plot(task_name: str, runs: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    colors = {"ppo": "C0", "sac": "C1", "fast_td3": "C2"}
    for run in runs:
        curve = np.asarray(run["curve"], float).reshape(-1, 3)
        label = f"{run['algorithm']} seed {run['seed']}"
        for ax, column in zip(axes, (0, 1)):
            ax.plot(curve[:, column], curve[:, 2], color=colors[run["algorithm"]], alpha=0.8, label=label)
    axes[0].set_xlabel("env steps")
    axes[1].set_xlabel("seconds (compile included)")
    for ax in axes:
        ax.set_ylabel("eval return")
        ax.set_title(task_name)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", nargs="+", default=list(TASKS))
    parser.add_argument("--algorithms", nargs="+", default=["sac", "fast_td3"], choices=["sac", "fast_td3"])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--ppo-steps", type=int, default=None, help="default: the env's registered budget")
    parser.add_argument("--steps", type=int, default=None, help="off-policy env steps; default: per task")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "offpolicy")
    parser.add_argument("--smoke", action="store_true", help="tiny configs on pendulum_swingup: that it executes")
    args = parser.parse_args()
    if args.smoke:
        args.tasks, args.out = ["pendulum_swingup"], args.out / "smoke"
    args.out.mkdir(parents=True, exist_ok=True)
    result = {"device": jax.devices()[0].device_kind, "tasks": {}}
    for task_name in args.tasks:
        task = mjzoo.envs.make(task_name)
        ppo_steps = args.ppo_steps or mjzoo.envs.hyperparameters(task_name, "ppo").get("total_steps", 50_000_000)
        off_steps = args.steps or STEPS.get(task_name, DEFAULT_STEPS)
        if args.smoke:
            ppo_steps, off_steps = 4 * 8 * 4, 4 * 64
        runs = []
        for seed in range(args.seeds):
            for algorithm in ["ppo", *args.algorithms]:
                out = args.out / "runs" / task_name.replace(":", "_") / f"{algorithm}_{seed}"
                steps = ppo_steps if algorithm == "ppo" else off_steps
                run = train_one(algorithm, task_name, task, steps, seed, out, args.smoke)
                runs.append(run)
                print(
                    f"{task_name:<28} {algorithm:<9} seed {seed}  return {run['final_return']:9.2f}  "
                    f"{run['env_steps']:>11,} steps  {run['wall_s']:8.1f} s",
                    flush=True,
                )
        summary = compare(runs)
        result["tasks"][task_name] = {"summary": summary, "runs": runs}
        plot(task_name, runs, args.out / f"curves_{task_name.replace(':', '_')}.png")
        (args.out / "offpolicy.json").write_text(json.dumps(result, indent=1))  # after every task
        print(json.dumps({task_name: summary}, indent=1), flush=True)


if __name__ == "__main__":
    main()
