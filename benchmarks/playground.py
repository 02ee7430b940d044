"""mjzoo PPO against Brax PPO on MuJoCo Playground's own envs: the very same env object.

For each Playground env and physics implementation: (a) raw batched stepping of the env
(`jax.vmap(env.step)` in a `lax.scan`), (b) Brax PPO as Playground trains it
(`brax.training.agents.ppo.train` on the env, `mujoco_playground.wrapper.wrap_for_brax_training`,
Playground's tuned config from its suite's params: DM Control's, locomotion's or
manipulation's, `playground.brax_ppo_config`), (c) mjzoo PPO on the same env
object through `mjzoo.interop.playground.task`, with the same hyperparameters in mjzoo's
terms (`playground.ppo_hyperparameters`), evaluated as often as Brax. Reported, per seed
and measured the same way for both: steps/s over the wall-clock from the first to the
last evaluation after training began (evaluations included) and over training alone
(mjzoo: the median chunk; Brax: its ``training/walltime``), training's ratio to raw
stepping, wall-clock time to `--threshold` of the better final return (compile
included), the final evaluation return. Playground's published figure for the env, where
the issue quotes one, is printed beside them.

    python benchmarks/playground.py --envs CartpoleBalance PendulumSwingup
    python benchmarks/playground.py --envs CheetahRun --trainers brax      # merges into the JSON
    python benchmarks/playground.py --envs CheetahRun --first-seed 1      # a second seed beside the first
    python benchmarks/playground.py --envs CartpoleBalance --smoke       # tiny sizes, on a CPU
    python benchmarks/playground.py --envs LeapCubeReorient              # manipulation's tuned config, 200M steps
    python benchmarks/playground.py --envs PandaPickCube                 # manipulation: its tuned 20M steps
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from brax_peer import wall_steps_per_s  # noqa: E402
from ppo_vs_brax import merged  # noqa: E402
from ppo_vs_brax import time_to  # noqa: E402
from ppo_vs_brax import training_curve  # noqa: E402

from mjzoo.algorithms import ppo  # noqa: E402
from mjzoo.harness import training  # noqa: E402
from mjzoo.harness.cli import arguments  # noqa: E402
from mjzoo.interop import brax as brax_adapter  # noqa: E402
from mjzoo.interop import playground  # noqa: E402

DEFAULT_ENVS = ["CartpoleBalance", "PendulumSwingup", "CheetahRun", "WalkerWalk"]
# Measured by the author on one H100 with Playground's tuned config (JAX physics;
# 995k steps/s on Warp): Brax PPO on CartpoleBalance returns ~993 after 9.8M steps.
PUBLISHED = {
    "CartpoleBalance": {
        "brax_steps_per_s_jax": 734_000,
        "brax_steps_per_s_warp": 995_000,
        "return": 993.0,
        "at_steps": 9_800_000,
    },
    # Playground's paper: Brax PPO trains LeapCubeReorient (200M steps) in about 33 min on an RTX 4090.
    "LeapCubeReorient": {"brax_train_minutes_rtx_4090": 33},
}
SMOKE = dict(num_envs=16, batch_size=16, num_minibatches=4, num_updates_per_batch=2, num_evals=3, episode_length=50)
SMOKE_STEPS = 1  # Brax rounds it up to one epoch between evaluations (`brax_env_steps`)


def brax_config(name: str, steps: int | None, smoke: bool, evals: int | None = None) -> dict:
    """Playground's tuned Brax PPO config for `name` (its suite's: DM Control, locomotion
    or manipulation), `steps` long (None: its own length), `evals` evaluations."""
    config = {**playground.brax_ppo_config(name).to_dict(), **(SMOKE if smoke else {})}
    steps = steps or (SMOKE_STEPS if smoke else None)
    config.update(**({"num_timesteps": steps} if steps else {}), **({"num_evals": evals} if evals else {}))
    return config


def raw_steps_per_s(env, num_envs: int, steps: int = 100, repeats: int = 3) -> float:
    """Env steps/s of `env.step` vmapped over `num_envs`, zero actions, in one jitted scan."""
    keys = jax.random.split(jax.random.key(0), num_envs)
    states = jax.jit(jax.vmap(env.reset))(jax.vmap(jax.random.key_data)(keys))
    action = jnp.zeros((num_envs, env.action_size))

    @jax.jit
    def run(states):
        return jax.lax.scan(lambda s, _: (jax.vmap(env.step)(s, action), None), states, None, length=steps)[0]

    jax.block_until_ready(run(states))
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run(states))
        best = min(best, time.perf_counter() - start)
    return num_envs * steps / best


class _OutOfTime(Exception):
    """Raised from Brax's `progress_fn` to end a run at an evaluation (`--brax-time-limit`)."""


