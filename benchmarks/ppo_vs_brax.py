"""mjzoo PPO against Brax PPO on the same task, same hyperparameters, one process.

For each env: (a) raw batched stepping of the task's physics at the same number of envs,
(b) mjzoo PPO (`mjzoo.algorithms.ppo.train`), (c) Brax PPO (`brax.training.agents.ppo.train`)
through `mjzoo.interop.brax`. Hyperparameters: MuJoCo Playground's DM Control defaults
(2048 envs, batch 1024, unroll 30, 32 minibatches, 16 updates per batch, lr 1e-3,
entropy 1e-2, discount 0.995, reward scaling 10, normalized observations, clip 0.3, no
gradient clipping, Brax's default networks: policy 4x32, value 5x256, swish).

Each env runs on every physics implementation of ``--impl`` (MJX-JAX, MuJoCo Warp), all
three measurements per implementation; Brax PPO runs on Warp where it can (it vmaps the
env itself: the task's contact pool is sized for its batches first), else the reason is
recorded and printed.

Two rates per trainer, each measured the same way for both: ``steps_per_s``, env steps
over the wall-clock from its first to its last evaluation after training began (its own
evaluations included: Brax's 20, mjzoo's default budget of 5% of the wall-clock), and
``train_steps_per_s``, training alone (mjzoo: the median chunk; Brax: its
``training/walltime``). Prints a table (both rates, training's share of raw stepping,
wall-clock time to a return threshold, final return) and writes JSON: ``rows`` holds one
row per (env, impl), its ``"impl"`` naming the physics, with the old keys' meanings (old
files, without ``"impl"``, are JAX) plus ``mjzoo_fraction_of_raw`` /
``brax_fraction_of_raw`` (training alone over raw stepping) and the ratios
``mjzoo_over_brax_steps_per_s`` / ``mjzoo_over_brax_train_steps_per_s``; a trainer that
could not run has ``{"error": why}`` in place of its result. ``warp_vs_jax`` holds, per
env measured on both, Warp's figure over JAX's for raw stepping, each trainer's steps/s
and time to its threshold.

    python benchmarks/ppo_vs_brax.py --envs cartpole_balance cylinder_push --steps 20000000
    python benchmarks/ppo_vs_brax.py --envs cartpole_balance --steps 4000000 --impl warp jax
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from brax_peer import train_brax_ppo  # noqa: E402
from brax_peer import wall_steps_per_s  # noqa: E402
from task_overhead import add_impl_argument  # noqa: E402
from task_overhead import impls  # noqa: E402
from task_overhead import inputs  # noqa: E402
from task_overhead import ratio  # noqa: E402
from task_overhead import raw_steps_per_s  # noqa: E402

import mjzoo  # noqa: E402
import mjzoo.envs  # noqa: E402
from mjzoo.algorithms import ppo  # noqa: E402
from mjzoo.harness import metrics  # noqa: E402
from mjzoo.harness import training  # noqa: E402
from mjzoo.harness.cli import arguments  # noqa: E402

HYPER = dict(
    num_envs=2048,
    batch_size=1024,
    unroll_length=30,
    num_minibatches=32,
    num_updates_per_batch=16,
    learning_rate=1e-3,
    entropy_cost=1e-2,
    discounting=0.995,
    reward_scaling=10.0,
)


def mjzoo_config(total_steps: int) -> dict:
    """The same algorithm in mjzoo's terms, as `ppo.configure`'s fields: Brax collects
    batch*minibatches/envs = 16 unrolls of 30 steps per env per update; mjzoo collects
    one unroll of 480."""
    h = HYPER
    unrolls = h["batch_size"] * h["num_minibatches"] // h["num_envs"]
    return dict(
        num_envs=h["num_envs"],
        unroll_length=h["unroll_length"] * unrolls,
        num_minibatches=h["num_minibatches"],
        num_epochs=h["num_updates_per_batch"],
        learning_rate=h["learning_rate"],
        entropy_coef=h["entropy_cost"],
        discount=h["discounting"],
        reward_scaling=h["reward_scaling"],
        gae_lambda=0.95,
        clip_epsilon=0.3,
        max_grad_norm=None,
        normalize_observations=True,
        policy_hidden_sizes=(32,) * 4,
        value_hidden_sizes=(256,) * 5,
        activation="swish",
        **ppo.PLAIN,  # Brax's PPO: a constant rate, value targets and rewards as they are
        total_steps=total_steps,
    )


def train_mjzoo(task: mjzoo.Task, total_steps: int, episode_length: int, seed: int = 0, **overrides) -> dict:
    config, hyperparams = ppo.configure(**{**mjzoo_config(total_steps), **overrides})
    with tempfile.TemporaryDirectory() as out:
        # Evaluate about as often as Brax does with num_evals=20 (every ~2M steps); Brax
        # writes no checkpoints, so neither do we here.
        settings = training.Settings(
            out_dir=Path(out),
            updates_per_chunk=2,
            eval_envs=128,
            eval_steps=episode_length,
            video=False,
            progress=False,
            checkpoint_every=0,
            seed=seed,
        )
        start = time.perf_counter()
        training.run(ppo.make(config), task, settings, hyperparams)
        curve, train_steps_per_s = training_curve(Path(out) / "metrics.jsonl", time.perf_counter() - start)
    return {
        "steps_per_s": wall_steps_per_s(curve),
        "train_steps_per_s": train_steps_per_s,
        "curve": curve,
        "final_return": curve[-1][2],
        "compile_s": curve[0][1] - config.steps_per_update / train_steps_per_s,
    }


def training_curve(metrics_path: Path, total_s: float) -> tuple[list, float]:
    """([(step, wall-clock s since training started, eval return)], median steps/s after
    the first chunk) of a harness run that took `total_s` in all."""
    lines = metrics.read_metrics(metrics_path)
    offset = total_s - lines[-1]["perf/elapsed_s"]  # init before the loop's clock started
    curve = [
        (line["step"], line["perf/elapsed_s"] + offset, line["eval/return"]) for line in lines if "eval/return" in line
    ]  # the harness evaluates within its wall-clock budget, not every chunk
    steady = [line["perf/steps_per_s"] for line in lines[1:]] or [lines[0]["perf/steps_per_s"]]
    return curve, float(np.median(steady))


def time_to(curve: list, threshold: float) -> float | None:
    return next((seconds for _, seconds, ret in curve if ret >= threshold), None)


def train_peer(task: mjzoo.Task, total_steps: int, episode_length: int, seed: int = 0) -> dict:
    """Brax PPO's result, or ``{"error": why}`` where it cannot train `task` (Brax's
    wrappers on Warp's physics state)."""
    try:
        # Brax trains at least one epoch between evaluations: fewer of them on short runs.
        epoch = HYPER["batch_size"] * HYPER["unroll_length"] * HYPER["num_minibatches"]
        num_evals = min(20, max(3, total_steps // epoch + 1))
        return train_brax_ppo(
            task, num_timesteps=total_steps, episode_length=episode_length, num_evals=num_evals, seed=seed, **HYPER
        )
    except Exception as e:  # noqa: BLE001  # recorded in the JSON: the run goes on
        return {"error": f"{type(e).__name__}: {e}"[:2000]}


def mean_of(runs: list[dict]) -> dict:
    """Several seeds' results as one: the means of steps/s, final return and compile time
    (and the final returns' spread), each seed's result under "runs"."""
    if any("error" in r for r in runs):
        return next(r for r in runs if "error" in r)
    mean = {k: float(np.mean([r[k] for r in runs])) for k in runs[0] if isinstance(runs[0][k], (int, float))}
    return {
        **mean,
        "final_return_std": float(np.std([r["final_return"] for r in runs])),
        "seeds": len(runs),
        "runs": runs,
    }


def measure(env: str, impl: str, total_steps: int, seeds: int, trainers: list[str], overrides: dict) -> dict:
    """One row: raw stepping, then mjzoo PPO (with `overrides` of its config) and Brax PPO
    on `env` with `impl` physics, over `seeds` seeds each (`summarize` adds the rest)."""
    task = mjzoo.envs.make(env, impl=impl)
    episode_length = mjzoo.envs.defaults(env)["episode_steps"]
    raw = raw_steps_per_s(task, env, *inputs(task, HYPER["num_envs"], 100), repeats=3)
    print(f"{env} ({impl}): raw stepping {raw:,.0f} steps/s", flush=True)
    train = {
        "mjzoo": lambda seed: train_mjzoo(task, total_steps, episode_length, seed, **overrides),
        "brax": lambda seed: train_peer(task, total_steps, episode_length, seed),
    }
    results = {}
    for name in trainers:
        runs = []
        for seed in range(seeds):
            runs.append(train[name](seed))
            if "error" in runs[-1]:
                print(f"{env} ({impl}): {name} PPO could not run: {runs[-1]['error'][:500]}", flush=True)
                break
            print(
                f"{env} ({impl}) seed {seed}: {name} {runs[-1]['steps_per_s']:,.0f} steps/s, final "
                f"{runs[-1]['final_return']:.1f}, compile {runs[-1]['compile_s']:.0f} s",
                flush=True,
            )
        results[name] = mean_of(runs)
    return {"env": env, "impl": impl, "raw_steps_per_s": raw, "mjzoo_overrides": overrides, **results}


def summarize(row: dict, threshold: float) -> dict:
    """Adds the threshold (`threshold` of the better final return), each trainer's time
    to it (the mean over seeds; None if a seed never got there) and its fraction of raw
    stepping, from the trainers' results in `row`."""
    results = {name: row[name] for name in ("mjzoo", "brax") if name in row}
    row["threshold"] = threshold * max(r["final_return"] for r in results.values() if "error" not in r)
    for name, r in results.items():
        if "error" in r:
            row[f"{name}_time_to_threshold_s"] = row[f"{name}_fraction_of_raw"] = None
            continue
        times = [time_to(run["curve"], row["threshold"]) for run in r.get("runs", [r])]
        row[f"{name}_time_to_threshold_s"] = None if None in times else float(np.mean(times))
        row[f"{name}_fraction_of_raw"] = r["train_steps_per_s"] / row["raw_steps_per_s"]
    if all(name in results and "error" not in results[name] for name in ("mjzoo", "brax")):
        for rate in ("steps_per_s", "train_steps_per_s"):
            row[f"mjzoo_over_brax_{rate}"] = ratio(results["mjzoo"].get(rate), results["brax"].get(rate))
    return row


def merged(old: list[dict], row: dict) -> list[dict]:
    """`old` rows with `row` in place of the one of the same env and physics, keeping
    that one's trainers `row` did not measure (each trainer may run in its own process)."""
    same = next((r for r in old if (r["env"], r["impl"]) == (row["env"], row["impl"])), None)
    if same is None:
        return [*old, row]
    kept = {name: same[name] for name in ("mjzoo", "brax") if name in same and name not in row}
    return [{**row, **kept} if r is same else r for r in old]


def warp_vs_jax(env: str, warp: dict, jax_: dict) -> dict:
    """Warp's figures over JAX's (None where a trainer did not run or never got there)."""
    speed = lambda row, name: row[name].get("steps_per_s")  # noqa: E731
    return {
        "env": env,
        "raw_steps_per_s": ratio(warp["raw_steps_per_s"], jax_["raw_steps_per_s"]),
        **{f"{name}_steps_per_s": ratio(speed(warp, name), speed(jax_, name)) for name in ("mjzoo", "brax")},
        **{
            f"{name}_time_to_threshold_s": ratio(
                warp[f"{name}_time_to_threshold_s"], jax_[f"{name}_time_to_threshold_s"]
            )
            for name in ("mjzoo", "brax")
        },
    }


def warp_vs_jax_rows(rows: list[dict]) -> list[dict]:
    """`warp_vs_jax` of each env with both physics measured by both trainers."""
    complete = [r for r in rows if "mjzoo" in r and "brax" in r]
    by_env = {r["env"]: {q["impl"]: q for q in complete if q["env"] == r["env"]} for r in complete}
    return [warp_vs_jax(env, both["warp"], both["jax"]) for env, both in by_env.items() if len(both) == 2]


def print_table(rows: list[dict]) -> None:
    print(
        f"\n{'env':<18} {'impl':<5} {'trainer':<7} {'steps/s':>11} {'training':>11} {'/raw':>6} {'to thr (s)':>10} "
        f"{'final':>8} {'compile s':>9}"
    )
    for r in rows:
        for name in (n for n in ("mjzoo", "brax") if n in r):
            res, ttt = r[name], r[f"{name}_time_to_threshold_s"]
            if "error" in res:
                print(f"{r['env']:<18} {r['impl']:<5} {name:<7} did not run: {res['error'][:200]}")
                continue
            print(
                f"{r['env']:<18} {r['impl']:<5} {name:<7} {res['steps_per_s'] or 0:>11,.0f} {res['train_steps_per_s']:>11,.0f} "
                f"{r[f'{name}_fraction_of_raw']:>6.2f} "
                f"{'never' if ttt is None else f'{ttt:.1f}':>10} {res['final_return']:>8.1f} {res['compile_s']:>9.1f}"
            )
        wall, train = r.get("mjzoo_over_brax_steps_per_s"), r.get("mjzoo_over_brax_train_steps_per_s")
        print(
            f"{'':<18} {r['impl']:<5} raw     {r['raw_steps_per_s']:>11,.0f}   threshold {r['threshold']:.1f}"
            + (f"; mjzoo/brax steps/s = {wall:.2f}x (training alone {train:.2f}x)" if wall and train else "")
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="*", default=["cartpole_balance", "cylinder_push"])
    parser.add_argument("--steps", type=int, default=20_000_000)
    parser.add_argument("--threshold", type=float, default=0.9, help="fraction of the best final return of the two")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes, to check the script on a CPU")
    parser.add_argument("--tag", default="", help="suffix of the JSON file")
    parser.add_argument(
        "--merge",
        action="store_true",
        help="merge into the JSON's rows (the trainers measured now replace theirs; others stay)",
    )
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--trainers", nargs="+", default=["mjzoo", "brax"], choices=["mjzoo", "brax"])
    parser.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="FIELD=VALUE",
        help="ppo.configure overrides for mjzoo (e.g. compute_dtype=bfloat16 learning_rate=1e-3)",
    )
    add_impl_argument(parser)
    args = parser.parse_args()
    overrides = arguments.parse_assignments(tuple(args.set), "--set")
    if args.smoke:
        HYPER.update(num_envs=16, batch_size=16, num_minibatches=4, num_updates_per_batch=2)
    device = jax.devices()[0].device_kind
    print(f"device: {device}, jax {jax.__version__}, {args.steps:,} env steps per run", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"ppo_vs_brax_{jax.default_backend()}{'_' + args.tag if args.tag else ''}.json"
    rows = json.loads(path.read_text())["rows"] if args.merge and path.exists() else []
    for env in args.envs:
        for impl in impls(args.impl):
            row = measure(env, impl, args.steps, args.seeds, args.trainers, overrides)
            rows = [summarize(r, args.threshold) for r in merged(rows, row)]
            ratios = warp_vs_jax_rows(rows)
            # After each row: a later one that runs out of time leaves these.
            path.write_text(
                json.dumps(
                    {"device": device, "jax": jax.__version__, "hyper": HYPER, "rows": rows, "warp_vs_jax": ratios},
                    indent=2,
                )
            )
    print_table(rows)
    for r in ratios:
        print(
            f"{r['env']}: warp/jax raw {r['raw_steps_per_s']:.2f}x, mjzoo PPO {r['mjzoo_steps_per_s']:.2f}x"
            + (f", brax PPO {r['brax_steps_per_s']:.2f}x" if r["brax_steps_per_s"] else "")
        )
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
    os._exit(0)  # Warp on a CPU may hang at interpreter exit
