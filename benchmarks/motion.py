"""Human motion on the G1, one GPU: whole-body tracking (PPO), style (AMP) and tracking MPC.

Parts (``--parts``, default all), each from the G1's retargeted clips
(``envs/assets/motions/g1``, `mjzoo.motion.retarget`):

  walk  PPO on ``g1_track(clips="walk")``, ``--seeds`` (3) in one vmapped program, until
        every seed tracks: success >= 0.95 and MPJPE <= 50 mm. Goal: <= 3 min.
  all   PPO on ``g1_track`` (every committed clip), one seed, until every clip has
        success >= 0.90 (MPJPE reported). Goal: <= 15 min.
  amp   AMP on ``g1_amp_joystick``, one seed, until a deterministic episode keeps up
        (no fall), its style error (`robot_amp.style_error`) is below `STYLE_THRESHOLD`
        and its mean command error below 0.3 m/s.
  mpc   MPPI (and CEM) on ``g1_track(clips="walk")`` at ``--samples`` (1024) x 0.5 s,
        closed loop over the clip: replan latency and rate, MPJPE, whether it finished
        the clip standing (`mjzoo.planning.closed_loop`; the planner's model is the
        task's, its reward the tracking reward).

Training runs ``--evals`` chunks of updates (`lax.scan` of the algorithm's update, one
jit, seeds vmapped) up to the registered budget (or ``--steps``) or ``--budget`` seconds, each followed
by a deterministic evaluation in the same program. A tracking evaluation starts
``--eval-envs`` episodes per clip at start frames drawn uniformly over that clip (the
task's own start table with the other clips' rows zeroed) and runs each to the clip's
end: success is the share that got there without a termination, MPJPE (mm) the mean
over their steps. Times are wall-clock from the part's start, compile included.

    python benchmarks/motion.py                                   # everything, one H100/H200
    python benchmarks/motion.py --parts walk --seeds 3 --budget 300 --steps 40000000   # 2M-step chunks
    python benchmarks/motion.py --parts mpc --samples 256 1024
    python benchmarks/motion.py --smoke --parts walk amp mpc      # tiny sizes, on a CPU: checks the script

Results merge into ``benchmarks/results/motion/motion_<card>.json`` (``--out``) after every
evaluation (a part's re-run on the same physics, ``--impl``, replaces its entry).
"""

from __future__ import annotations

import argparse
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

import mjzoo  # noqa: E402
import mjzoo.envs  # noqa: E402
from mjzoo import names  # noqa: E402
from mjzoo import physics  # noqa: E402
from mjzoo import running  # noqa: E402
from mjzoo.algorithms import amp  # noqa: E402
from mjzoo.algorithms import cem  # noqa: E402
from mjzoo.algorithms import mppi  # noqa: E402
from mjzoo.algorithms import ppo  # noqa: E402
from mjzoo.catalog import commands  # noqa: E402
from mjzoo.envs import motion_tracking  # noqa: E402
from mjzoo.envs import robot_amp  # noqa: E402
from mjzoo.interop import tracking  # noqa: E402
from mjzoo.layers import find  # noqa: E402
from mjzoo.learning.actions import to_controls  # noqa: E402
from mjzoo.planning import closed_loop  # noqa: E402

OUT = Path(__file__).parent / "results" / "motion"
PARTS = ("walk", "all", "amp", "mpc")
WALK_GOAL = dict(success=0.95, mpjpe_mm=50.0)
ALL_GOAL = dict(success=0.90)
STYLE_THRESHOLD = 0.15  # rad, as the humanoid's (envs/humanoid_amp.py)
COMMAND_ERROR = 0.3  # m/s
SMOKE = dict(num_envs=8, unroll_length=4, num_minibatches=2, num_epochs=1, total_steps=64)
SMOKE_AMP = dict(SMOKE, disc_minibatches=2, replay_size=64)


# --- evaluation, inside the training program --------------------------------------------


