"""Warp conformance: every registered env, bare and under the stack of every combinator,
passes `mjzoo.testing.check_task` on MuJoCo Warp (jit, vmap, no retrace, finite, same
key same trajectory, ...); and short trajectories on Warp follow MJX-JAX's.

    python benchmarks/warp_conformance.py --out benchmarks/results/warp/conformance.json
    python benchmarks/warp_conformance.py --envs cartpole_balance point_mass --compare cartpole_balance

The cases are the CPU conformance suite's (tests/conformance/test_conformance.py, imported:
it needs pytest, the "test" extra): "bare" is the env with a 6-step episode, "all" the
env under every combinator, both checked over 10 steps of 2 worlds. A failing
"deterministic" is measured again: two runs of the same keys, and the largest difference
between them (Warp's kernels add with atomics, so a GPU run may differ in the last bits).

The comparison resets both implementations from one key and applies one sequence of
uniform random actions for --steps control steps (one world each); per step, the largest
|difference| of qpos, qvel and reward. A step is within tolerance when every entry is
``np.isclose(warp, jax, rtol=RTOL, atol=ATOL)``; an env conforms when its first
--tight-steps steps are. Contact-rich models are chaotic: two float32 solvers part ways
after a while, reported as the first step out of tolerance (``diverges_at``).

Runs on one GPU; with MJZOO_WARP_ON_CPU=1 on Warp's CPU backend (slow: for debugging).
The JSON is rewritten after every case, so an interrupted run keeps what it measured.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import time
import traceback
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "conformance"))
from test_conformance import STEPS
from test_conformance import task_for

import mjzoo
import mjzoo.envs
from mjzoo import batching
from mjzoo import physics
from mjzoo import running
from mjzoo.testing import PROPERTIES
from mjzoo.testing import TaskCheckError
from mjzoo.testing import check_task

RTOL, ATOL = 1e-3, 1e-3  # per entry: |warp - jax| <= ATOL + RTOL |jax| (qpos: m, rad; qvel: m/s, rad/s)
# Compared with MJX-JAX: contact-free models first, then contact-rich ones.
COMPARED = (
    "pendulum_swingup",
    "cartpole_balance",
    "point_mass",
    "cylinder_push",
    "hopper",
    "cheetah",
    "ant",
    "humanoid_walk",
)


@functools.partial(jax.jit, static_argnums=2)
def _trajectories(task: mjzoo.Task, keys: jax.Array, num_steps: int) -> dict[str, jax.Array]:
    """Reset per key ([E]) and `num_steps` uniform random actions drawn from the key:
    qpos and qvel [E, T+1, ...] (the reset's first), reward [E, T]."""
    task = batching.sized(task, keys.shape[0])

    def policy(obs: Any, key: jax.Array) -> jax.Array:
        return jax.random.uniform(key, (task.action_size,), minval=-1.0, maxval=1.0)

    def one(key: jax.Array) -> dict[str, jax.Array]:
        reset_key, run_key = jax.random.split(key)
        first = running.reset(task, reset_key)
        states = running.rollout(task, policy, first, run_key, num_steps)[1].next_state
        joined = lambda a, b: jnp.concatenate([a[None], b])
        return {
            "qpos": joined(first.data.qpos, states.data.qpos),
            "qvel": joined(first.data.qvel, states.data.qvel),
            "reward": states.reward,
        }

    return jax.vmap(one)(keys)


def _largest_difference(a: dict[str, jax.Array], b: dict[str, jax.Array]) -> float:
    return max(float(np.max(np.abs(np.asarray(a[k]) - np.asarray(b[k])), initial=0.0)) for k in a)


def conformance(env: str, stack: str, num_envs: int = 2) -> dict[str, Any]:
    """check_task's verdict per property on `env` under `stack` ("bare" or "all") on Warp;
    a failed "deterministic" also gets the largest difference between two same-key runs."""
    start = time.perf_counter()
    result: dict[str, Any] = {"env": env, "stack": stack}
    try:
        task = task_for(env, stack, impl="warp")
        report = check_task(task, num_steps=STEPS, num_envs=num_envs)
        verdicts = {p: "pass" for p in report.passed}
        verdicts.update({p: f"skipped: {why}" for p, why in report.skipped.items()})
        result["traces"] = report.traces
    except TaskCheckError as error:
        verdicts = {p: "pass" for p in PROPERTIES if p not in error.failures and p not in error.skipped}
        verdicts.update({p: f"fail: {why}" for p, why in error.failures.items()})
        verdicts.update({p: f"skipped: {why}" for p, why in error.skipped.items()})
        if "deterministic" in error.failures:
            keys = jax.random.split(jax.random.key(0), num_envs)
            gap = _largest_difference(_trajectories(task, keys, STEPS), _trajectories(task, keys, STEPS))
            result["deterministic_max_difference"] = gap
            verdicts["deterministic"] += f" (same keys, two runs: max |difference| of qpos, qvel, reward {gap:.3g})"
    except Exception as error:  # noqa: BLE001  the task does not build: every property unchecked
        verdicts = {p: f"error: {type(error).__name__}: {str(error)[:300]}" for p in PROPERTIES}
        result["traceback"] = traceback.format_exc(limit=4)
    result["properties"] = verdicts
    result["ok"] = all(v == "pass" or v.startswith("skipped") for v in verdicts.values())
    result["seconds"] = round(time.perf_counter() - start, 1)
    return result


def comparison(env: str, steps: int, tight_steps: int, options: dict[str, Any] | None = None) -> dict[str, Any]:
    """Per-step largest |warp - jax| of qpos, qvel and reward on `env` (with physics
    `options`, e.g. a converged solver) over `steps` control steps from one key with one
    action sequence, and the first step out of tolerance."""
    start = time.perf_counter()
    options = options or {}
    keys = jax.random.split(jax.random.key(1), 1)
    make = lambda impl: mjzoo.envs.make(env, impl=impl, **options)  # noqa: E731
    runs = {
        impl: jax.tree.map(lambda x: np.asarray(x[0]), _trajectories(make(impl), keys, steps))
        for impl in ("jax", "warp")
    }
    jx, wp = runs["jax"], runs["warp"]
    reward = lambda r: np.concatenate([[0.0], r])
    error = {k: np.max(np.abs(wp[k] - jx[k]), axis=1) for k in ("qpos", "qvel")}
    error["reward"] = reward(np.abs(wp["reward"] - jx["reward"]))
    inside = np.all(np.isclose(wp["qpos"], jx["qpos"], RTOL, ATOL), axis=1)
    inside &= np.all(np.isclose(wp["qvel"], jx["qvel"], RTOL, ATOL), axis=1)
    inside &= np.isclose(reward(wp["reward"]), reward(jx["reward"]), RTOL, ATOL)
    out = np.flatnonzero(~inside)
    return {
        "env": env,
        "physics": options,
        "steps": steps,
        f"max_first_{tight_steps}": {k: float(v[: tight_steps + 1].max()) for k, v in error.items()},
        f"max_all_{steps}": {k: float(v.max()) for k, v in error.items()},
        "diverges_at": int(out[0]) if out.size else None,
        "conforms": bool(inside[: tight_steps + 1].all()),
        "error_per_step": {k: [float(f"{x:.3g}") for x in v] for k, v in error.items()},
        "seconds": round(time.perf_counter() - start, 1),
    }


def _number(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _table(results: dict[str, Any]) -> str:
    """The conformance cases, one row each (failing properties named), then the comparison."""
    lines = [f"{'env':24s} {'stack':5s} {'ok':4s} {'s':>6s}  failed / not run"]
    for r in results["conformance"]:
        bad = [p for p, v in r["properties"].items() if not (v == "pass" or v.startswith("skipped"))]
        lines.append(
            f"{r['env']:24s} {r['stack']:5s} {'yes' if r['ok'] else 'NO':4s} {r['seconds']:6.1f}  "
            f"{', '.join(bad) or '-'}"
        )
        lines += [f"{'':36s}{p}: {r['properties'][p]}" for p in bad]
    c = results["comparison"]
    if c["envs"]:
        tight = c["tight_steps"]
        lines += [
            "",
            f"warp vs jax, {c['steps']} steps; tolerance |warp - jax| <= {ATOL} + {RTOL}|jax|",
            f"{'env':24s} {'conforms':8s} {'diverges':>8s}   max |diff| first {tight} steps "
            + "(qpos, qvel, reward)   max over all steps",
        ]
        for r in c["envs"]:
            if "error" in r:
                lines.append(f"{r['env']:24s} ERROR {r['error']}")
                continue
            first, every = r[f"max_first_{tight}"], r[f"max_all_{c['steps']}"]
            fmt = lambda d: ", ".join(f"{d[k]:.2g}" for k in ("qpos", "qvel", "reward"))
            lines.append(
                f"{r['env']:24s} {'yes' if r['conforms'] else 'NO':8s} {r['diverges_at']!s:>8s}   "
                f"{fmt(first):40s} {fmt(every)}"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=mjzoo.envs.names(), help="default: every registered env")
    parser.add_argument(
        "--stacks", nargs="*", default=["bare", "all"], choices=["bare", "all"], help="--stacks alone: none"
    )
    parser.add_argument(
        "--compare",
        nargs="*",
        default=list(COMPARED),
        help="envs whose Warp and JAX trajectories are compared (those also in --envs); --compare alone: none",
    )
    parser.add_argument("--steps", type=int, default=50, help="control steps compared")
    parser.add_argument("--tight-steps", type=int, default=10, help="the first steps that must stay within tolerance")
    parser.add_argument(
        "--physics",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="physics options of the compared envs, e.g. iterations=50 ls_iterations=20 (a converged "
        "solver: the envs' own single Newton iteration leaves each implementation its own answer)",
    )
    parser.add_argument("--out", type=Path, default=None, help="JSON file, rewritten after every case")
    args = parser.parse_args(argv)
    options = {k: _number(v) for k, _, v in (p.partition("=") for p in args.physics)}
    unknown = sorted(set(args.envs) - set(mjzoo.envs.names()))
    if unknown:
        parser.error(f"unknown env(s) {unknown}; registered: {mjzoo.envs.names()}")

    results: dict[str, Any] = {
        "device": str(jax.devices()[0]),
        "warp_on_cpu": os.environ.get(physics.WARP_ON_CPU) == "1",
        "conformance": [],
        "comparison": {"steps": args.steps, "tight_steps": args.tight_steps, "rtol": RTOL, "atol": ATOL, "envs": []},
    }

    def save() -> None:
        if args.out:
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(json.dumps(results, indent=1) + "\n")

    for stack in args.stacks:  # every env bare first: the cheapest compiles
        for env in args.envs:
            results["conformance"].append(conformance(env, stack))
            r = results["conformance"][-1]
            print(f"{env} {stack}: {'ok' if r['ok'] else 'FAILED'} ({r['seconds']} s)", flush=True)
            save()
            jax.clear_caches()
    for env in [e for e in args.compare if e in args.envs]:
        try:
            results["comparison"]["envs"].append(comparison(env, args.steps, args.tight_steps, options))
        except Exception as error:  # noqa: BLE001  reported; the other envs still run
            results["comparison"]["envs"].append({"env": env, "error": f"{type(error).__name__}: {str(error)[:300]}"})
        print(f"{env} warp vs jax: {results['comparison']['envs'][-1].get('diverges_at', 'error')}", flush=True)
        save()
        jax.clear_caches()
    print(_table(results), flush=True)
    return results


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)  # Warp's CPU backend may hang at interpreter exit
