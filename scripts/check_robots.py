"""`mjzoo.testing.check_task` on every robot joystick and terrain (envs/robot_joystick.py).

    python scripts/check_robots.py                       # all nine, ~5 min each on a 2-core CPU
    python scripts/check_robots.py --only go1:rough g1:flat

Each variant is one compile of minutes on a CPU, so the suite checks the Go1 on flat
ground alone (tests/envs/test_robot_joystick.py) and this script the rest. Prints one line
per variant (passed, skipped with why, or the failures) and merges the results into
benchmarks/results/robots/check_task.json. Exits 1 when any variant fails.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

VARIANTS = [f"{robot}:{terrain}" for robot in ("go1", "g1", "t1", "berkeley_humanoid") for terrain in ("flat", "rough")]
VARIANTS.append("go1:stairs")
OUT = Path(__file__).resolve().parent.parent / "benchmarks" / "results" / "robots" / "check_task.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", choices=VARIANTS, default=VARIANTS)
    parser.add_argument("--num-envs", type=int, default=2)
    parser.add_argument("--num-steps", type=int, default=8)
    args = parser.parse_args()

    import jax

    import mjzoo.envs
    from mjzoo import testing

    results = json.loads(OUT.read_text()) if OUT.is_file() else {}
    failed = False
    for variant in args.only:
        robot, terrain = variant.split(":")
        start = time.perf_counter()
        task = mjzoo.envs.make(f"{robot}_joystick", terrain=terrain)
        try:
            report = testing.check_task(task, num_envs=args.num_envs, num_steps=args.num_steps)
            entry = dict(passed=list(report.passed), skipped=report.skipped, failures={})
        except testing.TaskCheckError as e:
            entry, failed = dict(passed=[], skipped=e.skipped, failures=e.failures), True
        entry.update(seconds=round(time.perf_counter() - start, 1), num_envs=args.num_envs, num_steps=args.num_steps)
        entry.update(machine=f"{platform.node()} ({jax.devices()[0].platform}, {jax.__version__})")
        results[variant] = entry
        verdict = (
            "FAILED " + "; ".join(f"{k}: {v}" for k, v in entry["failures"].items()) if entry["failures"] else "ok"
        )
        skipped = f" (skipped: {', '.join(entry['skipped'])})" if entry["skipped"] else ""
        print(f"{variant:26s} {verdict}{skipped}  {entry['seconds']:.0f} s", flush=True)
        OUT.parent.mkdir(parents=True, exist_ok=True)
        OUT.write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")
        jax.clear_caches()  # nine robots' programs in one process exhausted LLVM's memory
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
