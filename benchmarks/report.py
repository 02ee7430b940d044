"""Writes docs/benchmarks.md from the measurements in benchmarks/results/: one section per
result family (robots, learning quality, PPO against Brax, Playground, locomotion, AMP,
planning, scaling, start-up, physics), each a short account and tables built from its
JSON files. The page is never edited by hand, and the suite checks that it is this
script's output (so it cannot drift from the JSON beside the scripts that wrote it).

    python benchmarks/report.py           # rewrite docs/benchmarks.md
    python benchmarks/report.py --check   # exit 1 if the page differs from the results
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
PAGE = ROOT / "docs" / "benchmarks.md"
DM_CONTROL_ENVS = 25  # Playground's DM Control Suite, as learning_quality.py runs it
COLLAPSE = 0.9  # learning_quality.py's: a run that ends below this fraction of its best


def _link(path: Path) -> str:
    """`path` relative to docs/, for a link from the page."""
    return "../" + path.relative_to(ROOT).as_posix()


def _number(x: float | None, digits: int = 1) -> str:
    return "-" if x is None else f"{x:,.{digits}f}"


def collapsed(trainer: dict) -> str:
    """A trainer's collapsed runs, and in brackets those beyond evaluation noise where it
    was measured (learning_quality.run_record)."""
    beyond = trainer.get("collapsed_beyond_noise")
    return f"{trainer['collapsed_runs']}" + ("" if beyond is None else f" ({beyond})")


def _trainer_table(rows: list[dict]) -> list[str]:
    """One line per env, reward scale and trainer: final return (mean ± std over seeds),
    best, the lowest kept fraction of a seed, collapsed seeds (in brackets, those beyond
    evaluation noise, where measured), time to 90% of the better final return, steps/s,
    and how many processes shared the GPU."""
    lines = [
        "| env | env steps | reward x | trainer | seeds | final (mean ± std) | best | lowest kept | collapsed | "
        "to 90% (s) | steps/s | GPU shared by |",
        "| --- | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for row in sorted(rows, key=lambda r: (r["env"], r["steps"], r["reward_scale"])):
        for name, t in row["trainers"].items():
            to_90 = "never" if t["time_to_threshold_s"] is None else f"{t['time_to_threshold_s']:.0f}"
            lines.append(
                f"| {row['env']} | {row['steps'] / 1e6:.1f}M | {row['reward_scale']:g} | {name} | {t['seeds']} | "
                f"{t['final_return']:,.1f} ± {t['final_return_std']:,.1f} | {t['best_return']:,.1f} | "
                f"{_number(t.get('min_kept_fraction'), 2)} | {collapsed(t)} | {to_90} | "
                f"{_number(t.get('steps_per_s'), 0)} | {t.get('gpu_shared_by', 1)} |"
            )
    return lines


def _per_device(folder: Path) -> Iterator[tuple[dict, list[str]]]:
    """Each JSON of `folder` (one per device: "<folder name>_<card>.json") and its heading."""
    for path in sorted(folder.glob(f"{folder.name}_*.json")):
        data = json.loads(path.read_text())
        note = [f"> {data['note']}", ""] if data.get("note") else []
        yield data, [f"### {data['device']} ([{path.name}]({_link(path)}))", "", *note]


def _figures(folder: Path) -> list[str]:
    return [f"![{png.stem}]({_link(png)})" for png in sorted(folder.glob("*.png"))]


def learning_quality() -> list[str]:
    folder = RESULTS / "learning_quality"
    lines = [
        "## PPO's learning quality",
        "",
        "`benchmarks/learning_quality.py`: every seed of an mjzoo configuration in one vmapped",
        "program, Brax PPO one seed after another on the same env object, at one env-step budget",
        "per env. Trainers: `mjzoo-translated` (Playground's tuned Brax PPO hyperparameters in",
        "mjzoo's terms), `mjzoo-defaults` (`ppo.Config()`'s, with the same number of envs), `brax`.",
        "A final return is the last evaluation's (deterministic first episodes); normalized, it",
        "is divided by the better trainer's on that env; a run *collapsed* when it ended below",
        f"{COLLAPSE} of its own best evaluation. Times and steps/s are the GPU's own only where",
        "it was shared by 1 process: the waves train several envs at once on one GPU.",
        "",
    ]
    for data, heading in _per_device(folder):
        rows = data["rows"]
        playground = sorted({r["env"] for r in rows if r.get("source") == "playground"})
        lines += [
            *heading,
            f"Playground's DM Control envs measured: {len(playground)} of {DM_CONTROL_ENVS}; "
            f"mjzoo's own: {len({r['env'] for r in rows}) - len(playground)}.",
            "",
            "| reward x | trainer | envs | runs | median normalized final | collapsed runs |",
            "| ---: | --- | ---: | ---: | ---: | ---: |",
        ]
        for scale, trainers in data["summary"].items():
            for name, s in trainers.items():
                lines.append(
                    f"| {float(scale):g} | {name} | {s['envs']} | {s['runs']} | "
                    f"{_number(s['median_normalized_final'], 3)} | {s['collapsed_runs']} |"
                )
        lines += ["", *_trainer_table(rows), ""]
    return [*lines, *_figures(folder), ""]


def ppo_stability() -> list[str]:
    folder = RESULTS / "ppo_stability"
    lines = [
        "## PPO's stability switches",
        "",
        "`benchmarks/ppo_stability.py`: PPO without its stability switches (`plain`, `ppo.PLAIN`),",
        "with each switch alone, and with today's defaults, seeds vmapped in one program.",
        "",
    ]
    for data, heading in _per_device(folder):
        lines += [*heading, *_trainer_table(data["rows"]), ""]
    return [*lines, *_figures(folder), ""]


# --- tables from rows of JSON --------------------------------------------------------

Column = tuple[str, Callable[[dict], object]]  # (header, the cell's value from a row)


def _at(path: str) -> Callable[[dict], object]:
    """A getter of `path` ("mjzoo.steps_per_s") in a row; None where any part is missing."""

    def get(row: dict) -> object:
        value: object = row
        for key in path.split("."):
            if not isinstance(value, dict) or key not in value:
                return None
            value = value[key]
        return value

    return get


def _cell(value: object) -> str:
    """A table cell: numbers to 3-4 significant figures, rates as 347k or 1.37M."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value:,}"
    if isinstance(value, float):
        if value != value:
            return "-"
        if abs(value) >= 1000:
            return f"{value:,.0f}"
        return f"{value:.3g}" if abs(value) < 10 else f"{value:.1f}"
    return str(value).replace("|", "\\|").replace("\n", " ")


