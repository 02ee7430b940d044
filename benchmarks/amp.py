"""AMP on Brax's humanoid, one GPU: does it learn to walk in the teacher's style, how fast, at what cost?

In one process, at AMP's batch (`humanoid_amp.AMP`: 2048 envs, unrolls of 160):

  (a) raw batched `mjx.step` of the humanoid's physics (the physical limit);
  (b) PPO on `humanoid_walk`'s task reward (forward speed, alive, effort), its
      registered hyperparameters: the walk a reward engineer gets;
  (c) AMP on `humanoid_amp_walk` (alive and effort, no forward speed; the style reward
      of the teacher's walk does the rest).

Each trains through the shared harness (`training.run` of `ppo.make` / `amp.make`,
a call each), which evaluates the deterministic policy after every chunk of updates; env 0's
episode of each evaluation is kept (a host callback) and measured after training, off
the clock: the style error of its steps 200-1000 (`humanoid_amp.style_error`: mean
hinge-angle error to the nearest 10-frame reference window, rad; the reference was cut
from step 200 of the teacher's episode, past its start from rest), its forward speed,
whether it fell. It walks in the teacher's style (`humanoid_amp.walks_like_teacher`)
when it lasts its 1000 steps, errs less than 0.15 rad and moves at >= 1 m/s. Reported:
steps/s of each and AMP's overhead over PPO (time per step; goal <= 15%), wall-clock
time (compile included) until AMP's episode first walks in style, the style error and
speed of AMP, of PPO and of the teacher (its other 7 episodes, when
``--teacher-episodes`` is given; else the numbers measured on them once, below), final
returns (each on its own task's reward), and the final episodes as video (or .npz with
``--no-video``; ``--render`` makes the videos elsewhere).

    python benchmarks/amp.py                   # AMP 32.8M steps, PPO 16.4M: about 8.6 minutes on an H100
    python benchmarks/amp.py --steps 60000000  # about 10.5 minutes
    python benchmarks/amp.py --quick --no-video  # tiny, on a CPU: checks the script (13 min on 2 busy cores)

Measured on an H100 (AMP 42.6M steps, PPO 22.9M; 9.6 minutes in all): raw 536k steps/s;
PPO 350k (0.65 of raw), AMP 337k (0.63): AMP costs 3.7% over PPO. AMP's episode walked
in the teacher's style at 16.4M steps, 211 s after training started (about 150 s of
it compiling), in both of two runs; its final style error 0.032 rad at 1.88 m/s (the
teacher: 0.033 rad, 1.95 m/s). PPO on the task reward at 22.9M steps: 0.26 rad, and it
still fell (return 4564; it walks from ~33M steps, benchmarks/locomotion.py). Steps run
in whole chunks of 10 updates (3.3M steps), so a run does up to a chunk more than asked.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

if "--quick" in sys.argv:  # XLA's backend optimizations triple MJX compiles on a CPU
    flags = [os.environ.get("XLA_FLAGS"), "--xla_backend_optimization_level=0"]
    os.environ["XLA_FLAGS"] = " ".join(filter(None, flags))

import jax  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from ppo_vs_brax import training_curve  # noqa: E402
from task_overhead import inputs  # noqa: E402
from task_overhead import raw_steps_per_s  # noqa: E402

import mjzoo  # noqa: E402
import mjzoo.envs  # noqa: E402
from mjzoo import learning  # noqa: E402
from mjzoo import motion  # noqa: E402
from mjzoo.algorithms import amp  # noqa: E402
from mjzoo.algorithms import ppo  # noqa: E402
from mjzoo.envs import humanoid_amp  # noqa: E402
from mjzoo.harness import rendering  # noqa: E402
from mjzoo.harness import training  # noqa: E402

STYLE_FROM = 200  # steps: the style is that of the steady walk (the reference starts there too)
# The teacher's 7 episodes other than the reference's, measured as above (steps 200-1000).
TEACHER = {
    "style_error": 0.0331,
    "style_error_range": [0.0310, 0.0345],
    "forward_speed_m_s": 1.948,
    "fell": False,
    "source": "the teacher's episodes 1-7 (walk_episodes.npz)",
}
QUICK = dict(num_envs=8, unroll_length=8, num_minibatches=4, num_epochs=1, disc_minibatches=2, replay_size=256)


# --- keeping each evaluation's episode ----------------------------------------------------


def recording(algorithm: learning.Algorithm, episodes: list) -> learning.Algorithm:
    """`algorithm` whose `evaluate` also hands env 0's episode to the host: appends
    ``(qpos [T, nq], terminated [T], truncated [T])`` to `episodes` once per evaluation
    (`jax.debug.callback`: a copy of 100 kB, nothing computed on the host meanwhile)."""

    def keep(qpos, terminated, truncated):
        episodes.append((np.asarray(qpos), np.asarray(terminated), np.asarray(truncated)))

    def evaluate(task, state, key, num_envs, num_steps):
        evaluation = algorithm.evaluate(task, state, key, num_envs, num_steps)
        after = evaluation.trajectory.next_state
        jax.debug.callback(keep, after.data.qpos, after.terminated, after.truncated)
        return evaluation

    return algorithm._replace(evaluate=evaluate)


def measure_episode(
    reference: motion.Reference, qpos: np.ndarray, terminated: np.ndarray, truncated: np.ndarray
) -> dict:
    """Style error (steps `STYLE_FROM`.. of the first episode), forward speed, length,
    fall and whether it walks in the teacher's style, of one recorded episode."""
    done = np.flatnonzero(terminated | truncated)
    length = int(done[0]) + 1 if done.size else len(qpos)
    fell = bool(done.size and terminated[done[0]])
    steady = qpos[min(STYLE_FROM, max(length - humanoid_amp.STYLE_WINDOW, 0)) : length]
    error = humanoid_amp.style_error(reference, steady, window=min(humanoid_amp.STYLE_WINDOW, len(steady)))
    speed = humanoid_amp.forward_speed(steady, float(reference.dt)) if len(steady) > 1 else float("nan")
    whole = length == len(qpos) and humanoid_amp.walks_like_teacher(error, speed, fell)
    return {
        "style_error": error,
        "forward_speed_m_s": speed,
        "length": length,
        "fell": fell,
        "walks_like_teacher": whole,
    }


