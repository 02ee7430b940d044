"""PPO on the locomotion tasks, on one GPU: `ant`, `humanoid_walk` and the ant joystick.

Per task, in one process: (a) raw batched `mjx.step` of the task's physics at PPO's number
of envs (the physical limit), (b) PPO with the env's registered hyperparameters
(`mjzoo.envs.hyperparameters(name, "ppo")`, after Brax's / Playground's), its curves,
metrics and evaluation video under ``--out/<task>/``, (c) a final deterministic
evaluation of 256 envs over one full episode, with the task's own measure:

  ant            return; forward speed of the centre of mass (m/s). Running: a return
                 >= 3000, which under the task's reward (alive 1 + speed - effort per
                 step) takes at least 2 m/s over a full 1000-step episode (faster
                 over a shorter one).
  humanoid_walk  return; forward speed; the fraction of episodes that never fall.
                 Walking: every episode lasts its 1000 steps (15 s) at >= 1 m/s, which
                 under the task's reward (alive 5 + 1.25 x speed - effort per step)
                 means a return >= 6000 (standing still earns at most 5000).
  ant_joystick   trained through `joystick_curriculum()`; evaluated at level 1 (the
                 hardest pushes and noise): mean |v_xy - command_xy| (m/s, base frame)
                 over the steps before any fall, and the fraction of falls. Tracking:
                 the training evaluation (level 0) returns >= 1000 over its 500 steps
                 (standing still earns about 250).

Time to the stated return is wall-clock from the start of training (compile included).

Each task runs on every physics implementation of ``--impl`` (MJX-JAX, MuJoCo Warp), one
after the other in this process; a run's files go under ``--out/<task>/`` on JAX (as
before) and ``--out/<task>_warp/`` on Warp. JSON: ``rows`` holds one row per (task,
impl), its ``"impl"`` naming the physics, with the old keys' meanings (old files,
without ``"impl"``, are JAX) plus ``fraction_of_raw`` (PPO's steps/s over raw
stepping's), ``first_update_s`` (wall-clock from the start of training to its first
metrics record: setup, compile, one chunk of updates and its evaluation) and, for the
process's first run only, ``launch_to_first_update_s`` (from the process's start,
imports included; later runs find JAX and Warp warm). ``warp_vs_jax`` holds, per task
run on both, Warp's figure over JAX's for raw and PPO steps/s, time to the stated
return and train time.
Where the machine has no video encoder (the GPU image lacks ffmpeg), `--no-video` saves
each final episode as .npz and `--render` makes the videos elsewhere.

    python benchmarks/locomotion.py --tasks ant --steps 100000000
    python benchmarks/locomotion.py --tasks humanoid_walk --steps 45000000
    python benchmarks/locomotion.py --tasks ant_joystick --steps 40000000
    python benchmarks/locomotion.py --tasks humanoid_walk --steps 36000000 --impl warp jax --no-final-eval
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import os
import sys
import time
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from ppo_vs_brax import time_to  # noqa: E402
from ppo_vs_brax import training_curve  # noqa: E402
from task_overhead import add_impl_argument  # noqa: E402
from task_overhead import impls  # noqa: E402
from task_overhead import inputs  # noqa: E402
from task_overhead import ratio  # noqa: E402
from task_overhead import raw_steps_per_s  # noqa: E402

import mjzoo  # noqa: E402
import mjzoo.envs  # noqa: E402
from mjzoo.algorithms import ppo  # noqa: E402
from mjzoo.catalog import commands  # noqa: E402
from mjzoo.catalog import observations  # noqa: E402
from mjzoo.envs import joystick  # noqa: E402
from mjzoo.harness import rendering  # noqa: E402
from mjzoo.harness import training  # noqa: E402


@dataclasses.dataclass(frozen=True)
class Spec:
    train_task: Callable[[str], mjzoo.Task]  # impl -> task
    eval_task: Callable[[str], mjzoo.Task]
    threshold: float  # the stated return


SPECS = {
    "ant": Spec(lambda impl: mjzoo.envs.make("ant", impl=impl), lambda impl: mjzoo.envs.make("ant", impl=impl), 3000.0),
    "humanoid_walk": Spec(
        lambda impl: mjzoo.envs.make("humanoid_walk", impl=impl),
        lambda impl: mjzoo.envs.make("humanoid_walk", impl=impl),
        6000.0,
    ),
    "ant_joystick": Spec(
        lambda impl: joystick.joystick_curriculum(impl=impl),
        lambda impl: mjzoo.envs.make("ant_joystick", level=1.0, impl=impl),
        1000.0,
    ),
}


@functools.partial(jax.jit, static_argnums=(0, 4, 5))
def episode_measures(config: ppo.Config, task: mjzoo.Task, train_state, key, num_envs: int, num_steps: int) -> dict:
    """Deterministic first episodes of `num_envs` envs, each measure [num_envs]: return,
    length (steps), forward distance of the centre of mass (m), velocity-command error
    (m/s; 0 where the task has no command), whether it fell, and qpos [num_envs, T, nq]
    (for the video). One compile per task structure."""
    act, params = ppo.policy(config, task), ppo.policy_params(train_state)
    velocity = observations.base_linear_velocity(task.mj_model)
    task = mjzoo.batching.sized(task, num_envs)  # Warp: a contact pool for every env

    def one(key):
        state = mjzoo.reset(task, key)

        def body(carry, key):
            state, alive = carry
            next_state = mjzoo.transition(task, state, act(params, state.obs, key), key)
            command = getattr(mjzoo.find(state, commands.VelocityCommandState, None), "command", jnp.zeros(3))
            error = jnp.linalg.norm(velocity(task.model, next_state)[:2] - command[:2])
            out = dict(
                reward=next_state.reward * alive,
                alive=alive,
                error=error * alive,
                com=next_state.data.subtree_com[1, 0],
                fell=next_state.terminated & alive,
                qpos=next_state.data.qpos,
            )
            return (next_state, alive & ~(next_state.terminated | next_state.truncated)), out

        start = state.data.subtree_com[1, 0]
        _, out = jax.lax.scan(body, (state, jnp.ones((), bool)), jax.random.split(key, num_steps))
        steps = jnp.sum(out["alive"])
        last = out["com"][jnp.maximum(steps - 1, 0).astype(jnp.int32)]
        return dict(
            ret=jnp.sum(out["reward"]),
            length=steps,
            distance=last - start,
            error=jnp.sum(out["error"]) / steps,
            fell=jnp.any(out["fell"]),
            qpos=out["qpos"],
        )

    return jax.vmap(one)(jax.random.split(key, num_envs))


def evaluate(config: ppo.Config, task: mjzoo.Task, train_state, num_envs: int, num_steps: int):
    """The means of `episode_measures` over `num_envs` envs (speed in m/s), and the first
    env's qpos [T, nq] (its episode runs on after an end: it is the video)."""
    result = jax.device_get(episode_measures(config, task, train_state, jax.random.key(123), num_envs, num_steps))
    speed = result["distance"] / (result["length"] * mjzoo.control_dt(task))
    means = {
        "return": float(np.mean(result["ret"])),
        "length": float(np.mean(result["length"])),
        "forward_speed_m_s": float(np.mean(speed)),
        "velocity_error_m_s": float(np.mean(result["error"])),
        "fell_fraction": float(np.mean(result["fell"])),
    }
    return means, np.asarray(result["qpos"][0])


