"""The peer baseline: Brax's own PPO (`brax.training.agents.ppo.train`) on an mjzoo task.

The task goes through `mjzoo.interop.brax`, so both trainers see the same physics,
observations, rewards and episode ends, on either physics (``impl="jax"`` or ``"warp"``:
Brax vmaps the env itself, so a Warp task's shared contact pool is sized here for the
larger of Brax's training and evaluation batches). Import `train_brax_ppo` from a benchmark script
(this folder is not a package):

    sys.path.insert(0, str(Path(__file__).parent)); from brax_peer import train_brax_ppo

or run it alone for a quick look (prints the curve, optionally writes JSON):

    python benchmarks/brax_peer.py --env cartpole_balance --num-timesteps 20000 \\
        --num-envs 16 --batch-size 16 --num-minibatches 4 --num-evals 4
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import jax

import mjzoo
import mjzoo.envs
from mjzoo.interop import brax as adapter

__all__ = ["train_brax_ppo", "wall_steps_per_s"]


def wall_steps_per_s(curve: list) -> float | None:
    """Env steps per wall-clock second from the first to the last evaluation after
    training began, of a curve ``[(env_steps, wall_seconds, eval_return), ...]``: what a
    trainer delivers, its own evaluations in between included. The first compile stays
    out of it. None with fewer than two such evaluations."""
    trained = [point for point in curve if point[0] > 0]
    if len(trained) < 2:
        return None
    (first_step, first_t, _), (last_step, last_t, _) = trained[0], trained[-1]
    return (last_step - first_step) / (last_t - first_t)


def train_brax_ppo(
    task: mjzoo.Task,
    *,
    num_timesteps: int,
    num_envs: int = 2048,
    batch_size: int = 1024,
    unroll_length: int = 30,
    num_minibatches: int = 32,
    num_updates_per_batch: int = 16,
    learning_rate: float = 1e-3,
    entropy_cost: float = 1e-2,
    discounting: float = 0.995,
    reward_scaling: float = 10.0,
    normalize_observations: bool = True,
    episode_length: int,
    num_evals: int = 10,
    seed: int = 0,
    num_eval_envs: int = 128,
) -> dict:
    """Trains Brax PPO (its default networks) on `task` and times it.

    `episode_length` should be the task's own episode length (its `episode_steps`):
    Brax's evaluator unrolls that many steps. Needs ``num_evals >= 3``: the training
    rate is timed between the reports after the first and the last training epochs,
    so the first compile stays out of it.

    Returns:
      steps_per_s: env steps per wall-clock second from the first to the last
        post-training report (Brax's progress_fn timestamps); Brax's evaluations in
        between count, as in any wall-clock training time.
      train_steps_per_s: the same steps over Brax's own training time alone
        (``training/walltime``, evaluations excluded).
      curve: ``[(env_steps, wall_seconds since the call, eval_return), ...]``, one per
        report, from step 0 (the untrained policy).
      final_return: the last mean evaluation return.
      compile_s: wall time to the first post-training report less the time its steps
        take at `steps_per_s`: setup, tracing and compiling (reset, the training epoch,
        the evaluator) and the initial evaluation.
      env_steps: env steps actually trained (Brax rounds up to whole epochs).
    """
    if num_evals < 3:
        raise ValueError(f"train_brax_ppo: num_evals={num_evals} must be >= 3 to time training past the first compile")
    from brax.training.agents.ppo import train as ppo  # after the patch is in place

    adapter.patch_brax_for_current_jax()
    # Warp: one contact pool for every world Brax vmaps (training envs, or eval envs).
    env = adapter.to_brax_env(mjzoo.batching.sized(task, max(num_envs, num_eval_envs)))
    reports: list[tuple[int, float, dict]] = []
    start = time.perf_counter()

    def progress(step: int, metrics: dict) -> None:
        reports.append((int(step), time.perf_counter() - start, dict(metrics)))

    ppo.train(
        env,
        num_timesteps=num_timesteps,
        num_envs=num_envs,
        batch_size=batch_size,
        unroll_length=unroll_length,
        num_minibatches=num_minibatches,
        num_updates_per_batch=num_updates_per_batch,
        learning_rate=learning_rate,
        entropy_cost=entropy_cost,
        discounting=discounting,
        reward_scaling=reward_scaling,
        normalize_observations=normalize_observations,
        episode_length=episode_length,
        num_evals=num_evals,
        num_eval_envs=num_eval_envs,
        seed=seed,
        wrap_env_fn=adapter.wrap_for_training,  # keeps the task's truncation flags
        progress_fn=progress,
    )

    trained = [r for r in reports if r[0] > 0]  # reports after training epochs
    (first_step, first_t, first_m), (last_step, _, last_m) = trained[0], trained[-1]
    curve = [(step, t, float(m.get("eval/episode_reward", math.nan))) for step, t, m in reports]
    steps_per_s = wall_steps_per_s(curve)
    train_seconds = last_m["training/walltime"] - first_m["training/walltime"]
    return {
        "steps_per_s": steps_per_s,
        "train_steps_per_s": (last_step - first_step) / train_seconds,
        "curve": curve,
        "final_return": curve[-1][2],
        "compile_s": first_t - first_step / steps_per_s,
        "env_steps": last_step,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="cartpole_balance")
    parser.add_argument("--num-timesteps", type=int, default=20_000)
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--batch-size", type=int, default=16)
    parser.add_argument("--num-minibatches", type=int, default=4)
    parser.add_argument("--num-evals", type=int, default=4)
    parser.add_argument("--num-eval-envs", type=int, default=128)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--impl", choices=mjzoo.physics.IMPLS, default=None, help="physics (default: the default)")
    parser.add_argument("--out", type=Path, help="write the result as JSON here")
    args = parser.parse_args()

    task = mjzoo.envs.make(args.env, impl=args.impl or mjzoo.physics.default_impl())
    episode_length = mjzoo.envs.defaults(args.env)["episode_steps"]
    print(f"device: {jax.devices()[0].device_kind} ({jax.default_backend()}), jax {jax.__version__}")
    result = train_brax_ppo(
        task,
        num_timesteps=args.num_timesteps,
        num_envs=args.num_envs,
        batch_size=args.batch_size,
        num_minibatches=args.num_minibatches,
        num_evals=args.num_evals,
        num_eval_envs=args.num_eval_envs,
        episode_length=episode_length,
        seed=args.seed,
    )
    print(f"{'env steps':>10} {'wall s':>8} {'eval return':>12}")
    for step, seconds, ret in result["curve"]:
        print(f"{step:>10} {seconds:>8.1f} {ret:>12.2f}")
    print(
        f"steps/s {result['steps_per_s']:,.0f} (training alone {result['train_steps_per_s']:,.0f}), "
        f"compile {result['compile_s']:.1f} s, final return {result['final_return']:.2f}"
    )
    if args.out:
        settings = {k: v for k, v in vars(args).items() if k != "out"}
        args.out.write_text(json.dumps({**settings, "device": jax.devices()[0].device_kind, **result}, indent=2))
        print(f"wrote {args.out}", flush=True)


if __name__ == "__main__":
    main()
    os._exit(0)  # Warp on a CPU may hang at interpreter exit
