"""What the task layer costs over raw physics, on each physics implementation.

For each env, physics implementation (``--impl``: MJX-JAX, MuJoCo Warp) and batch, in one
process: (a) raw batched `mjzoo.physics.step` of the env's model (its substeps per control
step, same starting states, same controls), and (b) the same batch through
`mjzoo.transition` (dynamics, observation, reward terms, termination, time limit and
divergence guard), bare and with auto-reset. Prints env-steps/s for each and the ratios;
writes JSON.

JSON: ``rows`` holds one row per (env, batch, impl), its ``"impl"`` naming the physics;
the other keys mean what they always meant (old files, without ``"impl"``, are JAX).
``warp_vs_jax`` holds, per (env, batch) measured on both, Warp's steps/s over JAX's for
``raw``, ``transition`` and ``auto_reset``.

    python benchmarks/task_overhead.py                       # all envs, default batches
    python benchmarks/task_overhead.py --batch 1024 4096 --envs cartpole_balance --impl warp jax
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import jax
import numpy as np

import mjzoo
import mjzoo.envs


def raw_runner(task: mjzoo.Task, n_substeps: int):
    """Steps a batch of physics states through a [T, B, nu] control sequence."""

    @jax.jit
    def run(model, data, controls):
        def body(data, ctrl):
            data = jax.vmap(lambda d, u: mjzoo.physics.step(model, d, u, n_substeps))(data, ctrl)
            return data, None

        return jax.lax.scan(body, data, controls)[0]

    return run


def task_runner():
    """Steps a batch of task states through the same controls with `mjzoo.transition`."""

    @jax.jit
    def run(task, state, controls, key):
        def body(state, inputs):
            ctrl, key = inputs
            keys = jax.random.split(key, ctrl.shape[0])
            return jax.vmap(lambda s, u, k: mjzoo.transition(task, s, u, k))(state, ctrl, keys), None

        keys = jax.random.split(key, controls.shape[0])
        return jax.lax.scan(body, state, (controls, keys))[0]

    return run


def best_time(fn, *args, repeats: int) -> float:
    jax.block_until_ready(fn(*args))  # compile and warm up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - start)
    return min(times)


def inputs(task: mjzoo.Task, batch: int, steps: int) -> tuple[jax.Array, jax.Array]:
    """Reset keys [batch] and random controls [steps, batch, nu] within ctrlrange."""
    low, high = np.asarray(task.mj_model.actuator_ctrlrange).T
    controls = jax.random.uniform(jax.random.key(1), (steps, batch, task.action_size), minval=low, maxval=high)
    return jax.random.split(jax.random.key(0), batch), controls


def raw_steps_per_s(task: mjzoo.Task, name: str, reset_keys: jax.Array, controls: jax.Array, repeats: int) -> float:
    """Env-steps/s of raw batched `mjx.step` from the task's reset states, with the
    env's substeps per control step."""
    state = batch_reset(task, reset_keys)
    substeps = round(mjzoo.envs.defaults(name)["ctrl_dt"] / float(task.mj_model.opt.timestep))
    seconds = best_time(raw_runner(task, substeps), task.model, state.data, controls, repeats=repeats)
    return controls.shape[0] * controls.shape[1] / seconds


def batch_reset(task: mjzoo.Task, reset_keys: jax.Array) -> mjzoo.State:
    """States [B] reset from `reset_keys` [B]; on Warp with a contact pool for all B worlds."""
    task = mjzoo.batching.sized(task, reset_keys.shape[0])
    return jax.jit(jax.vmap(mjzoo.reset, in_axes=(None, 0)))(task, reset_keys)


def impls(chosen: list[str] | None) -> list[str]:
    """The physics implementations to measure: `chosen` (``--impl``), else both where Warp
    is the default (a CUDA GPU with Warp installed), else JAX alone."""
    if chosen:
        return list(dict.fromkeys(chosen))
    return ["jax", "warp"] if mjzoo.physics.default_impl() == "warp" else ["jax"]


