"""Writes docs/benchmarks.md from the measurements in benchmarks/results/: the page is
never edited by hand, and the suite checks that it is this script's output (so it
cannot drift from the JSON beside the scripts that wrote it).

    python benchmarks/report.py           # rewrite docs/benchmarks.md
    python benchmarks/report.py --check   # exit 1 if the page differs from the results
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
PAGE = ROOT / "docs" / "benchmarks.md"
DM_CONTROL_ENVS = 25  # Playground's DM Control Suite, as learning_quality.py runs it
COLLAPSE = 0.9  # learning_quality.py's: a run that ends below this fraction of its best


def _link(path: Path) -> str:
    """`path` relative to docs/, for a link from the page."""
    return "../" + path.relative_to(ROOT).as_posix()


def _number(x: float | None, digits: int = 1) -> str:
    return "-" if x is None else f"{x:,.{digits}f}"


def _trainer_table(rows: list[dict]) -> list[str]:
    """One line per env, reward scale and trainer: final return (mean ± std over seeds),
    best, the lowest kept fraction of a seed, collapsed seeds, time to 90% of the better
    final return, steps/s, and how many processes shared the GPU."""
    lines = [
        "| env | reward x | trainer | seeds | final (mean ± std) | best | lowest kept | collapsed | "
        "to 90% (s) | steps/s | GPU shared by |",
        "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for row in sorted(rows, key=lambda r: (r["env"], r["reward_scale"])):
        for name, t in row["trainers"].items():
            to_90 = "never" if t["time_to_threshold_s"] is None else f"{t['time_to_threshold_s']:.0f}"
            lines.append(
                f"| {row['env']} | {row['reward_scale']:g} | {name} | {t['seeds']} | "
                f"{t['final_return']:,.1f} ± {t['final_return_std']:,.1f} | {t['best_return']:,.1f} | "
                f"{_number(t.get('min_kept_fraction'), 2)} | {t['collapsed_runs']} | {to_90} | "
                f"{_number(t.get('steps_per_s'), 0)} | {t.get('gpu_shared_by', 1)} |"
            )
    return lines


def _per_device(folder: Path) -> Iterator[tuple[dict, list[str]]]:
    """Each JSON of `folder` (one per device: "<folder name>_<card>.json") and its heading."""
    for path in sorted(folder.glob(f"{folder.name}_*.json")):
        data = json.loads(path.read_text())
        yield data, [f"### {data['device']} ([{path.name}]({_link(path)}))", ""]


def _figures(folder: Path) -> list[str]:
    return [f"![{png.stem}]({_link(png)})" for png in sorted(folder.glob("*.png"))]


def learning_quality() -> list[str]:
    folder = RESULTS / "learning_quality"
    lines = [
        "## PPO's learning quality",
        "",
        "`benchmarks/learning_quality.py`: every seed of an mjzoo configuration in one vmapped",
        "program, Brax PPO one seed after another on the same env object, at one env-step budget",
        "per env. Trainers: `mjzoo-translated` (Playground's tuned Brax PPO hyperparameters in",
        "mjzoo's terms), `mjzoo-defaults` (`ppo.Config()`'s, with the same number of envs), `brax`.",
        "A final return is the last evaluation's (deterministic first episodes); normalized, it",
        "is divided by the better trainer's on that env; a run *collapsed* when it ended below",
        f"{COLLAPSE} of its own best evaluation. Times and steps/s are the GPU's own only where",
        "it was shared by 1 process: the waves train several envs at once on one GPU.",
        "",
    ]
    for data, heading in _per_device(folder):
        rows = data["rows"]
        playground = sorted({r["env"] for r in rows if r.get("source") == "playground"})
        lines += [
            *heading,
            f"Playground's DM Control envs measured: {len(playground)} of {DM_CONTROL_ENVS}; "
            f"mjzoo's own: {len({r['env'] for r in rows}) - len(playground)}.",
            "",
            "| reward x | trainer | envs | runs | median normalized final | collapsed runs |",
            "| ---: | --- | ---: | ---: | ---: | ---: |",
        ]
        for scale, trainers in data["summary"].items():
            for name, s in trainers.items():
                lines.append(
                    f"| {float(scale):g} | {name} | {s['envs']} | {s['runs']} | "
                    f"{_number(s['median_normalized_final'], 3)} | {s['collapsed_runs']} |"
                )
        lines += ["", *_trainer_table(rows), ""]
    return [*lines, *_figures(folder), ""]


def ppo_stability() -> list[str]:
    folder = RESULTS / "ppo_stability"
    lines = [
        "## PPO's stability switches",
        "",
        "`benchmarks/ppo_stability.py`: PPO without its stability switches (`plain`, `ppo.PLAIN`),",
        "with each switch alone, and with today's defaults, seeds vmapped in one program.",
        "",
    ]
    for data, heading in _per_device(folder):
        lines += [*heading, *_trainer_table(data["rows"]), ""]
    return [*lines, *_figures(folder), ""]


def render() -> str:
    lines = [
        "# Benchmarks",
        "",
        "Generated by `python benchmarks/report.py` from the JSON in `benchmarks/results/`; do not",
        "edit it by hand (the suite checks that it is the script's output).",
        "",
        *learning_quality(),
        *ppo_stability(),
    ]
    return "\n".join(lines).rstrip() + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--check", action="store_true", help="exit 1 if docs/benchmarks.md is not up to date")
    args = parser.parse_args()
    page = render()
    if args.check:
        if not PAGE.exists() or PAGE.read_text() != page:
            sys.exit(f"{PAGE} is out of date: run python benchmarks/report.py")
        return
    PAGE.write_text(page)
    print(f"wrote {PAGE}")


if __name__ == "__main__":
    main()
