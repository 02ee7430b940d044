"""The `mjzoo` command's surface: a user's mistake is one line on stderr and exit status 2,
found before anything is compiled or written; damaged checkpoints are skipped with a
warning. Errors here fire before any MJX compile, except where a template train state
is needed (PPO's init, compiled once for the module)."""

from __future__ import annotations

import argparse
import dataclasses
import glob
import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tyro

import mjzoo.envs
from mjzoo import learning
from mjzoo.algorithms import ppo
from mjzoo.harness import checkpoints
from mjzoo.harness import cli
from mjzoo.harness import rendering
from mjzoo.harness import training
from mjzoo.harness.cli.arguments import parse_assignments

ENV = "pendulum_swingup"
TINY = dict(num_envs=8, unroll_length=8, num_minibatches=2, num_epochs=1, total_steps=128)


def run_cli(capsys, *argv: str) -> tuple[int | str | None, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        cli.main(list(argv))
    out, err = capsys.readouterr()
    return exit_info.value.code, out, err


def assert_usage_error(capsys, argv: list[str], *words: str) -> str:
    """Exit status 2 and exactly one line, `mjzoo COMMAND: ...`, holding `words`."""
    code, _, err = run_cli(capsys, *argv)
    lines = err.splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"mjzoo {argv[0]}: "), err
    for word in words:
        assert word in lines[0], (word, err)
    return lines[0]


def snapshot(directory: Path) -> dict[str, tuple[bytes | None, int]]:
    """Every path under `directory` with its bytes (files) and mtime."""
    return {
        str(p): (p.read_bytes() if p.is_file() else None, p.stat().st_mtime_ns)
        for p in [directory, *sorted(directory.rglob("*"))]
    }


