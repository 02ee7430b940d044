"""How fast a run starts, and what its in-loop evaluation costs, as a user launches it.

For each env: `mjzoo train ppo ENV` is launched twice in fresh processes with one new
persistent compilation cache (cold, then warm), and the time from launch to its first
update is read off: the first metrics line's arrival, less what the run did after the
first chunk ended (its clock's ``perf/elapsed_s`` minus ``perf/first_update_s``: the
final evaluation, when the first chunk is also the last; that evaluation's end is recorded
too, as ``*_first_evaluation_s``: its compile waits behind the chunk's or runs beside
it). Then one run with the default
evaluation schedule (`Settings.eval_count` points, 20, evenly spaced, plus what
`Settings.eval_budget`'s 5% of the wall-clock affords) reports the share of its wall-clock
spent evaluating, and its overall rate against the training rate.

    python benchmarks/startup.py --envs cartpole_balance humanoid_walk
    python benchmarks/startup.py --envs cartpole_balance --steps 20000 --smoke   # on a CPU
    python benchmarks/startup.py --envs humanoid_walk --eval-run-steps 0 --logs  # where the start goes

Writes JSON to --out and prints a table.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SMOKE_CONFIG = ("num_envs=32", "unroll_length=8", "num_minibatches=2", "num_epochs=1")


def launch(
    env: str,
    out: Path,
    cache: Path,
    steps: int,
    extra: tuple[str, ...],
    smoke: bool,
    timeout: float,
    keep: Path | None = None,
) -> dict:
    """Runs `mjzoo train ppo env` to the end; returns launch-to-first-update seconds, the
    total wall-clock, and the metrics lines; with `keep`, its log (JAX's compile steps
    timed) goes there."""
    command = [
        sys.executable,
        "-m",
        "mjzoo",
        "train",
        "ppo",
        env,
        "--out",
        str(out),
        "--total-steps",
        str(steps),
        "--no-video",
        *extra,
        *(("--config", *SMOKE_CONFIG, "--eval-envs", "4") if smoke else ()),
    ]
    environment = {**os.environ, "MJZOO_COMPILE_CACHE": str(cache), **({"JAX_LOG_COMPILES": "1"} if keep else {})}
    metrics = out / "metrics.jsonl"
    log = open(out.parent / f"{out.name}.log", "w+")  # not a pipe: a full one would stall the child's progress bar
    start = time.perf_counter()
    process = subprocess.Popen(command, env=environment, stdout=log, stderr=subprocess.STDOUT, text=True)
    first = None
    while process.poll() is None:
        if first is None and metrics.exists() and metrics.stat().st_size > 0:
            first = time.perf_counter() - start
        if time.perf_counter() - start > timeout:
            process.kill()
            raise TimeoutError(f"{env}: no end after {timeout:.0f} s")
        time.sleep(0.05)
    total = time.perf_counter() - start
    log.seek(0)
    output = log.read()
    log.close()
    if keep is not None:
        (keep / f"{env}_{out.name}.log").write_text(output)
    if process.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{output[-3000:]}")
    lines = [json.loads(line) for line in metrics.read_text().splitlines()]
    # The first line is written after its chunk's evaluation, if one was due (always when
    # the first chunk is the last): the run's own clock says how long that took.
    first -= lines[0]["perf/elapsed_s"] - lines[0]["perf/first_update_s"]
    return {"launch_to_first_update_s": first, "wall_s": total, "lines": lines}


def measure(env: str, steps: int, eval_steps: int, smoke: bool, timeout: float, keep: Path | None) -> dict:
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        cache = scratch / "cache"
        no_eval = ("--eval-every", "0")
        cold = launch(env, scratch / "cold", cache, steps, no_eval, smoke, timeout, keep)
        print(f"{env}: cold launch to first update {cold['launch_to_first_update_s']:.1f} s", flush=True)
        warm = launch(env, scratch / "warm", cache, steps, no_eval, smoke, timeout, keep)
        print(f"{env}: warm launch to first update {warm['launch_to_first_update_s']:.1f} s", flush=True)
        budget = launch(env, scratch / "budget", cache, eval_steps, (), smoke, timeout) if eval_steps else None
    row = {
        "env": env,
        "cold_launch_to_first_update_s": cold["launch_to_first_update_s"],
        "warm_launch_to_first_update_s": warm["launch_to_first_update_s"],
        "cold_first_update_s": cold["lines"][0]["perf/first_update_s"],
        "warm_first_update_s": warm["lines"][0]["perf/first_update_s"],
        # To the end of the first evaluation (run's clock), whose compile waits behind the chunk's or beside it.
        **{
            f"{name}_first_evaluation_s": run["lines"][0]["perf/elapsed_s"]
            for name, run in (("cold", cold), ("warm", warm))
            if "eval/return" in run["lines"][0]
        },
    }
    if budget is None:
        return row
    lines = budget["lines"]
    elapsed = lines[-1]["perf/elapsed_s"]
    first = lines[0]["perf/first_update_s"]
    evaluating = sum(line.get("perf/eval_s", 0.0) for line in lines[:-1])  # the last always evaluates
    training_rates = [line["perf/steps_per_s"] for line in lines[1:]] or [lines[0]["perf/steps_per_s"]]
    overall = (lines[-1]["step"] - lines[0]["step"]) / max(elapsed - first, 1e-9)
    row["budget_run"] = {
        "steps": lines[-1]["step"],
        "evaluations": sum("eval/return" in line for line in lines),
        "eval_share_before_last": evaluating / elapsed,
        "elapsed_s": elapsed,
        "training_steps_per_s": sum(training_rates) / len(training_rates),
        "overall_steps_per_s_after_first": overall,
        "final_return": lines[-1].get("eval/return"),
    }
    print(
        f"{env}: budget run: {row['budget_run']['evaluations']} evaluations, "
        f"{100 * row['budget_run']['eval_share_before_last']:.1f}% of {elapsed:.0f} s evaluating; training "
        f"{row['budget_run']['training_steps_per_s']:,.0f} steps/s, overall {overall:,.0f}",
        flush=True,
    )
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["cartpole_balance", "humanoid_walk"])
    parser.add_argument("--steps", type=int, default=2_000_000, help="env steps of the cold and warm launches")
    parser.add_argument("--eval-run-steps", type=int, default=20_000_000, help="env steps of the budget run; 0: none")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes, to check the script on a CPU")
    parser.add_argument("--timeout", type=float, default=900.0)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "startup")
    parser.add_argument("--name-envs", action="store_true", help="name the JSON after the envs too")
    parser.add_argument(
        "--logs",
        action="store_true",
        help="keep the cold and warm launches' logs in OUT/logs, with JAX's compile steps timed",
    )
    args = parser.parse_args()
    import jax  # after the children's launch settings are read: only to name the device

    device = jax.devices()[0].device_kind
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"startup_{jax.default_backend()}{'_' + '_'.join(args.envs) if args.name_envs else ''}.json"
    keep = args.out / "logs" if args.logs else None
    if keep is not None:
        keep.mkdir(exist_ok=True)
    rows = []
    for env in args.envs:
        eval_steps = args.steps if args.smoke and args.eval_run_steps else args.eval_run_steps
        rows.append(measure(env, args.steps, eval_steps, args.smoke, args.timeout, keep))
        path.write_text(json.dumps({"device": device, "rows": rows}, indent=1))
    print(f"\n{'env':<18} {'cold (s)':>9} {'warm (s)':>9} {'eval share':>10} {'train/s':>12} {'overall/s':>12}")
    for r in rows:
        b = r.get("budget_run")
        print(
            f"{r['env']:<18} {r['cold_launch_to_first_update_s']:>9.1f} {r['warm_launch_to_first_update_s']:>9.1f} "
            + (
                f"{100 * b['eval_share_before_last']:>9.1f}% {b['training_steps_per_s']:>12,.0f} "
                f"{b['overall_steps_per_s_after_first']:>12,.0f}"
                if b
                else "  (no budget run)"
            )
        )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