def _rate(path: str) -> Callable[[dict], object]:
    """Steps per second at `path` as 347k or 1.37M."""

    def get(row: dict) -> object:
        x = _at(path)(row)
        if not isinstance(x, (int, float)):
            return x
        return f"{x / 1e6:.3g}M" if x >= 1e6 else f"{x / 1e3:.0f}k" if x >= 1e3 else f"{x:.0f}"

    return get


def _options(path: str) -> Callable[[dict], object]:
    """A dict of options at `path` as "dt=0.01 iterations=2"; None where absent or empty."""

    def get(row: dict) -> object:
        options = _at(path)(row)
        return " ".join(f"{k}={v}" for k, v in options.items()) if options else None

    return get


def _percent(path: str) -> Callable[[dict], object]:
    def get(row: dict) -> object:
        x = _at(path)(row)
        return f"{100 * x:+.1f}%" if isinstance(x, (int, float)) else x

    return get


def _table(rows: list[dict], columns: list[Column]) -> list[str]:
    """A Markdown table of `rows`, one line each, with the columns any row has."""
    kept = [(header, get) for header, get in columns if any(get(row) is not None for row in rows)]
    lines = ["| " + " | ".join(_cell(h) for h, _ in kept) + " |", "|" + " --- |" * len(kept)]
    lines += ["| " + " | ".join(_cell(get(row)) for _, get in kept) + " |" for row in rows]
    return lines


def _card(data: dict | list, path: Path) -> str:
    """The device a file was measured on, as the file records it (at its top, in its
    meta or rows, or in its name: robots_nvidia_h200.json)."""
    rows = data if isinstance(data, list) else data.get("rows", [])
    meta = data.get("meta", {}) if isinstance(data, dict) else {}
    for where in (data, meta, rows[0] if rows and isinstance(rows[0], dict) else {}):
        for key in ("device", "card", "machine"):
            if isinstance(where, dict) and isinstance(where.get(key), str):
                return where[key]
    for suffix, card in (
        ("_nvidia_h200", "NVIDIA H200"),
        ("_cpu", "CPU"),
        ("_H200", "NVIDIA H200"),
        ("_4xH100", "4x NVIDIA H100"),
    ):
        if path.stem.endswith(suffix) or f"{suffix}_" in path.stem:
            return card
    return "card not recorded"


def _notes(data: dict | list) -> list[str]:
    """A file's own notes on how it was measured, as quoted lines."""
    if not isinstance(data, dict):
        return []
    notes = [
        n for key in ("note", "notes") for n in ([data[key]] if isinstance(data.get(key), str) else data.get(key) or [])
    ]
    return [line for note in notes for line in (f"> {' '.join(str(note).split())}", ">")][:-1] + ([""] if notes else [])


def _files(pattern: str) -> list[Path]:
    """The result files matching `pattern`, a script's ``--smoke`` output left out."""
    return sorted(path for path in RESULTS.glob(pattern) if not path.stem.endswith("_smoke"))


def _file_tables(pattern: str, columns: list[Column], rows: Callable[[dict], list[dict]] | None = None) -> list[str]:
    """For each JSON file matching `pattern`: a heading naming it and its card, its notes
    if it has any, and the table of its rows."""
    lines = []
    for path in _files(pattern):
        data = json.loads(path.read_text())
        lines += [f"**[{path.name}]({_link(path)})** ({_card(data, path)})", "", *_notes(data)]
        lines += [*_table((rows or _at("rows"))(data) if isinstance(data, dict) else data, columns), ""]
    return lines


def _section(title: str, prose: str, *parts: list[str]) -> list[str]:
    return [f"## {title}", "", *prose.strip().splitlines(), "", *[line for part in parts for line in part]]


def row_settings(row: dict) -> str:
    """What a robots.py row changed from the robot's registered settings: its learner
    fields, joystick options and named numbers, as ``NAME=VALUE`` words ("" for none)."""
    return " ".join(
        f"{k}={v}" for part in ("config", "task_options", "task_params") for k, v in (row.get(part) or {}).items()
    )


