"""Every MuJoCo Playground env through `mjzoo.interop.playground.task` and
`mjzoo.testing.check_task`: which pass the Task contract, which fail and why, which were
skipped (a locomotion or manipulation env whose robot models no source of
`mjzoo.robots` holds here: ``pip install 'mjzoo[robots]'`` installs them all).

    python scripts/playground_conformance.py                       # all, 2 processes
    python scripts/playground_conformance.py --only CartpoleBalance CheetahRun --jobs 1
                                           # (--only: their records replace theirs in the JSON)

Writes JSON (one record per env: status, passed and failed properties with why, seconds;
"seconds" sums the envs' build and check times)
and the same as a Markdown table next to it, and prints the table. Each env compiles once:
its episode is shortened to --episode-length steps (inside check_task's rollout of
--num-steps, so the time limit is checked on the same compile); --episode-length 0 keeps
the env's own (1000 steps: check_task then compiles a second time under a shorter limit).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import multiprocessing
import platform
import time
from pathlib import Path

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "playground" / "conformance.json"


def suite(name: str) -> str:
    from mujoco_playground._src import dm_control_suite
    from mujoco_playground._src import locomotion

    if name in dm_control_suite.ALL_ENVS:
        return "dm_control_suite"
    return "locomotion" if name in locomotion.ALL_ENVS else "manipulation"


def check_one(name: str, episode_length: int, num_steps: int) -> dict:
    """One env's record; runs in a worker process of its own."""
    import jax

    import mjzoo
    from mjzoo.interop import playground

    record = {"env": name, "suite": suite(name)}
    if playground.needs_network(name):
        return {
            **record,
            "status": "skipped",
            "why": f"its robot models {playground.robots_of(name)} are not on this machine (pip install 'mjzoo[robots]')",
        }
    started = time.perf_counter()
    try:
        overrides = {"episode_length": episode_length} if episode_length else {}
        task = playground.task(name, **overrides)
    except Exception as error:  # noqa: BLE001 (a record, not a crash: the others still run)
        return {**record, "status": "fail", "why": f"does not build: {type(error).__name__}: {error}"[:400]}
    built = time.perf_counter()
    shape = jax.eval_shape(lambda k: mjzoo.reset(task, k), jax.random.key(0))
    record.update(
        action_size=task.action_size,
        obs=jax.tree.map(lambda x: list(x.shape), shape.obs),
        episode_length=None if task.time_limit is None else int(task.time_limit),
        control_dt=float(mjzoo.control_dt(task)),
        build_s=round(built - started, 2),
    )
    try:
        report = mjzoo.testing.check_task(task, num_steps=num_steps)
        record.update(status="pass", passed=list(report.passed), not_checked=report.skipped, traces=report.traces)
    except mjzoo.testing.TaskCheckError as error:
        record.update(
            status="fail",
            failures=error.failures,
            not_checked=error.skipped,
            why="; ".join(f"{k}: {v}" for k, v in error.failures.items())[:400],
        )
    record["check_s"] = round(time.perf_counter() - built, 2)
    return record


def table(records: list[dict]) -> str:
    lines = ["| env | suite | status | obs | actions | check (s) | why |", "|---|---|---|---|---|---|---|"]
    for r in records:
        obs = json.dumps(r.get("obs", "")).replace("|", "/")
        why = r.get("why", "").replace("|", "/")
        lines.append(
            f"| {r['env']} | {r['suite']} | {r['status']} | {obs} | {r.get('action_size', '')} "
            f"| {r.get('check_s', '')} | {why} |"
        )
    counts = {s: sum(r["status"] == s for r in records) for s in ("pass", "fail", "skipped")}
    lines.append("")
    lines.append(f"{counts['pass']} pass, {counts['fail']} fail, {counts['skipped']} skipped of {len(records)}")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", nargs="*", help="env names (default: all of Playground's registry)")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (each compiles one env at a time)")
    parser.add_argument("--episode-length", type=int, default=8, help="0: the env's own")
    parser.add_argument("--num-steps", type=int, default=10, help="check_task's rollout length")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    from mjzoo.interop import playground

    names = args.only or playground.names()
    unknown = sorted(set(names) - set(playground.names()))
    if unknown:
        parser.error(f"unknown Playground env(s) {unknown}")
    context = multiprocessing.get_context("spawn")  # JAX does not survive fork
    with concurrent.futures.ProcessPoolExecutor(args.jobs, mp_context=context, max_tasks_per_child=1) as pool:
        futures = {name: pool.submit(check_one, name, args.episode_length, args.num_steps) for name in names}
        records = []
        for name, future in futures.items():
            try:
                record = future.result()
            except Exception as error:  # noqa: BLE001 (a worker that died: its env failed)
                record = {
                    "env": name,
                    "suite": suite(name),
                    "status": "fail",
                    "why": f"worker died: {type(error).__name__}: {error}"[:400],
                }
            records.append(record)
            print(f"{name}: {record['status']} {record.get('why', '')}".rstrip(), flush=True)
            write(args, records, final=False)  # a run cut short keeps what it checked
    write(args, records, final=True)


def write(args: argparse.Namespace, records: list[dict], final: bool) -> None:
    """The JSON and Markdown files: with --only, `records` replace theirs among the earlier ones."""
    from importlib import metadata

    import mujoco_playground  # noqa: F401 (its version, below)

    from mjzoo.interop import playground

    result = {
        "machine": f"{platform.machine()}, {multiprocessing.cpu_count()} CPUs, {args.jobs} jobs",
        "playground": metadata.version("playground"),
        "jax": metadata.version("jax"),
        "mujoco_mjx": metadata.version("mujoco-mjx"),
        "episode_length": args.episode_length or "own",
        "num_steps": args.num_steps,
        "envs": records,
    }
    if args.only and args.out.exists():  # the other envs' records stay, in registry order
        earlier = json.loads(args.out.read_text())
        mine = {r["env"]: r for r in records}
        kept = [r for r in earlier["envs"] if r["env"] not in mine]
        order = {name: i for i, name in enumerate(playground.names())}
        result["envs"] = sorted(kept + records, key=lambda r: order.get(r["env"], len(order)))
    result["seconds"] = round(sum(r.get("build_s", 0.0) + r.get("check_s", 0.0) for r in result["envs"]), 1)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    text = table(result["envs"])
    args.out.with_suffix(".md").write_text(text + "\n")
    if final:
        print(text)
        print(f"{args.out} ({result['seconds']} s)")


if __name__ == "__main__":
    main()
