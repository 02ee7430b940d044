"""Auto-reset under `jax.vmap`: the batched rule (new episodes computed in one `lax.cond`,
only on steps where some env ended) against choosing per env (a fresh reset computed for
every env on every step, then selected), on the same task, keys and actions.

Prints env steps/s of each and whether the two runs' states are bit-identical.

    python benchmarks/auto_reset.py --envs playground:CheetahRun cartpole_balance --num-envs 32
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp

import mjzoo.envs
from mjzoo import combinators
from mjzoo import running


def measure(name: str, num_envs: int, steps: int, batched_rule: bool) -> tuple[float, object]:
    """(env steps/s, the stacked outcomes) of `steps` auto-resetting transitions of `num_envs` envs."""
    saved = combinators._restarted
    if not batched_rule:
        combinators._restarted = combinators._restarted_select  # the per-env choice
    try:
        task = combinators.with_auto_reset(mjzoo.envs.make(name))
        keys = jax.random.split(jax.random.key(0), num_envs)
        states = jax.vmap(lambda k: running.reset(task, k))(keys)
        action = 0.5 * jnp.ones((task.action_size,))

        def body(states, key):
            states = jax.vmap(lambda s, k: running.transition(task, s, action, k))(
                states, jax.random.split(key, num_envs)
            )
            return states, (states.reward, states.obs, states.terminated | states.truncated)

        run = jax.jit(lambda s: jax.lax.scan(body, s, jax.random.split(jax.random.key(1), steps)))
        jax.block_until_ready(run(states))
        start = time.perf_counter()
        out = jax.block_until_ready(run(states))
        return num_envs * steps / (time.perf_counter() - start), out[1]
    finally:
        combinators._restarted = saved


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["playground:CheetahRun", "cartpole_balance", "humanoid_walk"])
    parser.add_argument("--num-envs", type=int, default=32)
    parser.add_argument("--steps", type=int, default=100)
    args = parser.parse_args()
    print(f"device: {jax.devices()[0].device_kind}; {args.num_envs} envs x {args.steps} steps")
    for name in args.envs:
        per_env, a = measure(name, args.num_envs, args.steps, batched_rule=False)
        batched, b = measure(name, args.num_envs, args.steps, batched_rule=True)
        same = all(jax.tree.leaves(jax.tree.map(lambda x, y: bool(jnp.array_equal(x, y)), a, b)))
        print(
            f"{name}: per-env choice {per_env:,.0f} steps/s, batched {batched:,.0f} ({batched / per_env:.2f}x); "
            f"episodes ended {int(jnp.sum(a[2]))}; identical: {same}",
            flush=True,
        )


if __name__ == "__main__":
    main()
