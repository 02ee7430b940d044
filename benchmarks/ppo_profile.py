"""Where one PPO update's time goes: the rollout (physics and acting) against the learner
(GAE and the epochs of minibatch steps), each jitted and timed alone, for each
`ppo.Config` variant asked for, with MuJoCo Playground's DM Control hyperparameters
(2048 envs, 983,040 env steps and 512 minibatch steps of 30,720 samples per update).
A whole update is timed three ways: from one state again and again, fed its own output
(episodes end and restart), and inside the harness's chunk (`training.run`'s scan of
updates over a donated state), so that what the harness costs shows beside the rest.

A variant is ``NAME=FIELD:VALUE,...`` over `ppo.Config` (e.g. ``bf16=compute_dtype:bfloat16``);
``base`` is the config unchanged. The matmul precision of float32 (JAX's default on recent
GPUs is TF32) is the variant field ``precision`` (``float32`` / ``tensorfloat32`` /
``bfloat16``), set with `jax.default_matmul_precision` around compiling and running;
``flat_adam:1`` runs the config's optimizer over the parameters concatenated
(`optax.flatten`). Each row also counts the kernels one minibatch step launches, read off
the compiled program. XLA's own options go in ``XLA_FLAGS`` (a run per setting, ``--tag``
naming its JSON), e.g. CUDA graphs around the minibatch loop:
``XLA_FLAGS=--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL``.

    python benchmarks/ppo_profile.py --envs cartpole_balance playground:CartpoleBalance \\
        --variants base bf16=compute_dtype:bfloat16 f32=precision:float32
    python benchmarks/ppo_profile.py --envs cartpole_balance --smoke        # on a CPU

Several GPUs: ``--devices N`` splits one update over the first N devices as
`scaling.py --split-unroll` does (``num_envs`` x N, ``unroll_length`` / N: the same batch,
minibatches and gradient steps, each minibatch split N ways), so that the minibatch
step's time shows whether splitting it shortens it; its kernel count then includes the
gradients' all-reduce. ``--env-config`` takes each env's registered PPO hyperparameters
instead of Playground's. By default each minibatch step is split over the devices
(`ppo.Config.split_minibatches`); the variant ``whole=split_minibatches:False`` has
every device compute every step whole:

    python benchmarks/ppo_profile.py --envs humanoid_walk --env-config --devices 4 --variants base whole=split_minibatches:False
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import re
import sys
import time
from pathlib import Path

import jax
import numpy as np
import optax

sys.path.insert(0, str(Path(__file__).parent))
from ppo_vs_brax import mjzoo_config  # noqa: E402

import mjzoo.envs  # noqa: E402
from mjzoo.algorithms import ppo  # noqa: E402
from mjzoo.harness import training  # noqa: E402
from mjzoo.harness.cli import arguments  # noqa: E402
from mjzoo.harness.devices import env_mesh_scope  # noqa: E402
from mjzoo.harness.devices import replicate  # noqa: E402
from mjzoo.harness.devices import shard_envs  # noqa: E402

CHUNK = 5  # updates per harness chunk timed (`training.run` scans its chunks the same way)
SMOKE = dict(num_envs=16, unroll_length=8, num_minibatches=4, num_epochs=2)


def parse_variant(text: str) -> tuple[str, dict[str, str]]:
    name, _, fields = text.partition("=")
    pairs = [f.split(":", 1) for f in fields.split(",") if f]
    if any(len(p) != 2 for p in pairs):
        raise SystemExit(f"ppo_profile: variant {text!r} must be NAME=FIELD:VALUE,...")
    return name, dict(pairs)


def loop_kernels(hlo: str) -> int:
    """Kernel launches in one minibatch step: the fusions and library calls (cuBLAS, ...)
    of the compiled program's busiest computation, which is the minibatch loop's body."""
    computations = re.split(r"\n(?=[%A-Z][^\n]*\{\n)", hlo)
    return max(
        len(re.findall(r"= (?:\S+|\([^)]*\)) (?:fusion|custom-call|all-reduce(?:-start)?)\(", c)) for c in computations
    )


def best_of(fn, *args, repeats: int) -> float:
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def in_mesh(fn, devices: list):
    """`fn` traced under the env mesh of `devices` (`devices.env_mesh_scope`)."""

    def traced(*args):
        with env_mesh_scope(devices):
            return fn(*args)

    return traced


def per_update(run, state, updates: int, repeats: int) -> float:
    """Median seconds per update of `run` (`updates` of them per call) fed its own output,
    so that the envs move on and episodes end and restart, as in training."""
    state = jax.block_until_ready(run(training._owned(state)))  # compiled; the harness donates its state
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        state = jax.block_until_ready(run(state))
        times.append((time.perf_counter() - start) / updates)
    return float(np.median(times))


def profile(env: str, base: dict, fields: dict[str, str], repeats: int, devices: int = 1) -> dict:
    """`base`: `ppo.configure`'s fields; `fields` a variant's changes of them."""
    fields = dict(fields)
    precision = fields.pop("precision", None)
    flat_adam = fields.pop("flat_adam", None) == "1"
    values = arguments.parse_assignments(tuple(f"{f}={v}" for f, v in fields.items()), "--variants")
    config, hyperparams = ppo.configure(**{**base, **values})
    components = ppo.NO_COMPONENTS
    if flat_adam:  # the config's own optimizer over all parameters concatenated, not one update per array
        components = ppo.Components(optimizer=optax.flatten(ppo._optimizer(config, ppo.as_leaves(hyperparams))))
    if devices not in (1, jax.device_count()):  # the harness's chunk (timed too) meshes every device
        raise SystemExit(
            f"ppo_profile: --devices {devices} of {jax.device_count()}: show it only those (CUDA_VISIBLE_DEVICES)"
        )
    if config.unroll_length % devices:
        raise SystemExit(f"ppo_profile: --devices {devices} must divide unroll_length {config.unroll_length}")
    config = dataclasses.replace(
        config, num_envs=config.num_envs * devices, unroll_length=config.unroll_length // devices
    )
    placed = jax.devices()[:devices]
    task = mjzoo.envs.make(env)
    placed_task = replicate(task, placed)  # as `training.run` holds it
    scope = jax.default_matmul_precision(precision) if precision else contextlib.nullcontext()
    with scope:
        algorithm = ppo.make(config, optimizer=components.optimizer)
        state = shard_envs(algorithm.init(task, hyperparams, jax.random.key(0)), ppo.PER_ENV_FIELDS, placed)
        # Traced under the env mesh, as the harness's chunk is (`learning.learn` splits minibatches by it).
        rollout = jax.jit(in_mesh(lambda t, s, k: ppo.collect(config, t, s, k, components)[1], placed))
        improve = jax.jit(in_mesh(lambda t, s, d, k: ppo.improve(config, t, s, d, k, components)[0], placed))
        update = jax.jit(in_mesh(lambda t, s: algorithm.update(t, s)[0], placed))
        key = jax.random.key(1)
        start = time.perf_counter()
        data = jax.block_until_ready(rollout(placed_task, state, key))
        compile_rollout = time.perf_counter() - start
        start = time.perf_counter()
        jax.block_until_ready(improve(placed_task, state, data, key))
        compile_improve = time.perf_counter() - start
        kernels = loop_kernels(improve.lower(placed_task, state, data, key).compile().as_text())
        t_rollout = best_of(rollout, placed_task, state, key, repeats=repeats)
        t_improve = best_of(improve, placed_task, state, data, key, repeats=repeats)
        t_update = best_of(update, placed_task, state, repeats=repeats)
        t_onward = per_update(lambda s: update(placed_task, s), state, 1, repeats)
        chunk = training._chunk_fn(algorithm.update, CHUNK)
        t_chunk = per_update(lambda s: chunk(placed_task, s)[0], state, CHUNK, repeats)
        defaults = mjzoo.envs.defaults(env)
        steps = defaults.get("episode_steps") or defaults.get("episode_length", 1000)
        evaluate = jax.jit(lambda s, k: algorithm.evaluate(task, s, k, 128, steps).returns.mean())
        t_evaluate = best_of(evaluate, state, key, repeats=1)
        # As the harness runs it: the task an argument, every result (env 0's trajectory too) returned.
        in_loop = training._evaluate_fn(algorithm.evaluate)
        t_in_loop = best_of(lambda s, k: in_loop(placed_task, s, k, 128, steps), state, key, repeats=1)
    sgd_steps = config.num_epochs * config.num_minibatches
    return {
        "env": env,
        "devices": devices,
        "num_envs": config.num_envs,
        "unroll_length": config.unroll_length,
        "steps_per_update": config.steps_per_update,
        "sgd_steps": sgd_steps,
        "minibatch_samples_per_device": config.steps_per_update // config.num_minibatches // devices,
        "config": {**fields, **({"precision": precision} if precision else {})},
        "rollout_s": t_rollout,
        "improve_s": t_improve,
        "update_s": t_update,
        "update_onward_s": t_onward,
        "chunk_update_s": t_chunk,
        "evaluate_128_envs_s": t_evaluate,
        "evaluate_in_loop_s": t_in_loop,
        "evaluate_steps": steps,
        "sgd_step_ms": 1e3 * t_improve / sgd_steps,
        "sgd_step_kernels": kernels,
        "steps_per_s": config.steps_per_update / t_update,
        "compile_rollout_s": compile_rollout,
        "compile_improve_s": compile_improve,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["cartpole_balance"])
    parser.add_argument("--variants", nargs="+", default=["base"])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--smoke", action="store_true", help="tiny sizes, to check the script on a CPU")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "ppo_profile")
    parser.add_argument("--tag", default="", help="added to the JSON's name (e.g. for a run under other XLA_FLAGS)")
    parser.add_argument("--devices", type=int, default=1, help="split each update over this many devices")
    parser.add_argument("--env-config", action="store_true", help="each env's registered PPO hyperparameters")
    args = parser.parse_args()
    base = mjzoo_config(total_steps=10**9)
    if args.smoke:
        base = {**base, **SMOKE}
    device = jax.devices()[0].device_kind
    print(f"device: {device}, jax {jax.__version__}", flush=True)
    rows = []
    args.out.mkdir(parents=True, exist_ok=True)
    name = f"ppo_profile_{jax.default_backend()}" + (f"_{args.devices}_devices" if args.devices > 1 else "")
    path = args.out / f"{name}{'_' + args.tag if args.tag else ''}.json"
    print(
        f"{'env':<28} {'variant':<10} {'rollout s':>9} {'improve s':>9} {'update s':>9} {'onward s':>8} {'chunk s':>8} {'sgd ms':>7} {'kernels':>7} {'steps/s':>11} {'eval s':>7} {'in loop':>7}"
    )
    for env in args.envs:
        config = base
        if args.env_config:
            config = {**mjzoo.envs.hyperparameters(env, "ppo"), "total_steps": 10**9, **(SMOKE if args.smoke else {})}
        structure = ppo.configure(**config)[0]
        print(
            f"{env}: per update (unless a variant changes it) {structure.steps_per_update:,} env steps x devices, "
            f"{structure.num_epochs * structure.num_minibatches} minibatch steps",
            flush=True,
        )
        for name, fields in map(parse_variant, args.variants):
            row = {"variant": name, **profile(env, config, fields, args.repeats, args.devices)}
            rows.append(row)
            print(
                f"{env:<28} {name:<10} {row['rollout_s']:>9.3f} {row['improve_s']:>9.3f} {row['update_s']:>9.3f} {row['update_onward_s']:>8.3f} {row['chunk_update_s']:>8.3f} "
                f"{row['sgd_step_ms']:>7.2f} {row['sgd_step_kernels']:>7} {row['steps_per_s']:>11,.0f} {row['evaluate_128_envs_s']:>7.2f} {row['evaluate_in_loop_s']:>7.2f}",
                flush=True,
            )
            path.write_text(
                json.dumps(
                    {
                        "device": device,
                        "jax": jax.__version__,
                        "xla_flags": os.environ.get("XLA_FLAGS", ""),
                        "rows": rows,
                    },
                    indent=1,
                )
            )
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
    os._exit(0)
