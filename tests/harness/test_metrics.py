"""Metrics logging (JSON lines + TensorBoard) and the progress bar."""

from __future__ import annotations

import io
import json
import math
import os
import struct
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest
from tensorboardX.proto import event_pb2

from mjzoo.harness import metrics
from mjzoo.harness.metrics import MetricsWriter
from mjzoo.harness.metrics import Progress
from mjzoo.harness.metrics import read_metrics


def tensorboard_events(directory) -> list[list[event_pb2.Event]]:
    """The events of each TFRecord event file under `directory`, oldest file first."""
    files = []
    for path in sorted(directory.glob("events.out.tfevents.*")):  # by name, as TensorBoard reads them
        data, offset, events = path.read_bytes(), 0, []
        while offset < len(data):  # record: u64 length, u32 crc, payload, u32 crc
            (length,) = struct.unpack_from("<Q", data, offset)
            events.append(event_pb2.Event.FromString(data[offset + 12 : offset + 12 + length]))
            offset += 16 + length
        files.append(events)
    return files


def tensorboard_scalars(directory) -> list[tuple[str, int, float]]:
    """(tag, step, value) of every scalar in the event files under `directory`."""
    return [(v.tag, e.step, v.simple_value) for f in tensorboard_events(directory) for e in f for v in e.summary.value]


def test_writes_json_lines_and_tensorboard(tmp_path):
    with MetricsWriter(tmp_path) as log:
        log.write(0, {"loss/value": jnp.float32(0.25), "train/episode_return": np.array([3.5]), "n": 2})
        # Each line is on disk as soon as it is written, before close.
        lines = (tmp_path / "metrics.jsonl").read_text().splitlines()
        assert [json.loads(line) for line in lines] == [
            {"step": 0, "loss/value": 0.25, "train/episode_return": 3.5, "n": 2.0}
        ]
        log.write(100, {"loss/value": jnp.asarray(0.125), "done": jnp.asarray(True)})

    records = read_metrics(tmp_path / "metrics.jsonl")
    assert records == [
        {"step": 0, "loss/value": 0.25, "train/episode_return": 3.5, "n": 2.0},
        {"step": 100, "loss/value": 0.125, "done": 1.0},
    ]
    assert all(type(v) is float for r in records for k, v in r.items() if k != "step")
    assert read_metrics(tmp_path) == records  # a run directory works too

    scalars = tensorboard_scalars(tmp_path / "tensorboard")
    assert sorted(scalars) == sorted(
        [
            ("loss/value", 0, 0.25),
            ("train/episode_return", 0, 3.5),
            ("n", 0, 2.0),
            ("loss/value", 100, 0.125),
            ("done", 100, 1.0),
        ]
    )


def test_without_tensorboard_and_non_finite_values(tmp_path):
    with MetricsWriter(tmp_path, tensorboard=False) as log:
        log.write(1, {"a": float("nan"), "b": -np.inf})
    assert not (tmp_path / "tensorboard").exists()
    (record,) = read_metrics(tmp_path)
    assert math.isnan(record["a"]) and record["b"] == -math.inf


def test_rejects_non_scalars_and_reserved_name_and_writes_after_close(tmp_path):
    log = MetricsWriter(tmp_path, tensorboard=False)
    with pytest.raises(ValueError, match=r"'per_env' must be a scalar, got shape \(4,\)"):
        log.write(0, {"per_env": jnp.zeros(4)})
    with pytest.raises(ValueError, match="reserved"):
        log.write(0, {"step": 1.0})
    log.close()
    log.close()
    with pytest.raises(RuntimeError, match="closed"):
        log.write(1, {"x": 1.0})
    assert read_metrics(tmp_path) == []


def test_line_cut_by_a_crash_is_skipped_and_resume_replaces_redone_steps(tmp_path):
    with MetricsWriter(tmp_path, tensorboard=False) as log:
        for step in [0, 10, 10, 20, 30]:  # two writes at step 10 (e.g. train, then eval)
            log.write(step, {"x": float(step)})
    with open(tmp_path / "metrics.jsonl", "a") as f:
        f.write('{"step": 40, "x": 4')  # the process died mid-line

    # The run resumes from its checkpoint at step 10 and redoes 20 and 30.
    with MetricsWriter(tmp_path, tensorboard=False) as log:
        for step in [20, 30, 40]:
            log.write(step, {"x": -float(step)})

    with pytest.warns(UserWarning, match="not JSON"):
        records = read_metrics(tmp_path)
    assert [(r["step"], r["x"]) for r in records] == [
        (0, 0.0),
        (10, 10.0),
        (10, 10.0),
        (20, -20.0),
        (30, -30.0),
        (40, -40.0),
    ]


