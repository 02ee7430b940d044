"""Planning latency per replan against the bare rollouts it is made of, one process.

For each env, sample count N and horizon H: the median wall time of one jitted
`mppi.plan` (sample, roll out N x H steps of the task's `transition`, weigh, update) and,
beside it, of one jitted batch of bare MJX rollouts of the same N x H (raw `mjx.step`
on the same model, controls given): the physical limit. Also predictive sampling and
CEM at 1024 samples, and what `lax.scan` unrolling buys.

Each measurement runs on every physics implementation of ``--impl`` (MJX-JAX, MuJoCo
Warp), one after the other in this process. JSON: ``rows`` holds one row per (env,
impl, planner, samples, horizon, unroll), its ``"impl"`` naming the physics and the
other keys meaning what they always did (old files, without ``"impl"``, are JAX);
``warp_vs_jax`` holds, per row measured on both, Warp's replanning rate over JAX's
(``plan_hz``) and the bare rollouts' speed-up (``bare``: JAX's ms over Warp's).

Envs: any registered one; `--physics` makes the planning model coarser. A humanoid
plans with Brax's humanoid (`humanoid_walk`: MJX collisions, 17 actuators) at physics step
0.025 s and control step 0.05 s (8 and 3.3 x coarser than the simulation's 0.003 /
0.015 s), so a 0.5 s horizon is 20 sequential physics steps, and few solver iterations.

    python benchmarks/planner_latency.py --envs cartpole_swingup
    python benchmarks/planner_latency.py --envs humanoid_walk --horizons 10 20 --tag humanoid \
        --physics dt=0.025 ctrl_dt=0.05 iterations=1 ls_iterations=2
    # the humanoid's replanning rate at 1024 samples over 0.5 s, on both physics:
    python benchmarks/planner_latency.py --envs humanoid_walk --samples 1024 --horizons 10 --no-extras \
        --physics dt=0.025 ctrl_dt=0.05 iterations=1 ls_iterations=2 --impl jax warp --tag humanoid_impls
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import jax

import mjzoo
import mjzoo.envs
from mjzoo import batching
from mjzoo import physics
from mjzoo.algorithms import cem
from mjzoo.algorithms import mppi
from mjzoo.algorithms import predictive_sampling

sys.path.insert(0, str(Path(__file__).parent))
from task_overhead import add_impl_argument  # noqa: E402
from task_overhead import impls  # noqa: E402
from task_overhead import ratio  # noqa: E402


def make(env: str, physics_options: dict) -> tuple[mjzoo.Task, int]:
    """(planning task, physics substeps per control step)."""
    task = mjzoo.envs.make(env, episode_steps=10**9, **physics_options)
    return task, round(mjzoo.control_dt(task) / float(task.model.opt.timestep))


# --- measurements ------------------------------------------------------------------------


def median_ms(fn, *args, repeats: int) -> float:
    jax.block_until_ready(fn(*args))  # compile
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def bare_rollouts(task: mjzoo.Task, n_substeps: int, unroll: int = 1):
    @jax.jit
    def run(data, controls):  # controls [N, H, nu]
        data = batching.sized(data, controls.shape[0])  # Warp: a contact pool for the N samples

        def one(sample_controls):
            step = lambda d, u: (physics.step(task.model, d, u, n_substeps), None)  # noqa: E731
            return jax.lax.scan(step, data, sample_controls, unroll=unroll)[0].qpos

        return jax.vmap(one)(controls)

    return run


def measure(
    env: str,
    physics_options: dict,
    samples: list[int],
    horizons: list[int],
    repeats: int,
    extras: bool,
    save,
    impl: str = "jax",
) -> list[dict]:
    task, n_substeps = make(env, {**physics_options, "impl": impl})
    state = mjzoo.fill_transition_entries(task, mjzoo.reset(task, jax.random.key(0)))
    rows = []

    def row(planner, n, h, unroll=1):
        config = planner.Config(num_samples=n, horizon_steps=h, num_knots=min(4, h), unroll=unroll)
        plan = jax.jit(planner.plan, static_argnums=0)
        planner_state = planner.init(config, task)
        plan_ms = median_ms(plan, config, task, planner_state, state, jax.random.key(1), repeats=repeats)
        controls = jax.random.uniform(jax.random.key(2), (n, h, task.action_size), minval=-1, maxval=1)
        bare_ms = median_ms(bare_rollouts(task, n_substeps, unroll), state.data, controls, repeats=repeats)
        result = {
            "env": env,
            "impl": impl,
            "physics": physics_options,
            "planner": planner.__name__.rsplit(".", 1)[-1],
            "samples": n,
            "horizon_steps": h,
            "horizon_s": h * n_substeps * float(task.model.opt.timestep),
            "unroll": unroll,
            "plan_ms": plan_ms,
            "bare_ms": bare_ms,
            "overhead": plan_ms / bare_ms - 1.0,
            "ms_per_physics_step": plan_ms / (h * n_substeps),
            "plan_hz": 1e3 / plan_ms,
        }
        print(
            f"{env:<16} {impl:<5} {result['planner']:<20} N={n:<6} H={h:<3} ({result['horizon_s']:.2f} s) unroll={unroll} "
            f"plan {plan_ms:8.2f} ms  bare {bare_ms:8.2f} ms  overhead {100 * result['overhead']:+6.1f}%  "
            f"{result['ms_per_physics_step']:.3f} ms/step  {result['plan_hz']:.0f} Hz",
            flush=True,
        )
        rows.append(result)
        save(rows)

    for h in horizons:
        for n in samples:
            row(mppi, n, h)
    if extras:
        for planner in (predictive_sampling, cem):
            row(planner, 1024, horizons[0])
        row(mppi, 1024, horizons[0], unroll=4)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="*", default=["cartpole_swingup", "humanoid_walk"])
    parser.add_argument(
        "--physics",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="physics options of the planning model, e.g. dt=0.025 ctrl_dt=0.05 iterations=1",
    )
    parser.add_argument("--samples", nargs="*", type=int, default=[64, 256, 1024, 4096, 16384])
    parser.add_argument("--horizons", nargs="*", type=int, default=[13, 25], help="planning control steps")
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--no-extras", action="store_true", help="only MPPI over the samples x horizons grid")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--tag", default="", help="suffix of the JSON file, e.g. for a run under other XLA_FLAGS")
    add_impl_argument(parser)
    args = parser.parse_args()
    device = jax.devices()[0].device_kind
    print(f"device: {device}, jax {jax.__version__}, XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}", flush=True)
    rows = []
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"planner_latency_{jax.default_backend()}{'_' + args.tag if args.tag else ''}.json"
    flags = os.environ.get("XLA_FLAGS", "")

    def save(env_rows: list[dict]) -> None:
        path.write_text(
            json.dumps(
                {
                    "device": device,
                    "jax": jax.__version__,
                    "xla_flags": flags,
                    "rows": rows + env_rows,
                    "warp_vs_jax": warp_vs_jax(rows + env_rows),
                },
                indent=2,
            )
        )

    options = {k: float(v) if "." in v else int(v) for k, v in (item.split("=", 1) for item in args.physics)}
    for env in args.envs:
        for impl in impls(args.impl):
            rows += measure(env, options, args.samples, args.horizons, args.repeats, not args.no_extras, save, impl)
    for r in warp_vs_jax(rows):
        print(
            f"{r['env']:<16} warp/jax {r['planner']:<20} N={r['samples']:<6} H={r['horizon_steps']:<3} "
            f"({r['horizon_s']:.2f} s) unroll={r['unroll']}  plan Hz {r['plan_hz']:.2f}x  bare {r['bare']:.2f}x  "
            f"(warp {r['warp_plan_hz']:.0f} Hz, jax {r['jax_plan_hz']:.0f} Hz)"
        )
    print(f"wrote {path}", flush=True)


def warp_vs_jax(rows: list[dict]) -> list[dict]:
    """Per measurement made on both physics: Warp's plan_hz over JAX's, and JAX's bare
    rollout time over Warp's."""
    setting = lambda r: (r["env"], r["planner"], r["samples"], r["horizon_steps"], r["unroll"])  # noqa: E731
    jax_rows = {setting(r): r for r in rows if r["impl"] == "jax"}
    pairs = [(r, jax_rows[setting(r)]) for r in rows if r["impl"] == "warp" and setting(r) in jax_rows]
    return [
        {
            "env": w["env"],
            "planner": w["planner"],
            "samples": w["samples"],
            "horizon_steps": w["horizon_steps"],
            "horizon_s": w["horizon_s"],
            "unroll": w["unroll"],
            "plan_hz": ratio(w["plan_hz"], j["plan_hz"]),
            "bare": ratio(j["bare_ms"], w["bare_ms"]),
            "warp_plan_hz": w["plan_hz"],
            "jax_plan_hz": j["plan_hz"],
        }
        for w, j in pairs
    ]


if __name__ == "__main__":
    main()
    os._exit(0)  # Warp on a CPU may hang at interpreter exit
