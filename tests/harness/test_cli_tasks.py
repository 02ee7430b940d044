"""A user's own task on the command line: `package.module:factory` wherever a task is
named (train, eval, plan, collect), found from the current directory as `python -m`
finds modules; a run trained from Python evaluated with --task; `collect`'s dataset
directory. The user's module is written to a temporary directory; its factory is the
pendulum with 20-step episodes, so compiles stay small."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest
from test_cli import TINY  # the command's shared test helpers
from test_cli import assert_usage_error  # the command's shared test helpers
from test_cli import snapshot  # the command's shared test helpers

import mjzoo.envs
from mjzoo import learning
from mjzoo.algorithms import ppo
from mjzoo.algorithms import predictive_sampling
from mjzoo.harness import checkpoints
from mjzoo.harness import cli
from mjzoo.harness import datasets
from mjzoo.harness import training

MODULE = "mjzoo_cli_user_tasks"  # unique: imported modules stay in sys.modules
SPEC = f"{MODULE}:make_pendulum"
USER_TASKS = """
import jax.numpy as jnp
import mjzoo, mjzoo.envs
from mjzoo.envs import base
from mjzoo.envs.base import ASSETS

def make_pendulum(*, episode_steps: int = 20, upright_weight: float = 1.0) -> mjzoo.Task:
    return mjzoo.envs.make("pendulum_swingup", episode_steps=episode_steps, upright_weight=upright_weight)

def upright(p, model, state, action, next_state):
    return jnp.cos(next_state.data.qpos[0] - p["target"])

def make_own(**params):  # as docs/own-task.md writes a factory: its keywords are task parameters
    return mjzoo.task(ASSETS / "pendulum.xml", rewards={"upright": upright}, time_limit=20,
                      params={"target": 3.14, **params}, ctrl_dt=0.02)

def make_heavy(mass: float, episode_steps: int = 20):
    return make_pendulum(episode_steps=episode_steps)

def make_endless():
    return make_pendulum().replace(time_limit=None)  # as if built without mjzoo.with_time_limit

def not_a_task():
    return 3

NUMBER = 3
"""
PLANNED_TASKS = """
from mjzoo.envs import base
from mjzoo_cli_user_tasks import make_pendulum

PLANNING = base.PlanningSetup(seconds=0.1, replan_every=5, plan_overrides={}, configs={"mppi": {"num_samples": 6}},
                              success=None)
"""
BROKEN_TASKS = "import mjzoo_cli_no_such_dependency\n"
PLAN_CONFIG = ["--config", "num_samples=4", "horizon_steps=4", "num_knots=2"]


@pytest.fixture(scope="module")
def user_dir(tmp_path_factory) -> Path:
    """A directory holding the user's modules (not on sys.path: the CLI finds them from
    the current directory)."""
    directory = tmp_path_factory.mktemp("user")
    for name, text in (
        (MODULE, USER_TASKS),
        ("mjzoo_cli_planned_tasks", PLANNED_TASKS),
        ("mjzoo_cli_broken_tasks", BROKEN_TASKS),
    ):
        (directory / f"{name}.py").write_text(textwrap.dedent(text))
    return directory


@pytest.fixture
def in_user_dir(user_dir, monkeypatch) -> Path:
    monkeypatch.chdir(user_dir)
    return user_dir


def test_a_factory_spec_builds_from_python(user_dir, monkeypatch):
    monkeypatch.syspath_prepend(str(user_dir))
    task = mjzoo.envs.make(SPEC, episode_steps=7)
    assert isinstance(task, mjzoo.Task) and int(task.time_limit) == 7
    assert mjzoo.envs.defaults(SPEC) == {"episode_steps": 20, "upright_weight": 1.0}
    assert mjzoo.envs.factory(SPEC).__name__ == "make_pendulum"
    assert mjzoo.envs.hyperparameters(SPEC, "ppo") == {}  # ppo.configure's own defaults
    with pytest.raises(TypeError, match=r"unknown override\(s\) \['mass'\]; make_pendulum takes"):
        mjzoo.envs.make(SPEC, mass=2.0)
    assert mjzoo.envs.accepts(SPEC, "episode_steps") and not mjzoo.envs.accepts(SPEC, "mass")
    assert not mjzoo.envs.accepts(SPEC, "impl")  # its own physics: a resumed run does not pass one
    assert mjzoo.envs.accepts("cartpole_balance", "impl") and mjzoo.envs.accepts("cartpole_balance", "episode_steps")
    assert not mjzoo.envs.accepts("cartpole_balance", "mass")


def test_a_factory_without_planning_plans_one_episode(user_dir, monkeypatch):
    """Default setup: the episode's length (20 steps x 0.02 s), replanning every step, no
    success test; a module's PLANNING is used instead where it has one."""
    monkeypatch.syspath_prepend(str(user_dir))
    config = predictive_sampling.Config(num_samples=4, horizon_steps=4, num_knots=2)
    problem = mjzoo.envs.closed_loop_problem(SPEC, predictive_sampling, config, episode_steps=20)
    assert problem.seconds == pytest.approx(20 * 0.02) and problem.replan_every == 1 and problem.success is None
    assert int(problem.sim_task.time_limit) == 20
    planned = "mjzoo_cli_planned_tasks:make_pendulum"
    assert mjzoo.envs.hyperparameters(planned, "mppi") == {"num_samples": 6}
    assert mjzoo.envs.hyperparameters(planned, "ppo") == {}
    problem = mjzoo.envs.closed_loop_problem(planned, predictive_sampling, config)
    assert problem.seconds == 0.1 and problem.replan_every == 5


