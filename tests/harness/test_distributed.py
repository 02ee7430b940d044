"""Several processes (`mjzoo.harness.distributed`): two processes on localhost with one
CPU device each train as one process with two devices does (PPO, and AMP with its
discriminator and replay buffer), write one run directory (process 0's files, each
process its checkpoint shards) and resume from it; a malformed or partial setup is one
clear error.

The runs go through the CLI (`mjzoo train ... --coordinator --num-processes
--process-id`) on a one-joint task that compiles quickly. Every process compiles for
itself (JAX's compilation cache keys differ between processes, and sharing binaries
between hosts needs equal keys), so the test launches as few as it can: the two-process
run and its resume, then the one-process reference beside the resume."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import orbax.checkpoint as ocp
import pytest

import mjzoo
from mjzoo.harness import cli
from mjzoo.harness import distributed

ROOT = Path(__file__).resolve().parents[2]
XML = """
<mujoco model="block">
  <option timestep="0.05"/>
  <worldbody><body><joint name="x" type="slide" axis="1 0 0"/><geom type="box" size="0.1 0.1 0.1" mass="1"/></body></worldbody>
  <actuator><motor joint="x" ctrlrange="-1 1"/></actuator>
</mujoco>
"""
SPEC = "tests.harness.test_distributed:block_task"
FLAGS = [
    "--config",
    "num_envs=8",
    "unroll_length=8",
    "num_minibatches=2",
    "num_epochs=1",
    "policy_hidden_sizes=(16,)",
    "value_hidden_sizes=(16,)",
    "--updates-per-chunk",
    "2",
    "--eval-envs",
    "2",
    "--eval-every",
    "1",
    "--checkpoint-every",
    "1",
    "--no-video",
]  # (every chunk evaluates and
# saves, whatever the clocks say)
STEPS_PER_CHUNK = 2 * 8 * 8
RTOL, ATOL = 1e-5, 1e-6  # the runs agree to the bit here; this allows another order of summing


def _distance(p, model, state, action, next_state):
    return -((next_state.data.qpos[0] - 0.5) ** 2)


def block_task(impl: str = "jax") -> mjzoo.Task:
    """A block on a rail, to be held at x = 0.5 (a return of about -2.5 at first)."""
    return mjzoo.task(XML, rewards={"distance": _distance}, time_limit=10, impl=impl)


def block_amp_task() -> mjzoo.Task:
    """The block for AMP, a user's factory beside its module's `REFERENCE`
    (tests/envs/test_records.py finds the reference through it)."""
    return block_task()


def REFERENCE(task: mjzoo.Task, **overrides: object) -> mjzoo.motion.Reference:
    """The block's motion to imitate, sliding x = 0.3 sin(t): a factory module's
    reference, which `mjzoo train amp` finds beside the factory (`mjzoo.envs.reference`)."""
    dt = mjzoo.control_dt(task)
    t = np.arange(200) * dt
    clip = mjzoo.motion.Clip(
        name="slide", fps=1 / dt, qpos=0.3 * np.sin(t)[:, None], qvel=0.3 * np.cos(t)[:, None], joint_names=("x",)
    )
    return mjzoo.motion.reference(clip, task.mj_model, dt)


Launched = list[tuple[subprocess.Popen, Path]]  # each process with the stem of its log files


def _launch(
    out: Path | None,
    logs: Path,
    *args: str,
    processes: int = 1,
    devices: int = 1,
    spec: str = SPEC,
    algorithm: str = "ppo",
) -> Launched:
    """`mjzoo train algorithm spec` in `processes` processes of `devices` CPU devices each,
    writing their output to files in `logs` (a pipe nobody reads could fill and stall one)."""
    cache = logs.parent / "cache"  # process 0 of the resumed run finds its executables there
    env = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_COORDINATOR", "JAX_NUM_PROC", "JAX_PROCESS"))}
    env.update(
        JAX_PLATFORMS="cpu",
        MJZOO_COMPILE_CACHE=str(cache),
        JAX_COMPILATION_CACHE_DIR=str(cache),
        XLA_FLAGS=f"{env.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={devices}",
    )
    command = [
        sys.executable,
        "-m",
        "mjzoo",
        "train",
        algorithm,
        spec,
        *args,
        *FLAGS,
        *(["--out", str(out)] if out else []),
    ]
    port = distributed.free_port("localhost")
    joined = (
        [
            [f"--coordinator=localhost:{port}", f"--num-processes={processes}", f"--process-id={i}"]
            for i in range(processes)
        ]
        if processes > 1
        else [[]]
    )
    logs.mkdir(parents=True, exist_ok=True)
    launched = []
    for i, flags in enumerate(joined):
        with open(logs / f"{i}.out", "w") as stdout, open(logs / f"{i}.err", "w") as stderr:
            launched.append(
                (subprocess.Popen([*command, *flags], cwd=ROOT, env=env, stdout=stdout, stderr=stderr), logs / str(i))
            )
    return launched


def _finish(launched: Launched, timeout: float = 300) -> list[str]:
    """Each process's stdout, once all have ended well (else the failure's stderr)."""
    try:
        for proc, log in launched:
            proc.wait(timeout=timeout)
            err = log.with_suffix(".err").read_text()
            assert proc.returncode == 0, f"{log} failed (status {proc.returncode}):\n{err[-3000:]}"
    finally:
        for proc, _ in launched:  # a survivor would wait for its partner until JAX's timeouts
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    return [log.with_suffix(".out").read_text() for _, log in launched]


def _lines(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


def _saved_arrays(run: Path, step: int) -> dict[str, np.ndarray]:
    """Every array of checkpoint `step`, whole, as NumPy (no template: shapes from its metadata)."""
    path = (run / "checkpoints" / str(step) / "arrays").absolute()
    reader = ocp.StandardCheckpointer()
    metadata = reader.metadata(path)
    metadata = getattr(metadata, "item_metadata", metadata)
    return reader.restore(path, {k: np.zeros(m.shape, m.dtype) for k, m in metadata.items()})


def test_two_processes_train_as_one_process_with_two_devices_and_resume(tmp_path):
    """PPO's (AMP shares its harness and learner: `test_amp.py` runs it on two devices)."""
    two, one = tmp_path / "two", tmp_path / "one"
    run = dict(spec=SPEC)
    first, second = _finish(
        _launch(two, tmp_path / "logs-two", "--total-steps", str(2 * STEPS_PER_CHUNK), processes=2, **run)
    )
    assert "final eval/return" in first and "final eval/return" not in second  # process 0 reports
    assert sorted(p.name for p in two.iterdir()) == [
        "checkpoints",
        "config.json",
        "curves.png",
        "metrics.jsonl",
        "task.json",
        "tensorboard",
    ]
    assert [line["step"] for line in _lines(two)] == [STEPS_PER_CHUNK, 2 * STEPS_PER_CHUNK]  # written once
    assert len(list((two / "tensorboard").iterdir())) == 1
    assert sorted(int(p.name) for p in (two / "checkpoints").iterdir()) == [STEPS_PER_CHUNK, 2 * STEPS_PER_CHUNK]

    # The resume (two processes again) beside one process with two devices training straight through.
    total = ["--total-steps", str(3 * STEPS_PER_CHUNK)]
    resumed = _launch(None, tmp_path / "logs-resumed", "--resume", str(two), *total, processes=2, **run)
    reference = _launch(one, tmp_path / "logs-one", *total, devices=2, **run)
    _finish(resumed + reference)
    lines, expected = _lines(two), _lines(one)
    assert [line["step"] for line in lines] == [line["step"] for line in expected] == [128, 256, 384]
    for line, wanted in zip(lines, expected):
        assert "eval/return" in line and np.isfinite(line["eval/return"])
        for name, value in wanted.items():
            if not name.startswith("perf/"):
                np.testing.assert_allclose(line[name], value, rtol=RTOL, atol=ATOL, err_msg=name)
    final, wanted = _saved_arrays(two, 384), _saved_arrays(one, 384)  # the whole train state
    assert final.keys() == wanted.keys()
    for name in wanted:
        np.testing.assert_allclose(final[name], wanted[name], rtol=RTOL, atol=ATOL, err_msg=name)


