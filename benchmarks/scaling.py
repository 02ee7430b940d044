"""PPO over 1, 2, 4, ... GPUs of one host: env-steps/s at a fixed number of envs per GPU,
and wall-clock time to the task's return threshold (humanoid_walk: 6000, walking).

Each device count runs in its own process that sees only that many devices
(``CUDA_VISIBLE_DEVICES``; on a CPU, ``--xla_force_host_platform_device_count``), with
the env's registered PPO hyperparameters and ``num_envs = envs_per_device x devices``:
the harness shards the env batch over every local device and XLA averages the
gradients (`mjzoo.harness.devices`). Reported per count: the median training steps/s
after the first chunk, its speedup over one device and its share of linear scaling,
the time to the threshold (compile included; every chunk of about 3.3M env steps is
evaluated) and the final evaluation return. Goal (issue 19): >= 1.85x on 2 GPUs and
>= 3.5x on 4. With `--processes`, each device gets a process of its own, joined by
`jax.distributed` on localhost, as on several hosts. MuJoCo Warp (`--impl warp`) runs
here on one GPU only: split over two, its program crashed XLA's GPU compiler, in one
process and in one per GPU (`warp_multi_gpu_probe.py`); on CPU devices it splits.
More envs per update with the same `num_minibatches` means fewer gradient steps per env
step; `--scale-minibatches` multiplies `num_minibatches` by the device count instead, so
every count learns as one device does per env step (same minibatch size, same gradient
steps per env step), and only the rollout shrinks with more devices.

    python benchmarks/scaling.py --devices 1 2 4 --steps 40000000 --impl jax --scale-minibatches  # humanoid_walk
    python benchmarks/scaling.py --devices 1 2 --steps 20000000 --impl jax --processes
    python benchmarks/scaling.py --env cartpole_balance --devices 1 2 --smoke   # on a CPU
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import socket
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


def worker(env: str, devices: int, envs_per_device: int, steps: int, smoke: bool, impl: str | None,
           result: Path, joined: tuple[str, int] | None = None, scale_minibatches: bool = False) -> None:  # fmt: skip
    """One device count, in this process (or, `joined` = (coordinator, process id), in
    one of `devices` processes of a device each): train and write the figures to `result`."""
    import jax
    from ppo_vs_brax import training_curve

    import mjzoo.envs
    from mjzoo.algorithms import ppo
    from mjzoo.harness import distributed, training

    if joined is not None:
        distributed.initialize(joined[0], devices, joined[1])
    assert jax.device_count() == devices, (jax.devices(), devices)
    fields = {**mjzoo.envs.hyperparameters(env, "ppo"), "num_envs": envs_per_device * devices, "total_steps": steps}
    if smoke:  # two chunks of two updates at any count, so the steady rate is measured
        fields.update(SMOKE, total_steps=fields["num_envs"] * SMOKE["unroll_length"] * 4)
    if scale_minibatches:  # one device's minibatch size and gradient steps per env step
        fields["num_minibatches"] = fields.get("num_minibatches", ppo.Config.num_minibatches) * devices
    config = ppo.Config(**fields)
    with tempfile.TemporaryDirectory() as own:
        out = Path(own) if joined is None else result.parent / "run"  # one host: the processes share process 0's
        # Chunks of the same env steps at every count (10 updates on one device), each evaluated.
        settings = training.Settings(out_dir=out, video=False, progress=False, checkpoint_every=0, eval_every=1,
                                     eval_envs=16 if smoke else 256, updates_per_chunk=2 if smoke else max(1, 10 // devices))  # fmt: skip
        task = mjzoo.envs.make(env, **({"impl": impl} if impl else {}))
        start = time.perf_counter()
        training.run(ppo, config, task, settings)
        if not distributed.is_primary():  # process 0 writes the metrics and the result
            return
        curve, steps_per_s = training_curve(out / "metrics.jsonl", time.perf_counter() - start)
    threshold = THRESHOLDS.get(env, float("inf"))
    result.write_text(json.dumps({
        "devices": devices, "processes": jax.process_count(), "device_kind": jax.devices()[0].device_kind, "num_envs": config.num_envs,
        "num_minibatches": config.num_minibatches, "impl": training.physics_info(task).get("impl"),
        "steps_per_s": steps_per_s, "curve": curve, "final_return": curve[-1][2],
        "time_to_threshold_s": next((t for _, t, r in curve if r >= threshold), None), "threshold": threshold,
    }))  # fmt: skip


def run_count(args: argparse.Namespace, devices: int, log: Path) -> dict:
    """Runs `worker` for `devices` devices in a fresh process (`--processes`: one per
    device); the output goes to `log` (process I > 0: `log` with suffix .I.log)."""
    with tempfile.TemporaryDirectory() as tmp:
        result = Path(tmp) / "result.json"
        command = [sys.executable, __file__, "--worker", str(devices), "--env", args.env, "--steps", str(args.steps),
                   "--envs-per-device", str(args.envs_per_device), "--result", str(result)] + (["--smoke"] if args.smoke else [])
        command += ["--impl", args.impl] if args.impl else []
        command += ["--scale-minibatches"] if args.scale_minibatches else []
        if args.processes and devices > 1:
            port = _free_port()
            launches = [(command + ["--coordinator", f"localhost:{port}", "--process-id", str(i)], _visible(args, [i]))
                        for i in range(devices)]  # fmt: skip
        else:
            launches = [(command, _visible(args, list(range(devices))))]
        logs = [log] + [log.with_suffix(f".{i}.log") for i in range(1, len(launches))]
        codes = _run_all([(c, e, path) for (c, e), path in zip(launches, logs)])
        if any(codes):
            return {"devices": devices, "error": f"exit {codes}; see {log}"}
        return json.loads(result.read_text())


def _visible(args: argparse.Namespace, devices: list[int]) -> dict[str, str]:
    """The environment of a process that sees `devices` (GPU numbers; on a CPU, as many devices)."""
    environment = dict(os.environ)
    if args.cpu:
        flags = environment.get("XLA_FLAGS", "")
        environment.update(JAX_PLATFORMS="cpu", XLA_FLAGS=f"{flags} --xla_force_host_platform_device_count={len(devices)}")
    else:
        environment["CUDA_VISIBLE_DEVICES"] = ",".join(map(str, devices))
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


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="humanoid_walk")
    parser.add_argument("--devices", nargs="+", type=int, default=[1, 2, 4])
    parser.add_argument("--envs-per-device", type=int, default=None, help="default: the env's num_envs (smoke: 16)")
    parser.add_argument("--steps", type=int, default=None, help="env steps per run (default: the env's total_steps)")
    parser.add_argument("--impl", choices=["jax", "warp"], default=None, help="physics (default: the env's default)")
    parser.add_argument("--processes", action="store_true", help="one process per device (jax.distributed on localhost)")
    parser.add_argument("--scale-minibatches", action="store_true",
                        help="num_minibatches x devices: one device's minibatch size and gradient steps per env step, "
                             "so the learning curve per env step is one device's")  # fmt: skip
    parser.add_argument("--smoke", action="store_true", help="tiny sizes on CPU devices, to check the script")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "scaling")
    parser.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--result", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--coordinator", help=argparse.SUPPRESS)
    parser.add_argument("--process-id", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        joined = (args.coordinator, args.process_id) if args.coordinator else None
        worker(args.env, args.worker, args.envs_per_device, args.steps, args.smoke, args.impl, args.result, joined,
               args.scale_minibatches)
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
    name = f"scaling_{args.env}_{'cpu' if args.cpu else 'gpu'}" + (f"_{args.impl}" if args.impl else "")
    name += ("_processes" if args.processes else "") + ("_scaled" if args.scale_minibatches else "")
    path = args.out / f"{name}.json"
    rows = []
    print(f"{args.env}: {args.envs_per_device} envs per device, "
          f"{'smoke sizes' if args.smoke else f'{args.steps:,} env steps per run'}", flush=True)
    for devices in wanted:
        rows.append(run_count(args, devices, args.out / f"{name}_{devices}.log"))
        base = next((row["steps_per_s"] for row in rows if row["devices"] == 1 and "steps_per_s" in row), None)
        for row in rows:
            if "steps_per_s" in row and base:
                row.update(speedup=row["steps_per_s"] / base, efficiency=row["steps_per_s"] / base / row["devices"])
        row = rows[-1]
        speedup = f" ({row['speedup']:.2f}x)" if "speedup" in row else ""
        print(f"{devices} device(s): " + (row["error"] if "error" in row else
              f"{row['steps_per_s']:,.0f} steps/s{speedup}, to {row['threshold']:g}: "
              f"{'never' if row['time_to_threshold_s'] is None else format(row['time_to_threshold_s'], '.1f') + ' s'}, final return {row['final_return']:.1f}"), flush=True)  # fmt: skip
        path.write_text(json.dumps({"env": args.env, "envs_per_device": args.envs_per_device, "steps": args.steps,
                                    "rows": rows}, indent=1))  # fmt: skip
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