def _tracking_rows(data: dict) -> list[dict]:
    """One row per robot, terrain and seed of benchmarks/robots.py's JSON."""
    return [
        {
            "robot": row["robot"],
            "terrain": row["terrain"],
            "impl": row.get("impl", "jax"),
            "learner": row.get("algorithm", "ppo"),
            "envs": row["hyperparameters"]["num_envs"],
            "settings": row_settings(row) or "the robot's",
            **run,
        }
        for row in data["rows"]
        for run in row["runs"]
    ]


def robots() -> list[str]:
    prose = """
`benchmarks/robots.py` trains the joysticks of [robots.md](robots.md) with PPO (or,
`--algorithm`, an off-policy learner) on one GPU. A policy *tracks* when, over 64
evaluation episodes of 20 s with the task's pushes, noise and randomized physics, the mean |v_xy − cmd| ≤ 0.15 m/s, the mean |ω_z − cmd| ≤
0.2 rad/s and none falls (errors per control step); the time to tracking includes
compiling. The errors over 1 s windows (velocities and command averaged over the last
50 control steps; rows since 2026-11-30) say whether the command is followed on
average, apart from a walker's sway within its gait cycle. The G1 is bound by its
physics: 10 substeps of 2 ms per control step. `benchmarks/terrain_cost.py` measures
what a heightfield costs the physics, `scripts/check_robots.py` runs `check_task` on
every robot and terrain, and `mjzoo sim2sim` drives an exported policy in C MuJoCo
under another simulation configuration than training's (its physics step and solver
iterations in the table), with pushes of 0.5 m/s, against the same policy in MJX. The
first evaluation comes after compiling and one training chunk: compiling takes longest
on a fresh machine, where MuJoCo Warp builds its kernels (~90 s; later runs load them
from its cache).
"""
    runs = [
        ("robot", _at("robot")),
        ("terrain", _at("terrain")),
        ("physics", _at("impl")),
        ("learner", _at("learner")),
        ("envs", _at("envs")),
        ("settings (learner, task)", _at("settings")),
        ("seed", _at("seed")),
        ("first evaluation (s)", lambda r: r["curve"][0]["seconds"] if r.get("curve") else None),
        ("to tracking (s)", _at("seconds_to_tracking")),
        ("steps to tracking", _at("steps_to_tracking")),
        ("final step", _at("final.step")),
        ("final velocity error (m/s)", _at("final.linear_error")),
        ("final yaw-rate error (rad/s)", _at("final.yaw_error")),
        ("over 1 s: velocity", _at("final.linear_error_1s")),
        ("yaw rate", _at("final.yaw_error_1s")),
        ("falls", _at("final.falls")),
    ]
    cost = [
        ("variant", _at("variant")),
        ("physics", _at("impl")),
        ("envs", _at("num_envs")),
        ("substeps", _at("n_substeps")),
        ("env steps/s", _rate("steps_per_s")),
        ("compile (s)", _at("compile_s")),
    ]
    checks = [
        ("variant", _at("variant")),
        ("properties passed", lambda r: len(r["passed"])),
        ("failed", lambda r: ", ".join(r["failures"]) or "none"),
        ("machine", _at("machine")),
        ("seconds", _at("seconds")),
    ]
    sim2sim = [
        ("file", _at("file")),
        ("env", _at("env")),
        ("C timestep (s)", _at("mujoco.options.timestep")),
        ("C solver iterations", _at("mujoco.options.iterations")),
        ("C latency (steps)", _at("mujoco.options.latency")),
        ("C velocity error", _at("mujoco.linear_error")),
        ("MJX velocity error", _at("training.linear_error")),
        ("velocity ratio", _at("ratio.linear_error")),
        ("C yaw-rate error", _at("mujoco.yaw_error")),
        ("MJX yaw-rate error", _at("training.yaw_error")),
        ("yaw ratio", _at("ratio.yaw_error")),
        ("C falls", _at("mujoco.falls")),
        ("episodes", _at("mujoco.episodes")),
    ]
    sim_rows = [{"file": p.name, **json.loads(p.read_text())} for p in _files("robots/sim2sim_*.json")]
    check_rows = [
        {"variant": k, **v} for k, v in json.loads((RESULTS / "robots" / "check_task.json").read_text()).items()
    ]
    return _section(
        "Real robots",
        prose,
        _file_tables("robots/robots_*.json", runs, _tracking_rows),
        _figures(RESULTS / "robots"),
        [""],
        _file_tables("robots/terrain_cost_*.json", cost),
        ["**Sim-to-sim, exported policies in C MuJoCo against MJX** (each file holds its command)", ""],
        _table(sim_rows, sim2sim),
        ["", f"**[check_task.json]({_link(RESULTS / 'robots' / 'check_task.json')})**", ""],
        _table(check_rows, checks),
        [""],
    )


