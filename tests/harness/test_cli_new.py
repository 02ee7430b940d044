"""`mjzoo new NAME --mjcf PATH`: the module it writes runs as written under
`mjzoo.testing.check_task`, `mjzoo train` and `mjzoo plan`; it never overwrites a file
unasked. The model is the pendulum's (one hinge, one motor), so compiles stay small."""

from __future__ import annotations

import importlib
import json

import pytest
from test_cli import TINY  # the command's shared test helpers
from test_cli import assert_usage_error  # the command's shared test helpers

import mjzoo
import mjzoo.testing
from mjzoo.envs.base import ASSETS
from mjzoo.harness import cli

NAME = "mjzoo_cli_new_pendulum"  # unique: imported modules stay in sys.modules


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The directory `mjzoo new` wrote NAME.py in (the model copied beside it)."""
    directory = tmp_path_factory.mktemp("new")
    (directory / "models").mkdir()
    (directory / "models" / "pendulum.xml").write_text((ASSETS / "pendulum.xml").read_text())
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(directory)
        cli.main(["new", NAME, "--mjcf", "models/pendulum.xml"])
    return directory


def test_the_written_module_passes_check_task(written, monkeypatch):
    monkeypatch.syspath_prepend(str(written))
    module = importlib.import_module(NAME)
    assert "Path(__file__).parent / 'models/pendulum.xml'" in (written / f"{NAME}.py").read_text()
    task = module.make_task(reset_noise=0.1)
    mjzoo.testing.check_task(task)
    assert {"reset_noise", "posture_scale", "max_speed", "posture_weight", "effort_weight"} <= set(mjzoo.params(task))
    assert int(task.time_limit) == 500  # 10 s of 0.02 s control steps (the model's 0.01 s physics step x 2)
    assert mjzoo.envs.hyperparameters(f"{NAME}:make_task", "mppi")["num_samples"] == 64  # its PLANNING


def test_the_written_module_trains_and_plans_from_the_command_line(written, monkeypatch, capsys):
    monkeypatch.chdir(written)
    spec = f"{NAME}:make_task"
    tiny = [f"{k}={v}" for k, v in TINY.items()]
    cli.main(["train", "ppo", spec, "--out", "runs/ppo", "--config", *tiny, "--eval-envs", "2", "--no-video"])
    assert (written / "runs" / "ppo" / "curves.png").exists()
    plan = ["--config", "num_samples=4", "horizon_steps=4", "num_knots=2", "--seconds", "0.1", "--no-video"]
    cli.main(["plan", "mppi", spec, "--offline", "--out", "runs/mppi", *plan])
    summary = json.loads((written / "runs" / "mppi" / "summary.json").read_text())
    assert summary["env"] == spec and summary["success"] is None  # no success test: the final cost tells
    capsys.readouterr()


def test_new_refuses_to_overwrite_unless_forced(written, monkeypatch, capsys):
    monkeypatch.chdir(written)
    module = written / f"{NAME}.py"
    before = module.read_text()
    module.write_text(before + "# the user's edit\n")
    assert_usage_error(capsys, ["new", NAME, "--mjcf", "models/pendulum.xml"], f"{NAME}.py already exists", "--force")
    assert module.read_text().endswith("# the user's edit\n")
    cli.main(["new", NAME, "--mjcf", "models/pendulum.xml", "--force"])
    assert module.read_text() == before
    capsys.readouterr()


@pytest.mark.parametrize(
    "argv, words",
    [
        (["new", "my-task", "--mjcf", "x.xml"], ["NAME 'my-task': must be a Python module name"]),
        (["new", "task", "--mjcf", "no/such.xml"], ["--mjcf no/such.xml: no such file"]),
        (["new", "task", "--mjcf", "broken.xml"], ["--mjcf broken.xml: MuJoCo cannot load it"]),
        (["new", "task", "--mjcf", "still.xml"], ["the model has no actuators"]),
    ],
)
def test_a_bad_name_or_model_is_one_line(tmp_path, monkeypatch, capsys, argv, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "broken.xml").write_text("<mujoco><worldbody><body>")
    (tmp_path / "still.xml").write_text(
        "<mujoco><worldbody><body><freejoint/><geom size='1'/></body></worldbody></mujoco>"
    )
    assert_usage_error(capsys, argv, *words)
    assert not (tmp_path / "task.py").exists()