@pytest.mark.skipif(
    importlib.util.find_spec("warp") is None or os.environ.get("MJZOO_WARP_ON_CPU") != "1",
    reason="needs MuJoCo Warp installed and MJZOO_WARP_ON_CPU=1 (Warp's slow CPU backend)",
)
def test_two_processes_on_warp_train_as_one_process_with_two_devices(tmp_path):
    """One process per device is how Warp runs on several GPUs: each process's physics on
    its own device (MJX's default device for Warp is process 0's), each device its own
    worlds and share of the contact pool. The hopper: its worlds touch the floor."""
    two, one = tmp_path / "two", tmp_path / "one"
    args = ["--total-steps", str(STEPS_PER_CHUNK), "--env-overrides", "impl=warp"]
    _finish(
        _launch(two, tmp_path / "logs-two", *args, processes=2, spec="hopper")
        + _launch(one, tmp_path / "logs-one", *args, devices=2, spec="hopper"),
        timeout=900,
    )
    assert json.loads((two / "config.json").read_text())["physics"]["impl"] == "warp"
    (line,), (wanted,) = _lines(two), _lines(one)
    for name in ("eval/return", "loss/total", "train/episode_return"):
        np.testing.assert_allclose(line[name], wanted[name], rtol=RTOL, atol=ATOL, err_msg=name)