def _versus(prefix: str) -> list[Column]:
    """mjzoo against Brax columns of ppo_vs_brax.py's and playground.py's rows."""
    return [
        ("env", _at("env")),
        ("physics", _at("impl")),
        ("mjzoo steps/s", _rate("mjzoo.steps_per_s")),
        ("Brax steps/s", _rate("brax.steps_per_s")),
        ("ratio", _at("mjzoo_over_brax_steps_per_s")),
        ("mjzoo training alone", _rate("mjzoo.train_steps_per_s")),
        ("Brax training alone", _rate("brax.train_steps_per_s")),
        ("mjzoo to 90% (s)", _at(f"{prefix}time_to_threshold_s" if prefix else "mjzoo.time_to_threshold_s")),
        ("Brax to 90% (s)", _at("brax_time_to_threshold_s" if prefix else "brax.time_to_threshold_s")),
        ("mjzoo final", _at("mjzoo.final_return")),
        ("Brax final", _at("brax.final_return")),
        ("seeds", _at("mjzoo.seeds")),
        ("mjzoo compile (s)", _at("mjzoo.compile_s")),
    ]


def ppo_vs_brax() -> list[str]:
    prose = """
`benchmarks/ppo_vs_brax.py`: mjzoo's PPO against Brax's PPO on the same task with
Playground's DM Control hyperparameters, 20M steps, each trainer in its own process.
Both rates are measured alike: *wall-clock*, env steps between the first and the last
evaluation after training began (evaluations included), and *training alone* (mjzoo's
median chunk, Brax's `training/walltime`). On MJX-JAX physics mjzoo's rollout is already
96% of raw stepping, so raw stepping over Brax bounds the ratio; on Warp the learner and
the evaluation decide. `compute_dtype="bfloat16"` runs the hidden layers in bfloat16
(float32 params and Adam). `benchmarks/ppo_profile.py` splits an update: the rollout, the
learner's minibatch steps and their compiles. Per 983,040 env steps on our cart-pole the
rollout takes ~1.06 s and the learner's 512 minibatch steps 0.47 s with JAX's default TF32
matmuls, 0.29 s in bfloat16 and 0.91 s in full float32. On Playground's cart-pole, whose
physics is 8x cheaper, the learner decides: a minibatch step (30,720 samples) launches 69
kernels and takes ~0.56 ms, bound by the value net's work rather than by launches;
capturing the minibatch loop in CUDA graphs or one Adam update over all parameters
concatenated changes it by under 2% (`*_sgd*.json`). The harness's chunk costs 9% over a
bare update (`*_chunk.json`), and the evaluation stacks the state it films packed into
one array per dtype, 2.5x cheaper than leaf by leaf (`*_eval.json`).
"""
    profile = [
        ("variant", _at("variant")),
        ("env", _at("env")),
        ("rollout (s)", _at("rollout_s")),
        ("learner (s)", _at("improve_s")),
        ("update (s)", _at("update_s")),
        ("minibatch step (ms)", _at("sgd_step_ms")),
        ("env steps/s", _rate("steps_per_s")),
        ("evaluation (s)", _at("eval_s")),
    ]
    return _section(
        "PPO against Brax PPO",
        prose,
        _file_tables("ppo_vs_brax_gpu*.json", _versus("mjzoo_")),
        _file_tables("warp/ppo_vs_brax_gpu*.json", _versus("mjzoo_")),
        ["### Where an update's time goes", ""],
        _file_tables("ppo_profile/*.json", profile),
    )


def playground() -> list[str]:
    prose = """
`benchmarks/playground.py`: MuJoCo Playground's own envs, mjzoo's PPO through
`mjzoo.interop.playground` against Brax's PPO as Playground trains it, on the very same
env object with Playground's tuned hyperparameters, each trainer in its own process.
Brax trains Playground's 60M-step config for 88.5M steps (whole epochs of
`num_resets_per_eval`) and mjzoo as many. A *time to 90%* is to 90% of the better final
return; rates are defined as for PPO against Brax. PendulumSwingup's sparse reward makes a
swing-up a lottery for both trainers at this budget (on Warp, two of eight mjzoo seeds and
two of three Brax seeds), and one seed per row is not yet a comparison within seed noise.
Files named `*_entropy_fix` come after PPO's entropy estimate was fixed: it now takes a
fresh reparameterized sample per minibatch, as Brax's does; estimated at the rollout's
stored pre-tanh sample, its gradient only grew the policy's scale where the reward is
sparse (PendulumSwingup's first update took it from 0.69 to a median of 580:
`pendulum_diagnostics/`). `playground_jax_cheetah_recompile_fix.json` comes after the
harness began owning its initial state strongly typed: CheetahRun resets `data.time` to a
weakly typed 0.0, which made the second chunk and the evaluation compile again.
`scripts/playground_conformance.py` runs every Playground env through `check_task`
offline; `benchmarks/background_compile.py` times the evaluation's compile alone and beside
a training chunk.
"""
    conformance = json.loads((RESULTS / "playground" / "conformance.json").read_text())
    envs = conformance["envs"]
    return _section(
        "Playground's envs against Brax",
        prose,
        _file_tables("playground/playground_*.json", _versus("")),
        [
            f"**[conformance.json]({_link(RESULTS / 'playground' / 'conformance.json')})** "
            f"({conformance['machine']}, Playground {conformance['playground']}): "
            f"{sum(e['status'] == 'pass' for e in envs)} of {len(envs)} envs pass `check_task`.",
            "",
        ],
        _file_tables(
            "playground/background_compile_*.json",
            [
                ("where", _at("where")),
                ("options", _at("options")),
                ("eval envs", _at("eval_envs")),
                ("compile (s)", _at("compile_s")),
            ],
        ),
    )


