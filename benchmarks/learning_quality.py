"""PPO's learning quality, not its speed: how well mjzoo PPO learns, over seeds, against Brax PPO.

Envs: the 25 DM Control Suite envs of MuJoCo Playground (listed from its registry, run
through `mjzoo.interop.playground`) and mjzoo's own envs by their registered names
(hopper, walker, cheetah, ant, humanoid_walk, ...). Each env trains for a fixed budget
of env steps (``--steps``; default Playground's tuned ``num_timesteps`` for its envs, the
registered ``total_steps`` for mjzoo's), which Brax rounds up to whole epochs between
its evaluations (`playground.brax_env_steps`); every trainer trains that many.

Trainers (``--trainers``):

  mjzoo-translated  Playground's tuned Brax PPO config in mjzoo's terms
                    (`mjzoo.interop.playground.ppo_hyperparameters`; for an mjzoo env,
                    Playground's DM Control defaults, `ppo_vs_brax.mjzoo_config`).
  mjzoo-defaults    the env's registered mjzoo PPO hyperparameters (a Playground env:
                    `ppo.Config()` and `ppo.Hyperparams()` defaults), with only num_envs
                    and total_steps set to the translated config's.
  brax              Brax PPO (`brax.training.agents.ppo.train`) on the same env object with
                    Playground's tuned config (`playground.train_brax`); an mjzoo env goes
                    through `brax_peer.train_brax_ppo` with Playground's DM Control
                    defaults. Only on ``--brax-envs`` (default `BRAX_ENVS`), one seed after
                    another.

An mjzoo configuration trains all its seeds (``--seeds``, >= 3) in one program per env,
so one compile: a jitted function, vmapped over seeds, runs ``num_updates // evals`` PPO
updates (a `lax.scan` of the algorithm's `update`) and then `ppo.evaluate`, deterministic
first episodes of ``--eval-envs`` envs; it is called ``--evals`` times. Each run keeps
its per-update learning rate, KL, value loss, clip fraction and KL stops
(``diagnostics``), to see what a collapse did to the update. Brax evaluates
at the same ``--evals`` fractions of its budget (plus its own evaluation at step 0).

Reported per env and trainer (the JSON's ``rows``, the printed table): the final return
(the last evaluation's, mean and std over seeds), the best return, the kept fraction
(final / best of each run; a run that keeps < 0.9 of its best has collapsed), the
wall-clock time (compile included) to 0.9 of the better trainer's mean final return
(mjzoo's seeds train at once, so its time is for all its seeds; None when a seed never
gets there), and steps/s: env steps of all seeds trained together, per wall-clock
second from the first to the last evaluation (evaluations included, compile not).
``summary`` holds, per reward scale and trainer, the median over envs of the final
return normalized by the best trainer's mean final on that env, and the count of
collapsed runs. Returns are in units of the unscaled reward: ``--reward-scale S``
multiplies the task's reward by S for training (mjzoo: a reward wrapper on the task;
Brax: on the env), and the evaluations' returns are divided by S, so a run at S = 100
plots beside the run at S = 1 (a learner robust to the reward's scale draws the same curve).

The JSON (``learning_quality_<card>.json``) is merged with the one already there: each
wave of GPU time adds envs (a row per env, reward scale and budget: an env run at two
budgets has two rows), and re-running an env at a reward scale and budget replaces the
trainers it ran (its other trainers stay); a trainer re-run at the same budget and
hyperparameters on other seeds (``--first-seed``) adds them, so one env's seeds can be
split over GPUs or waves. Plots beside it: the normalized final returns per env and
trainer, and per-env learning curves (mean and std band over seeds).

The waves compare at ``--steps 30000000`` (39.3M after Brax's rounding); a wave run at
the default budget gets rows of its own (CheetahRun and FingerTurnHard at 78.6M).

Waves of ~30 minutes, each command under the device's 10 minutes. Measured on H200s at
39.3M steps, 3 seeds in one program, compile included: mjzoo-defaults alone on a GPU
~3-4.5 min on BallInCup, Finger, Fish and Hopper; mjzoo-translated (Playground's 16
epochs of 32 minibatches) ~8 min on Finger and Fish with the GPU shared by two, and a
quarter of its budget took Walker ~6 min and Humanoid ~9 min with it shared by three:
split those seeds over GPUs (``--seeds 1 --first-seed K``). Brax ~3-10 min per seed.

    python benchmarks/learning_quality.py --envs CartpoleBalance CartpoleSwingup PendulumSwingup --trainers mjzoo-translated mjzoo-defaults
    python benchmarks/learning_quality.py --envs CartpoleBalance CheetahRun --trainers brax   # merges beside the mjzoo rows
    python benchmarks/learning_quality.py --envs hopper walker cheetah --steps 20000000
    python benchmarks/learning_quality.py --envs CheetahRun --reward-scale 100 --trainers mjzoo-translated
    python benchmarks/learning_quality.py --smoke --envs CartpoleBalance --out /tmp/lq   # tiny sizes, on a CPU
    python benchmarks/learning_quality.py --merge wave/p*/learning_quality_nvidia_h200.json  # a wave's processes

Then ``python benchmarks/report.py`` regenerates docs/benchmarks.md from the results.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.tree_util import Partial
from mujoco_playground._src import wrapper as playground_wrapper

sys.path.insert(0, str(Path(__file__).parent))
from brax_peer import train_brax_ppo  # noqa: E402
from brax_peer import wall_steps_per_s  # noqa: E402
from cards import card_name  # noqa: E402
from playground import brax_config  # noqa: E402
from playground import brax_env_steps  # noqa: E402
from playground import train_brax  # noqa: E402
from ppo_vs_brax import HYPER  # noqa: E402
from ppo_vs_brax import mjzoo_config  # noqa: E402
from ppo_vs_brax import time_to  # noqa: E402
from report import collapsed  # noqa: E402

import mjzoo  # noqa: E402
import mjzoo.envs  # noqa: E402
from mjzoo.algorithms import ppo  # noqa: E402
from mjzoo.interop import playground  # noqa: E402

PLAYGROUND_ENVS = playground.offline_names()  # the DM Control Suite: sorted(registry.dm_control_suite.ALL_ENVS)
MJZOO_ENVS = ["hopper", "walker", "cheetah", "ant", "humanoid_walk"]
TRAINERS = ["mjzoo-translated", "mjzoo-defaults", "brax"]
# Brax PPO is the reference, not the subject: 9 envs that span the suite's kinds.
BRAX_ENVS = [
    "CartpoleBalance",  # contact-free, dense, easy: both should reach ~1000
    "CartpoleSwingupSparse",  # contact-free, sparse: exploration
    "PendulumSwingup",  # contact-free, reward only near upright: nearly sparse
    "ReacherHard",  # contact-free, sparse (inside a small target)
    "FingerSpin",  # contact-rich manipulation, dense
    "BallInCup",  # contacts, sparse (ball in cup)
    "CheetahRun",  # contact-rich locomotion, dense
    "WalkerWalk",  # contact-rich locomotion with falls, dense
    "HopperHop",  # contact-rich, hard and nearly sparse early on
]
# Per-update metrics kept with each mjzoo run, to see what a collapse did to the update.
DIAGNOSTICS = ("learning_rate", "loss/approx_kl", "loss/value", "loss/clip_fraction", "loss/kl_stopped")
COLLAPSE = 0.9  # a run that keeps less than this fraction of its best return has collapsed
THRESHOLD = 0.9  # time to this fraction of the better trainer's final return
# --smoke: tiny everything, to run the whole script on a CPU in minutes.
SMOKE_PPO = dict(num_envs=16, unroll_length=16, num_minibatches=4, num_epochs=2)
SMOKE_BRAX = dict(num_envs=16, batch_size=16, num_minibatches=4, num_updates_per_batch=2)
SMOKE_EPISODE = 50
SMOKE_STEPS = 4096


# --- envs, budgets and configurations -------------------------------------------------------


def is_playground(name: str) -> bool:
    return name in PLAYGROUND_ENVS


def default_steps(name: str) -> int:
    """Playground's tuned budget for its env; the registered one for mjzoo's."""
    if is_playground(name):
        from mujoco_playground.config import dm_control_suite_params

        return int(dm_control_suite_params.brax_ppo_config(name).num_timesteps)
    return int(mjzoo.envs.hyperparameters(name, "ppo")["total_steps"])


def brax_settings(name: str, steps: int, evals: int, smoke: bool, eval_envs: int) -> dict:
    """Brax's config for `name`: Playground's tuned one (its DM Control defaults for an
    mjzoo env), evaluated at step 0 and after each of `evals` equal parts of training."""
    if is_playground(name):
        config = brax_config(name, steps, smoke)  # smoke: its sizes and a short episode
    else:
        config = dict(HYPER, num_timesteps=steps, **(SMOKE_BRAX if smoke else {}))
    return {**config, "num_evals": evals + 1, "num_eval_envs": eval_envs}


def budget(name: str, steps: int, evals: int, smoke: bool) -> int:
    """Env steps every trainer trains: `steps` as Brax rounds it up to whole epochs."""
    return brax_env_steps(brax_settings(name, steps, evals, smoke, eval_envs=1))


def ppo_fields(name: str, trainer: str, steps: int, smoke: bool) -> dict[str, Any]:
    """`ppo.configure`'s fields of an mjzoo trainer on `name`, `steps` env steps long."""
    translated = playground.ppo_hyperparameters(name) if is_playground(name) else mjzoo_config(steps)
    if trainer == "mjzoo-translated":
        fields = dict(translated)
    else:  # the registered defaults; a Playground env has none, so ppo.Config's
        fields = {} if is_playground(name) else dict(mjzoo.envs.hyperparameters(name, "ppo"))
        fields["num_envs"] = translated["num_envs"]
    return {**fields, "total_steps": steps, **(SMOKE_PPO if smoke else {})}


