"""Training throughput of two source trees of mjzoo, side by side in one process's
machine: did a change move the hot path?

    python benchmarks/tree_ab.py --trees base=.ab/base new=. --runs ppo:humanoid_walk amp:humanoid_amp_walk

Each tree is imported from its own source folder (a shim maps ``mjzoo`` onto its lib/,
algorithms/ and envs/, so neither needs installing); each run is ``mjzoo train ALGO ENV``
through the tree's own CLI, in a fresh process, with the env's registered
hyperparameters, no video, no checkpoints and evaluation only at the end. The measure is
the median of ``perf/steps_per_s`` (training only) over every chunk after the first
(which compiles). Trees alternate within each run (A B, then B A with --repeats 2), so a
drifting clock charges both. Writes ``benchmarks/results/tree_ab/tree_ab_<card>.json``
and prints a table of steps/s and the ratio of each tree to the first.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def shim(tree: Path, into: Path) -> Path:
    """A folder whose ``mjzoo`` package is `tree`'s source, laid out as installed."""
    package = into / "mjzoo"
    package.mkdir(parents=True)
    for entry in (tree / "lib").iterdir():
        (package / entry.name).symlink_to(entry.resolve())
    (package / "algorithms").symlink_to((tree / "algorithms").resolve())
    (package / "envs").symlink_to((tree / "envs").resolve())
    return into


def train(path: Path, algorithm: str, env: str, steps: int, out: Path) -> list[float]:
    """The training steps/s of every chunk after the first, of one run."""
    code = "import sys; from mjzoo.harness.cli import main; sys.exit(main())"
    command = [sys.executable, "-c", code, "train", algorithm, env, "--out", str(out), "--total-steps", str(steps)]
    command += ["--updates-per-chunk", "5", "--no-video", "--eval-every", "0", "--checkpoint-every", "0"]
    env_vars = dict(os.environ, PYTHONPATH=f"{path}:{os.environ.get('PYTHONPATH', '')}")
    subprocess.run(command, check=True, env=env_vars, cwd=out.parent)
    lines = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    return [line["perf/steps_per_s"] for line in lines[1:] if "perf/steps_per_s" in line]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trees", nargs="+", required=True, help="NAME=PATH, the first is the baseline")
    parser.add_argument("--runs", nargs="+", default=["ppo:humanoid_walk", "amp:humanoid_amp_walk"])
    parser.add_argument("--steps", type=int, default=16_384_000, help="env steps of each run")
    parser.add_argument("--repeats", type=int, default=1, help="runs per tree; the order flips each repeat")
    parser.add_argument("--card", default="gpu", help="names the result file (e.g. H100)")
    args = parser.parse_args()
    trees = dict(item.split("=", 1) for item in args.trees)
    work = Path(tempfile.mkdtemp(prefix="tree_ab_"))
    paths = {name: shim(Path(tree), work / f"shim_{name}") for name, tree in trees.items()}
    rows = []
    for run in args.runs:
        algorithm, env = run.split(":")
        chunks: dict[str, list[float]] = {name: [] for name in trees}
        for repeat in range(args.repeats):
            order = list(trees) if repeat % 2 == 0 else list(reversed(trees))
            for name in order:
                out = work / f"{name}_{algorithm}_{env}_{repeat}"
                chunks[name] += train(paths[name], algorithm, env, args.steps, out)
        medians = {name: statistics.median(values) for name, values in chunks.items()}
        first = next(iter(trees))
        row = {"algorithm": algorithm, "env": env, "steps": args.steps, "steps_per_s": medians, "chunks": chunks}
        row["ratio_to_" + first] = {name: medians[name] / medians[first] for name in trees}
        rows.append(row)
        print(
            f"{algorithm}:{env:<20} "
            + "  ".join(f"{name} {medians[name]:>11,.0f} ({medians[name] / medians[first]:.3f}x)" for name in trees),
            flush=True,
        )
    results = ROOT / "benchmarks" / "results" / "tree_ab"
    results.mkdir(parents=True, exist_ok=True)
    (results / f"tree_ab_{args.card}.json").write_text(json.dumps({"trees": trees, "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