def render(task: mjzoo.Task, qpos: np.ndarray, path: Path) -> None:
    """The video of an episode's qpos [T, nq] of `task` at its control rate."""
    config = rendering.with_model_camera(rendering.RenderConfig(), task.mj_model)
    if rendering.render_video(task.mj_model, qpos, path, dt=mjzoo.control_dt(task), config=config) is not None:
        print(f"wrote {path}")  # else rendering said why not


def render_saved(out: Path) -> None:
    """Videos of the final episodes saved under `out`/<task>/final_policy.npz."""
    for saved in sorted(out.glob("*/final_policy.npz")):
        name = saved.parent.name.split("_seed")[0].removesuffix("_warp")  # rendered by C MuJoCo either way
        render(SPECS[name].eval_task("jax"), np.load(saved)["qpos"], saved.with_suffix(".mp4"))


def launch_seconds() -> float:
    """Seconds since this process started (Linux: /proc), imports included."""
    start_ticks = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
    uptime = float(Path("/proc/uptime").read_text().split()[0])
    return uptime - start_ticks / os.sysconf("SC_CLK_TCK")


def run_task(
    name: str,
    total_steps: int | None,
    out: Path,
    eval_envs: int,
    smoke: bool,
    video: bool,
    impl: str = "jax",
    final_eval: bool = True,
    first_in_process: bool = False,
    seed: int = 0,
) -> dict:
    spec = SPECS[name]
    run_dir = out / (name + ("" if impl == "jax" else f"_{impl}") + (f"_seed{seed}" if seed else ""))
    fields = mjzoo.envs.hyperparameters(name, "ppo")
    if total_steps:
        fields["total_steps"] = total_steps
    if smoke:  # two updates of 8 envs; 50-step evaluations
        fields.update(num_envs=8, unroll_length=8, num_minibatches=4, num_epochs=1, total_steps=128)
        eval_envs = min(eval_envs, 8)
    config, hyperparams = ppo.configure(**fields)
    episode = 50 if smoke else mjzoo.envs.defaults(name)["episode_steps"]
    # Training first: launch-to-first-update counts from the process start to its first record.
    # Every chunk evaluates (not the default 5% budget), to time the stated return.
    settings = training.Settings(
        out_dir=run_dir,
        updates_per_chunk=1 if smoke else 10,
        eval_envs=16 if smoke else 128,
        eval_steps=episode,
        checkpoint_every=0,
        eval_every=1,
        video=video,
        overwrite=True,
        seed=seed,
    )  # a new measurement replaces the last
    launched = launch_seconds()
    start = time.perf_counter()
    train_state, _ = training.run(ppo.make(config), spec.train_task(impl), settings, hyperparams)
    total = time.perf_counter() - start
    curve, steps_per_s = training_curve(run_dir / "metrics.jsonl", total)
    eval_task = spec.eval_task(impl)
    raw = raw_steps_per_s(eval_task, name, *inputs(eval_task, config.num_envs, 20 if smoke else 100), repeats=3)
    print(f"{name} ({impl}): raw stepping {raw:,.0f} steps/s at {config.num_envs} envs", flush=True)
    row = {
        "task": name,
        "impl": impl,
        "seed": seed,
        "config": training.config_dict(config),
        "hyperparams": training.hyperparams_dict(hyperparams),
        "raw_steps_per_s": raw,
        "steps_per_s": steps_per_s,
        "fraction_of_raw": steps_per_s / raw,
        "train_s": total,
        "threshold": spec.threshold,
        "time_to_threshold_s": time_to(curve, spec.threshold),
        "first_update_s": curve[0][1],
        "launch_to_first_update_s": launched + curve[0][1] if first_in_process else None,
        "curve": curve,
    }
    # Kept before evaluating: compiling the evaluation takes minutes on a GPU.
    (run_dir / "training.json").write_text(json.dumps(row, indent=2))
    if not final_eval:
        return row
    row["final"], qpos = evaluate(config, eval_task, train_state, eval_envs, episode)
    # The task as evaluated (the joystick: at level 1); --render makes the video elsewhere.
    np.savez_compressed(run_dir / "final_policy.npz", qpos=qpos)
    if video:
        render(eval_task, qpos, run_dir / "final_policy.mp4")
    return row


