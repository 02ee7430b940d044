"""PPO over 1, 2, 4, ... GPUs of one host: env-steps/s at a fixed number of envs per GPU,
and wall-clock time to the task's return threshold (humanoid_walk: 6000, walking).

Each device count runs in its own process that sees only that many devices
(``CUDA_VISIBLE_DEVICES``; on a CPU, ``--xla_force_host_platform_device_count``), with
the env's registered PPO hyperparameters and ``num_envs = envs_per_device x devices``:
the harness shards the env batch over every local device and XLA averages the
gradients (`mjzoo.harness.devices`). Reported per count: the median training steps/s
after the first chunk, its speedup over one device and its share of linear scaling,
the time to the threshold (compile included) and the final evaluation return. Goal
(issue 19): >= 1.85x on 2 GPUs and >= 3.5x on 4.

    python benchmarks/scaling.py --devices 1 2 4 --steps 100000000        # humanoid_walk
    python benchmarks/scaling.py --env cartpole_balance --devices 1 2 --smoke   # on a CPU
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))  # the worker's ppo_vs_brax

THRESHOLDS = {"humanoid_walk": 6000.0, "ant": 3000.0, "cartpole_balance": 450.0}
SMOKE = dict(num_minibatches=4, num_epochs=1, unroll_length=8)


def gpu_count() -> int:
    """GPUs on this host, without starting JAX here (it would take their memory)."""
    if shutil.which("nvidia-smi") is None:
        return 0
    listed = subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True, check=False).stdout
    return sum(line.startswith("GPU ") for line in listed.splitlines())


def worker(env: str, devices: int, envs_per_device: int, steps: int, smoke: bool, result: Path) -> None:
    """One device count, in this process: train and write the figures to `result`."""
    import jax
    from ppo_vs_brax import training_curve

    import mjzoo.envs
    from mjzoo.algorithms import ppo
    from mjzoo.harness import training

    assert jax.local_device_count() == devices, (jax.local_devices(), devices)
    fields = {**mjzoo.envs.hyperparameters(env, "ppo"), "num_envs": envs_per_device * devices, "total_steps": steps}
    if smoke:  # two chunks of two updates at any count, so the steady rate is measured
        fields.update(SMOKE, total_steps=fields["num_envs"] * SMOKE["unroll_length"] * 4)
    config = ppo.Config(**fields)
    with tempfile.TemporaryDirectory() as out:
        settings = training.Settings(out_dir=Path(out), video=False, progress=False, checkpoint_every=0,
                                     eval_envs=16 if smoke else 256, updates_per_chunk=2 if smoke else 10)  # fmt: skip
        start = time.perf_counter()
        training.run(ppo, config, mjzoo.envs.make(env), settings)
        curve, steps_per_s = training_curve(Path(out) / "metrics.jsonl", time.perf_counter() - start)
    threshold = THRESHOLDS.get(env, float("inf"))
    result.write_text(json.dumps({
        "devices": devices, "device_kind": jax.devices()[0].device_kind, "num_envs": config.num_envs,
        "steps_per_s": steps_per_s, "curve": curve, "final_return": curve[-1][2],
        "time_to_threshold_s": next((t for _, t, r in curve if r >= threshold), None), "threshold": threshold,
    }))  # fmt: skip


def run_count(args: argparse.Namespace, devices: int, log: Path) -> dict:
    """Runs `worker` for `devices` devices in a fresh process; its output goes to `log`."""
    environment = dict(os.environ)
    if args.cpu:
        flags = environment.get("XLA_FLAGS", "")
        environment.update(JAX_PLATFORMS="cpu", XLA_FLAGS=f"{flags} --xla_force_host_platform_device_count={devices}")
    else:
        environment["CUDA_VISIBLE_DEVICES"] = ",".join(map(str, range(devices)))
    with tempfile.TemporaryDirectory() as tmp:
        result = Path(tmp) / "result.json"
        command = [sys.executable, __file__, "--worker", str(devices), "--env", args.env, "--steps", str(args.steps),
                   "--envs-per-device", str(args.envs_per_device), "--result", str(result)] + (["--smoke"] if args.smoke else [])  # fmt: skip
        with log.open("w") as out:  # a file, not a pipe: a full pipe would stall the child
            code = subprocess.run(command, env=environment, stdout=out, stderr=subprocess.STDOUT, check=False).returncode
        if code != 0:
            return {"devices": devices, "error": f"exit {code}; see {log}"}
        return json.loads(result.read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="humanoid_walk")
    parser.add_argument("--devices", nargs="+", type=int, default=[1, 2, 4])
    parser.add_argument("--envs-per-device", type=int, default=None, help="default: the env's num_envs (smoke: 16)")
    parser.add_argument("--steps", type=int, default=None, help="env steps per run (default: the env's total_steps)")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes on CPU devices, to check the script")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "scaling")
    parser.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--result", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.env, args.worker, args.envs_per_device, args.steps, args.smoke, args.result)
        return
    import mjzoo.envs

    tuned = mjzoo.envs.hyperparameters(args.env, "ppo")
    args.envs_per_device = args.envs_per_device or (16 if args.smoke else tuned.get("num_envs", 2048))
    args.steps = args.steps or tuned.get("total_steps", 10**8)
    available = gpu_count()
    args.cpu = args.smoke or available == 0
    wanted = [d for d in args.devices if args.cpu or d <= available]
    if not wanted:
        raise SystemExit(f"scaling: this host has {available} GPU(s); --devices {args.devices} needs more")
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"scaling_{args.env}_{'cpu' if args.cpu else 'gpu'}.json"
    rows = []
    print(f"{args.env}: {args.envs_per_device} envs per device, "
          f"{'smoke sizes' if args.smoke else f'{args.steps:,} env steps per run'}", flush=True)
    for devices in wanted:
        rows.append(run_count(args, devices, args.out / f"scaling_{args.env}_{devices}.log"))
        base = rows[0].get("steps_per_s")
        for row in rows:
            if "steps_per_s" in row and base:
                row.update(speedup=row["steps_per_s"] / base, efficiency=row["steps_per_s"] / base / row["devices"])
        row = rows[-1]
        print(f"{devices} device(s): " + (row["error"] if "error" in row else
              f"{row['steps_per_s']:,.0f} steps/s ({row['speedup']:.2f}x), to {row['threshold']:g}: "
              f"{'never' if row['time_to_threshold_s'] is None else format(row['time_to_threshold_s'], '.1f') + ' s'}, final return {row['final_return']:.1f}"), flush=True)  # fmt: skip
        path.write_text(json.dumps({"env": args.env, "envs_per_device": args.envs_per_device, "steps": args.steps,
                                    "rows": rows}, indent=1))  # fmt: skip
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