def train_brax(env, config: dict, seed: int, time_limit: float | None = None) -> dict:
    """Brax PPO as Playground runs it; its curve from `progress_fn`'s reports, each also
    printed (a run killed midway leaves its curve in the log). With `time_limit`, the run
    ends at its first evaluation after that many seconds (and two epochs), and says at which step."""
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as brax_ppo
    from mujoco_playground import wrapper

    brax_adapter.patch_brax_for_current_jax()
    params = dict(config)
    network = functools.partial(ppo_networks.make_ppo_networks, **params.pop("network_factory", {}))
    reports: list[tuple[int, float, float]] = []
    trained_s: list[tuple[int, float]] = []  # (step, Brax's training/walltime) after each training epoch
    total = brax_env_steps(config)
    start = time.perf_counter()

    def progress(step: int, metrics: dict) -> None:
        reports.append((int(step), time.perf_counter() - start, float(metrics.get("eval/episode_reward", np.nan))))
        print(f"  brax: step {step:,}, {reports[-1][1]:.0f} s, return {reports[-1][2]:.1f}", flush=True)
        if step > 0:
            trained_s.append((int(step), float(metrics["training/walltime"])))
        if time_limit is not None and reports[-1][1] > time_limit and len(trained_s) > 1 and step < total:
            raise _OutOfTime

    try:
        brax_ppo.train(
            environment=env,
            wrap_env_fn=wrapper.wrap_for_brax_training,
            network_factory=network,
            progress_fn=progress,
            seed=seed,
            **params,
        )
        cut_off = None
    except _OutOfTime:
        cut_off = reports[-1][0]
    (first_step, first_s), (last_step, last_s) = trained_s[0], trained_s[-1]
    steps_per_s = wall_steps_per_s(reports)
    first_report = next(t for step, t, _ in reports if step > 0)
    return {
        "steps_per_s": steps_per_s,
        "train_steps_per_s": (last_step - first_step) / (last_s - first_s),
        "curve": reports,
        "final_return": reports[-1][2],
        "compile_s": first_report - first_step / steps_per_s,
        **({"cut_off_at_step": cut_off} if cut_off is not None else {}),
    }


def brax_env_steps(config: dict) -> int:
    """The env steps Brax PPO actually trains for `config`: whole epochs of
    `num_resets_per_eval` training steps between `num_evals - 1` evaluations, rounded up
    (Playground's 60M-step DM Control config trains 88.5M)."""
    per_step = (
        config["batch_size"] * config["unroll_length"] * config["num_minibatches"] * config.get("action_repeat", 1)
    )
    evals = max(config["num_evals"] - 1, 1)
    resets = max(config.get("num_resets_per_eval", 0), 1)
    return evals * resets * per_step * int(np.ceil(config["num_timesteps"] / (evals * per_step * resets)))