def locomotion() -> list[str]:
    prose = """
`benchmarks/locomotion.py`: PPO on the locomotion catalog, one GPU, evaluating every
chunk. The time to the stated return (`humanoid_walk` 6000: every episode its full 1000
steps at ≥ 1 m/s; `ant` 3000: ≥ 2 m/s) includes compiling; the final columns are a
deterministic evaluation of 256 episodes. Before the fall ceiling of 1 m (Brax's and
Gym's too) PPO learned to bounce the ant 4 m high off the soft contacts; with torque
actions the joystick ant only learned to stand still, so its actions are PD targets.
Files named `*_entropy_fix` were measured after PPO's entropy estimate was fixed (a
fresh reparameterized sample per minibatch, as Brax's), the others before.
"""
    columns = [
        ("task", _at("task")),
        ("physics", _at("impl")),
        ("envs", _at("config.num_envs")),
        ("env steps/s", _rate("steps_per_s")),
        ("share of raw", _at("fraction_of_raw")),
        ("threshold", _at("threshold")),
        ("to threshold (s)", _at("time_to_threshold_s")),
        ("first update (s)", _at("first_update_s")),
        ("final return", _at("final.return")),
        ("speed (m/s)", _at("final.forward_speed_m_s")),
        ("command error (m/s)", _at("final.velocity_error_m_s")),
        ("fell", _at("final.fell_fraction")),
    ]
    return _section(
        "Locomotion with PPO",
        prose,
        _file_tables("locomotion/locomotion_*.json", columns),
        _file_tables("warp/locomotion_*.json", columns),
    )


def amp() -> list[str]:
    prose = """
`benchmarks/amp.py`: `humanoid_amp_walk` rewards only being alive and little effort, no
forward speed, and AMP's discriminator supplies the style of a teacher's walk (the PPO
policy of `humanoid_walk`, recorded with `mjzoo collect`). The *style error* is the mean
hinge-angle error to the nearest 10-frame window of the reference (below the threshold:
walks like the teacher); PPO on `humanoid_walk`'s task reward at the same batch is the
comparison. AMP trains as fast per step as PPO.
"""
    columns = [
        ("trainer", _at("trainer")),
        ("env steps/s", _rate("steps_per_s")),
        ("to style (s)", _at("time_to_style_s")),
        ("steps to style", _at("steps_to_style")),
        ("final step", _at("final.step")),
        ("style error (rad)", _at("final.style_error")),
        ("speed (m/s)", _at("final.forward_speed_m_s")),
        ("episode length", _at("final.length")),
    ]
    lines = []
    for path in _files("amp/**/amp_gpu_*.json"):
        data = json.loads(path.read_text())
        rows = [{"trainer": name, **data[name]} for name in ("ppo", "amp") if isinstance(data.get(name), dict)]
        teacher = data["teacher"]
        lines += [
            f"**[{path.relative_to(RESULTS / 'amp').as_posix()}]({_link(path)})** ({_card(data, path)}; "
            f"teacher: style error {teacher['style_error']} rad at {teacher['forward_speed_m_s']} m/s)",
            "",
            *_notes(data),
            *_table(rows, columns),
            "",
        ]
    return _section("AMP: walking in a teacher's style", prose, lines)


def planning() -> list[str]:
    prose = """
`benchmarks/planner_latency.py`: a replan's latency on a GPU against bare MJX rollouts of
the same samples x horizon. Latency, not throughput, bounds it: a sequential physics step
costs 0.6-1 ms whatever the batch up to ~1024 samples, so a humanoid plans on a coarse
model (0.025 s physics steps, 1 solver iteration). XLA's default GPU command buffers
matter (without them a replan is 4x slower); capturing while loops bought nothing.
"""
    latency = [
        ("env", _at("env")),
        ("planner", _at("planner")),
        ("samples", _at("samples")),
        ("horizon (steps)", _at("horizon_steps")),
        ("horizon (s)", _at("horizon_s")),
        ("replan (ms)", _at("plan_ms")),
        ("bare rollouts (ms)", _at("bare_ms")),
        ("overhead", _percent("overhead")),
        ("ms per physics step", _at("ms_per_physics_step")),
        ("replans/s", _at("plan_hz")),
    ]
    cpu_prose = """
`benchmarks/planner_cpu.py`, side by side with Judo (`judo-rai` 0.1.0 in its own venv:
`bash benchmarks/judo_env.sh`) on a 2-core CPU: Judo's shipped settings (4 knots, a 1 s
horizon, replanning every 0.05 s of simulated time), 2 rollout threads each. mjzoo's
*native* backend rolls out in C MuJoCo through `mujoco.rollout` and scores the samples
with the task's own JAX reward; *mjx* is MJX on the CPU. Replan times are medians; the
rollouts are C MuJoCo's share, the rest everything but physics. The LEAP cube
(`--tasks leap_cube`, Judo's LEAP settings, which `leap_cube_rotate` registers): its
success is 10 goals in a row without a drop within the run (40 s, then 120 s: `_120s`);
`_judo` puts Judo on its own LEAP task beside it, offline, with Menagerie's LEAP meshes in
place of the ones Judo downloads (visual only in its scene). Each peer plans on its own
scene there: Judo's has elliptic friction cones, 100 Newton iterations and the cube's
pips as collision geoms, mjzoo's is Playground's. Clock `wall`: in real time (the world
does not wait for a replan).
The score is the task's own measure, averaged over seeds: the cart-pole's worst angle
from upright over the last second (rad), the push's final distance (m), the LEAP cube's
goals in a row.
"""
    cpu = [
        ("task", _at("task")),
        ("planner", _at("planner")),
        ("samples", _at("num_samples")),
        ("who", _at("peer")),
        ("backend", _at("backend")),
        ("clock", _at("clock")),
        ("replan (ms)", _at("replan_ms.median")),
        ("p95 (ms)", _at("replan_ms.p95")),
        ("rollouts (ms)", _at("rollout_ms.median")),
        ("rest (ms)", _at("overhead_ms.median")),
        ("success", _at("success_rate")),
        ("score", _at("score")),
        ("seeds", _at("seeds")),
    ]
    return _section(
        "Planning latency",
        prose,
        _file_tables("planner_latency_gpu*.json", latency),
        _file_tables("warp/planner_latency_*.json", latency),
        _file_tables(
            "warp/planner_graph_modes.json",
            [
                ("Warp graph mode", _at("mode")),
                *[(f"bare, {n} samples (ms)", _at(f"bare_ms_{n}")) for n in (64, 256, 1024, 4096)],
                ("replan, 1024 (ms)", _at("plan_ms_1024")),
            ],
            lambda data: data,
        ),
        ["### Planning on a CPU, against Judo", "", *cpu_prose.strip().splitlines(), ""],
        _file_tables("planner_cpu/planner_cpu*.json", cpu),
    )