# --- one trainer ------------------------------------------------------------------------


def train(
    label: str,
    algorithm: learning.Algorithm,
    hyperparams,
    task: mjzoo.Task,
    reference: motion.Reference,
    out: Path,
    quick: bool,
    video: bool,
) -> dict:
    """Trains `algorithm` on `task` through the harness, evaluating every chunk; the row of
    results, with the final episode saved under `out`/`label`/."""
    episodes: list = []
    settings = training.Settings(
        out_dir=out / label,
        updates_per_chunk=1 if quick else 10,
        eval_envs=2 if quick else 16,
        eval_steps=50 if quick else 1000,
        checkpoint_every=0,
        eval_every=1,  # every chunk, to time the first walk in style: not the default budget
        video=False,
        overwrite=True,
        progress=False,
    )
    start = time.perf_counter()
    training.run(recording(algorithm, episodes), task, settings, hyperparams)
    total = time.perf_counter() - start
    curve, steps_per_s = training_curve(out / label / "metrics.jsonl", total)
    measured = [measure_episode(reference, *episode) for episode in episodes]  # one per chunk, in order
    points = [
        {"step": step, "elapsed_s": seconds, "eval_return": ret, **m}
        for (step, seconds, ret), m in zip(curve, measured)
    ]
    first = next((p for p in points if p["walks_like_teacher"]), None)
    qpos = episodes[-1][0]
    np.savez_compressed(out / label / "final_policy.npz", qpos=qpos, dt=float(reference.dt))
    if video:
        render(task, qpos, out / label / "final_policy.mp4", float(reference.dt))
    last = measured[-1]
    print(
        f"{label}: {steps_per_s:,.0f} steps/s, final return {curve[-1][2]:.1f}, style {last['style_error']:.3f} rad, "
        f"speed {last['forward_speed_m_s']:.2f} m/s, trained {total:.0f} s",
        flush=True,
    )
    return {
        "config": training.config_dict(algorithm.config),
        "hyperparams": training.hyperparams_dict(hyperparams),
        "steps_per_s": steps_per_s,
        "train_s": total,
        "compile_s": curve[0][1] - settings.updates_per_chunk * algorithm.steps_per_update / steps_per_s,
        "time_to_style_s": first and first["elapsed_s"],
        "steps_to_style": first and first["step"],
        "final": points[-1],
        "curve": points,
    }


def render(task: mjzoo.Task, qpos: np.ndarray, path: Path, dt: float) -> None:
    """The video of an episode's qpos [T, nq] at the task's control rate."""
    config = rendering.with_model_camera(rendering.RenderConfig(), task.mj_model)
    rendering.render_video(task.mj_model, qpos, path, dt=dt, config=config)
    print(f"wrote {path}")


def teacher(reference: motion.Reference, path: Path | None) -> dict:
    """The teacher's style measures: from its episodes file ([E, T, nq] qpos; the
    reference was cut from episode 0, so 1.. are measured), else `TEACHER`."""
    if path is None:
        return TEACHER
    qpos = np.load(path)["qpos"]
    done = np.zeros(qpos.shape[1], bool)
    rows = [measure_episode(reference, q, done, done) for q in qpos[1:]]
    errors = [r["style_error"] for r in rows]
    return {
        "style_error": float(np.mean(errors)),
        "style_error_range": [min(errors), max(errors)],
        "forward_speed_m_s": float(np.mean([r["forward_speed_m_s"] for r in rows])),
        "fell": False,
        "source": str(path),
    }


# --- the run --------------------------------------------------------------------------------