def write_run(directory: Path, algorithm: str = "ppo", **config) -> Path:
    """task.json and config.json as `mjzoo train` writes them (no checkpoints yet)."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "task.json").write_text(json.dumps({"env": ENV, "overrides": {}}))
    structure, numbers = ppo.configure(**{**TINY, **config})
    fields = {"config": training.config_dict(structure), "hyperparams": training.hyperparams_dict(numbers)}
    (directory / "config.json").write_text(json.dumps({"algorithm": algorithm, **fields, "settings": {}}))
    return directory


def test_assignments_read_python_literals_and_inf():
    pairs = ("a=1", "b=(64, 64)", "c=swish", "d=(0.7, inf)", "e=-inf", "f=info")
    assert parse_assignments(pairs, "--env-overrides") == {
        "a": 1,
        "b": (64, 64),
        "c": "swish",
        "d": (0.7, float("inf")),  # a published healthy range
        "e": -float("inf"),
        "f": "info",
    }


def damage(directory: Path, step: int) -> None:
    """Truncates the array data of checkpoint `step`, as a full disk would."""
    files = glob.glob(str(directory / str(step) / "arrays" / "d" / "*"))
    assert files
    for name in files:
        Path(name).write_bytes(b"")


@pytest.mark.parametrize(
    "argv, words",
    [
        (["train", "ppo", "cartpole_balanse"], ["unknown env 'cartpole_balanse'", "did you mean 'cartpole_balance'"]),
        (["demo", "--env", "pendulum", "--steps", "5"], ["unknown env 'pendulum'", "pendulum_swingup"]),
        (["plan", "mppi", "cartpole_balanse"], ["unknown env 'cartpole_balanse'"]),
        (["plan", "mppi", "cartpole_balance"], ["'cartpole_balance' has no planning setup", "pendulum_swingup"]),
        (["train", "ppo", ENV, "--config", "num_envs=-3"], ["num_envs=-3", "integer >= 1"]),
        (["train", "ppo", ENV, "--config", "nonsense=1"], ["--config: unknown field(s) ['nonsense']", "num_envs"]),
        (["train", "ppo", ENV, "--config", "num_env=8"], ["unknown field(s) ['num_env'] (did you mean 'num_envs'?)"]),
        (["train", "ppo", ENV, "--config", "num_envs"], ["--config: expected NAME=VALUE, got 'num_envs'"]),
        (["train", "ppo", ENV, "--config", "learning_rate=abc"], ["learning_rate='abc' must be a number"]),
        (
            ["train", "ppo", ENV, "--config", "policy_hidden_sizes=64"],
            ["policy_hidden_sizes=64 must be a tuple of int"],
        ),
        (["train", "ppo", ENV, "--config", "activation=gelu"], ["activation='gelu' must be one of 'swish'"]),
        (["plan", "mppi", ENV, "--config", "num_samples=many"], ["num_samples='many' is invalid; expected an int"]),
        (["train", "ppo", ENV, "--env-overrides", "nope=1"], ["unknown override(s) ['nope']", "upright_weight"]),
        (
            ["train", "ppo", ENV, "--env-overrides", "episode_steps=abc"],
            [f"{ENV}: override episode_steps='abc' must be an int"],
        ),
        (
            ["train", "ppo", ENV, "--env-overrides", "upright_weight=[1,2]"],
            ["override upright_weight=[1, 2] must be a number"],
        ),
        (["train", "ppo", ENV, "--env-overrides", "solver=pgs"], ["physics option solver='pgs'"]),
        (["demo", "--num-envs", "0"], ["--num-envs must be >= 1, got 0"]),
        (["plan", "mppi", ENV, "--seconds", "-1"], ["--seconds must be > 0"]),
        (["eval", "no/such/run"], ["no/such/run: no such run directory"]),
        (["train", "ppo", ENV, "--resume", "no/such/run"], ["--resume no/such/run: no such run directory"]),
    ],
)
def test_a_mistake_is_one_line_and_status_2(capsys, tmp_path, monkeypatch, argv, words):
    monkeypatch.chdir(tmp_path)
    assert_usage_error(capsys, argv, *words)
    assert list(tmp_path.iterdir()) == []  # nothing written (no runs/ directory either)


def test_envs_that_do_not_split_over_the_devices_are_one_line(capsys, tmp_path, monkeypatch):
    """Three devices (this one, thrice) and 8 envs: refused before anything is written."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(jax, "devices", lambda *backend: [jax.local_devices()[0]] * 3)
    assert_usage_error(
        capsys,
        ["train", "ppo", ENV, "--config", "num_envs=8"],
        "8 envs do not split evenly over 3 devices",
        "multiple of 3",
    )
    assert list(tmp_path.iterdir()) == []


def test_an_unknown_algorithm_is_tyros_short_usage_error(capsys):
    code, _, err = run_cli(capsys, "train", "ppx", ENV)
    assert code == 2 and "Traceback" not in err
    assert "invalid choice 'ppx'" in err and "'ppo'" in err and "mjzoo train --help" in err
    assert len(err.strip().splitlines()) <= 8


@pytest.mark.parametrize("command", ["eval", "train"])
def test_an_incomplete_run_directory_is_named(capsys, tmp_path, command):
    def argv(run: Path) -> list[str]:
        return ["eval", str(run)] if command == "eval" else ["train", "ppo", ENV, "--resume", str(run)]

    flag = "--resume " if command == "train" else ""
    (tmp_path / "empty").mkdir()
    assert_usage_error(
        capsys, argv(tmp_path / "empty"), f"{flag}{tmp_path / 'empty'}: not a complete run", "no config.json"
    )
    run = write_run(tmp_path / "run")
    (run / "config.json").unlink()
    assert_usage_error(capsys, argv(run), "no config.json")
    (run / "config.json").write_text("{not json")
    assert_usage_error(capsys, argv(run), "config.json is not valid JSON")
    write_run(run)
    before = snapshot(run)
    assert_usage_error(capsys, argv(run), "not a complete run", f"no checkpoint in {run / 'checkpoints'}")
    assert snapshot(run) == before
    (tmp_path / "notes.txt").write_text("x")
    assert_usage_error(capsys, argv(tmp_path / "notes.txt"), "not a directory")


