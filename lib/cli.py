"""The `mjzoo` command line (also `python -m mjzoo`).

    mjzoo envs                    # list the registered tasks and their overrides
    mjzoo demo --steps 200        # random policy on every env, batched, prints returns
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np
import tyro

import mjzoo
import mjzoo.envs

__all__ = ["main", "demo", "envs"]


def envs() -> None:
    """List the registered tasks with their overridable defaults."""
    for name in mjzoo.envs.names():
        overrides = ", ".join(f"{k}={v}" for k, v in mjzoo.envs.defaults(name).items())
        print(f"{name}\n    {overrides}")


def demo(env: tuple[str, ...] = (), num_envs: int = 32, steps: int = 250, seed: int = 0) -> None:
    """Roll out a uniformly random policy on each env (all by default) in a vmapped batch
    of `num_envs` and print the return of each first episode (up to `steps` steps)."""
    names = env or tuple(mjzoo.envs.names())
    if num_envs < 1 or steps < 1:
        raise SystemExit("demo: --num-envs and --steps must be >= 1")
    print(f"{'env':<18} {'obs':>5} {'act':>4} {'return (mean ± std)':>22} {'env-steps/s':>12}")
    for name in names:
        task = mjzoo.envs.make(name)
        run = jax.jit(_random_returns, static_argnums=(2, 3))
        keys = jax.random.split(jax.random.key(seed), num_envs)
        jax.block_until_ready(run(task, keys, steps, task.action_size))  # compile
        start = time.perf_counter()
        returns, obs_size = jax.block_until_ready(run(task, keys, steps, task.action_size))
        rate = num_envs * steps / (time.perf_counter() - start)
        returns = np.asarray(returns)
        print(
            f"{name:<18} {int(obs_size[0]):>5} {task.action_size:>4} "
            f"{returns.mean():>13.2f} ± {returns.std():<7.2f} {rate:>12,.0f}"
        )


def _random_returns(task: mjzoo.Task, keys: jax.Array, steps: int, nu: int):
    """Per env: the return of the first episode under uniform random controls."""
    low, high = task.model.actuator_ctrlrange[:, 0], task.model.actuator_ctrlrange[:, 1]

    def policy(obs, key):
        return jax.random.uniform(key, (nu,), minval=low, maxval=high)

    def one(key):
        reset_key, run_key = jax.random.split(key)
        state = mjzoo.reset(task, reset_key)
        _, trajectory = mjzoo.rollout(task, policy, state, run_key, steps)
        done = trajectory.next_state.terminated | trajectory.next_state.truncated
        alive = jnp.cumsum(done) - done == 0  # up to and including the first episode end
        obs_size = jnp.size(jax.tree.leaves(state.obs)[0])
        return jnp.sum(trajectory.next_state.reward * alive), obs_size

    return jax.vmap(one)(keys)


def main(argv: list[str] | None = None) -> None:
    tyro.extras.subcommand_cli_from_dict({"demo": demo, "envs": envs}, args=argv)


if __name__ == "__main__":
    main()
