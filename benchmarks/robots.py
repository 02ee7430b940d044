"""The robot joysticks trained with PPO on one GPU: time until a policy tracks commands.

Per robot and terrain (``--variants go1:flat g1:rough ...``), all ``--seeds`` train in one
vmapped program (the registered PPO settings, after Playground's: 8192 envs, privileged
critic), evaluated ``--evals`` times during training. An evaluation runs
``--eval-envs`` deterministic 20 s episodes of the task as trained (its pushes, noise and
randomized physics; on a terrain, from the hardest row) and measures velocity tracking
(`mjzoo.interop.tracking`). A seed **tracks** at the first evaluation where

    mean |v_xy - cmd_xy| <= 0.15 m/s,  mean |w_z - cmd_yaw| <= 0.2 rad/s,  no falls

(errors per control step, averaged over the steps and episodes) and its time to tracking
is the wall-clock from the start of the process's work on the variant (setup and compile
included). The errors of velocities and command averaged over 1 s windows are reported
beside them (a walker's base sways and yaws back and forth within a gait cycle). The
goal: flat terrain within 5 minutes, rough within 15 (anchors: Playground's Go1
joystick in 7 min and Berkeley Humanoid in 17 on an RTX 4090; mjlab's G1 flat velocity
within ~1 h on an RTX 5090).

    python benchmarks/robots.py --variants go1:flat --seeds 3 --budget 400 --runs runs/robots
    python benchmarks/robots.py --variants g1:flat --seeds 2 --algorithm fast_td3 --steps 10000000
    python benchmarks/robots.py --smoke --variants go1:flat     # tiny sizes, on a CPU

A variant stops once every seed tracks or after ``--budget`` seconds (default: the goal,
5 min flat, 15 rough). Results merge into ``benchmarks/results/robots/robots_<card>.json``
(``--out``) after every evaluation (a variant's re-run with the same seeds on the same
physics, ``--impl``, replaces its entry), with
the curves of tracking error against seconds in a figure. ``--runs`` keeps the first seed's
policy as a run that `mjzoo export` and `mjzoo sim2sim` take. ``--algorithm`` trains
with an off-policy learner instead (offpolicy.py's settings: FastTD3's recipe, SAC at its
scale), measured the same way: does an off-policy learner track sooner than PPO?
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from cards import card_name  # noqa: E402
from offpolicy import MODULES  # noqa: E402
from offpolicy import STEPS  # noqa: E402
from offpolicy import fields as offpolicy_fields  # noqa: E402
from report import row_settings  # noqa: E402

import mjzoo.envs  # noqa: E402
from mjzoo import physics  # noqa: E402
from mjzoo.algorithms import ppo  # noqa: E402
from mjzoo.envs import robot_joystick  # noqa: E402
from mjzoo.harness import checkpoints  # noqa: E402
from mjzoo.harness import settings  # noqa: E402
from mjzoo.harness.cli.arguments import UsageError  # noqa: E402
from mjzoo.harness.cli.arguments import parse_assignments  # noqa: E402
from mjzoo.interop import tracking  # noqa: E402

OUT = Path(__file__).parent / "results" / "robots"
GOAL = dict(linear_error=0.15, yaw_error=0.2)
EVAL_SECONDS = 20.0
# The goal's errors per control step, and (reported beside them) over 1 s windows: a
# walker's base sways and yaws back and forth within a gait cycle.
WINDOWS = (1, 50)
ERRORS = ("linear_error", "yaw_error", "linear_error_1s", "yaw_error_1s")
SMOKE = dict(num_envs=8, unroll_length=4, num_minibatches=2, num_epochs=1, total_steps=64)


def tracks(point: dict) -> bool:
    return (
        point["linear_error"] <= GOAL["linear_error"]
        and point["yaw_error"] <= GOAL["yaw_error"]
        and point["falls"] == 0
    )


def train(
    variant: str,
    seeds: list[int],
    steps: int | None,
    evals: int,
    eval_envs: int,
    smoke: bool,
    budget: float,
    report: Callable[[dict], None],
    run_dir: Path | None,
    impl: str = "jax",
    overrides: dict[str, Any] | None = None,
    task_options: dict[str, Any] | None = None,
    task_params: dict[str, Any] | None = None,
    algorithm_name: str = "ppo",
) -> dict[str, Any]:
    """Every seed of one robot and terrain in one vmapped program: up to `evals` chunks of
    updates, each followed by a tracking evaluation, until every seed tracks or `budget`
    seconds have passed. `report` gets the row so far after each evaluation; `run_dir`, if
    given, gets the first seed's policy as a run (`save_run`); `overrides` are PPO fields over the
    robot's registered ones, `task_options` the joystick's own (e.g. gait_frequency),
    `task_params` its named numbers (`mjzoo.params`: reward weights), `algorithm_name` the
    learner (`offpolicy.MODULES`). Returns the row."""
    start = time.perf_counter()
    robot, terrain = variant.split(":")
    name = f"{robot}_joystick"
    options = {"terrain": terrain, "impl": impl, **(task_options or {})}
    task = mjzoo.envs.make(name, **options)  # on a terrain: the curriculum, auto-reset inside
    # Evaluated where the curriculum ends: the hardest row (flat: the task itself).
    judge = task if terrain == "flat" else robot_joystick.robot_joystick(robot, level=1.0, **options)
    if task_params:
        task, judge = task.with_params(**task_params), judge.with_params(**task_params)
    module = MODULES[algorithm_name]
    fields = {**learner_fields(algorithm_name, name, smoke), **(overrides or {})}
    if steps:
        fields["total_steps"] = steps
    config, hyperparams = module.configure(**fields)
    algorithm = module.make(config)
    policy = module.policy(config, judge, deterministic=True)
    per_chunk = max(1, config.num_updates // evals)
    eval_steps = 10 if smoke else round(EVAL_SECONDS / 0.02)

    def chunk(state: Any, key: jax.Array):
        state, _ = jax.lax.scan(lambda s, _: algorithm.update(task, s), state, None, length=per_chunk)
        params, unused = module.policy_params(state), jax.random.key(0)  # deterministic: no key drawn
        linear, yaw, lived, fell, *over_1s = tracking.closed_loop(
            judge, lambda obs: policy(params, obs, unused), key, eval_envs, eval_steps, windows=WINDOWS
        )
        steps_lived = jnp.maximum(lived.sum(1), 1)
        errors = dict(zip(ERRORS, (linear, yaw, *over_1s)))
        measured = {k: (jnp.where(lived, e, 0.0).sum(1) / steps_lived).mean() for k, e in errors.items()}
        return state, {**measured, "falls": fell.any(1).sum()}

    init = jax.jit(jax.vmap(algorithm.init, in_axes=(None, None, 0)))
    run = jax.jit(jax.vmap(chunk), donate_argnums=() if jax.default_backend() == "cpu" else (0,))
    keys = jax.vmap(jax.random.key)(jnp.asarray(seeds))
    state = init(task, hyperparams, keys)
    curves: list[list[dict]] = [[] for _ in seeds]
    row: dict[str, Any] = {}
    for i in range(evals):
        state, measured = run(state, jax.vmap(jax.random.fold_in, in_axes=(0, None))(keys, 1000 + i))
        measured = jax.device_get(measured)  # waits for the chunk
        seconds = time.perf_counter() - start
        for s in range(len(seeds)):
            point = {k: float(v[s]) for k, v in measured.items()}
            curves[s].append({"step": (i + 1) * per_chunk * config.steps_per_update, "seconds": seconds, **point})
        print(
            f"  {variant} step {curves[0][-1]['step']:,} {seconds:.0f} s: "
            + "; ".join(
                f"seed {seed} |v-c| {c[-1]['linear_error']:.3f} |w-c| {c[-1]['yaw_error']:.3f} "
                f"(1 s: {c[-1]['linear_error_1s']:.3f}, {c[-1]['yaw_error_1s']:.3f}) falls {c[-1]['falls']:.0f}"
                for seed, c in zip(seeds, curves)
            ),
            flush=True,
        )
        row = {
            "algorithm": algorithm_name,
            **summarize(variant, fields, seeds, curves, eval_envs, eval_steps, start, smoke),
        }
        report(row)
        if row["seeds_tracking"] == len(seeds) or seconds > budget:
            break
    if run_dir is not None:
        save_run(run_dir / variant.replace(":", "_"), name, options, config, state)
    return row


def learner_fields(algorithm_name: str, name: str, smoke: bool) -> dict[str, Any]:
    """The learner's fields on joystick `name`: PPO's registered ones, or offpolicy.py's
    settings for an off-policy learner; tiny sizes if `smoke`."""
    if algorithm_name == "ppo":
        return {**mjzoo.envs.hyperparameters(name, "ppo"), **(SMOKE if smoke else {})}
    fields = offpolicy_fields(algorithm_name, name, STEPS.get(name, 10_000_000), smoke)  # its smoke sizes too
    return {**fields, **({"total_steps": 256} if smoke else {})}


def summarize(
    variant: str,
    fields: dict[str, Any],
    seeds: list[int],
    curves: list[list[dict]],
    eval_envs: int,
    eval_steps: int,
    start: float,
    smoke: bool,
) -> dict[str, Any]:
    """The benchmark's row for a variant from the seeds' curves so far."""
    robot, terrain = variant.split(":")
    runs = []
    for seed, curve in zip(seeds, curves):
        reached = next((p for p in curve if tracks(p)), None)
        runs.append(
            {
                "seed": seed,
                "curve": curve,
                "seconds_to_tracking": None if reached is None else reached["seconds"],
                "steps_to_tracking": None if reached is None else reached["step"],
                "final": curve[-1],
            }
        )
    reached = [r["seconds_to_tracking"] for r in runs if r["seconds_to_tracking"] is not None]
    return {
        "variant": variant,
        "robot": robot,
        "terrain": terrain,
        "hyperparameters": {k: (list(v) if isinstance(v, tuple) else v) for k, v in fields.items()},
        "seeds": seeds,
        "eval_envs": eval_envs,
        "eval_seconds": eval_steps * 0.02,
        "goal": GOAL,
        "runs": runs,
        "seeds_tracking": len(reached),
        "median_seconds_to_tracking": float(np.median(reached)) if len(reached) == len(runs) else None,
        "total_seconds": time.perf_counter() - start,
        "smoke": smoke,
    }


def save_run(
    out: Path, name: str, options: dict[str, Any], config: ppo.Config, state: ppo.TrainState, envs: int = 16
) -> None:
    """The first seed of the vmapped train `state` as a run directory that `mjzoo export` and
    `mjzoo sim2sim` read: task.json, config.json and a checkpoint of `envs` envs (config.json
    says so), megabytes rather than the 8192 envs' state. `options` are the joystick's
    (terrain, gait clock: what shapes its observation), as task.json records them. Its env
    states are fresh MJX-JAX ones, as the run's readers build the task: a Warp state also
    shares buffers across worlds, with no seed axis to take it from."""
    envs = min(envs, config.num_envs)
    small = dataclasses.replace(config, num_envs=envs)
    learner = jax.tree.map(lambda x: x[0], state.replace(collector=None))
    fresh = jax.jit(ppo.make(small).init)(
        mjzoo.envs.make(name, **{**options, "impl": "jax"}), learner.hyperparams, jax.random.key(0)
    )
    state = learner.replace(
        collector=fresh.collector,
        reward_scaling=dataclasses.replace(
            learner.reward_scaling, discounted_return=learner.reward_scaling.discounted_return[:envs]
        ),
    )
    checkpoints.save(out / "checkpoints", int(state.updates), state)
    info = {
        "algorithm": "ppo",
        "config": settings.config_dict(small),
        "hyperparams": settings.hyperparams_dict(state.hyperparams),
    }
    (out / "config.json").write_text(json.dumps(info, indent=2))
    overrides = {k: v for k, v in options.items() if k != "impl"}
    (out / "task.json").write_text(json.dumps({"env": name, "overrides": overrides}, indent=2))


def plot(rows: list[dict], path: Path) -> None:
    """Tracking errors against wall-clock minutes, a colour per row, labelled by robot,
    learner, physics, settings and seeds, the legend below the axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 5 + 0.22 * len(rows)))
    colors = plt.get_cmap("tab20").colors
    for n, row in enumerate(rows):
        what = [row["variant"], row.get("algorithm", "ppo"), f"({row.get('impl', 'jax')})", row_settings(row)]
        seeds = row["seeds"]
        which = f"seed {seeds[0]}" if len(seeds) == 1 else f"seeds {', '.join(map(str, seeds))} in one program"
        label = f"{' '.join(w for w in what if w)}, {which}"
        for i, run in enumerate(row["runs"]):
            t = [p["seconds"] / 60 for p in run["curve"]]
            for ax, key in zip(axes, ("linear_error", "yaw_error")):
                ax.plot(
                    t, [p[key] for p in run["curve"]], color=colors[n % len(colors)], label=label if i == 0 else None
                )
    for ax, key, unit in zip(axes, ("linear_error", "yaw_error"), ("m/s", "rad/s")):
        ax.axhline(GOAL[key], color="k", linestyle="--", linewidth=0.8)
        ax.set(
            xlabel="wall-clock minutes (compile included)",
            ylabel=f"mean {key.replace('_', ' ')} ({unit})",
            yscale="log",
        )
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.025 * -(-len(rows) // 2) + 0.03, 1, 1))  # room for the legend's rows
    fig.savefig(path, dpi=100)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variants", nargs="+", default=["go1:flat", "g1:flat", "t1:flat", "berkeley_humanoid:flat"])
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument(
        "--first-seed", type=int, default=0, help="seeds FIRST..FIRST+SEEDS-1 (beside an earlier run's)"
    )
    parser.add_argument("--steps", type=int, default=None, help="env steps per seed (default: the registered budget)")
    parser.add_argument("--evals", type=int, default=20)
    parser.add_argument("--eval-envs", type=int, default=64)
    parser.add_argument(
        "--budget", type=float, default=None, help="seconds per variant before it stops (default: 5 min flat, 15 rough)"
    )
    parser.add_argument(
        "--runs", type=Path, default=None, help="save the first seed's policy as a run in RUNS/<robot>_<terrain>"
    )
    parser.add_argument(
        "--impl", choices=physics.IMPLS, default=None, help="the physics (default: Warp where installed on a GPU)"
    )
    parser.add_argument(
        "--config",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="PPO fields over the robot's registered ones, e.g. lr_schedule=constant (a row of its own)",
    )
    parser.add_argument(
        "--task",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="the joystick's options, e.g. gait_frequency=1.375 (a row of its own)",
    )
    parser.add_argument(
        "--params",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="the joystick's named numbers (mjzoo.params), e.g. yaw_tracking_weight=1.0 (a row of its own)",
    )
    parser.add_argument(
        "--algorithm", choices=sorted(MODULES), default="ppo", help="the learner (off-policy: offpolicy.py's settings)"
    )
    parser.add_argument("--out", type=Path, default=OUT, help="the results' folder")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: checks the script runs, on a CPU")
    args = parser.parse_args()
    args.impl = args.impl or physics.default_impl()
    try:
        overrides = parse_assignments(tuple(args.config), "--config")
        if args.runs and args.algorithm != "ppo":
            raise UsageError("--runs keeps PPO runs only (an off-policy state carries its whole replay)")
        task_options = parse_assignments(tuple(args.task), "--task")
        task_params = parse_assignments(tuple(args.params), "--params")
        for variant in args.variants:  # a bad option, name or field: one line, now
            name = f"{variant.split(':')[0]}_joystick"
            mjzoo.envs.make(name, **task_options).with_params(**task_params)
            MODULES[args.algorithm].configure(**{**learner_fields(args.algorithm, name, False), **overrides})
    except (UsageError, ValueError, TypeError) as e:
        parser.error(str(e))
    except KeyError as e:
        parser.error(f"--params: {e.args[0]}")
    card = card_name() + ("_smoke" if args.smoke else "")
    path = args.out / f"robots_{card}.json"
    rows = json.loads(path.read_text())["rows"] if path.is_file() else []

    def report(row: dict) -> None:  # after every evaluation: a run stopped midway keeps its curve
        row["device"], row["impl"], row["config"] = jax.devices()[0].device_kind, args.impl, overrides
        row["task_options"], row["task_params"] = task_options, task_params
        chosen = ("config", "task_options", "task_params")
        key = lambda r: (  # noqa: E731
            r["variant"],
            r["seeds"],
            r.get("impl", "jax"),
            r.get("algorithm", "ppo"),
            *(r.get(k, {}) for k in chosen),
        )
        same = lambda r: key(r) == key(row)  # noqa: E731
        rows[:] = [r for r in rows if not same(r)] + [row]
        args.out.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"rows": rows}, indent=1) + "\n")

    for variant in args.variants:
        budget = args.budget or (300.0 if variant.endswith(":flat") else 900.0)
        row = train(
            variant,
            list(range(args.first_seed, args.first_seed + args.seeds)),
            args.steps,
            2 if args.smoke else args.evals,
            4 if args.smoke else args.eval_envs,
            args.smoke,
            budget,
            report,
            args.runs,
            args.impl,
            overrides,
            task_options,
            task_params,
            args.algorithm,
        )
        plot(rows, path.with_suffix(".png"))
        median = row["median_seconds_to_tracking"]
        print(
            f"{variant}: {row['seeds_tracking']}/{len(row['seeds'])} seeds track; median time to tracking "
            f"{'not reached by every seed' if median is None else f'{median:.0f} s'}; {path}",
            flush=True,
        )


if __name__ == "__main__":
    main()
