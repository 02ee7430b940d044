"""What PPO's KL-adaptive learning rate does over a run: seeds of one env vmapped in one
program, and the rate and approximate KL at the end of each update, sampled over the run.
Runs on a CPU in minutes (compiled at XLA -O3).

    python benchmarks/adaptive_lr_probe.py --env cartpole_swingup --steps 2000000
    python benchmarks/adaptive_lr_probe.py --env cartpole_swingup --steps 2000000 --lr-schedule adaptive_update
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import mjzoo
import mjzoo.envs
from mjzoo.algorithms import ppo


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="cartpole_swingup")
    parser.add_argument("--steps", type=int, default=2_000_000)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--lr-schedule", default="adaptive", choices=["adaptive", "adaptive_update"])
    parser.add_argument("--samples", type=int, default=12, help="updates shown, evenly over the run")
    args = parser.parse_args()
    task = mjzoo.envs.make(args.env)
    config, hyperparams = ppo.configure(
        num_envs=256,
        unroll_length=32,
        num_minibatches=8,
        num_epochs=4,
        total_steps=args.steps,
        lr_schedule=args.lr_schedule,
    )

    def run(key: jax.Array):
        state, metrics = ppo.train(config, task, hyperparams, key)
        final = ppo.evaluate(config, task, state, jax.random.key(1), 16, mjzoo.episode_steps(task)).returns.mean()
        return final, {k: metrics[k] for k in ("learning_rate", "loss/approx_kl")}

    keys = jax.random.split(jax.random.key(0), args.seeds)
    start = time.perf_counter()
    compiled = jax.jit(jax.vmap(run)).lower(keys).compile({"xla_backend_optimization_level": 3})
    finals, metrics = jax.block_until_ready(compiled(keys))
    print(f"{args.env}, {args.lr_schedule}, {args.steps:,} steps, {time.perf_counter() - start:.0f} s with the compile")
    print("final deterministic returns per seed:", np.round(np.asarray(finals), 1))
    for name, values in metrics.items():
        values = np.asarray(values)  # [seed, update]
        shown = np.linspace(0, values.shape[1] - 1, args.samples).astype(int)
        for seed, row in enumerate(values):
            print(f"{name}, seed {seed}, updates {shown[0]}..{shown[-1]}:", " ".join(f"{x:.2g}" for x in row[shown]))


if __name__ == "__main__":
    main()