def test_resume_must_match_the_run_it_continues(capsys, tmp_path):
    run = write_run(tmp_path / "run")
    checkpoints.save(run / "checkpoints", 64, {"x": jnp.zeros(1)})
    before = snapshot(run)
    assert_usage_error(
        capsys,
        ["train", "ppo", "cartpole_balance", "--resume", str(run)],
        f"that run's env is {ENV}, not cartpole_balance",
    )
    assert_usage_error(
        capsys,
        ["train", "ppo", ENV, "--resume", str(run), "--env-overrides", "episode_steps=9"],
        "--env-overrides: a resumed run keeps",
    )
    assert_usage_error(capsys, ["train", "ppo", ENV, "--resume", str(run), "--out", str(tmp_path / "b")], "give one")
    assert snapshot(run) == before


@pytest.mark.parametrize("marker", ["config.json", "metrics.jsonl", "checkpoints"])
def test_train_refuses_an_out_that_holds_a_run_and_touches_nothing(capsys, tmp_path, monkeypatch, marker):
    out = tmp_path / "runs" / f"{ENV}-ppo"  # also the default --out
    out.mkdir(parents=True)
    if marker == "checkpoints":
        checkpoints.save(out / "checkpoints", 64, {"x": jnp.zeros(1)})
    else:
        (out / marker).write_text('{"step": 64}\n')
    (out / "curves.png").write_bytes(b"\x89PNG")
    before = snapshot(tmp_path)
    monkeypatch.chdir(tmp_path)
    for extra, where in ((["--out", str(out)], out), ([], Path("runs") / f"{ENV}-ppo")):
        line = assert_usage_error(capsys, ["train", "ppo", ENV, *extra], f"--out {where} already holds a run", marker)
        assert line.endswith(f"continue it with --resume {where}, or choose a new --out")
    assert snapshot(tmp_path) == before


def test_plan_refuses_an_out_that_holds_a_plan_run(capsys, tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "summary.json").write_text("{}")
    (tmp_path / "file").write_text("")
    before = snapshot(tmp_path)
    assert_usage_error(
        capsys, ["plan", "mppi", ENV, "--out", str(tmp_path / "run")], "already holds a run (summary.json)"
    )
    assert_usage_error(capsys, ["plan", "mppi", ENV, "--out", str(tmp_path / "file")], "is a file, not a directory")
    assert snapshot(tmp_path) == before


@pytest.fixture(scope="module")
def ppo_state():
    """PPO's initial train state for TINY on the env (one compile for the module)."""
    config, hyperparams = ppo.configure(**TINY)
    return ppo.init(config, mjzoo.envs.make(ENV), hyperparams, jax.random.key(0))


def test_eval_falls_back_past_a_damaged_checkpoint(capsys, tmp_path, monkeypatch, ppo_state):
    """The warning is one line and the older state is the one evaluated (evaluation
    itself is faked: it reports the restored update count as the return)."""
    run = write_run(tmp_path / "run")
    for step, updates in ((64, 1), (128, 2)):
        checkpoints.save(run / "checkpoints", step, dataclasses.replace(ppo_state, updates=ppo_state.updates + updates))
    damage(run / "checkpoints", 128)

    def evaluate(config, task, state, key, episodes, steps):
        return state.updates.astype(jnp.float32), jnp.zeros(episodes), None

    monkeypatch.setattr(ppo, "evaluate", evaluate)
    monkeypatch.setattr(training, "write_video", lambda task, trajectory, path, config=None: None)
    cli.main(["eval", str(run), "--episodes", "2"])
    out, err = capsys.readouterr()
    assert f"{ENV}: mean return 1.00" in out
    lines = err.splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"mjzoo eval: warning: {run / 'checkpoints'}: checkpoint 128 is damaged (")
    assert lines[0].endswith("restored checkpoint 64, the newest intact one")
    assert checkpoints.all_steps(run / "checkpoints") == [64, 128]  # eval leaves the run as it was