def configs(steps: int, ppo_steps: int, quick: bool) -> tuple[tuple, tuple]:
    """PPO's registered humanoid_walk hyperparameters and AMP's `humanoid_amp.AMP`, at AMP's
    number of envs (the same batch for both), each for its number of env steps: each a
    (Config, Hyperparams) pair."""
    ppo_fields = dict(mjzoo.envs.hyperparameters("humanoid_walk", "ppo"), total_steps=ppo_steps)
    amp_fields = dict(humanoid_amp.AMP, total_steps=steps)
    ppo_fields["num_envs"] = amp_fields["num_envs"]
    if quick:  # two updates of 8 envs
        ppo_fields.update({k: v for k, v in QUICK.items() if k in ppo_fields}, total_steps=128)
        amp_fields.update(QUICK, total_steps=128)
    return ppo.configure(**ppo_fields), amp.configure(**amp_fields)


def print_table(result: dict) -> None:
    names = {"ppo": "PPO (task reward)", "amp": "AMP (style)"}
    rows = [(name, result[key]) for key, name in names.items() if key in result]
    print(
        f"\n{'trainer':<18} {'steps/s':>11} {'/raw':>6} {'to style (s)':>12} {'style (rad)':>11} {'speed':>6} "
        f"{'length':>6} {'return':>8} {'compile s':>9}"
    )
    for name, r in rows:
        f, ttt = r["final"], r["time_to_style_s"]
        print(
            f"{name:<18} {r['steps_per_s']:>11,.0f} {r['steps_per_s'] / result['raw_steps_per_s']:>6.2f} "
            f"{'never' if ttt is None else f'{ttt:.1f}':>12} {f['style_error']:>11.3f} "
            f"{f['forward_speed_m_s']:>6.2f} "
            f"{f['length']:>6} {f['eval_return']:>8.1f} {r['compile_s']:>9.1f}"
        )
    t = result["teacher"]
    print(f"{'teacher':<18} {'':>11} {'':>6} {'':>12} {t['style_error']:>11.3f} {t['forward_speed_m_s']:>6.2f}")
    overhead = f"{100 * result['amp_overhead']:.1f}%" if "amp_overhead" in result else "not measured"
    print(
        f"raw {result['raw_steps_per_s']:,.0f} steps/s at {result['num_envs']} envs; AMP's overhead over PPO "
        f"{overhead} (goal <= 15%); style threshold {humanoid_amp.STYLE_THRESHOLD} rad, "
        f">= {humanoid_amp.MIN_SPEED} m/s, no fall"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=30_000_000, help="AMP's env steps")
    parser.add_argument("--ppo-steps", type=int, default=16_384_000, help="PPO's env steps (5 chunks)")
    parser.add_argument("--trainers", nargs="+", default=["ppo", "amp"], choices=["ppo", "amp"])
    parser.add_argument("--teacher-episodes", type=Path, default=None, help="the teacher's episodes (.npz, qpos)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "amp")
    parser.add_argument("--quick", action="store_true", help="tiny sizes, to check the script on a CPU")
    parser.add_argument("--no-video", action="store_true", help="save the final episodes, render them later")
    parser.add_argument("--render", action="store_true", help="only render the saved final episodes under --out")
    args = parser.parse_args()
    style_task = humanoid_amp.humanoid_amp_walk()
    reference = humanoid_amp.reference(style_task)  # what AMP imitates and the style is measured against
    if args.render:
        for saved in sorted(args.out.glob("*/final_policy.npz")):
            render(style_task, np.load(saved)["qpos"], saved.with_suffix(".mp4"), float(reference.dt))
        return
    device = jax.devices()[0].device_kind
    print(f"device: {device}, jax {jax.__version__}", flush=True)
    (ppo_config, ppo_hyperparams), (amp_config, amp_hyperparams) = configs(args.steps, args.ppo_steps, args.quick)
    walk = mjzoo.envs.make("humanoid_walk")
    batch = inputs(walk, amp_config.num_envs, 20 if args.quick else 100)
    raw = raw_steps_per_s(walk, "humanoid_walk", *batch, repeats=3)
    print(f"raw stepping {raw:,.0f} steps/s at {amp_config.num_envs} envs", flush=True)
    video = not args.no_video
    result = {
        "device": device,
        "jax": jax.__version__,
        "num_envs": amp_config.num_envs,
        "raw_steps_per_s": raw,
        "style_threshold_rad": humanoid_amp.STYLE_THRESHOLD,
        "min_speed_m_s": humanoid_amp.MIN_SPEED,
        "style_from_step": STYLE_FROM,
        "teacher": teacher(reference, args.teacher_episodes),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"amp_{jax.default_backend()}_{'_'.join(args.trainers)}{'_quick' if args.quick else ''}.json"
    for key, label, algorithm, hyperparams, task in (
        ("ppo", "ppo_walk", ppo.make(ppo_config), ppo_hyperparams, walk),
        ("amp", "amp_walk", amp.make(amp_config, reference), amp_hyperparams, style_task),
    ):
        if key in args.trainers:
            result[key] = train(label, algorithm, hyperparams, task, reference, args.out, args.quick, video)
            path.write_text(json.dumps(result, indent=2))  # what is done survives a run cut short
    if len(args.trainers) == 2:
        result["amp_overhead"] = result["ppo"]["steps_per_s"] / result["amp"]["steps_per_s"] - 1.0
    print_table(result)
    path.write_text(json.dumps(result, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
