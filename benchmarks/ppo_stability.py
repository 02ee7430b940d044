"""Which of PPO's stability switches help, measured: each variant over seeds, on the same envs and budget.

Variants (``--variants``) are `ppo.configure` fields over an env's registered PPO
hyperparameters (a Playground env: `ppo.Config()`'s, as learning_quality's
"mjzoo-defaults"): ``plain`` is PPO without its stability switches (`ppo.PLAIN`, as it
was before them), each other variant adds some to it, and ``defaults`` is `ppo.Config`'s
own (the KL-adaptive rate, PopArt and reward normalization, chosen with this
benchmark). Every variant trains all its seeds (``--seeds``) in one vmapped program (`learning_quality.train_mjzoo`),
evaluated ``--evals`` times. Reported per env, reward scale and variant: final and best
return (mean ± std over seeds), kept fraction (final / best; < 0.9 is a collapse), the
seeds that reach ``--target`` and the median wall-clock seconds and env steps to it.

    python benchmarks/ppo_stability.py --envs humanoid_walk --steps 30000000 --seeds 3 --variants plain defaults
    python benchmarks/ppo_stability.py --envs hopper --reward-scale 100 --variants plain popart
    python benchmarks/ppo_stability.py --smoke --envs cartpole_balance   # tiny sizes, on a CPU

Results merge into ``benchmarks/results/ppo_stability/ppo_stability_<card>.json`` (a
variant re-run replaces its old entry) with one curves figure per reward scale.
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
from learning_quality import SMOKE_STEPS  # noqa: E402
from learning_quality import card_name  # noqa: E402
from learning_quality import default_steps  # noqa: E402
from learning_quality import kept_note  # noqa: E402
from learning_quality import load  # noqa: E402
from learning_quality import merged  # noqa: E402
from learning_quality import ppo_fields  # noqa: E402
from learning_quality import print_table  # noqa: E402
from learning_quality import saved_rows  # noqa: E402
from learning_quality import scaled_task  # noqa: E402
from learning_quality import summarize  # noqa: E402
from learning_quality import train_mjzoo  # noqa: E402

from mjzoo.algorithms import ppo  # noqa: E402

# Each variant adds to PPO without its stability switches; "defaults" is ppo.Config's
# own (the KL-adaptive rate, PopArt and reward normalization).
PLAIN = dict(ppo.PLAIN)
VARIANTS: dict[str, dict] = {
    "plain": PLAIN,
    "adaptive_lr": {**PLAIN, "lr_schedule": "adaptive"},
    "adaptive_update_lr": {**PLAIN, "lr_schedule": "adaptive_update"},
    "kl_stop": {**PLAIN, "max_kl": 0.05},
    "popart": {**PLAIN, "value_normalization": "popart"},
    "running_values": {**PLAIN, "value_normalization": "running"},
    "reward_norm": {**PLAIN, "reward_normalization": True},
    "entropy_decay": {**PLAIN, "entropy_schedule": "linear"},
    "norms": {**PLAIN, "value_normalization": "popart", "reward_normalization": True},
    "defaults": {},
    "defaults_update_lr": {"lr_schedule": "adaptive_update"},  # the defaults, the rate adapted once per update
    # The defaults with the adaptive rate's ceiling lowered from rsl_rl's 1e-2: the
    # learning-quality runs' rates climbed to it, and their KL spiked to 10-800 after.
    "defaults_lr_cap": {"max_learning_rate": 1e-3},
    "defaults_lr_cap_kl_stop": {"max_learning_rate": 1e-3, "max_kl": 0.05},
    # The defaults at Brax's constant rate: what the G1 joystick needed (its adaptive
    # rate sat at the 1e-5 floor, 32 x 4 minibatch steps an update).
    "defaults_constant_lr": {"lr_schedule": "constant"},
    # The defaults with a rate that decays linearly from 1e-3 to 0 over the run: a policy
    # that settles at the end of its run rather than wandering from its best.
    "defaults_linear_lr": {"lr_schedule": "linear", "learning_rate": 1e-3},
    # The defaults at Playground's DM Control discount (0.995, against 0.99): on the CPU no
    # rate schedule kept CartpoleSwingup's evaluations from wandering; its config did.
    "defaults_discount_995": {"discount": 0.995},
    # The defaults with Playground's DM Control update: 32 minibatches x 16 epochs a batch
    # (the defaults: 8 x 4), the one size that differs in its steady translated config.
    "defaults_playground_update": {"num_minibatches": 32, "num_epochs": 16},
}


def reach(runs: list[dict], target: float | None) -> dict:
    """Seeds whose evaluation reached `target`, and the median seconds and steps to it
    over the seeds that did (mjzoo's seeds train at once: seconds are for all of them)."""
    if target is None:
        return {}
    firsts = [next(((s, t) for s, t, r in run["curve"] if r >= target), None) for run in runs]
    hit = [f for f in firsts if f is not None]
    return {
        "target": target,
        "seeds_reaching_target": len(hit),
        "median_steps_to_target": float(np.median([s for s, _ in hit])) if hit else None,
        "median_seconds_to_target": float(np.median([t for _, t in hit])) if hit else None,
    }


def plot(rows: list[dict], out: Path, card: str) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")  # no display
    import matplotlib.pyplot as plt

    paths = []
    for scale in sorted({r["reward_scale"] for r in rows}):
        at = sorted((r for r in rows if r["reward_scale"] == scale), key=lambda r: r["env"])
        columns = min(4, len(at))
        lines = -(-len(at) // columns)
        figure, grid = plt.subplots(lines, columns, figsize=(4.5 * columns, 3.4 * lines), squeeze=False)
        for axes in grid.flat[len(at) :]:
            axes.set_visible(False)
        for axes, row in zip(grid.flat, at):
            for name, t in sorted(row["trainers"].items()):
                steps = np.asarray([p[0] for p in t["runs"][0]["curve"]])
                returns = np.asarray([[p[2] for p in run["curve"]] for run in t["runs"]])  # [seed, evaluation]
                i = list(VARIANTS).index(name)  # one color and line per variant in every panel
                color, line = f"C{i % 10}", "-" if i < 10 else "--"
                axes.plot(steps, returns.mean(0), line, label=f"{name} ({len(returns)})", color=color)
                axes.fill_between(steps, returns.min(0), returns.max(0), color=color, alpha=0.15)
            axes.set(title=f"{row['env']} ({row['impl']})", xlabel="env steps")
            axes.legend(fontsize=7)
        for axes in grid[:, 0]:
            axes.set_ylabel("evaluation return (mean, min-max over seeds)")
        figure.suptitle(f"PPO stability variants, {card}, reward x{scale:g}", fontsize=9)
        figure.tight_layout()
        paths.append(out / f"curves_{card}{'' if scale == 1 else f'_scale{scale:g}'}.png")
        figure.savefig(paths[-1], dpi=110)
        plt.close(figure)
    return paths


def write(path: Path, device: str, rows: list[dict]) -> None:
    """The results file at `path`: its rows, and the note it had."""
    path.write_text(json.dumps({"device": device, **kept_note(path), "rows": rows}, indent=1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["humanoid_walk"])
    parser.add_argument("--variants", nargs="+", default=["plain", "defaults"], choices=sorted(VARIANTS))
    parser.add_argument("--impl", default="jax", choices=["jax", "warp"], help="physics of mjzoo's envs")
    parser.add_argument("--steps", type=int, default=None, help="env steps per run (default: the registered ones)")
    parser.add_argument("--evals", type=int, default=10)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--eval-envs", type=int, default=128)
    parser.add_argument("--reward-scale", type=float, default=1.0)
    parser.add_argument("--target", type=float, default=None, help="report the seeds reaching this return")
    parser.add_argument("--gpu-shared-by", type=int, default=1, help="processes training on this GPU at once")
    parser.add_argument("--merge", nargs="+", type=Path, default=None, help="fold these runs' JSON files into --out's")
    parser.add_argument("--smoke", action="store_true")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    if args.smoke and args.out is None:
        args.out = Path(tempfile.mkdtemp(prefix="ppo_stability_smoke_"))
    out = args.out or Path(__file__).parent / "results" / "ppo_stability"
    out.mkdir(parents=True, exist_ok=True)
    card = card_name()
    path = out / f"ppo_stability_{card}.json"
    rows = saved_rows(path)
    seeds = list(range(args.seeds))
    if args.merge:
        for other in args.merge:
            data = json.loads(other.read_text())
            card = card_name(data["device"])
            path = out / f"ppo_stability_{card}.json"
            rows = saved_rows(path)
            for row in data["rows"]:
                rows = [summarize(r) for r in merged(rows, row, ("env", "impl", "reward_scale"))]
            write(path, data["device"], rows)
        args.envs = []  # only the report below
    else:
        print(
            f"device: {jax.devices()[0].device_kind}, jax {jax.__version__}, seeds {seeds}, writing {path}", flush=True
        )
    for name in args.envs:
        task = load(name, args.smoke, args.impl)[1]
        steps = SMOKE_STEPS if args.smoke else (args.steps or default_steps(name))
        base = ppo_fields(name, "mjzoo-defaults", steps, args.smoke)
        key = (name, args.impl, args.reward_scale)
        row = next((r for r in rows if (r["env"], r["impl"], r["reward_scale"]) == key), None)
        if row is None:
            row = {"env": name, "impl": args.impl, "reward_scale": args.reward_scale, "steps": steps, "trainers": {}}
            rows.append(row)
        for variant in args.variants:
            print(f"{name} ({args.impl}), reward x{args.reward_scale:g}, {variant}: {steps:,} steps", flush=True)
            start = time.perf_counter()
            fields = {**base, **VARIANTS[variant]}
            result = train_mjzoo(
                scaled_task(task, args.reward_scale),
                fields,
                seeds,
                args.evals,
                min(args.eval_envs, 8) if args.smoke else args.eval_envs,
                args.reward_scale,
            )
            result.update(
                reach(result["runs"], args.target),
                variant=VARIANTS[variant],
                wall_s=time.perf_counter() - start,
                gpu_shared_by=args.gpu_shared_by,
            )
            row["trainers"][variant] = result
            summarize(row)
            write(path, jax.devices()[0].device_kind, rows)
            print(
                f"  {time.perf_counter() - start:.0f} s; {result.get('seeds_reaching_target', '-')} reached", flush=True
            )
    print_table(rows)
    for p in plot(rows, out, card):
        print(f"wrote {p}")


if __name__ == "__main__":
    main()