@pytest.mark.parametrize("command", ["eval", "train"])
def test_only_damaged_checkpoints_is_status_2_and_touches_nothing(capsys, tmp_path, command, ppo_state):
    run = write_run(tmp_path / "run")
    for step in (64, 128):
        checkpoints.save(run / "checkpoints", step, ppo_state)
        damage(run / "checkpoints", step)
    before = snapshot(run)
    argv = ["eval", str(run)] if command == "eval" else ["train", "ppo", ENV, "--resume", str(run)]
    line = assert_usage_error(
        capsys, argv, f"no intact checkpoint in {run / 'checkpoints'}: checkpoint 128 is damaged ("
    )
    assert "; checkpoint 64 is damaged (" in line
    assert snapshot(run) == before


def test_plan_takes_a_trained_runs_policy_as_its_prior(capsys, tmp_path, ppo_state):
    """`--prior RUN` restores RUN's newest checkpoint into every replan (its effect on
    planning is tests/planning/test_prior.py's) and the summary names the run."""
    run = write_run(tmp_path / "run")
    checkpoints.save(run / "checkpoints", 128, ppo_state)
    out = tmp_path / "plan"
    argv = ["plan", "mppi", ENV, "--prior", str(run), "--offline", "--seconds", "0.4", "--no-video", "--out", str(out)]
    cli.main([*argv, "--config", "num_samples=4", "horizon_steps=4"])
    capsys.readouterr()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["prior"] == str(run) and np.isfinite(summary["final_cost"])
    assert_usage_error(capsys, [*argv[:4], str(tmp_path / "none"), *argv[5:-1], str(tmp_path / "p2")], "none")


def test_resuming_a_checkpoint_of_another_state_is_status_2(capsys, tmp_path, ppo_state):
    """A mismatch is not damage: every checkpoint would mismatch alike, none is skipped."""
    run = write_run(tmp_path / "run")
    checkpoints.save(run / "checkpoints", 64, ppo_state)
    checkpoints.save(run / "checkpoints", 128, {"params": jnp.zeros(3)})
    before = snapshot(run)
    assert_usage_error(
        capsys,
        ["train", "ppo", ENV, "--resume", str(run)],
        f"checkpoint 128 in {run / 'checkpoints'} does not match the template",
    )
    assert snapshot(run) == before


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Count:
    updates: jax.Array
    total: jax.Array


def counter(num_updates: int) -> learning.Algorithm:
    """An algorithm value whose state counts its updates."""
    return learning.Algorithm(
        name="counter",
        config=None,
        hyperparams=None,
        init=_count_init,
        update=_count_update,
        evaluate=_count_evaluate,
        steps_per_update=10,
        num_updates=num_updates,
    )


def _count_init(task, hyperparams, key):
    return Count(jnp.zeros((), jnp.int32), jnp.zeros(()))


def _count_update(task, s):
    return Count(s.updates + 1, s.total + 1.0), {"loss/total": s.total}


def _count_evaluate(task, s, key, n, steps):
    return learning.Evaluation(jnp.full(n, s.total), jnp.full(n, steps), None)