@pytest.mark.parametrize(
    "argv, words",
    [
        (
            ["train", "ppo", "mjzoo_cli_nowhere:make"],
            ["task spec 'mjzoo_cli_nowhere:make': no module named 'mjzoo_cli_nowhere'"],
        ),
        (["train", "ppo", f"{MODULE}.sub:make"], [f"no module named '{MODULE}.sub'"]),
        (["train", "ppo", f"{MODULE}:nothing"], [f"module '{MODULE}' has no attribute 'nothing'"]),
        (["train", "ppo", f"{MODULE}:NUMBER"], ["NUMBER is not callable (type int)"]),
        (
            ["train", "ppo", f"{MODULE}:not_a_task"],
            [f"{MODULE}:not_a_task: returned a value of type int, not a mjzoo.Task"],
        ),
        (["train", "ppo", f"{MODULE}:"], ["expected a registered env or package.module:factory"]),
        (
            ["train", "ppo", SPEC, "--env-overrides", "mass=2"],
            ["unknown override(s) ['mass']; make_pendulum takes ['episode_steps', 'upright_weight']"],
        ),
        (
            ["train", "ppo", SPEC, "--env-overrides", "episode_steps=abc"],
            [f"{SPEC}: override episode_steps='abc' must be an int"],
        ),
        (
            ["train", "ppo", f"{MODULE}:make_heavy"],
            ["required argument(s) ['mass'] not given; make_heavy takes ['mass', 'episode_steps']"],
        ),
        (["train", "ppo", SPEC, "--config", "num_envs=-3"], ["num_envs=-3", "integer >= 1"]),
        (["train", "ppo", f"{MODULE}:make_endless"], ["make_endless: the task has no time limit"]),
        (["plan", "mppi", f"{MODULE}:make_endless"], ["make_endless: the task has no time limit", "give seconds"]),
        (["plan", "mppi", f"{MODULE}:nothing"], ["has no attribute 'nothing'"]),
        (["plan", "mppi", SPEC, "--env-overrides", "mass=2"], ["unknown override(s) ['mass']"]),
        (["collect", "mppi", "--out", "data"], ["--task: a planner needs the task to plan on"]),
        (["collect", "mppi", "--task", SPEC, "--out", "x.npz"], ["--out x.npz: names a directory", "e.g. --out x"]),
        (["collect", "mppi", "--task", SPEC, "--out", f"{MODULE}.py"], [f"--out {MODULE}.py: is a file, not a dir"]),
        (["collect", "mppi", "--task", SPEC, "--out", "data", "--sampled"], ["--sampled: only for a run's policy"]),
        (["collect", "no/such/run", "--out", "data"], ["no/such/run: no such run directory"]),
        (["collect", "no/such/run", "--out", "data", "--config", "num_envs=2"], ["--config: only for a planner"]),
        (["collect", "mppi", "--task", SPEC, "--out", "data", "--episodes", "0"], ["--episodes must be >= 1, got 0"]),
        (["collect", "mppi", "--task", SPEC, "--out", "data", "--steps", "0"], ["--steps must be >= 1, got 0"]),
    ],
)
def test_a_mistake_in_a_users_task_is_one_line_and_status_2(capsys, in_user_dir, argv, words):
    before = snapshot(in_user_dir)
    assert_usage_error(capsys, argv, *words)
    assert snapshot(in_user_dir) == before  # nothing written


def test_a_missing_import_inside_the_users_module_keeps_its_traceback(in_user_dir):
    """Only the spec's own module missing is the user's slip; their module's import is
    their code's bug, shown whole."""
    with pytest.raises(ModuleNotFoundError, match="mjzoo_cli_no_such_dependency"):
        cli.main(["train", "ppo", "mjzoo_cli_broken_tasks:make"])


TRAIN = [
    "--config",
    *(f"{k}={v}" for k, v in TINY.items()),
    "--eval-envs",
    "2",
    "--updates-per-chunk",
    "2",
    "--no-video",
]