def warp_vs_jax(name: str, warp: dict, jax_: dict) -> dict:
    """Warp's figures over JAX's for one task (None where either never got there)."""
    keys = ("raw_steps_per_s", "steps_per_s", "time_to_threshold_s", "train_s", "first_update_s")
    return {"task": name, **{k: ratio(warp[k], jax_[k]) for k in keys}}


def summary(row: dict) -> str:
    ttt, f = row["time_to_threshold_s"], row.get("final")
    line = (
        f"{row['task']} ({row['impl']}): {row['steps_per_s']:,.0f} steps/s ({row['fraction_of_raw']:.2f} of raw), "
        f"threshold {row['threshold']:.0f} at {'never' if ttt is None else f'{ttt:.1f} s'} (compile included), "
        f"first update at {row['first_update_s']:.1f} s"
        + (f" ({row['launch_to_first_update_s']:.1f} s from launch)" if row["launch_to_first_update_s"] else "")
        + f", trained {row['train_s']:.0f} s, last eval return {row['curve'][-1][2]:.1f}"
    )
    if f:
        line += (
            f"; final return {f['return']:.1f}, speed {f['forward_speed_m_s']:.2f} m/s, velocity error "
            f"{f['velocity_error_m_s']:.3f} m/s, fell {f['fell_fraction']:.2f}, length {f['length']:.0f}"
        )
    return line


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", nargs="*", default=list(SPECS), choices=list(SPECS))
    parser.add_argument("--steps", type=int, default=None, help="env steps per task (default: the registered ones)")
    parser.add_argument("--eval-envs", type=int, default=256)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "locomotion")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes, to check the script on a CPU")
    parser.add_argument("--no-video", action="store_true", help="save the final episodes, render them later")
    parser.add_argument("--render", action="store_true", help="only render the saved final episodes under --out")
    parser.add_argument(
        "--no-final-eval", action="store_true", help="skip (c), the final evaluation (minutes to compile)"
    )
    parser.add_argument("--tag", default="", help="suffix of the JSON file")
    parser.add_argument("--seed", type=int, default=0, help="training seed (not 0: named in the run directories)")
    add_impl_argument(parser)
    args = parser.parse_args()
    if args.render:
        return render_saved(args.out)
    device = jax.devices()[0].device_kind
    print(f"device: {device}, jax {jax.__version__}", flush=True)
    rows, ratios = [], []
    args.out.mkdir(parents=True, exist_ok=True)
    tag = "_".join(args.tasks) + (f"_{args.tag}" if args.tag else "") + (f"_seed{args.seed}" if args.seed else "")
    path = args.out / f"locomotion_{jax.default_backend()}_{tag}.json"
    for name in args.tasks:
        by_impl = {}
        for impl in impls(args.impl):
            row = run_task(
                name,
                args.steps,
                args.out,
                args.eval_envs,
                args.smoke,
                not args.no_video,
                impl,
                final_eval=not args.no_final_eval,
                first_in_process=not rows,
                seed=args.seed,
            )
            rows.append(by_impl.setdefault(impl, row))
            print(summary(row), flush=True)
            if len(by_impl) == 2:
                ratios.append(warp_vs_jax(name, by_impl["warp"], by_impl["jax"]))
                print(
                    f"{name}: warp/jax "
                    + ", ".join(f"{k} {v:.2f}x" for k, v in ratios[-1].items() if k != "task" and v)
                )
            path.write_text(
                json.dumps({"device": device, "jax": jax.__version__, "rows": rows, "warp_vs_jax": ratios}, indent=2)
            )
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
    os._exit(0)  # Warp on a CPU may hang at interpreter exit