@pytest.fixture
def clean_env(monkeypatch):
    """No launcher or coordinator variables from the machine running the tests."""
    for name in list(os.environ):
        if name.startswith(("JAX_COORDINATOR", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID", "SLURM_", "OMPI_")):
            monkeypatch.delenv(name)
    return monkeypatch


@pytest.mark.parametrize(
    "args,message",
    [
        (("localhost", 2, 0), "coordinator='localhost' is not HOST:PORT"),
        (("localhost:70000", 2, 0), "coordinator='localhost:70000' is not HOST:PORT"),
        ((":1234", 2, 0), "coordinator=':1234' is not HOST:PORT (e.g. 10.0.0.1:1234, port 1 .. 65535)"),
        (("localhost:1234", 2, 2), "process_id=2 is out of range for num_processes=2: it must be 0 .. 1"),
        (("localhost:1234", 0, 0), "num_processes=0 must be an int >= 1"),
        (("localhost:1234", 2, -1), "process_id=-1 must be an int >= 0"),
        (("localhost:1234", 2.0, 0), "num_processes=2.0 must be an int >= 1"),
        (
            ("localhost:1234", None, None),
            "num_processes and process_id missing; give coordinator, num_processes and process_id together",
        ),
        (
            (None, 2, 1),
            "coordinator missing; give coordinator, num_processes and process_id together (or set "
            "JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, JAX_PROCESS_ID)",
        ),
    ],
)
def test_initialize_refuses_bad_or_partial_input(clean_env, args, message):
    with pytest.raises(ValueError, match="^" + re.escape(f"distributed: {message}")):
        distributed.initialize(*args)


def test_initialize_reads_the_environment_and_names_the_variable(clean_env):
    assert distributed.initialize() is False  # one process: nothing to join, nothing done
    clean_env.setenv("JAX_COORDINATOR_ADDRESS", "localhost:1234")
    clean_env.setenv("JAX_NUM_PROCESSES", "two")
    with pytest.raises(ValueError, match="^distributed: JAX_NUM_PROCESSES='two' must be an int >= 1$"):
        distributed.initialize()
    clean_env.setenv("JAX_NUM_PROCESSES", "2")
    with pytest.raises(ValueError, match="process_id missing"):
        distributed.initialize()
    clean_env.setenv("JAX_PROCESS_ID", "5")
    with pytest.raises(ValueError, match="process_id=5 is out of range for num_processes=2"):
        distributed.initialize()
    with pytest.raises(ValueError, match="coordinator='x:y' is not HOST:PORT"):
        distributed.initialize("x:y")  # an argument before its variable


def test_several_processes_of_a_launcher_ask_for_a_run(clean_env):
    slurm = {"SLURM_JOB_ID": "7", "SLURM_NODELIST": "node[1-2]", "SLURM_PROCID": "1", "SLURM_LOCALID": "0"}
    for name, value in slurm.items():
        clean_env.setenv(name, value)
    assert distributed._launcher() is None  # one task: trains alone, as before
    clean_env.setenv("SLURM_NTASKS", "2")
    assert distributed._launcher() == "slurm"
    with pytest.raises(ValueError, match="process_id=3 is out of range"):  # the launcher fills in only what is missing
        distributed.initialize(num_processes=2, process_id=3)


def test_the_cli_reports_a_bad_coordinator_in_one_line(clean_env, capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(
            [
                "train",
                "ppo",
                "pendulum_swingup",
                "--coordinator",
                "nowhere",
                "--num-processes",
                "2",
                "--process-id",
                "0",
            ]
        )
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and err.splitlines() == [
        "mjzoo train: distributed: coordinator='nowhere' is not HOST:PORT (e.g. 10.0.0.1:1234, port 1 .. 65535)"
    ], err


IDEMPOTENT = """
import sys
from mjzoo.harness import distributed
address = sys.argv[1]
assert distributed.initialize(address, 1, 0) and distributed.initialize(address, 1, 0) and distributed.initialize()
assert distributed.is_primary()
try:
    distributed.initialize(address, 2, 0)
except ValueError as e:
    print(e)
"""


def test_initialize_is_idempotent_but_not_with_other_values(clean_env):
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    result = subprocess.run(
        [sys.executable, "-c", IDEMPOTENT, f"localhost:{distributed.free_port('localhost')}"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.strip() == "distributed: already initialized otherwise: num_processes=2 (it is 1)"