@pytest.fixture(scope="module")
def cli_run(user_dir) -> Path:
    """A run of the user's task trained through `mjzoo train` (a few updates)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(user_dir)
        cli.main(["train", "ppo", SPEC, "--out", "runs/cli", "--env-overrides", "upright_weight=2.0", *TRAIN])
    return user_dir / "runs" / "cli"


def test_resume_builds_a_factorys_task_as_the_first_run_did(in_user_dir):
    """A ``**params`` factory takes any keyword as a task parameter: a resume passes it
    task.json's overrides alone, no physics `impl` (which it would take as a number)."""
    own, out = f"{MODULE}:make_own", in_user_dir / "runs" / "own"
    first = [f"{k}={v}" for k, v in {**TINY, "total_steps": 64}.items()]
    cli.main(["train", "ppo", own, "--out", str(out), *TRAIN, "--config", *first, "--updates-per-chunk", "1"])
    assert checkpoints.latest_step(out / "checkpoints") == 64
    cli.main(["train", "ppo", own, "--resume", str(out), "--config", "total_steps=128"])
    assert checkpoints.latest_step(out / "checkpoints") == 128


def test_train_writes_the_spec_and_eval_runs_its_episode_length(capsys, cli_run, in_user_dir, monkeypatch):
    assert json.loads((cli_run / "task.json").read_text()) == {"env": SPEC, "overrides": {"upright_weight": 2.0}}
    built, lengths = [], []
    make, evaluate = mjzoo.envs.make, ppo.evaluate
    monkeypatch.setattr(
        mjzoo.envs, "make", lambda spec, **overrides: (built.append((spec, overrides)), make(spec, **overrides))[1]
    )
    monkeypatch.setattr(ppo, "evaluate", lambda *args: (lengths.append(args[4:]), evaluate(*args))[1])
    monkeypatch.setattr(training, "write_video", lambda task, trajectory, path, config=None: None)
    cli.main(["eval", str(cli_run), "--episodes", "2"])
    assert capsys.readouterr().out.startswith(f"{SPEC}: mean return ")
    assert built[0] == (SPEC, {"upright_weight": 2.0})  # the saved overrides (then the factory's own make)
    assert lengths == [(2, 20)]  # the task's episode length, under jit a static argument
    monkeypatch.setattr(
        ppo,
        "evaluate",
        lambda *args: (lengths.append(args[4:]), learning.Evaluation(np.zeros(2), np.zeros(2), None))[1],
    )
    cli.main(["eval", str(cli_run), "--episodes", "2", "--env-overrides", "episode_steps=5"])  # on top of the saved
    assert built[2] == (SPEC, {"upright_weight": 2.0, "episode_steps": 5}) and lengths[-1] == (2, 5)


def test_eval_of_a_run_trained_from_python_needs_task(capsys, in_user_dir, monkeypatch):
    """`training.run(..., Settings(out_dir=...))` writes no task.json: --task names the task, and its
    --env-overrides set it up as it was trained."""
    monkeypatch.syspath_prepend(str(in_user_dir))
    run = in_user_dir / "runs" / "python"
    config, hyperparams = ppo.configure(**TINY)
    settings = training.Settings(out_dir=run, eval_envs=2, updates_per_chunk=2, video=False, progress=False)
    training.run(ppo.make(config), mjzoo.envs.make(SPEC, episode_steps=10), settings, hyperparams)
    capsys.readouterr()  # training's own news (on a busy CPU: "still compiling ..."), not the command's
    assert not (run / "task.json").exists()
    assert_usage_error(capsys, ["eval", str(run)], f"{run}: has no task.json (trained from Python?)", "--task")
    seen = []
    monkeypatch.setattr(
        ppo, "evaluate", lambda config, task, state, key, n, steps: (seen.append(steps), (0.0, np.zeros(n), None))[1]
    )
    monkeypatch.setattr(training, "write_video", lambda task, trajectory, path, config=None: None)
    cli.main(["eval", str(run), "--task", SPEC, "--env-overrides", "episode_steps=10", "--episodes", "2"])
    assert capsys.readouterr().out.startswith(f"{SPEC}: mean return 0.00")
    assert seen == [10]


def _collected(capsys, argv: list[str]) -> tuple[datasets.Dataset, list[str]]:
    """`mjzoo collect ...`'s dataset read back, and the lines it printed."""
    cli.main(argv)
    return datasets.load(argv[argv.index("--out") + 1]), capsys.readouterr().out.splitlines()