def robot_mpc() -> list[str]:
    prose = """
`benchmarks/robot_mpc.py`: sampling planners on the real robots in real time
(`mjzoo.planning.realtime`, as `mjzoo plan` runs): the simulation advances with the wall
clock and waits for no replan, so a slow planner acts late, as it would on a robot. The
planner's model is the task's own MJX physics, on one GPU; the world steps there too
(world `mjx`) or in C MuJoCo on the host (`native`, `robot_mpc.py --world`). Success is the
task's own measure (G1 standup: the pelvis within 0.1 m of standing height over the
last second); replan times are medians over each episode's replans, averaged over
episodes. A replan scans the horizon's physics steps in sequence, each over all samples
at once, so the replan over those steps (ms / physics step: one batched MJX step; DIAL
runs its iterations' rollouts in it) is what bounds the rate: the contact-rich G1
(49 contact pairs, 5 solver iterations) costs ~9 times the Go1's. Physics `warp`, world
`mjx`: the planner on MuJoCo Warp and its world on Warp too (run before a Warp planner
could start from C MuJoCo's states); one G1 world's Warp step took 20-37 ms of each 20 ms
control step, so those loops ran at half real time and their replans/s are low for that
reason. Their ms / physics step, the planner's own, hardly moves from 256 to 1024
samples (1.27, 1.48): a per-step floor of kernel launches, where MJX-JAX's grows with
the batch (2.64, 4.23). Clock `simulated` (`--clock simulated`): the world waits for each
replan, so success says whether the planner can do the task at one replan a control
step, apart from its rate; plan physics (`--plan-physics`) is the planner's model where
it is coarser than the world's (a longer step, fewer solver iterations). Actions: where
the planners sampled these robots' actions (servo-target offsets in [-1, 1]). Until
7a83dd6 they sampled them inside the joints' ctrlranges, with noise scaled by them, so
most joints could reach only part of their targets' range (the Go1's knee targets never
within 0.44 rad of its pose): those rows measure rates soundly, their success a crippled
search.
"""
    columns = [
        ("task", _at("task")),
        ("planner", _at("planner")),
        ("samples", _at("num_samples")),
        ("horizon (s)", _at("horizon_s")),
        ("physics", _at("impl")),
        ("world", _at("world")),
        ("clock", _at("clock")),
        ("plan physics", _options("plan_physics")),
        ("actions", _at("actions")),
        ("replan (ms)", _at("replan_ms.median")),
        ("p95 (ms)", _at("replan_ms.p95")),
        ("ms / physics step", _at("ms_per_physics_step")),
        ("replans/s", _at("plan_hz")),
        ("success", _at("success_rate")),
        ("score", _at("score")),
        ("episodes", _at("episodes")),
    ]
    return _section("Whole-body MPC on the robots", prose, _file_tables("robot_mpc/robot_mpc_*.json", columns))


def guided_mpc() -> list[str]:
    if not _files("guided_mpc/guided_mpc_*.json"):  # measured on a GPU: no section until then
        return []
    prose = """
`benchmarks/guided_mpc.py`: MPPI plain and guided by a PPO policy trained on the task
(`mjzoo.planning.prior.residual`: the planner samples offsets to the policy's actions,
which rollouts and the world apply in closed loop, and values the horizon's end by the
policy's critic) at equal samples, beside the policy alone; the task's own success
measure over the episodes, the world in C MuJoCo, the planner on MuJoCo Warp. Clock
`simulated`: the world waits for each replan, so the rows compare what each planner
finds with its samples.
"""
    columns = [
        ("task", _at("task")),
        ("planner", _at("planner")),
        ("samples", _at("num_samples")),
        ("success", _at("success_rate")),
        ("score", _at("score")),
        ("replan (ms)", _at("replan_ms")),
    ]
    return _section("Policy-guided sampling", prose, _file_tables("guided_mpc/guided_mpc_*.json", columns))


