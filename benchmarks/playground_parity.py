"""Does `mjzoo.interop.playground.task` step a Playground env exactly as the bare env does,
on each physics implementation, and do the implementations agree?

The same reset keys and random actions drive `jax.vmap(env.step)` on the bare env and
`mjzoo.transition` on the adapter; prints the largest reward and observation differences,
and, with two implementations, the largest difference between them.

    python benchmarks/playground_parity.py --env PendulumSwingup --impl jax warp   # Warp needs mujoco_warp
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

import mjzoo
from mjzoo.interop import playground


def trajectories(name: str, impl: str, envs: int, steps: int) -> dict[str, np.ndarray]:
    """Rewards [steps, envs] and observations [steps, envs, ...] of the bare env and of the adapter."""
    env = playground.load(name, impl=impl)
    task = playground.task(env)
    keys = jax.random.split(jax.random.key(3), envs)
    actions = jax.random.uniform(jax.random.key(7), (steps, envs, env.action_size), minval=-1, maxval=1)

    def bare(state, action):
        state = jax.vmap(env.step)(state, action)
        return state, (state.reward, state.obs)

    def adapted(state, action):
        state = jax.vmap(lambda s, a, k: mjzoo.transition(task, s, a, k))(state, action, keys)
        return state, (state.reward, state.obs)

    run = lambda step, start: jax.jit(lambda s: jax.lax.scan(step, s, actions)[1])(start)  # noqa: E731
    (r0, o0), (r1, o1) = (
        run(bare, jax.vmap(env.reset)(keys)),
        run(adapted, jax.vmap(lambda k: mjzoo.reset(task, k))(keys)),
    )
    return {"bare_reward": np.asarray(r0), "bare_obs": np.asarray(o0), "reward": np.asarray(r1), "obs": np.asarray(o1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="PendulumSwingup")
    parser.add_argument("--impl", nargs="+", default=["jax"], choices=["jax", "warp"])
    parser.add_argument("--envs", type=int, default=4)
    parser.add_argument("--steps", type=int, default=300)
    args = parser.parse_args()
    runs = {impl: trajectories(args.env, impl, args.envs, args.steps) for impl in args.impl}
    for impl, r in runs.items():
        print(
            f"{args.env} ({impl}): adapter - bare env: {_max_gaps(r, r, 'bare_')}; "
            f"returns {r['reward'].sum(0).round(2).tolist()}"
        )
    if len(runs) == 2:
        a, b = runs.values()
        print(f"{args.env}: {' - '.join(runs)}: {_max_gaps(a, b, 'bare_', 'bare_')}")


def _max_gaps(a: dict, b: dict, a_prefix: str = "", b_prefix: str = "") -> str:
    """The largest reward and observation differences between two `trajectories` entries."""
    reward, obs = (np.abs(a[a_prefix + k] - b[b_prefix + k]).max() for k in ("reward", "obs"))
    return f"max |reward| {reward:.3g}, max |obs| {obs:.3g}"


if __name__ == "__main__":
    main()