def add_impl_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--impl",
        nargs="*",
        choices=mjzoo.physics.IMPLS,
        default=None,
        help="physics implementations, measured in this order (default: jax and warp "
        "where Warp is the default physics, else jax)",
    )


def ratio(warp: float | None, jax_: float | None) -> float | None:
    """warp / jax, None when either is missing."""
    return warp / jax_ if warp and jax_ else None


def measure(name: str, batch: int, steps: int, repeats: int, impl: str = "jax") -> dict:
    base = mjzoo.envs.make(name, impl=impl)
    reset_keys, controls = inputs(base, batch, steps)
    result = {"env": name, "impl": impl, "batch": batch, "steps": steps}
    result["raw_steps_per_s"] = raw_steps_per_s(base, name, reset_keys, controls, repeats)
    key = jax.random.key(0)
    for label, task in (("transition", base), ("auto_reset", mjzoo.with_auto_reset(base))):
        task = mjzoo.batching.sized(task, batch)  # the task's reset template sits in the jitted args
        state = batch_reset(task, reset_keys)
        seconds = best_time(task_runner(), task, state, controls, key, repeats=repeats)
        result[f"{label}_steps_per_s"] = batch * steps / seconds
        result[f"{label}_overhead"] = result["raw_steps_per_s"] / result[f"{label}_steps_per_s"] - 1.0
    return result


def main() -> None:
    gpu = jax.default_backend() != "cpu"
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="*", default=mjzoo.envs.names())
    parser.add_argument("--batch", nargs="*", type=int, default=[1024, 4096] if gpu else [256, 1024])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5 if gpu else 2)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--tag", default="", help="suffix of the JSON file")
    add_impl_argument(parser)
    args = parser.parse_args()

    device = jax.devices()[0].device_kind
    print(f"device: {device} ({jax.default_backend()}), jax {jax.__version__}")
    header = (
        f"{'env':<18} {'impl':<5} {'batch':>6} {'raw steps/s':>13} {'transition':>13} {'overhead':>9} "
        f"{'auto-reset':>13} {'overhead':>9}"
    )
    print(header)
    rows, ratios = [], []
    for name in args.envs:
        for batch in args.batch:
            by_impl = {}
            for impl in impls(args.impl):
                r = by_impl[impl] = measure(name, batch, args.steps, args.repeats, impl)
                rows.append(r)
                print(
                    f"{name:<18} {impl:<5} {batch:>6} {r['raw_steps_per_s']:>13,.0f} {r['transition_steps_per_s']:>13,.0f} "
                    f"{r['transition_overhead']:>8.1%} {r['auto_reset_steps_per_s']:>13,.0f} {r['auto_reset_overhead']:>8.1%}",
                    flush=True,
                )
            if len(by_impl) == 2:
                w, j = by_impl["warp"], by_impl["jax"]
                ratios.append(
                    {
                        "env": name,
                        "batch": batch,
                        **{
                            label: ratio(w[f"{label}_steps_per_s"], j[f"{label}_steps_per_s"])
                            for label in ("raw", "transition", "auto_reset")
                        },
                    }
                )
                print(
                    f"{'':<18} warp/jax {'':>3} raw {ratios[-1]['raw']:.2f}x, transition {ratios[-1]['transition']:.2f}x, "
                    f"auto-reset {ratios[-1]['auto_reset']:.2f}x",
                    flush=True,
                )
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"task_overhead_{jax.default_backend()}{'_' + args.tag if args.tag else ''}.json"
    meta = {
        "device": device,
        "backend": jax.default_backend(),
        "jax": jax.__version__,
        "python": platform.python_version(),
    }
    path.write_text(json.dumps({"meta": meta, "rows": rows, "warp_vs_jax": ratios}, indent=2))
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
    os._exit(0)  # Warp on a CPU may hang at interpreter exit