def episodes(task: mjzoo.Task, act: Callable, keys: jax.Array, steps: int) -> dict[str, jax.Array]:
    """One episode per key of ``act(obs) -> action in [-1, 1]`` for `steps` steps (or to its
    end): per step [E, T], whether it was lived, ended by a termination, and its metrics;
    qpos [E, T, nq]; the command error (m/s) where the task has a velocity command."""

    address = tuple(int(a[0]) for a in names.free_joint_addresses(task.mj_model, None, "motion"))  # the base
    task = mjzoo.batching.sized(task, keys.shape[0])  # Warp: a contact pool for every episode

    def one(key):
        state = running.reset(task, jax.random.split(key)[0])

        def body(carry, key):
            state, done = carry
            after = running.transition(task, state, to_controls(task, act(state.obs)), key)
            lived = ~done
            out = {"lived": lived, "fell": lived & after.terminated, "qpos": state.data.qpos, **after.metrics}
            command = find(state, commands.VelocityCommandState, None)
            if command is not None:  # the base's planar velocity against the command, as robots.py measures it
                v_xy, _ = tracking.base_velocities(after.data.qpos, after.data.qvel, address)
                out["command_error"] = jnp.linalg.norm(v_xy - command.command[:2])
            return (after, done | after.terminated | after.truncated), out

        return jax.lax.scan(body, (state, jnp.zeros((), bool)), jax.random.split(jax.random.split(key)[1], steps))[1]

    return jax.vmap(one)(keys)


def per_clip_tasks(task: mjzoo.Task) -> list[mjzoo.Task]:
    """`task` with its starts drawn uniformly over one clip each (its start table's other
    rows zeroed)."""
    table = np.asarray(mjzoo.params(task)["start_probabilities"])
    out = []
    for c in range(table.shape[0]):
        only = np.zeros_like(table)
        only[c] = table[c] / table[c].sum()
        out.append(task.with_params(start_probabilities=jnp.asarray(only)))
    return out


def tracking_measure(task: mjzoo.Task, act: Callable, key: jax.Array, num_envs: int, steps: int) -> dict:
    """Per clip of `task`: success (share of episodes that reached the clip's end without a
    termination) and MPJPE (mm, mean over lived steps)."""
    out = {}
    for c, clip_task in enumerate(per_clip_tasks(task)):
        ep = episodes(clip_task, act, jax.random.split(jax.random.fold_in(key, c), num_envs), steps)
        lived = ep["lived"]
        out[f"success/{c}"] = 1.0 - ep["fell"].any(1).mean()
        out[f"mpjpe_mm/{c}"] = jnp.where(lived, ep["tracking/mpjpe_mm"], 0.0).sum() / jnp.maximum(lived.sum(), 1)
    return out


def amp_measure(task: mjzoo.Task, act: Callable, key: jax.Array, num_envs: int, steps: int) -> dict:
    """Falls, mean command error (m/s) over lived steps, and env 0's qpos [T, nq] (its style
    error is measured on the host)."""
    ep = episodes(task, act, jax.random.split(key, num_envs), steps)
    lived = ep["lived"]
    return {
        "falls": ep["fell"].any(1).sum(),
        "command_error": jnp.where(lived, ep["command_error"], 0.0).sum() / jnp.maximum(lived.sum(), 1),
        "qpos": ep["qpos"][0],
        "fell0": ep["fell"][0].any(),
    }


# --- training until the goal --------------------------------------------------------------