def test_resumed_run_tells_tensorboard_to_hide_the_redone_steps(tmp_path):
    with MetricsWriter(tmp_path) as log:
        for step in [0, 10, 20, 30]:
            log.write(step, {"x": 1.0})
    with MetricsWriter(tmp_path) as log:  # resumed from a checkpoint at step 10
        for step in [20, 30]:
            log.write(step, {"x": 2.0})

    first, second = tensorboard_events(tmp_path / "tensorboard")
    assert not any(e.HasField("session_log") for e in first)  # a fresh run purges nothing
    starts = [e.step for e in second if e.session_log.status == event_pb2.SessionLog.START]
    assert starts == [20]  # TensorBoard hides the first run's events from step 20 on
    assert [(e.step, e.summary.value[0].simple_value) for e in second if e.summary.value] == [(20, 2.0), (30, 2.0)]


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_progress_without_terminal_prints_compact_lines_at_most_every_interval(monkeypatch):
    clock = FakeClock()
    monkeypatch.setattr(metrics.time, "monotonic", clock)
    out = io.StringIO()
    with Progress(1000, "ppo", file=out, min_interval=5.0) as bar:
        for step in range(100, 1001, 100):  # 100 steps per simulated second
            clock.now += 1.0
            bar.update(step, ret=jnp.float32(1.23456), phase="warmup", iters=7)

    lines = out.getvalue().splitlines()
    # First update, then every 5 s (steps 600), then the final one.
    assert [line.split(" steps")[0] for line in lines] == ["ppo: 100/1,000", "ppo: 600/1,000", "ppo: 1,000/1,000"]
    assert lines[0] == "ppo: 100/1,000 steps (10%) | ret=1.235 phase=warmup iters=7"
    assert lines[1] == "ppo: 600/1,000 steps (60%) | 100 steps/s | eta 0:00:04 | ret=1.235 phase=warmup iters=7"
    assert "\x1b" not in out.getvalue()  # no terminal escape codes in a log file


def test_progress_without_terminal_prints_last_pending_update_on_close(monkeypatch):
    clock = FakeClock()
    monkeypatch.setattr(metrics.time, "monotonic", clock)
    out = io.StringIO()
    bar = Progress(1000, "run", file=out, min_interval=60.0)
    bar.update(10)
    clock.now += 1.0
    bar.update(20, loss=0.5)
    assert len(out.getvalue().splitlines()) == 1
    bar.close()
    lines = out.getvalue().splitlines()
    assert lines[-1].startswith("run: 20/1,000 steps (2%) | 10 steps/s") and lines[-1].endswith("loss=0.5")


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_on_a_terminal_draws_a_rich_bar(monkeypatch):
    for name in ["TTY_COMPATIBLE", "TTY_INTERACTIVE", "FORCE_COLOR", "NO_COLOR"]:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("TERM", "xterm-256color")
    out = FakeTerminal()
    with Progress(50, "train", file=out) as bar:
        for step in range(10, 51, 10):
            bar.update(step, ret=2.5)
    text = out.getvalue()
    assert "\x1b" in text  # drawn with terminal control codes
    assert "50/50" in text and "steps/s" in text and "ret=2.5" in text and "train" in text


def test_progress_leaves_paused_time_out_of_steps_per_s_but_not_out_of_the_eta(monkeypatch):
    clock = FakeClock()
    monkeypatch.setattr(metrics.time, "monotonic", clock)
    out = io.StringIO()
    with Progress(1000, "train", file=out, min_interval=0.0) as bar:
        bar.update(100)
        with bar.paused():  # an evaluation
            clock.now += 3.0
        clock.now += 1.0
        bar.update(200)  # 4 s of wall-clock, 1 of them training: the eta counts all 4
    assert out.getvalue().splitlines()[1] == "train: 200/1,000 steps (20%) | 100 steps/s | eta 0:00:32"


class FakeDevice:
    def __init__(self, platform: str, id: int, stats: dict | None) -> None:
        self.platform, self.id, self.stats = platform, id, stats

    def memory_stats(self) -> dict | None:
        return self.stats


def test_device_memory_names_each_device_and_those_without_statistics():
    devices = [
        FakeDevice("gpu", 0, {"bytes_in_use": 5, "peak_bytes_in_use": 9, "bytes_limit": 100}),
        FakeDevice("gpu", 1, {"bytes_in_use": 7}),
        FakeDevice("cpu", 0, None),
    ]
    values, silent = metrics.device_memory(devices)
    assert values == {
        "memory/gpu0/bytes_in_use": 5.0,
        "memory/gpu0/peak_bytes_in_use": 9.0,
        "memory/gpu1/bytes_in_use": 7.0,
    }
    assert silent == ["cpu0"]
    assert metrics.device_memory() == ({}, ["cpu0"])  # what XLA's CPU reports: nothing


def test_tensorboard_logging_does_not_import_pytorch(tmp_path):
    """tensorboardX's writer imports torch where it is installed, seconds of every
    launch; mjzoo logs without it. A stand-in `torch` package records any import."""
    (tmp_path / "torch").mkdir()
    marker = tmp_path / "imported"
    (tmp_path / "torch" / "__init__.py").write_text(f"open({str(marker)!r}, 'w').close()\n")
    code = (
        f"import os\nfrom mjzoo.harness.metrics import MetricsWriter\nw = MetricsWriter({str(tmp_path / 'run')!r})\n"
        f"w.write(1, {{'loss': 1.0}})\nw.close()\nprint(os.path.exists({str(marker)!r}))\n"
        f"import torch\nprint(os.path.exists({str(marker)!r}))\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")]))}
    result = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True, timeout=120
    )
    assert list((tmp_path / "run" / "tensorboard").glob("events.out.tfevents.*"))  # TensorBoard's file was written
    assert result.stdout.split() == ["False", "True"]  # not imported by logging; the stand-in itself works