def test_training_resumes_from_the_newest_intact_checkpoint(tmp_path):
    """A resume skips a damaged newest checkpoint (warning), sets it aside, cuts
    metrics.jsonl back and trains on to the same end, saving that step anew."""
    settings = training.Settings(
        out_dir=tmp_path, updates_per_chunk=1, eval_steps=1, video=False, progress=False, checkpoint_every=1
    )
    training.run(counter(3), {}, settings)
    damage(tmp_path / "checkpoints", 30)
    with pytest.warns(checkpoints.DamagedCheckpointWarning, match="checkpoint 30 is damaged .*restored checkpoint 20"):
        state, last = training.run(counter(4), {}, dataclasses.replace(settings, resume=True))
    assert int(state.updates) == 4 and last["eval/return"] == 4.0
    assert checkpoints.all_steps(tmp_path / "checkpoints") == [20, 30, 40]
    assert (tmp_path / "checkpoints" / "30.damaged").is_dir()
    steps = [json.loads(line)["step"] for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert steps == [10, 20, 30, 40]


def test_a_bug_past_the_checks_keeps_its_exception(tmp_path, monkeypatch):
    """Only the checks' errors are the user's: a ValueError from inside training is a bug."""

    def broken(algorithm, task, settings, hyperparams=None):
        raise ValueError("a bug deep inside")

    monkeypatch.setattr(training, "run", broken)
    with pytest.raises(ValueError, match="a bug deep inside"):
        cli.main(["train", "ppo", ENV, "--out", str(tmp_path / "run")])


def test_subprocess_errors_have_no_traceback(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "mjzoo", "train", "ppo", ENV, "--config", "num_envs=-3"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.splitlines() == ["mjzoo train: ppo.Config: num_envs=-3 is invalid; expected an integer >= 1"]
    assert list(tmp_path.iterdir()) == []


def test_only_damaged_checkpoints_in_a_fresh_process_is_one_line(tmp_path, ppo_state):
    """Outside pytest (which takes them over) orbax's abandoned reads would print
    "Event loop is closed" tracebacks after the error: they must not reach stderr."""
    run = write_run(tmp_path / "run")
    for step in (64, 128):
        checkpoints.save(run / "checkpoints", step, ppo_state)
        damage(run / "checkpoints", step)
    result = subprocess.run(
        [sys.executable, "-m", "mjzoo", "eval", "run"], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 2 and result.stdout == ""
    (line,) = result.stderr.splitlines()
    assert line.startswith(
        "mjzoo eval: no intact checkpoint in run/checkpoints: checkpoint 128 is damaged (ValueError: "
    )


def test_a_closed_stdout_ends_quietly():
    """`mjzoo envs | head -1`: the reader is gone before anything is written."""
    with subprocess.Popen(
        [sys.executable, "-m", "mjzoo", "envs"], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    ) as process:
        process.stdout.close()
        err = process.stderr.read().decode()
        assert process.wait(timeout=120) == 1
    assert err == "", err  # no BrokenPipeError, at the print or at the exit's flush


def test_resume_keeps_the_runs_own_settings(capsys, tmp_path, monkeypatch, ppo_state):
    """--seed, --eval-envs and --updates-per-chunk come back from config.json, so a resume
    continues the run it was (its chunk size decides where training stops)."""
    run = write_run(tmp_path / "run")
    info = json.loads((run / "config.json").read_text())
    info["settings"] = {"seed": 3, "eval_envs": 2, "updates_per_chunk": 1, "video": False}
    (run / "config.json").write_text(json.dumps(info))
    checkpoints.save(run / "checkpoints", 64, ppo_state)
    seen = []
    monkeypatch.setattr(training, "run", lambda algorithm, task, settings, hp: (seen.append(settings), (None, {}))[1])
    cli.main(["train", "ppo", ENV, "--resume", str(run), "--no-video"])
    cli.main(["train", "ppo", ENV, "--resume", str(run), "--seed", "5"])
    assert [(s.seed, s.eval_envs, s.updates_per_chunk, s.resume) for s in seen] == [(3, 2, 1, True), (5, 2, 1, True)]
    assert not seen[0].video and seen[1].video


def test_schedule_and_render_flags_reach_the_settings_and_a_resume_keeps_them(tmp_path, monkeypatch, ppo_state):
    """KSim's validation, logging and render options on the command line; a resumed run
    keeps what it started with (config.json) unless the flag is given again."""
    seen, configs = [], []

    def run(algorithm, task, settings, hyperparams):
        seen.append(settings)
        configs.append(algorithm.config)
        return None, {}

    monkeypatch.setattr(training, "run", run)
    run = tmp_path / "run"
    cli.main(
        [
            "train",
            "ppo",
            ENV,
            "--out",
            str(run),
            "--rollout-seconds",
            "0.5",
            "--eval-every",
            "3",
            "--eval-seconds",
            "0.5",
            "--log-every",
            "2",
            "--no-log-train-metrics",
            "--video-every",
            "4",
            "--profile-memory",
            "--checkpoint-every-seconds",
            "300",
            "--render.width",
            "64",
            "--render.contact-points",
            "--render.lookat",
            "0",
            "0",
            "1",
        ]
    )
    new = seen[-1]
    assert configs[-1].unroll_length == 25  # KSim's rollout_length_seconds: 0.5 s of 0.02 s control steps
    assert (new.eval_every, new.eval_seconds, new.log_every, new.log_train_metrics, new.video_every) == (
        3,
        0.5,
        2,
        False,
        4,
    )
    assert (new.checkpoint_every_seconds, new.checkpoint_every) == (300.0, None)
    assert new.profile_memory and new.render == rendering.RenderConfig(width=64, contact_points=True, lookat=(0, 0, 1))
    info = json.loads((write_run(tmp_path / "resumed") / "config.json").read_text())
    info["settings"] = json.loads(json.dumps({k: v for k, v in dataclasses.asdict(new).items() if k != "out_dir"}))
    (tmp_path / "resumed" / "config.json").write_text(json.dumps(info))
    checkpoints.save(tmp_path / "resumed" / "checkpoints", 64, ppo_state)
    cli.main(["train", "ppo", ENV, "--resume", str(tmp_path / "resumed")])
    cli.main(["train", "ppo", ENV, "--resume", str(tmp_path / "resumed"), "--eval-every", "5", "--render.width", "32"])
    kept, changed = seen[-2:]
    assert (kept.eval_every, kept.log_every, kept.render, kept.resume) == (3, 2, new.render, True)
    assert changed.render == dataclasses.replace(new.render, width=32)
    assert (changed.eval_every, changed.log_every) == (5, 2)


def test_training_refuses_a_directory_that_holds_a_run_unless_told(tmp_path):
    """From Python too: no file of an earlier run is touched without resume or overwrite."""
    settings = training.Settings(out_dir=tmp_path, updates_per_chunk=1, eval_steps=1, video=False, progress=False)
    training.run(counter(2), {}, settings)
    before = snapshot(tmp_path)
    with pytest.raises(FileExistsError, match=r"already holds a run \(config.json, metrics.jsonl, checkpoints/"):
        training.run(counter(1), {}, settings)
    assert snapshot(tmp_path) == before
    state, _ = training.run(counter(1), {}, dataclasses.replace(settings, overwrite=True))
    assert int(state.updates) == 1 and checkpoints.all_steps(tmp_path / "checkpoints") == [10]
    steps = [json.loads(line)["step"] for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert steps == [10]


def _own_help(action) -> str:
    """An option's --help without what tyro adds to every one: its default (or
    "required"), and a positional's bare name."""
    text = re.sub(r"\s*\((default: .*|required|fixed to: .*)\)\s*$", "", action.help or "", flags=re.S).strip()
    return "" if text == action.dest else text


@pytest.mark.parametrize("command", sorted(cli.COMMANDS))
def test_every_option_of_every_command_has_a_line_of_help(command):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # tyro's argparse parser: the one --help prints
        parser = tyro.extras.get_parser(cli.COMMANDS[command])
    actions = [a for a in parser._actions if not isinstance(a, argparse._HelpAction)]
    assert actions or command == "envs"
    bare = [a.option_strings[0] if a.option_strings else a.dest for a in actions if not _own_help(a)]
    assert bare == [], f"mjzoo {command}: options without --help: {bare}"
