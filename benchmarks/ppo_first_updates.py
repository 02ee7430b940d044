"""The first PPO updates on a Playground env with Playground's tuned config, one line
each: the entropy estimate, the approximate KL and clip fraction of the update, the
value loss, and the policy's scale (1st / 50th / 99th percentile over the envs). A
healthy update moves the policy a little (KL ~ 0.01, clip fraction ~ 0.05); a scale
that explodes in one update is the failure fixed in `distributions.entropy`.

    python benchmarks/ppo_first_updates.py --env PendulumSwingup --num-envs 256 --updates 3
    python benchmarks/ppo_first_updates.py --set entropy_coef=0.0     # ppo.configure overrides
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

from mjzoo.algorithms import ppo
from mjzoo.harness.cli import arguments
from mjzoo.interop import playground
from mjzoo.learning import distributions


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="PendulumSwingup")
    parser.add_argument("--impl", default="jax", choices=["jax", "warp"])
    parser.add_argument("--num-envs", type=int, default=None, help="default: Playground's (2048)")
    parser.add_argument("--updates", type=int, default=3)
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE", help="ppo.configure fields")
    args = parser.parse_args()
    task = playground.task(args.env, impl=args.impl)
    fields = {**playground.ppo_hyperparameters(args.env), **arguments.parse_assignments(tuple(args.set), "--set")}
    config, hyperparams = ppo.configure(**{**fields, **({"num_envs": args.num_envs} if args.num_envs else {})})
    policy_net = ppo._networks(config, task)[0]
    update = jax.jit(ppo.update, static_argnums=0)
    state = ppo.init(config, task, hyperparams, jax.random.key(0))
    for i in range(args.updates):
        state, m = update(config, task, state)
        obs = ppo._inputs(config, state.obs_stats, state.collector.env_state.obs)[0]
        _, scale = distributions.split_params(policy_net.apply(state.params["policy"], obs))
        print(
            f"update {i}: entropy {float(m['loss/entropy']):.3g}, approx KL {float(m['loss/approx_kl']):.3g}, "
            f"clip fraction {float(m['loss/clip_fraction']):.3f}, value loss {float(m['loss/value']):.3g}, "
            f"scale {np.percentile(np.asarray(scale), [1, 50, 99]).round(3)}",
            flush=True,
        )


if __name__ == "__main__":
    main()
