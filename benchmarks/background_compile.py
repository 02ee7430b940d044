"""Does XLA compile slower beside work on the GPU? The harness compiles the evaluation on
a thread while the first training chunk runs (`mjzoo.harness.compilation.compile_ahead`).
On an H100, one run of Playground's WalkerWalk waited over 75 s for that compile, the GPU
idle (a compile of 26 s on a 2-core CPU; `results/playground/walker_jax_eval_compile_stall/`).
On another H100 this found no such effect: 22-24 s all four ways, and a re-run of that
training compiled it in 21 s (`results/playground/background_compile_gpu_WalkerWalk.json`).

This times the evaluation's compile for one Playground env four ways: alone, and on a
thread while a training chunk runs on the device, each with XLA's GPU autotuner on and
off (``xla_gpu_autotune_level=0``, a compile option). Each variant evaluates a different
number of envs, so that no compile reuses another's executable.

    python benchmarks/background_compile.py --env WalkerWalk
    python benchmarks/background_compile.py --env CartpoleBalance --smoke   # tiny sizes, on a CPU

Writes JSON to --out and prints one line per variant.
"""

from __future__ import annotations

import argparse
import json
import threading
import time
from pathlib import Path

import jax

from mjzoo.algorithms import ppo
from mjzoo.harness import training
from mjzoo.interop import playground

VARIANTS = [
    ("alone", {}),
    ("alone", {"xla_gpu_autotune_level": 0}),
    ("beside a chunk", {}),
    ("beside a chunk", {"xla_gpu_autotune_level": 0}),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="WalkerWalk")
    parser.add_argument("--updates", type=int, default=20, help="updates in the chunk that runs beside the compile")
    parser.add_argument("--eval-envs", type=int, default=128)
    parser.add_argument("--eval-steps", type=int, default=1000)
    parser.add_argument("--smoke", action="store_true", help="tiny sizes, to check the script on a CPU")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args()

    task = playground.task(args.env)
    fields = {**playground.ppo_hyperparameters(args.env), "compute_dtype": "bfloat16"}
    if args.smoke:
        fields.update(num_envs=16, num_minibatches=2, num_epochs=1, unroll_length=4)
        args.updates, args.eval_envs, args.eval_steps = 2, 4, 20
    algorithm, hyperparams = ppo.configure(**fields)
    algorithm = ppo.make(algorithm)
    state = training._init_fn(algorithm.init)(task, hyperparams, jax.random.key(0))

    @jax.jit  # the harness's chunk (`training._chunk_fn`) donates its state; this one runs from `state` again
    def chunk(task, state):  # `args.updates` updates in one program
        return jax.lax.scan(lambda s, _: algorithm.update(task, s), state, None, length=args.updates)[0]

    jax.block_until_ready(chunk(task, state))  # compiled and run once: the timed runs only execute it
    evaluate = training._evaluate_fn(algorithm.evaluate)  # the very function the harness compiles ahead

    rows = []
    for i, (where, options) in enumerate(VARIANTS):
        lowered = evaluate.lower(task, state, jax.random.key(1), args.eval_envs + i, args.eval_steps)
        timing: dict[str, float] = {}

        def compile_it(lowered=lowered, options=options, timing=timing) -> None:
            start = time.perf_counter()
            lowered.compile(compiler_options=options)
            timing["compile_s"] = time.perf_counter() - start

        thread = threading.Thread(target=compile_it)
        if where == "alone":
            thread.start()
            thread.join()
        else:
            start = time.perf_counter()
            result = chunk(task, state)  # dispatched: runs on the device while the thread compiles
            thread.start()
            jax.block_until_ready(result)
            timing["chunk_s"] = time.perf_counter() - start
            thread.join()
        rows.append({"where": where, "options": options, "eval_envs": args.eval_envs + i, **timing})
        print(
            f"{args.env}: evaluation compiled {where} with {options or 'default options'}: "
            f"{timing['compile_s']:.1f} s"
            + (f" (the chunk ran {timing['chunk_s']:.1f} s)" if "chunk_s" in timing else ""),
            flush=True,
        )

    device = jax.devices()[0]
    path = args.out / f"background_compile_{jax.default_backend()}_{args.env}.json"
    args.out.mkdir(parents=True, exist_ok=True)
    path.write_text(
        json.dumps(
            {
                "device": device.device_kind,
                "jax": jax.__version__,
                "env": args.env,
                "updates": args.updates,
                "eval_steps": args.eval_steps,
                "rows": rows,
            },
            indent=1,
        )
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