def train(
    name: str,
    module: Any,
    task: mjzoo.Task,
    fields: dict[str, Any],
    seeds: list[int],
    evals: int,
    budget: float,
    measure: Callable[[Callable, jax.Array], dict],
    judge: Callable[[dict], dict],
    report: Callable[[dict], None],
    reference: Any = None,
) -> dict:
    """Every seed in one vmapped program: chunks of updates, each followed by `measure`
    (of the deterministic policy); `judge(point)` adds the goal's verdict ("reached") to
    a seed's point on the host. Stops when every seed reached it or after `budget` s."""
    start = time.perf_counter()
    config, hyperparams = module.configure(**fields)
    algorithm = module.make(config, reference) if reference is not None else module.make(config)
    per_chunk = max(1, config.num_updates // evals)

    def chunk(state, key):
        state, _ = jax.lax.scan(lambda s, _: algorithm.update(task, s), state, None, length=per_chunk)
        if module is amp:
            act_fn, params = amp.policy(config, task), amp.policy_params(state)
        else:
            act_fn, params = ppo.policy(config, task), ppo.policy_params(state)
        return state, measure(lambda obs: act_fn(params, obs, jax.random.key(0)), key)

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
            point = judge({k: np.asarray(v[s]) for k, v in measured.items()})
            curves[s].append({"step": (i + 1) * per_chunk * config.steps_per_update, "seconds": seconds, **point})
        print(f"  {name} step {curves[0][-1]['step']:,} {seconds:.0f} s: " + " | ".join(_brief(c[-1]) for c in curves))
        row = summarize(name, fields, seeds, curves, start)
        report(row)
        if all(c[-1]["reached"] for c in curves) or seconds > budget:
            break
    return row


def _brief(point: dict) -> str:
    return ", ".join(f"{k} {v:.3g}" for k, v in point.items() if isinstance(v, float) and k not in ("seconds",))


def summarize(name: str, fields: dict, seeds: list[int], curves: list[list[dict]], start: float) -> dict:
    runs = []
    for seed, curve in zip(seeds, curves):
        reached = next((p for p in curve if p["reached"]), None)
        runs.append(
            {
                "seed": seed,
                "curve": curve,
                "seconds_to_goal": None if reached is None else reached["seconds"],
                "steps_to_goal": None if reached is None else reached["step"],
                "final": curve[-1],
            }
        )
    times = [r["seconds_to_goal"] for r in runs]
    return {
        "part": name,
        "hyperparameters": {k: (list(v) if isinstance(v, tuple) else v) for k, v in fields.items()},
        "seeds": seeds,
        "runs": runs,
        "seeds_reaching_goal": sum(t is not None for t in times),
        "median_seconds_to_goal": float(np.median(times)) if None not in times else None,
        "total_seconds": time.perf_counter() - start,
    }


def tracking_judge(clips: tuple[str, ...], goal: dict) -> Callable[[dict], dict]:
    def judge(point: dict) -> dict:
        out = {}
        for c, clip in enumerate(clips):
            out[f"{clip}/success"] = float(point[f"success/{c}"])
            out[f"{clip}/mpjpe_mm"] = float(point[f"mpjpe_mm/{c}"])
        out["reached"] = all(
            out[f"{clip}/success"] >= goal["success"] and out[f"{clip}/mpjpe_mm"] <= goal.get("mpjpe_mm", np.inf)
            for clip in clips
        )
        return out

    return judge


def amp_judge(reference: mjzoo.motion.Reference) -> Callable[[dict], dict]:
    def judge(point: dict) -> dict:
        style = robot_amp.style_error(reference, point["qpos"])
        out = {
            "style_error": float(style),
            "command_error": float(point["command_error"]),
            "falls": float(point["falls"]),
        }
        out["reached"] = bool(not point["fell0"] and style < STYLE_THRESHOLD and out["command_error"] < COMMAND_ERROR)
        return out

    return judge


# --- the parts ------------------------------------------------------------------------------


def tracking_part(name: str, clips: str | None, args, report) -> dict:
    overrides = {} if clips is None else {"clips": clips}
    task = mjzoo.envs.make("g1_track", impl=args.impl, **overrides)
    names = motion_tracking.G1_CLIPS if clips is None else tuple(clips.split(","))  # the start table's rows
    fields = {**mjzoo.envs.hyperparameters("g1_track", "ppo"), **_steps(args), **(SMOKE if args.smoke else {})}
    steps = 10 if args.smoke else running.episode_steps(task)
    seeds = list(range(args.seeds if name == "walk" else 1))

    def measure(act, key):
        return tracking_measure(task, act, key, args.eval_envs, steps)

    goal = WALK_GOAL if name == "walk" else ALL_GOAL
    budget = args.budget or (180.0 if name == "walk" else 900.0)
    return train(name, ppo, task, fields, seeds, args.evals, budget, measure, tracking_judge(names, goal), report)


def _steps(args) -> dict:
    """The training budget's override: ``--steps`` sets the chunk between evaluations
    (steps / evals), the resolution of a time to the goal."""
    return {"total_steps": args.steps} if args.steps else {}


def amp_part(args, report) -> dict:
    task = mjzoo.envs.make("g1_amp_joystick", impl=args.impl)
    reference = mjzoo.envs.reference("g1_amp_joystick", task)
    fields = {
        **mjzoo.envs.hyperparameters("g1_amp_joystick", "amp"),
        **_steps(args),
        **(SMOKE_AMP if args.smoke else {}),
    }
    steps = 10 if args.smoke else running.episode_steps(task)

    def measure(act, key):
        return amp_measure(task, act, key, args.eval_envs, steps)

    budget = args.budget or 900.0
    return train("amp", amp, task, fields, [0], args.evals, budget, measure, amp_judge(reference), report, reference)


def mpc_part(args, report) -> dict:
    """Closed-loop MPPI and CEM on the walk clip: the simulation is the task, the planner
    plans on the same task (its reward: the tracking reward)."""
    task = mjzoo.envs.make("g1_track", clips="walk", impl=args.impl)
    clip_task = per_clip_tasks(task)[0].with_params(start_probabilities=_first_bin(task))
    (walk,) = motion_tracking.g1_clips(("walk",))
    steps = 10 if args.smoke else round((walk.qpos.shape[0] - 1) / walk.fps / 0.02)  # replans, one per 0.02 s step
    start_state = running.reset(clip_task, jax.random.key(0))  # the clip's first frame
    rows = []
    for module in (mppi, cem):
        for samples in [8] if args.smoke else args.samples:
            fields = dict(num_samples=samples, horizon_steps=4 if args.smoke else 25, num_knots=4)
            if module is cem:
                fields["num_elites"] = mjzoo.envs.base.elite_count(samples)
            config, hyperparams = mjzoo.planning.configure(module, fields)
            run = jax.jit(
                lambda key, hp, module=module, config=config: closed_loop.run(
                    module, config, clip_task, clip_task, start_state, key, steps, hyperparams=hp
                )
            )
            start = time.perf_counter()
            result = jax.block_until_ready(run(jax.random.key(0), hyperparams))
            compiled = time.perf_counter() - start
            start = time.perf_counter()
            result = jax.block_until_ready(run(jax.random.key(1), hyperparams))
            seconds = time.perf_counter() - start
            states = result.states
            mpjpe = np.asarray(states.metrics["tracking/mpjpe_mm"])
            fell = np.asarray(states.terminated)
            lived = ~np.concatenate([[False], np.cumsum(fell)[:-1] > 0])
            row = {
                "planner": module.__name__.rsplit(".", 1)[-1],
                "num_samples": samples,
                "horizon_s": fields["horizon_steps"] * 0.02,
                "replan_hz": steps / seconds,
                "replan_ms": 1000 * seconds / steps,
                "compile_s": compiled,
                "mpjpe_mm": float(mpjpe[lived].mean()),
                "fell": bool(fell.any()),
                "steps": steps,
            }
            print(f"  mpc {row['planner']} {samples}: {row['replan_hz']:.1f} Hz, MPJPE {row['mpjpe_mm']:.1f} mm")
            rows.append(row)
            report({"part": "mpc", "rows": rows})
    return {"part": "mpc", "rows": rows}


def _first_bin(task: mjzoo.Task) -> jax.Array:
    table = np.zeros_like(np.asarray(mjzoo.params(task)["start_probabilities"]))
    table[0, 0] = 1.0
    return jnp.asarray(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", nargs="+", default=list(PARTS), choices=PARTS)
    parser.add_argument("--seeds", type=int, default=3, help="seeds of the walk's tracking (the others: 1)")
    parser.add_argument("--evals", type=int, default=20)
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help="env steps per seed (default: the registered budget); chunks are steps/evals",
    )
    parser.add_argument("--eval-envs", type=int, default=64)
    parser.add_argument("--budget", type=float, default=None, help="seconds per part (default: its goal)")
    parser.add_argument("--samples", type=int, nargs="+", default=[1024], help="the MPC's sample counts")
    parser.add_argument(
        "--impl", choices=physics.IMPLS, default=None, help="the physics (default: Warp where installed on a GPU)"
    )
    parser.add_argument("--out", type=Path, default=OUT, help="the results' folder")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: checks the script runs, on a CPU")
    args = parser.parse_args()
    args.impl = args.impl or physics.default_impl()
    card = card_name() + ("_smoke" if args.smoke else "")
    path = args.out / f"motion_{card}.json"
    rows = json.loads(path.read_text())["rows"] if path.is_file() else []

    def report(row: dict) -> None:
        row["device"], row["impl"] = jax.devices()[0].device_kind, args.impl
        same = lambda r: (r["part"], r.get("impl", "jax")) == (row["part"], args.impl)  # noqa: E731
        rows[:] = [r for r in rows if not same(r)] + [row]
        args.out.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"rows": rows}, indent=1, default=float) + "\n")

    for part in args.parts:
        print(f"{part}:", flush=True)
        if part in ("walk", "all"):
            tracking_part(part, "walk" if part == "walk" else None, args, report)
        elif part == "amp":
            amp_part(args, report)
        else:
            mpc_part(args, report)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