def test_collect_writes_a_runs_deterministic_episodes(capsys, cli_run, in_user_dir):
    out = in_user_dir / "data" / "pendulum"
    data, lines = _collected(capsys, ["collect", str(cli_run), "--out", str(out), "--episodes", "3"])
    files = ["dataset.npz", "meta.json", *(f"motions/episode_{i:03d}.npz" for i in range(3))]
    assert sorted(lines[:-1]) == sorted(str(out / f) for f in files)  # one line per file written
    assert lines[-1] == (
        f"{out}: 3 episodes of 20 steps on {SPEC}, mean length 20.0, mean return {data.returns().mean():.2f}"
    )
    assert (data.qpos.shape, data.action.shape, data.obs.shape, data.xpos.shape) == (
        (3, 21, 1),
        (3, 20, 1),
        (3, 21, 3),
        (3, 21, 2, 3),
    )
    assert data.deterministic is True and data.seed == 0 and set(data.reward_terms) == {"upright", "velocity", "effort"}
    assert data.source == {
        "run": str(cli_run),
        "algorithm": "ppo",
        "task": SPEC,
        "env_overrides": {"upright_weight": 2.0},
    }
    angle, speed = data.qpos[..., 0], data.qvel[..., 0]
    np.testing.assert_allclose(data.obs, np.stack([np.cos(angle), np.sin(angle), speed], -1), atol=1e-5)
    np.testing.assert_allclose(np.diff(data.time, axis=1), 0.02, atol=1e-6)  # the control step
    assert data.dt == pytest.approx(0.02)
    assert np.all(np.abs(np.abs(angle[:, 0]) - np.pi) <= 0.1 + 1e-6)  # reset: hanging, +-0.1 rad of noise
    assert not data.terminated.any() and (data.length == 20).all()  # the pendulum only ends by its time limit:
    assert data.truncated[:, -1].all() and not data.truncated[:, :-1].any()
    np.testing.assert_allclose(data.ctrl, data.action, atol=1e-6)  # PPO's actions are within the ctrlrange
    assert np.all(np.abs(data.action) <= 1.0 + 1e-6)
    clip = mjzoo.motion.load_file(out / "motions" / "episode_002.npz")
    assert clip.num_frames == 21 and clip.joint_names == data.joint_names and clip.fps == pytest.approx(50.0)
    before = snapshot(out.parent)
    assert_usage_error(
        capsys, ["collect", str(cli_run), "--out", str(out)], f"--out {out} already holds a dataset", "give --overwrite"
    )
    assert snapshot(out.parent) == before
    assert_usage_error(
        capsys,
        ["collect", str(cli_run), "--out", str(out), "--overwrite", "--task", f"{MODULE}:make_endless"],
        "make_endless: the task has no time limit",
        "give --steps",
    )
    again, _ = _collected(capsys, ["collect", str(cli_run), "--out", str(out), "--episodes", "3", "--overwrite"])
    assert all(np.array_equal(a, b) for a, b in zip(data.arrays().values(), again.arrays().values()))  # same seed
    sampled, _ = _collected(
        capsys, ["collect", str(cli_run), "--out", str(out.parent / "sampled"), "--episodes", "3", "--sampled"]
    )
    assert sampled.deterministic is False and sampled.action.shape == data.action.shape
    assert not np.allclose(sampled.action, data.action)  # sampled actions differ from the mean's
    np.testing.assert_array_equal(sampled.qpos[:, 0], data.qpos[:, 0])  # from the same resets


def test_plan_and_collect_with_a_planner_on_a_users_task(capsys, in_user_dir):
    """Default planning setup: one episode (10 steps here), no success test."""
    out = in_user_dir / "runs" / "plan"
    cli.main(
        [
            "plan",
            "predictive_sampling",
            SPEC,
            "--offline",
            "--no-video",
            "--out",
            str(out),
            "--env-overrides",
            "episode_steps=10",
            *PLAN_CONFIG,
        ]
    )
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success"] is None and summary["env"] == SPEC and np.isfinite(summary["final_cost"])
    capsys.readouterr()
    data, lines = _collected(
        capsys,
        [
            "collect",
            "predictive_sampling",
            "--task",
            SPEC,
            "--env-overrides",
            "episode_steps=10",
            "--out",
            str(in_user_dir / "planned"),
            "--episodes",
            "2",
            "--steps",
            "9",
            *PLAN_CONFIG,
        ],
    )
    assert len(lines) == 5 and lines[-1].startswith(f"{in_user_dir / 'planned'}: 2 episodes of 9 steps on {SPEC}")
    assert data.qpos.shape == (2, 10, 1) and data.action.shape == (2, 9, 1) and (data.length == 9).all()
    assert not np.array_equal(data.qpos[0], data.qpos[1])  # episodes from their own resets
    np.testing.assert_allclose(data.obs[..., 2], data.qvel[..., 0], atol=1e-6)
    np.testing.assert_allclose(data.ctrl, np.clip(data.action, -1.0, 1.0), atol=1e-6)
    assert data.deterministic is None and data.source["planner"] == "predictive_sampling"
    assert data.source["task"] == SPEC and data.source["config"]["num_samples"] == 4
    assert data.source["env_overrides"] == {"episode_steps": 10}