def _motion_rows(data: dict) -> list[dict]:
    """One row per part and seed of benchmarks/motion.py's JSON (its last evaluation; a
    clip set's worst clip), one per planner and sample count for the MPC."""
    out = []
    for row in data["rows"]:
        if row["part"] == "mpc":
            out += [
                {"part": "mpc", "impl": row.get("impl", "jax"), **r, "seconds": r["steps"] / r["replan_hz"]}
                for r in row["rows"]
            ]
            continue
        for run in row["runs"]:
            final = run["final"]
            success = [v for k, v in final.items() if k.endswith("/success")]
            mpjpe = [v for k, v in final.items() if k.endswith("/mpjpe_mm")]
            out.append(
                {
                    "part": row["part"],
                    "impl": row.get("impl", "jax"),
                    "seed": run["seed"],
                    **final,
                    "success": min(success) if success else None,
                    "mpjpe_mm": max(mpjpe) if mpjpe else None,
                    "seconds_to_goal": run["seconds_to_goal"],
                }
            )
    return out


def motion() -> list[str]:
    prose = """
`benchmarks/motion.py`: human motion on the G1 from its retargeted clips. *walk*: PPO on
`g1_track(clips="walk")`, seeds vmapped in one program, until every seed tracks (success
>= 0.95, MPJPE <= 50 mm); *all*: one policy on every committed clip (its worst clip
shown); *amp*: AMP on `g1_amp_joystick` (style error against the clips' nearest window,
command error, falls over 64 episodes); *mpc*: MPPI and CEM tracking the walk clip
closed loop. Times are wall-clock from the part's start, compile included; a row is the
part's last evaluation. The main file's MJX-JAX walk shared its GPU with another run,
its MuJoCo Warp walk had one alone; `motion_nvidia_h200_unshared.json` is the MJX-JAX
walk alone on one, stopped by a 540 s budget.
"""
    columns = [
        ("part", _at("part")),
        ("physics", _at("impl")),
        ("seed", _at("seed")),
        ("planner", _at("planner")),
        ("samples", _at("num_samples")),
        ("env steps", _at("step")),
        ("seconds", _at("seconds")),
        ("success", _at("success")),
        ("MPJPE (mm)", _at("mpjpe_mm")),
        ("style error (rad)", _at("style_error")),
        ("command error (m/s)", _at("command_error")),
        ("falls", _at("falls")),
        ("replans/s", _at("replan_hz")),
        ("to goal (s)", _at("seconds_to_goal")),
    ]
    return _section("Human motion on the G1", prose, _file_tables("motion/motion_*.json", columns, _motion_rows))


def _offpolicy_rows(data: dict) -> list[dict]:
    """One row per task, algorithm and seed, with its steps and seconds to 95% of PPO's
    mean final return in the same run."""
    out = []
    for task, entry in data["tasks"].items():
        bar = 0.95 * entry["summary"]["ppo_return"]
        for run in entry["runs"]:
            hit = next(((step, sec) for step, sec, ret in run["curve"] if ret >= bar), (None, None))
            best = max(ret for _, _, ret in run["curve"])
            out.append({"task": task, **run, "best": best, "steps_to": hit[0], "seconds_to": hit[1]})
    return out


def offpolicy() -> list[str]:
    prose = """
`benchmarks/offpolicy.py`: SAC and FastTD3 beside PPO on the same task in one process,
each run through the harness (compile included in its seconds). PPO trains its
registered budget; the off-policy learners far fewer env steps. *To 95% of PPO*: env
steps and seconds until a run's evaluation return first reaches 95% of PPO's mean
final return.
"""
    columns = [
        ("task", _at("task")),
        ("learner", _at("algorithm")),
        ("seed", _at("seed")),
        ("env steps", _at("env_steps")),
        ("seconds", _at("wall_s")),
        ("env steps/s", _rate("steps_per_s")),
        ("final return", _at("final_return")),
        ("best return", _at("best")),
        ("steps to 95% of PPO", _at("steps_to")),
        ("seconds to 95% of PPO", _at("seconds_to")),
    ]
    return _section(
        "Off-policy learners beside PPO", prose, _file_tables("offpolicy/offpolicy*.json", columns, _offpolicy_rows)
    )


def scaling() -> list[str]:
    prose = """
`benchmarks/scaling.py`: PPO (and AMP) on several GPUs of one host, the env batch sharded
and each gradient step split over the devices (`split_minibatches`); `num_envs` x N with
`unroll_length` / N keeps one GPU's learning per env step. The learner caps the speedup:
its ~130 kernels a step are bound by latency. MuJoCo Warp trains on one GPU only (split
over two, its program crashed XLA's GPU compiler). [scaling.md](scaling.md) explains the
recipes.
"""
    columns = [
        ("algorithm", _at("algorithm")),
        ("recipe", _at("recipe")),
        ("devices", _at("devices")),
        ("processes", _at("processes")),
        ("physics", _at("impl")),
        ("seed", _at("seed")),
        ("envs", _at("num_envs")),
        ("unroll", _at("unroll_length")),
        ("env steps/s", _rate("steps_per_s")),
        ("speedup", _at("speedup")),
        ("efficiency", _at("efficiency")),
        ("to threshold (s)", _at("time_to_threshold_s")),
        ("final return", _at("final_return")),
        ("error", _at("error")),
    ]
    return _section("Several GPUs", prose, _file_tables("scaling/*.json", columns))


