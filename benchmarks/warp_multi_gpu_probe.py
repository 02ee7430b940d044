"""Which part of a Warp program split over two GPUs of one process crashes XLA.

Each variant runs in a fresh process (a segfault ends only it), with faulthandler on,
and prints one line: ok (with the max state difference against one device) or how it
ended. Variants:

    step        one jitted `batching.vmap_transition` of the task's transition on 2 GPUs
    step_nopsum the same without summing the contact pool's counters over the devices
    ppo         a PPO update (the harness's chunk, in small)

`--graph-mode` picks how Warp's CUDA graphs are made (MJX's default: warp); XLA_FLAGS
passes on to the variants.

    python benchmarks/warp_multi_gpu_probe.py --variants step ppo --graph-mode jax
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

VARIANTS = ("step", "step_nopsum", "ppo")


def probe(variant: str, env: str, num_envs: int, graph_mode: str) -> None:
    import functools

    import jax
    import numpy as np
    from mujoco import mjx

    if graph_mode != "warp":
        import mujoco.mjx.warp.types as warp_types

        mjx.put_model = functools.partial(mjx.put_model, graph_mode=getattr(warp_types.GraphMode, graph_mode.upper()))
    import mjzoo
    import mjzoo.envs
    from mjzoo import batching
    from mjzoo.harness import devices as placement

    if variant == "step_nopsum":
        batching._array_fields = lambda data, names: []  # noqa: SLF001 (a probe)
    assert jax.device_count() >= 2, jax.devices()
    task = mjzoo.envs.make(env, impl="warp")
    if variant == "ppo":
        from mjzoo.algorithms import ppo

        config = ppo.Config(num_envs=num_envs, unroll_length=8, num_minibatches=4, num_epochs=1, total_steps=10**6)
        init = jax.jit(ppo.init, static_argnums=0)
        hyperparams = ppo.Hyperparams()
        update = jax.jit(lambda t, s: ppo.update(config, t, s)[0].collector.env_state.data.qpos)
        results = []
        for devices in (jax.devices()[:1], jax.devices()[:2]):
            state = placement.shard_envs(
                init(config, task, hyperparams, jax.random.key(0)), ppo.PER_ENV_FIELDS, devices
            )
            with jax.set_mesh(placement.env_mesh(devices)):
                results.append(np.asarray(update(placement.replicate(task, devices), state)))
    else:
        keys = jax.random.split(jax.random.key(0), num_envs)
        reset = jax.jit(lambda t, k: batching.sized(jax.vmap(t.reset, in_axes=(None, 0))(t.model, k), num_envs))
        states = reset(task, keys)
        actions = np.zeros((num_envs, task.action_size), np.float32)
        step = jax.jit(lambda t, s, a, k: batching.vmap_transition(mjzoo.transition, t, s, a, k).data.qpos)
        results = []
        for devices in (jax.devices()[:1], jax.devices()[:2]):
            print(f"{variant}: {len(devices)} device(s)", file=sys.stderr, flush=True)
            placed = _split(states, devices)
            with jax.set_mesh(placement.env_mesh(devices)):
                results.append(np.asarray(step(placement.replicate(task, devices), placed, actions, keys)))
    print(
        f"{variant} ({graph_mode}): ok, max qpos difference {np.max(np.abs(results[0] - results[1])):.2e}", flush=True
    )
    os._exit(0)


def _split(states, devices):
    import jax
    from jax.sharding import NamedSharding

    from mjzoo import batching
    from mjzoo.harness import devices as placement

    mesh = placement.env_mesh(devices)
    return jax.tree.map(
        lambda x, spec: jax.device_put(x, NamedSharding(mesh, spec)), states, batching.partition(states)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    parser.add_argument("--env", default="hopper")
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--timeout", type=float, default=240)
    parser.add_argument("--graph-mode", choices=["warp", "jax", "none"], default="warp")
    parser.add_argument("--run", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.run:
        probe(args.run, args.env, args.num_envs, args.graph_mode)
        return
    for variant in args.variants:
        command = [
            sys.executable,
            "-X",
            "faulthandler",
            __file__,
            "--run",
            variant,
            "--env",
            args.env,
            "--num-envs",
            str(args.num_envs),
            "--graph-mode",
            args.graph_mode,
        ]
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=args.timeout)
        except subprocess.TimeoutExpired:
            print(f"{variant} ({args.graph_mode}): timed out after {args.timeout:.0f} s", flush=True)
            continue
        lines = [line for line in done.stdout.splitlines() if line.startswith(variant)]
        if done.returncode == 0 and lines:
            print(lines[-1], flush=True)
            continue
        noise = ("Warning", "warn", "Extension")
        quiet = [line for line in done.stderr.splitlines() if not any(word in line for word in noise)]
        tail = [line for line in quiet if line.startswith(f"{variant}:")] + quiet[-14:]
        print(f"{variant} ({args.graph_mode}): exit {done.returncode}\n  " + "\n  ".join(tail), flush=True)


if __name__ == "__main__":
    main()
