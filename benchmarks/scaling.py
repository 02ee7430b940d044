"""PPO over 1, 2, 4, ... GPUs of one host: env-steps/s at a fixed number of envs per GPU,
and wall-clock time to the task's return threshold (humanoid_walk: 6000, walking).

Each device count runs in its own process that sees only that many devices
(``CUDA_VISIBLE_DEVICES``; on a CPU, ``--xla_force_host_platform_device_count``), with
the env's registered PPO hyperparameters and ``num_envs = envs_per_device x devices``:
the harness shards the env batch over every local device (`mjzoo.harness.devices`;
each minibatch step is split too, unless ``--config split_minibatches=False``). Reported per count: the median training steps/s
after the first chunk, its speedup over one device and its share of linear scaling,
the time to the threshold (compile included; every chunk of about 3.3M env steps is
evaluated) and the final evaluation return. Goal: >= 1.85x on 2 GPUs and
>= 3.5x on 4. With `--processes`, each device gets a process of its own, joined by
`jax.distributed` on localhost, as on several hosts. MuJoCo Warp (`--impl warp`) runs
here on one GPU only: split over two, its program crashed XLA's GPU compiler, in one
process and in one per GPU (`warp_multi_gpu_probe.py`); on CPU devices it splits.
More envs per update with the same `num_minibatches` means fewer gradient steps per env
step; `--scale-minibatches` multiplies `num_minibatches` by the device count instead
(same minibatch size and gradient steps per env step, but more of them per update, so
the policy moves further from the one that collected the batch: on 4 GPUs the humanoid
no longer walked in 40M steps); `--split-unroll` divides `unroll_length` by it, so every
update has one device's batch, minibatches and gradient steps, and only each env's
segment is shorter (as Brax's humanoid trains with unrolls of 10). `--seeds 0 1 2 3
--parallel` runs a count's seeds side by side on disjoint GPUs. `--algorithm amp` measures
AMP the same way (default env `humanoid_amp_walk`; its threshold: lasting the episode).

    python benchmarks/scaling.py --devices 1 2 4 --steps 40000000 --impl jax --scale-minibatches  # humanoid_walk
    python benchmarks/scaling.py --devices 4 --steps 40000000 --impl jax --split-unroll --keep-runs
    python benchmarks/scaling.py --devices 1 --seeds 0 1 2 3 --parallel --steps 40000000 --impl jax
    python benchmarks/scaling.py --devices 1 2 --steps 20000000 --impl jax --processes
    python benchmarks/scaling.py --devices 4 --steps 40000000 --impl jax --split-unroll --config split_minibatches=False
    python benchmarks/scaling.py --algorithm amp --devices 1 2 4 --steps 40000000 --impl jax --split-unroll
    python benchmarks/scaling.py --env cartpole_balance --devices 1 2 --smoke   # on a CPU
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))  # the worker's ppo_vs_brax

# humanoid_amp_walk: it lasts the 1000-step episode (its reward is ~1 a step alive; the
# style is benchmarks/amp.py's measure).
THRESHOLDS = {"humanoid_walk": 6000.0, "ant": 3000.0, "cartpole_balance": 450.0, "humanoid_amp_walk": 950.0}
SMOKE = dict(num_minibatches=4, num_epochs=1, unroll_length=8)


def visible_gpus() -> list[str]:
    """The GPUs this process may use (``CUDA_VISIBLE_DEVICES`` if set, else every GPU of
    the host), without starting JAX here (it would take their memory)."""
    chosen = os.environ.get("CUDA_VISIBLE_DEVICES")
    if chosen is not None:
        return [gpu for gpu in chosen.split(",") if gpu.strip()]
    if shutil.which("nvidia-smi") is None:
        return []
    listed = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True, check=False).stdout
    return [str(i) for i in range(sum(line.startswith("GPU ") for line in listed.splitlines()))]


def worker(
    env: str,
    devices: int,
    envs_per_device: int,
    steps: int,
    smoke: bool,
    impl: str | None,
    result: Path,
    joined: tuple[str, int] | None = None,
    scale: str | None = None,
    seed: int = 0,
    run_dir: Path | None = None,
    algorithm_name: str = "ppo",
    config_fields: tuple[str, ...] = (),
) -> None:
    """One device count, in this process (or, `joined` = (coordinator, process id), in
    one of `devices` processes of a device each): train and write the figures to `result`
    (the run's own files to `run_dir`, if given; else they are dropped). `scale`:
    "minibatches" or "unroll" (see the module's docstring). `algorithm_name`: ppo or amp;
    `config_fields`: NAME=VALUE over the env's config (``--config``)."""
    import jax
    import numpy as np
    from ppo_vs_brax import training_curve

    import mjzoo.envs
    from mjzoo.algorithms import amp
    from mjzoo.algorithms import ppo
    from mjzoo.harness import distributed
    from mjzoo.harness import metrics
    from mjzoo.harness import training
    from mjzoo.harness.cli.arguments import parse_assignments

    algorithm = {"ppo": ppo, "amp": amp}[algorithm_name]
    if joined is not None:
        distributed.initialize(joined[0], devices, joined[1])
    assert jax.device_count() == devices, (jax.devices(), devices)
    tuned = mjzoo.envs.hyperparameters(env, algorithm_name)
    fields = {
        **tuned,
        **parse_assignments(tuple(config_fields), "--config"),
        "num_envs": envs_per_device * devices,
        "total_steps": steps,
    }
    if smoke:  # two chunks of two updates at any count, so the steady rate is measured
        fields.update(SMOKE, total_steps=fields["num_envs"] * SMOKE["unroll_length"] * 4)
    if scale == "minibatches":  # one device's minibatch size and gradient steps per env step
        fields["num_minibatches"] = fields.get("num_minibatches", ppo.Config.num_minibatches) * devices
    if scale == "unroll":  # one device's batch per update, minibatches and gradient steps
        fields["unroll_length"] = fields.get("unroll_length", ppo.Config.unroll_length) // devices
    config, hyperparams = algorithm.configure(**fields)
    with tempfile.TemporaryDirectory() as own:
        out = run_dir or (
            Path(own) if joined is None else result.parent / "run"
        )  # one host: the processes share process 0's
        # Chunks of the same env steps at every count and envs per device (10 updates of the
        # env's own batch), each evaluated: the curves' points line up.
        batch = tuned.get("num_envs", config.num_envs) * tuned.get("unroll_length", config.unroll_length)
        chunk = 2 if smoke else max(1, 10 * batch // (config.num_envs * config.unroll_length))
        settings = training.Settings(
            out_dir=out,
            seed=seed,
            video=False,
            progress=False,
            checkpoint_every=0,
            eval_every=1,
            eval_envs=16 if smoke else 256,
            updates_per_chunk=chunk,
        )
        task = mjzoo.envs.make(env, **({"impl": impl} if impl else {}))
        start = time.perf_counter()
        training.run(algorithm.make(config), task, settings, hyperparams)
        if not distributed.is_primary():  # process 0 writes the metrics and the result
            return
        curve, steps_per_s = training_curve(out / "metrics.jsonl", time.perf_counter() - start)
        evaluating = np.cumsum(
            [line["perf/eval_s"] for line in metrics.read_metrics(out / "metrics.jsonl") if "eval/return" in line]
        )
    threshold = THRESHOLDS.get(env, float("inf"))
    reached = next((i for i, (_, _, r) in enumerate(curve) if r >= threshold), None)
    result.write_text(
        json.dumps(
            {
                "algorithm": algorithm_name,
                "config_fields": list(config_fields),
                "devices": devices,
                "seed": seed,
                "processes": jax.process_count(),
                "device_kind": jax.devices()[0].device_kind,
                "num_envs": config.num_envs,
                "num_minibatches": config.num_minibatches,
                "unroll_length": config.unroll_length,
                "impl": training.physics_info(task).get("impl"),
                "steps_per_s": steps_per_s,
                "curve": curve,
                "final_return": curve[-1][2],
                "time_to_threshold_s": None if reached is None else curve[reached][1],
                "threshold": threshold,
                # The evaluations' share of it: a fixed cost per chunk, whatever the device count.
                "eval_s_to_threshold": None if reached is None else float(evaluating[reached]),
            }
        )
    )


def run_count(args: argparse.Namespace, gpus: list[int], seed: int, log: Path) -> dict:
    """Runs `worker` on the devices `gpus` (places in the visible GPUs; on a CPU, as many) in a
    fresh process (`--processes`: one per device); the output goes to `log` (process
    I > 0: `log` with suffix .I.log)."""
    devices = len(gpus)
    with tempfile.TemporaryDirectory() as tmp:
        result = Path(tmp) / "result.json"
        command = [
            sys.executable,
            __file__,
            "--worker",
            str(devices),
            "--env",
            args.env,
            "--steps",
            str(args.steps),
            "--algorithm",
            args.algorithm,
            "--config",
            *args.config,
            "--envs-per-device",
            str(args.envs_per_device),
            "--result",
            str(result),
            "--seed",
            str(seed),
        ] + (["--smoke"] if args.smoke else [])
        command += ["--impl", args.impl] if args.impl else []
        command += ["--scale-minibatches"] if args.scale_minibatches else []
        command += ["--split-unroll"] if args.split_unroll else []
        command += ["--run-dir", str(args.out / "runs" / f"{log.stem}")] if args.keep_runs else []
        if args.processes and devices > 1:
            from mjzoo.harness.distributed import free_port

            port = free_port("localhost")
            launches = [
                (command + ["--coordinator", f"localhost:{port}", "--process-id", str(i)], _visible(args, [gpu]))
                for i, gpu in enumerate(gpus)
            ]
        else:
            launches = [(command, _visible(args, gpus))]
        logs = [log] + [log.with_suffix(f".{i}.log") for i in range(1, len(launches))]
        codes = _run_all([(c, e, path) for (c, e), path in zip(launches, logs)])
        if any(codes):
            return {"devices": devices, "seed": seed, "error": f"exit {codes}; see {log}"}
        return json.loads(result.read_text())


def _visible(args: argparse.Namespace, devices: list[int]) -> dict[str, str]:
    """The environment of a process that sees `devices` (places in the visible GPUs; on a
    CPU, as many devices)."""
    environment = dict(os.environ)
    if args.cpu:
        flags = environment.get("XLA_FLAGS", "")
        environment.update(
            JAX_PLATFORMS="cpu", XLA_FLAGS=f"{flags} --xla_force_host_platform_device_count={len(devices)}"
        )
    else:
        environment["CUDA_VISIBLE_DEVICES"] = ",".join(args.gpus[i] for i in devices)
    return environment


def _run_all(launches: list[tuple[list[str], dict[str, str], Path]]) -> list[int]:
    """Starts every (command, environment, log) at once; their exit codes. Output goes to
    files, not pipes: a full pipe would stall a child."""
    running = []
    for command, environment, log in launches:
        with log.open("w") as out:
            running.append(subprocess.Popen(command, env=environment, stdout=out, stderr=subprocess.STDOUT))
    codes = [proc.wait() for proc in running[:1]]
    for proc in running[1:]:  # process 0 is done: the others end with it, or are stuck without it
        try:
            codes.append(proc.wait(timeout=60))
        except subprocess.TimeoutExpired:
            proc.kill()
            codes.append(proc.wait())
    return codes


def _seed_suffix(args: argparse.Namespace, seed: int) -> str:
    return "" if args.seeds == [0] else f"_seed{seed}"


def _summary(rows: list[dict], devices: int) -> str:
    """One line for `devices`: median steps/s over seeds and its speedup over one device
    (written into each row too), and every seed's time to the threshold."""

    def median_rate(count: int) -> float | None:
        rates = [row["steps_per_s"] for row in rows if row["devices"] == count and "steps_per_s" in row]
        return statistics.median(rates) if rates else None

    base = median_rate(1)
    for row in rows:
        if "steps_per_s" in row and base:
            row.update(speedup=row["steps_per_s"] / base, efficiency=row["steps_per_s"] / base / row["devices"])
    mine = [row for row in rows if row["devices"] == devices]
    errors = [row["error"] for row in mine if "error" in row]
    rate = median_rate(devices)
    if rate is None:
        return f"{devices} device(s): " + "; ".join(errors)
    speedup = f" ({rate / base:.2f}x)" if base else ""
    times = ", ".join(
        "never" if row["time_to_threshold_s"] is None else f"{row['time_to_threshold_s']:.1f} s"
        for row in mine
        if "steps_per_s" in row
    )
    finals = ", ".join(f"{row['final_return']:.0f}" for row in mine if "steps_per_s" in row)
    return (
        f"{devices} device(s): {rate:,.0f} steps/s median{speedup}; to {mine[0].get('threshold', 0):g}: {times}; "
        f"final returns {finals}" + (f"; failed: {'; '.join(errors)}" if errors else "")
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default=None, help="default: humanoid_walk (ppo), humanoid_amp_walk (amp)")
    parser.add_argument("--algorithm", choices=["ppo", "amp"], default="ppo")
    parser.add_argument("--devices", nargs="+", type=int, default=[1, 2, 4])
    parser.add_argument("--envs-per-device", type=int, default=None, help="default: the env's num_envs (smoke: 16)")
    parser.add_argument("--steps", type=int, default=None, help="env steps per run (default: the env's total_steps)")
    parser.add_argument("--impl", choices=["jax", "warp"], default=None, help="physics (default: the env's default)")
    parser.add_argument(
        "--processes", action="store_true", help="one process per device (jax.distributed on localhost)"
    )
    scaled = parser.add_mutually_exclusive_group()
    scaled.add_argument(
        "--scale-minibatches",
        action="store_true",
        help="num_minibatches x devices: one device's minibatch size and gradient steps per env step",
    )
    scaled.add_argument(
        "--split-unroll",
        action="store_true",
        help="unroll_length / devices: one device's batch per update, minibatches and gradient steps; "
        "each env's segment is shorter",
    )
    parser.add_argument("--keep-runs", action="store_true", help="keep each run's metrics under OUT/runs/")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0], help="one run per seed at every count")
    parser.add_argument(
        "--config", nargs="*", default=[], help="NAME=VALUE fields over the env's config, as for mjzoo train"
    )
    parser.add_argument(
        "--parallel",
        action="store_true",
        help="run a count's seeds side by side on disjoint GPUs (4 GPUs: four 1-GPU runs at once)",
    )
    parser.add_argument("--smoke", action="store_true", help="tiny sizes on CPU devices, to check the script")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "scaling")
    parser.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--result", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--coordinator", help=argparse.SUPPRESS)
    parser.add_argument("--process-id", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--seed", type=int, default=0, help=argparse.SUPPRESS)
    parser.add_argument("--run-dir", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    args.env = args.env or {"ppo": "humanoid_walk", "amp": "humanoid_amp_walk"}[args.algorithm]
    if args.worker:
        joined = (args.coordinator, args.process_id) if args.coordinator else None
        worker(
            args.env,
            args.worker,
            args.envs_per_device,
            args.steps,
            args.smoke,
            args.impl,
            args.result,
            joined,
            "minibatches" if args.scale_minibatches else "unroll" if args.split_unroll else None,
            args.seed,
            args.run_dir,
            args.algorithm,
            args.config,
        )
        return
    import mjzoo.envs
    from mjzoo.algorithms import ppo
    from mjzoo.harness.cli.arguments import parse_assignments

    # The workers' config as they will build it, so that --split-unroll is checked against an overridden unroll too.
    tuned = {
        **mjzoo.envs.hyperparameters(args.env, args.algorithm),
        **parse_assignments(tuple(args.config), "--config"),
    }
    args.envs_per_device = args.envs_per_device or (16 if args.smoke else tuned.get("num_envs", 2048))
    args.steps = args.steps or tuned.get("total_steps", 10**8)
    args.gpus = visible_gpus()
    args.cpu = args.smoke or not args.gpus
    wanted = [d for d in args.devices if args.cpu or d <= len(args.gpus)]
    if not wanted:
        raise SystemExit(f"scaling: {len(args.gpus)} GPU(s) visible; --devices {args.devices} needs more")
    unroll = SMOKE["unroll_length"] if args.smoke else tuned.get("unroll_length", ppo.Config.unroll_length)
    if args.split_unroll and (uneven := [d for d in wanted if unroll % d]):
        raise SystemExit(
            f"scaling: --split-unroll divides unroll_length ({unroll}) by the device count; "
            f"it does not divide by {uneven}"
        )
    args.out.mkdir(parents=True, exist_ok=True)
    name = f"scaling_{args.env}" + ("" if args.algorithm in args.env.split("_") + ["ppo"] else f"_{args.algorithm}")
    name += f"_{'cpu' if args.cpu else 'gpu'}"
    name += f"_{args.impl}" if args.impl else ""
    name += ("_processes" if args.processes else "") + ("_scaled" if args.scale_minibatches else "")
    name += "_split_unroll" if args.split_unroll else ""
    name += "".join(f"_{field.replace('=', '_')}" for field in args.config)
    name += "" if args.seeds == [0] else "_seeds_" + "_".join(map(str, args.seeds))
    path = args.out / f"{name}.json"
    rows = []

    def save():
        path.write_text(
            json.dumps(
                {
                    "env": args.env,
                    "algorithm": args.algorithm,
                    "envs_per_device": args.envs_per_device,
                    "steps": args.steps,
                    "seeds": args.seeds,
                    "parallel": args.parallel,
                    "rows": rows,
                },
                indent=1,
            )
        )

    print(
        f"{args.env}: {args.envs_per_device} envs per device, "
        f"{'smoke sizes' if args.smoke else f'{args.steps:,} env steps per run'}, seeds {args.seeds}",
        flush=True,
    )
    for devices in wanted:
        # CPU devices share the host's cores: side by side, the runs would slow each other.
        slots = len(args.gpus) // devices if args.parallel and not args.cpu else 1
        for wave in range(0, len(args.seeds), slots):
            seeds = args.seeds[wave : wave + slots]
            with ThreadPoolExecutor(len(seeds)) as pool:
                rows += pool.map(
                    lambda k, seed, devices=devices, name=name: run_count(
                        args,
                        list(range(k * devices, (k + 1) * devices)),
                        seed,
                        args.out / f"{name}_{devices}{_seed_suffix(args, seed)}.log",
                    ),
                    range(len(seeds)),
                    seeds,
                )
            save()  # after every wave: a run cut off later (a device call's time limit) keeps these rows
        print(_summary(rows, devices), flush=True)
        save()  # with the speedups _summary adds
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