def load(name: str, smoke: bool, impl: str = "jax") -> tuple[Any, mjzoo.Task]:
    """(Playground's env object or None, the mjzoo task): both trainers step the same
    object. `impl` is the physics of an mjzoo env (Playground's envs choose their own)."""
    if is_playground(name):
        env = playground.load(name, **({"episode_length": SMOKE_EPISODE} if smoke else {}))
        return env, playground.task(env)
    short = smoke and mjzoo.envs.accepts(name, "episode_steps")
    return None, mjzoo.envs.make(name, impl=impl, **({"episode_steps": SMOKE_EPISODE} if short else {}))


# --- reward scale ----------------------------------------------------------------------------


def _scaled_terms(reward_fn, scale, model, state, action, next_state) -> dict[str, jax.Array]:
    return {k: v * scale for k, v in reward_fn(model, state, action, next_state).items()}


def scaled_task(task: mjzoo.Task, scale: float) -> mjzoo.Task:
    """`task` with every reward term multiplied by `scale` (a leaf: no new trace per scale)."""
    return task if scale == 1 else task.replace(reward=Partial(_scaled_terms, task.reward, jnp.float32(scale)))


class ScaledReward(playground_wrapper.Wrapper):
    """A Playground env whose reward is multiplied by `scale`, for Brax's wrappers to wrap."""

    def __init__(self, env: Any, scale: float):
        super().__init__(env)
        self.scale = scale

    def step(self, state, action):
        state = self.env.step(state, action)
        return state.replace(reward=state.reward * self.scale)