def startup() -> list[str]:
    prose = """
`benchmarks/startup.py`: from launching `mjzoo train ppo` to its first update, on a fresh
machine (*cold*: nothing cached) and again with JAX's persistent compile cache warm. The
training chunk is traced on the launching thread and compiled, or loaded from the cache,
on its own while init compiles; importing `mjzoo` costs ~3.7 s of a warm launch (1.5 s of
it `trimesh`, which MJX imports), loading the chunk's executable from the cache ~2 s.
Fresh machines differ by 2-3 s.
"""
    columns = [
        ("env", _at("env")),
        ("variant", _at("variant")),
        ("round", _at("round")),
        ("cold: launch to first update (s)", _at("cold_launch_to_first_update_s")),
        ("warm (s)", _at("warm_launch_to_first_update_s")),
        ("cold: inside training.run (s)", _at("cold_first_update_s")),
        ("warm (s) ", _at("warm_first_update_s")),
    ]
    return _section("Starting a run", prose, _file_tables("startup/*.json", columns))


def physics() -> list[str]:
    prose = """
`benchmarks/task_overhead.py`: the task layer (`mjzoo.transition`, then with an
auto-reset) against raw batched `mjx.step`; overheads are relative to raw stepping. A
batch computes its new episodes in one `lax.cond`, only on steps where some env ended.
`benchmarks/warp_conformance.py`: every env through `check_task` on MuJoCo Warp, bare and
under the combinator stack; bit-exact repeats are the one property atomics in Warp's
kernels break (by up to 4e-6). Warp launches in 73 s cold, its kernel build included.
`benchmarks/tree_ab.py` compares two source trees' training rates on one warm card.
"""
    overhead = [
        ("env", _at("env")),
        ("physics", _at("impl")),
        ("batch", _at("batch")),
        ("raw steps/s", _rate("raw_steps_per_s")),
        ("transition", _rate("transition_steps_per_s")),
        ("overhead", _percent("transition_overhead")),
        ("with auto-reset", _rate("auto_reset_steps_per_s")),
        ("overhead ", _percent("auto_reset_overhead")),
    ]
    conformance = [
        ("env", _at("env")),
        ("stack", _at("stack")),
        ("passes", _at("ok")),
        ("failed", lambda r: ", ".join(k for k, v in r.get("properties", {}).items() if v != "pass") or None),
        ("seconds", _at("seconds")),
    ]
    tree = [
        ("algorithm", _at("algorithm")),
        ("env", _at("env")),
        ("steps", _at("steps")),
        ("base steps/s", _rate("steps_per_s.base")),
        ("new steps/s", _rate("steps_per_s.new")),
        ("new / base", _at("ratio_to_base.new")),
    ]
    return _section(
        "Physics and the task layer",
        prose,
        _file_tables("task_overhead_*.json", overhead),
        _file_tables("warp/task_overhead_*.json", overhead),
        _file_tables("warp/conformance_*.json", conformance, _at("conformance")),
        _file_tables("tree_ab/*.json", tree),
    )


def sim2sim() -> list[str]:
    prose = """
`scripts/sim2sim.py`: a trained `humanoid_walk` policy, exported to ONNX, earns in C MuJoCo
the returns its JAX evaluation gives, episode by episode (observation noise off in both).
"""
    path = RESULTS / "sim2sim" / "humanoid_walk.json"
    data = json.loads(path.read_text())
    columns = [
        ("episode", _at("episode")),
        ("JAX return", _at("jax_return")),
        ("C MuJoCo return", _at("c_return")),
        ("relative difference", _at("relative_difference")),
        ("largest observation error", _at("obs_error")),
    ]
    return _section(
        "Sim-to-sim: the exported policy in C MuJoCo",
        prose,
        [f"**[{path.name}]({_link(path)})** ({data['episodes']} episodes of {data['steps']} steps)", ""],
        _table(data["rows"], columns),
        [""],
    )


def render() -> str:
    lines = [
        "# Benchmarks",
        "",
        "Generated by `python benchmarks/report.py` from the JSON in `benchmarks/results/`; do not",
        "edit it by hand (the suite checks that it is the script's output). Each section names the",
        "script that measures it; each table, the file it comes from and the card it ran on.",
        "",
        *robots(),
        *learning_quality(),
        *ppo_stability(),
        *ppo_vs_brax(),
        *playground(),
        *locomotion(),
        *amp(),
        *motion(),
        *offpolicy(),
        *planning(),
        *robot_mpc(),
        *guided_mpc(),
        *scaling(),
        *startup(),
        *physics(),
        *sim2sim(),
    ]
    return "\n".join(lines).rstrip() + "\n"


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT / "scripts"))  # the write-or-check step every generated page shares
    import generated_page

    generated_page.main(PAGE, render, __doc__)