def train_mjzoo(env, name: str, config: dict, seed: int, overrides: dict) -> dict:
    """mjzoo PPO on `playground.task(env)` with the same hyperparameters (and
    `overrides` of `ppo.configure`'s fields), for as many env steps as Brax trains, evaluated about as
    often as Brax's `num_evals`."""
    fields = {**playground.ppo_hyperparameters(name), "total_steps": brax_env_steps(config), **overrides}
    if config["num_envs"] != fields["num_envs"]:  # --smoke
        fields.update(
            num_envs=config["num_envs"],
            unroll_length=config["unroll_length"],
            num_minibatches=config["num_minibatches"],
            num_epochs=config["num_updates_per_batch"],
        )
    ppo_config, hyperparams = ppo.configure(**fields)
    per_chunk = max(1, ppo_config.num_updates // max(1, config["num_evals"] - 1))
    with tempfile.TemporaryDirectory() as out:
        settings = training.Settings(
            out_dir=Path(out),
            updates_per_chunk=per_chunk,
            eval_envs=config["num_eval_envs"],
            eval_steps=config["episode_length"],
            eval_every=1,
            video=False,
            progress=False,
            checkpoint_every=0,
            seed=seed,
        )
        start = time.perf_counter()
        training.run(ppo.make(ppo_config), playground.task(env), settings, hyperparams)
        curve, train_steps_per_s = training_curve(Path(out) / "metrics.jsonl", time.perf_counter() - start)
    return {
        "steps_per_s": wall_steps_per_s(curve),
        "train_steps_per_s": train_steps_per_s,
        "curve": curve,
        "final_return": curve[-1][2],
        "overrides": overrides,
        "compile_s": curve[0][1] - ppo_config.steps_per_update / train_steps_per_s,
    }


TRAINERS = {
    "mjzoo": train_mjzoo,
    "brax": lambda env, name, config, seed, overrides, time_limit=None: train_brax(env, config, seed, time_limit),
}


def measure(
    name: str,
    impl: str,
    steps: int | None,
    seeds: range,
    trainers: list[str],
    smoke: bool,
    overrides: dict,
    evals: int | None = None,
    brax_time_limit: float | None = None,
) -> Iterator[dict]:
    """Raw stepping and each of `trainers` over `seeds` seeds on Playground's `name`: the
    row so far after each trainer (a run cut off keeps what it measured)."""
    config = brax_config(name, steps, smoke, evals)
    config.setdefault("num_eval_envs", 128)
    start = time.perf_counter()
    env = playground.load(name, impl=impl, **({"episode_length": config["episode_length"]} if smoke else {}))
    raw = raw_steps_per_s(env, config["num_envs"])
    print(
        f"{name} ({impl}): raw stepping {raw:,.0f} steps/s (load and compile included: "
        f"{time.perf_counter() - start:.0f} s); each trainer trains {brax_env_steps(config):,} env steps",
        flush=True,
    )
    row = {
        "env": name,
        "impl": impl,
        "raw_steps_per_s": raw,
        "steps": brax_env_steps(config),
        "published": PUBLISHED.get(name),
    }
    for trainer in trainers:
        runs = []
        for seed in seeds:
            limit = {"time_limit": brax_time_limit} if trainer == "brax" else {}
            runs.append({**TRAINERS[trainer](env, name, config, seed, overrides, **limit), "seed": seed})
            print(
                f"{name} ({impl}) seed {seed}: {trainer} {runs[-1]['steps_per_s']:,.0f} steps/s, final "
                f"{runs[-1]['final_return']:.1f}, compile {runs[-1]['compile_s']:.0f} s, "
                + (f"cut off at step {runs[-1]['cut_off_at_step']:,}, " if "cut_off_at_step" in runs[-1] else "")
                + f"{time.perf_counter() - start:.0f} s so far",
                flush=True,
            )
        row[trainer] = {"runs": runs}
        yield dict(row)


def with_earlier_seeds(rows: list[dict], row: dict) -> dict:
    """`row` with the runs that `rows` hold for its env, physics and trainers of seeds it
    did not run (`--first-seed` adds seeds to a row; a run without a seed is seed 0, 1, ...
    in order)."""
    same = next((r for r in rows if (r["env"], r["impl"]) == (row["env"], row["impl"])), None)
    row = dict(row)
    for trainer in (t for t in TRAINERS if t in row and same is not None and t in same):
        ran = {r["seed"] for r in row[trainer]["runs"]}
        earlier = [{"seed": i, **r} for i, r in enumerate(same[trainer]["runs"])]
        runs = [r for r in earlier if r["seed"] not in ran] + row[trainer]["runs"]
        row[trainer] = {"runs": sorted(runs, key=lambda r: r["seed"])}
    return row


def summarize(row: dict, threshold: float) -> dict:
    """Adds each trainer's means, its time to `threshold` of the better final return and
    the steps/s ratio, from the trainers' runs present in `row`."""
    trainers = [t for t in TRAINERS if t in row]
    finals = {t: float(np.mean([r["final_return"] for r in row[t]["runs"]])) for t in trainers}
    row["threshold"] = threshold * max(finals.values())
    for t in trainers:
        rs = row[t]["runs"]
        times = [time_to(r["curve"], row["threshold"]) for r in rs]
        speed, training = (_mean([r.get(rate) for r in rs]) for rate in ("steps_per_s", "train_steps_per_s"))
        row[t].update(
            steps_per_s=speed,
            train_steps_per_s=training,
            final_return=finals[t],
            fraction_of_raw=None if training is None else training / row["raw_steps_per_s"],
            final_return_std=float(np.std([r["final_return"] for r in rs])),
            seeds=len(rs),
            time_to_threshold_s=None if None in times else float(np.mean(times)),
        )
    if len(trainers) == 2:
        for rate in ("steps_per_s", "train_steps_per_s"):
            mjzoo, brax = row["mjzoo"][rate], row["brax"][rate]
            row[f"mjzoo_over_brax_{rate}"] = None if mjzoo is None or brax is None else mjzoo / brax
    return row


def _mean(values: list[float | None]) -> float | None:
    """The mean, or None where a run did not record the figure (Brax's training-alone
    rate, before the script read it)."""
    return None if None in values else float(np.mean(values))


def print_table(rows: list[dict]) -> None:
    print(
        f"\n{'env':<16} {'impl':<5} {'trainer':<6} {'seeds':>5} {'steps/s':>10} {'training':>10} {'/raw':>5} "
        f"{'to thr (s)':>10} {'final':>16}"
    )
    for r in rows:
        for trainer in (t for t in TRAINERS if t in r):
            t = r[trainer]
            ttt = "never" if t["time_to_threshold_s"] is None else f"{t['time_to_threshold_s']:.1f}"
            training, fraction = (
                ("-", "-")
                if t["train_steps_per_s"] is None
                else (f"{t['train_steps_per_s']:,.0f}", f"{t['fraction_of_raw']:.2f}")
            )
            print(
                f"{r['env']:<16} {r['impl']:<5} {trainer:<6} {t['seeds']:>5} {t['steps_per_s']:>10,.0f} {training:>10} "
                f"{fraction:>5} {ttt:>10} {t['final_return']:>7.1f} ± {t['final_return_std']:<6.1f}"
            )
        wall, train = r.get("mjzoo_over_brax_steps_per_s"), r.get("mjzoo_over_brax_train_steps_per_s")
        print(
            f"{'':<16} {r['impl']:<5} raw    {'':>5} {r['raw_steps_per_s']:>10,.0f}   threshold {r['threshold']:.1f}"
            + (f"; mjzoo/brax steps/s {wall:.2f}x" if wall else "")
            + (f" (training alone {train:.2f}x)" if train else "")
            + (f"; published: {r['published']}" if r["published"] else "")
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=DEFAULT_ENVS)
    parser.add_argument("--impl", nargs="+", default=["jax"], choices=["jax", "warp"])
    parser.add_argument(
        "--trainers",
        nargs="+",
        default=list(TRAINERS),
        choices=list(TRAINERS),
        help="measure only these; their rows merge into the JSON's rows of the same env",
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help="Brax's num_timesteps (default: Playground's for the env, 60M for DM Control, which Brax "
        "rounds up to 88.5M, 200M for LeapCubeReorient, 20M for PandaPickCube); mjzoo trains as many env steps as Brax does",
    )
    parser.add_argument(
        "--evals",
        type=int,
        default=None,
        help="Brax's num_evals (Playground's: 10). Brax trains whole epochs between evaluations: "
        "with --steps 20000000, 4 evaluations train 29.5M steps where 10 train 88.5M",
    )
    parser.add_argument(
        "--brax-time-limit",
        type=float,
        default=None,
        metavar="SECONDS",
        help="end each Brax run at its first evaluation after SECONDS (a run longer than one device "
        "call); the run's final return is then that evaluation's, and `cut_off_at_step` says so",
    )
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument(
        "--first-seed", type=int, default=0, help="seeds FIRST .. FIRST+SEEDS-1, added to the row's others"
    )
    parser.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="FIELD=VALUE",
        help="ppo.configure overrides for mjzoo (e.g. compute_dtype=bfloat16 learning_rate=1e-3)",
    )
    parser.add_argument("--threshold", type=float, default=0.9, help="fraction of the better final return")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes, to check the script on a CPU")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "playground")
    parser.add_argument("--name", default=None, help="the JSON's name (default: playground_BACKEND.json)")
    args = parser.parse_args()
    overrides = arguments.parse_assignments(tuple(args.set), "--set")
    device = jax.devices()[0].device_kind
    steps = "Playground's" if args.steps is None else f"{args.steps:,}"
    print(f"device: {device}, jax {jax.__version__}, Brax's num_timesteps {steps}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / (args.name or f"playground_{jax.default_backend()}.json")
    rows = json.loads(path.read_text())["rows"] if path.exists() else []
    for name in args.envs:
        for impl in args.impl:
            seeds = range(args.first_seed, args.first_seed + args.seeds)
            for row in measure(
                name, impl, args.steps, seeds, args.trainers, args.smoke, overrides, args.evals, args.brax_time_limit
            ):
                rows = [summarize(r, args.threshold) for r in merged(rows, with_earlier_seeds(rows, row))]
                path.write_text(json.dumps({"device": device, "jax": jax.__version__, "rows": rows}, indent=1))
    print_table(rows)
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
    os._exit(0)  # Warp on a CPU may hang at interpreter exit