# --- trainers ----------------------------------------------------------------------------------


def train_mjzoo(
    task: mjzoo.Task, fields: dict, seeds: list[int], evals: int, eval_envs: int, scale: float
) -> dict[str, Any]:
    """Every seed of one mjzoo PPO configuration in one vmapped program: `evals` calls of
    (num_updates // evals updates, then an evaluation). Returns the runs (curves of
    [step, wall-clock s, return / scale]) and the program's steps/s over all seeds."""
    config, hyperparams = ppo.configure(**fields)
    algorithm = ppo.make(config)
    per_chunk = max(1, config.num_updates // evals)
    eval_steps = mjzoo.episode_steps(task)  # on the host: a static length

    def chunk(task: mjzoo.Task, state: ppo.TrainState, key: jax.Array):
        def update(state: ppo.TrainState, _: None) -> tuple[ppo.TrainState, dict[str, jax.Array]]:
            state, metrics = algorithm.update(task, state)
            return state, {k: metrics[k] for k in DIAGNOSTICS if k in metrics}

        state, diagnostics = jax.lax.scan(update, state, None, length=per_chunk)
        # Only the mean return and its standard error leave the program: XLA drops the
        # evaluation's trajectory.
        returns = algorithm.evaluate(task, state, key, eval_envs, eval_steps).returns
        return state, (returns.mean(), returns.std() / np.sqrt(eval_envs)), diagnostics

    init = jax.jit(jax.vmap(algorithm.init, in_axes=(None, None, 0)))
    donate = () if jax.default_backend() == "cpu" else (1,)  # the CPU backend cannot donate
    run = jax.jit(jax.vmap(chunk, in_axes=(None, 0, 0)), donate_argnums=donate)
    start = time.perf_counter()
    init_keys, eval_keys = jnp.moveaxis(jax.vmap(jax.random.split)(jax.vmap(jax.random.key)(jnp.asarray(seeds))), 1, 0)
    state = init(task, hyperparams, init_keys)
    points, errors, diagnostics = [], [], []
    for i in range(evals):
        state, (returns, error), chunk_diagnostics = run(
            task, state, jax.vmap(jax.random.fold_in, in_axes=(0, None))(eval_keys, i)
        )
        returns = np.asarray(returns) / scale  # waits for the chunk
        errors.append(np.asarray(error) / scale)
        diagnostics.append(jax.tree.map(np.asarray, chunk_diagnostics))  # {key: [seed, update]}
        points.append(((i + 1) * per_chunk * config.steps_per_update, time.perf_counter() - start, returns))
        print(
            f"    step {points[-1][0]:,}, {points[-1][1]:.0f} s, returns {', '.join(f'{r:.1f}' for r in returns)}",
            flush=True,
        )
    runs = [
        run_record(seed, [(step, t, float(r[i])) for step, t, r in points], [float(e[i]) for e in errors])
        for i, seed in enumerate(seeds)
    ]
    for i, record in enumerate(runs):  # per update, for a collapse's post-mortem
        record["diagnostics"] = {k: np.concatenate([d[k][i] for d in diagnostics]).tolist() for k in diagnostics[0]}
    per_seed = wall_steps_per_s(runs[0]["curve"])
    return {
        "runs": runs,
        "hyperparameters": fields,
        "seeds_in_parallel": len(seeds),
        "steps_per_s": None if per_seed is None else per_seed * len(seeds),
    }


def train_brax_runs(env: Any, task: mjzoo.Task, config: dict, seeds: list[int], scale: float) -> dict[str, Any]:
    """Brax PPO over `seeds`, one after another, on the same env object (a Playground
    env) or the same task (an mjzoo env), rewards times `scale`."""
    runs, rates = [], []
    for seed in seeds:
        if env is not None:
            result = train_brax(env if scale == 1 else ScaledReward(env, scale), config, seed)
        else:
            hyper = {k: config[k] for k in HYPER}
            result = train_brax_ppo(
                scaled_task(task, scale),
                num_timesteps=config["num_timesteps"],
                episode_length=mjzoo.episode_steps(task),
                num_evals=config["num_evals"],
                num_eval_envs=config["num_eval_envs"],
                seed=seed,
                **hyper,
            )
        runs.append(run_record(seed, [(step, t, ret / scale) for step, t, ret in result["curve"]]))
        rates.append(result["steps_per_s"])
        print(f"    brax seed {seed}: final {runs[-1]['final_return']:.1f}, {rates[-1] or 0:,.0f} steps/s", flush=True)
    return {
        "runs": runs,
        "hyperparameters": {k: v for k, v in config.items() if k != "network_factory"}
        | {"network_factory": dict(config.get("network_factory", {}))},
        "seeds_in_parallel": 1,
        "steps_per_s": None if None in rates else float(np.mean(rates)),
    }


def run_record(seed: int, curve: list[tuple[int, float, float]], errors: list[float] | None = None) -> dict[str, Any]:
    """One run: its curve, final and best return (after training began), kept fraction.
    With `errors` (each evaluation's standard error of the mean return, one per curve
    point), whether a collapse is beyond evaluation noise: best - final more than twice
    the standard error of that difference. The best of several noisy evaluations is
    biased up, so a kept fraction below COLLAPSE can be noise on an env whose episodes'
    returns spread widely."""
    trained = [(ret, i) for i, (step, _, ret) in enumerate(curve) if step > 0]
    (final, last), (best, at) = trained[-1], max(trained)
    kept = final / best if best > 0 else None  # undefined for a non-positive best
    record = {
        "seed": seed,
        "curve": [list(point) for point in curve],
        "final_return": final,
        "best_return": best,
        "kept_fraction": kept,
    }
    if errors is not None:
        margin = 2.0 * float(np.hypot(errors[at], errors[last]))
        record["eval_standard_errors"] = errors
        record["collapse_beyond_noise"] = kept is not None and kept < COLLAPSE and best - final > margin
    return record


# --- summaries, the JSON and plots ---------------------------------------------------------


def summarize(row: dict) -> dict:
    """Adds each trainer's figures over its seeds and its comparison with the better trainer."""
    trainers = row["trainers"]
    for t in trainers.values():
        finals = [r["final_return"] for r in t["runs"]]
        kept = [r["kept_fraction"] for r in t["runs"] if r["kept_fraction"] is not None]
        t.update(
            seeds=len(finals),
            final_return=float(np.mean(finals)),
            final_return_std=float(np.std(finals)),
            best_return=float(np.mean([r["best_return"] for r in t["runs"]])),
            kept_fraction=float(np.mean(kept)) if kept else None,
            min_kept_fraction=float(np.min(kept)) if kept else None,
            collapsed_runs=sum(k < COLLAPSE for k in kept),
        )
        if all("collapse_beyond_noise" in r for r in t["runs"]):  # runs since the field was recorded
            t["collapsed_beyond_noise"] = sum(r["collapse_beyond_noise"] for r in t["runs"])
    better = max(t["final_return"] for t in trainers.values())
    row["better_final_return"] = better
    row["threshold"] = THRESHOLD * better
    for t in trainers.values():
        times = [time_to([p for p in r["curve"] if p[0] > 0], row["threshold"]) for r in t["runs"]]
        # No threshold where no trainer got above zero (a sparse task nobody solved).
        t["time_to_threshold_s"] = None if None in times or better <= 0 else float(np.mean(times))
        t["normalized_final"] = t["final_return"] / better if better > 0 else None
        t["normalized_final_std"] = t["final_return_std"] / better if better > 0 else None
    return row


def merged(rows: list[dict], row: dict, fields: tuple[str, ...] = ("env", "reward_scale", "steps")) -> list[dict]:
    """`rows` with `row` in place of the one that has its `fields` (its env, reward scale
    and env-step budget: trainers are compared only at one budget). A trainer `row` did not run keeps its old runs; one it ran again at the same
    budget and hyperparameters (a wave that split an env's seeds over GPUs) keeps the old
    runs of the seeds it did not run."""
    key = lambda r: tuple(r[f] for f in fields)  # noqa: E731
    old = next((r for r in rows if key(r) == key(row)), None)
    if old is None:
        return [*rows, row]
    trainers = dict(old["trainers"])
    for name, t in row["trainers"].items():
        before = trainers.get(name)
        if before and before.get("hyperparameters") == t.get("hyperparameters"):
            seeds = {r["seed"] for r in t["runs"]}
            runs = [r for r in before["runs"] if r["seed"] not in seeds] + t["runs"]
            t = {**t, "runs": sorted(runs, key=lambda r: r["seed"])}
        trainers[name] = t
    new = {**row, "trainers": trainers}
    return [new if r is old else r for r in rows]


def summary(rows: list[dict]) -> dict[str, dict]:
    """Per reward scale and trainer: the median normalized final return over its envs and
    its collapsed runs."""
    out: dict[str, dict] = {}
    for scale in sorted({r["reward_scale"] for r in rows}):
        at = [r for r in rows if r["reward_scale"] == scale]
        out[str(scale)] = {}
        for name in TRAINERS:
            ts = [r["trainers"][name] for r in at if name in r["trainers"]]
            normalized = [t["normalized_final"] for t in ts if t["normalized_final"] is not None]
            if ts:
                out[str(scale)][name] = {
                    "envs": len(ts),
                    "median_normalized_final": float(np.median(normalized)) if normalized else None,
                    "collapsed_runs": sum(t["collapsed_runs"] for t in ts),
                    "runs": sum(t["seeds"] for t in ts),
                }
    return out


def saved_rows(path: Path) -> list[dict]:
    return json.loads(path.read_text())["rows"] if path.exists() else []


def kept_note(path: Path) -> dict:
    """``{"note": ...}`` of the results file at `path`, or {}: a rewrite keeps what was written there by hand."""
    data = json.loads(path.read_text()) if path.exists() else {}
    return {"note": data["note"]} if "note" in data else {}


def save(path: Path, rows: list[dict], device: str) -> None:
    path.write_text(
        json.dumps(
            {"device": device, **kept_note(path), "jax": jax.__version__, "summary": summary(rows), "rows": rows},
            indent=1,
            default=float,
        )
    )


def label(row: dict, rows: list[dict]) -> str:
    """The env's name, with its budget where the env was also run at another."""
    budgets = {r["steps"] for r in rows if r["env"] == row["env"]}
    return row["env"] if len(budgets) == 1 else f"{row['env']} ({row['steps'] / 1e6:.1f}M)"


def plot(rows: list[dict], out: Path, card: str) -> list[Path]:
    """One figure of normalized final returns per env and trainer, one of learning curves
    (mean and std band over seeds), per reward scale."""
    import matplotlib

    matplotlib.use("Agg")  # no display
    import matplotlib.pyplot as plt

    paths = []
    colors = dict(zip(TRAINERS, ["tab:blue", "tab:cyan", "tab:orange"]))
    for scale in sorted({r["reward_scale"] for r in rows}):
        at = sorted((r for r in rows if r["reward_scale"] == scale), key=lambda r: (r["env"], r["steps"]))
        suffix = "" if scale == 1 else f"_scale{scale:g}"
        figure, axes = plt.subplots(figsize=(max(6, 0.7 * len(at) + 2), 4))
        width = 0.8 / len(TRAINERS)
        for i, name in enumerate(TRAINERS):
            xs = [j for j, r in enumerate(at) if r["trainers"].get(name, {}).get("normalized_final") is not None]
            if xs:
                ts = [at[j]["trainers"][name] for j in xs]
                axes.bar(
                    np.asarray(xs) + (i - 1) * width,
                    [t["normalized_final"] for t in ts],
                    width,
                    yerr=[t["normalized_final_std"] for t in ts],
                    label=name,
                    color=colors[name],
                )
        axes.axhline(THRESHOLD, color="gray", lw=0.8, ls="--")
        axes.set_xticks(range(len(at)), [label(r, rows) for r in at], rotation=60, ha="right")
        axes.set(ylabel="final return / better trainer's", title=f"PPO final returns, {card}, reward x{scale:g}")
        axes.legend(fontsize=8)
        figure.tight_layout()
        paths.append(out / f"normalized_final_{card}{suffix}.png")
        figure.savefig(paths[-1], dpi=120)
        plt.close(figure)

        cols = min(5, len(at))
        figure, grid = plt.subplots(
            -(-len(at) // cols), cols, figsize=(max(6.0, 3.2 * cols), 2.6 * -(-len(at) // cols) + 0.6)
        )
        for axes, r in zip(np.ravel(grid), at):
            for name, t in r["trainers"].items():
                steps = np.asarray([p[0] for p in t["runs"][0]["curve"]])
                returns = np.asarray([[p[2] for p in run["curve"]] for run in t["runs"]])  # [seed, evaluation]
                mean, std = returns.mean(axis=0), returns.std(axis=0)
                axes.plot(steps, mean, color=colors[name], label=name)
                axes.fill_between(steps, mean - std, mean + std, color=colors[name], alpha=0.25)
            axes.set_title(label(r, rows), fontsize=9)
            axes.tick_params(labelsize=7)
        for axes in np.ravel(grid)[len(at) :]:
            axes.axis("off")
        np.ravel(grid)[0].legend(fontsize=7)
        figure.suptitle(
            f"evaluation return (unscaled) over env steps, mean ± std over seeds, reward x{scale:g}", fontsize=9
        )
        figure.tight_layout()
        paths.append(out / f"curves_{card}{suffix}.png")
        figure.savefig(paths[-1], dpi=110)
        plt.close(figure)
    return paths


def print_table(rows: list[dict]) -> None:
    print(
        f"\n{'env':<22} {'steps':>6} {'scale':>6} {'trainer':<17} {'seeds':>5} {'final':>17} {'best':>8} {'kept':>5} "
        f"{'collapsed':>9} {'to 90% (s)':>10} {'steps/s':>11}"
    )
    for r in rows:
        for name, t in r["trainers"].items():
            ttt = "never" if t["time_to_threshold_s"] is None else f"{t['time_to_threshold_s']:.0f}"
            kept = "-" if t["kept_fraction"] is None else f"{t['kept_fraction']:.2f}"
            print(
                f"{r['env']:<22} {r['steps'] / 1e6:>5.1f}M {r['reward_scale']:>6g} {name:<17} {t['seeds']:>5} "
                f"{t['final_return']:>8.1f} ± {t['final_return_std']:<6.1f} {t['best_return']:>8.1f} {kept:>5} "
                f"{collapsed(t):>9} {ttt:>10} {t['steps_per_s'] or 0:>11,.0f}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--envs",
        nargs="+",
        default=None,
        help=f"Playground DM Control envs and/or mjzoo env names (default: the 25 Playground envs; "
        f"mjzoo's: {' '.join(MJZOO_ENVS)})",
    )
    parser.add_argument("--trainers", nargs="+", default=TRAINERS, choices=TRAINERS)
    parser.add_argument(
        "--brax-envs", nargs="+", default=BRAX_ENVS, help="Brax runs only on these of --envs ('all': every one)"
    )
    parser.add_argument("--steps", type=int, default=None, help="env steps per run (default: per env, see above)")
    parser.add_argument("--evals", type=int, default=4, help="evaluations, at equal fractions of the budget")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--eval-envs", type=int, default=128, help="episodes per evaluation")
    parser.add_argument("--reward-scale", type=float, default=1.0, help="train on reward x S; report unscaled")
    parser.add_argument(
        "--gpu-shared-by",
        type=int,
        default=1,
        help="processes training on this GPU at once (recorded: their times and steps/s are shared)",
    )
    parser.add_argument(
        "--merge",
        nargs="+",
        type=Path,
        default=None,
        help="merge these JSON files of other runs (in order) into --out's, and plot; trains nothing",
    )
    parser.add_argument("--smoke", action="store_true", help="tiny sizes, to check the script on a CPU")
    parser.add_argument("--out", type=Path, default=None, help="default: benchmarks/results/learning_quality")
    args = parser.parse_args()
    if args.reward_scale <= 0:
        parser.error("--reward-scale must be > 0")
    envs = args.envs or (["CartpoleBalance"] if args.smoke else PLAYGROUND_ENVS)
    unknown = [e for e in envs if not is_playground(e) and e not in mjzoo.envs.names()]
    if unknown:
        parser.error(
            f"unknown envs {unknown}; Playground's: {' '.join(PLAYGROUND_ENVS)}; mjzoo's: {' '.join(MJZOO_ENVS)}"
        )
    if args.smoke and args.out is None:  # keep tiny runs out of the results
        args.out = Path(tempfile.mkdtemp(prefix="learning_quality_smoke_"))
    out = args.out or Path(__file__).parent / "results" / "learning_quality"
    out.mkdir(parents=True, exist_ok=True)
    eval_envs = min(args.eval_envs, 8) if args.smoke else args.eval_envs
    card = card_name()
    path = out / f"learning_quality_{card}.json"
    rows = saved_rows(path)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    if args.merge:
        for other in args.merge:
            data = json.loads(other.read_text())
            card = card_name(data["device"])
            path = out / f"learning_quality_{card}.json"
            rows = saved_rows(path)
            for row in data["rows"]:
                rows = [summarize(r) for r in merged(rows, row)]
            save(path, rows, data["device"])
        envs = []  # only the report below
    else:
        print(
            f"device: {jax.devices()[0].device_kind}, jax {jax.__version__}, seeds {seeds}, writing {path}", flush=True
        )
    for name in envs:
        steps = budget(name, args.steps or (SMOKE_STEPS if args.smoke else default_steps(name)), args.evals, args.smoke)
        trainers = [t for t in args.trainers if t != "brax" or name in args.brax_envs or "all" in args.brax_envs]
        if not trainers:
            continue
        start = time.perf_counter()
        env, task = load(name, args.smoke)
        print(f"{name}: {steps:,} env steps per run, reward x{args.reward_scale:g}", flush=True)
        row = {
            "env": name,
            "source": "playground" if env is not None else "mjzoo",
            "reward_scale": args.reward_scale,
            "steps": steps,
            "evals": args.evals,
            "eval_envs": eval_envs,
            "smoke": args.smoke,
            "trainers": {},
        }
        for trainer in trainers:
            print(f"  {trainer}", flush=True)
            if trainer == "brax":
                config = brax_settings(name, steps, args.evals, args.smoke, eval_envs)
                result = train_brax_runs(env, task, config, seeds, args.reward_scale)
            else:
                fields = ppo_fields(name, trainer, steps, args.smoke)
                scaled = scaled_task(task, args.reward_scale)
                result = train_mjzoo(scaled, fields, seeds, args.evals, eval_envs, args.reward_scale)
            row["trainers"][trainer] = {**result, "gpu_shared_by": args.gpu_shared_by}
            # After each trainer: a wave cut off by its time limit keeps what it measured.
            rows = [summarize(r) for r in merged(rows, row)]
            save(path, rows, jax.devices()[0].device_kind)
        print(f"{name}: {time.perf_counter() - start:.0f} s", flush=True)

    print_table(rows)
    for scale, trainers in summary(rows).items():
        for name, s in trainers.items():
            median = "-" if s["median_normalized_final"] is None else f"{s['median_normalized_final']:.3f}"
            print(
                f"reward x{float(scale):g} {name}: median normalized final {median} over {s['envs']} envs, "
                f"{s['collapsed_runs']} of {s['runs']} runs collapsed"
            )
    for figure in plot(rows, out, card):
        print(f"wrote {figure}")
    print(f"wrote {path}", flush=True)


if __name__ == "__main__":
    main()
    os._exit(0)  # Warp on a CPU may hang at interpreter exit
