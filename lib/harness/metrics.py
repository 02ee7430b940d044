"""Host-side training logs: scalar metrics to JSON lines and TensorBoard, and a
progress bar.

    with MetricsWriter("runs/a") as log, Progress(total, "ppo") as bar:
        for ...:
            train_state, metrics = update(...)
            log.write(step, metrics)               # runs/a/metrics.jsonl + runs/a/tensorboard/
            bar.update(step, ret=metrics["train/episode_return"])

``metrics.jsonl`` holds one JSON object per `write`: ``{"step": int, name: float, ...}``;
non-finite values are written as ``NaN`` / ``Infinity``, which Python's `json` (and so
`read_metrics`) reads back. A run resumed from a checkpoint appends to the same file:
`read_metrics` keeps only the resumed run's records for the steps it redid.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
import time
import warnings
from collections.abc import Iterator
from collections.abc import Mapping
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING
from typing import Any
from typing import Self
from typing import TextIO

import jax
import numpy as np
import rich.console
import rich.progress
import rich.text

if TYPE_CHECKING:
    from tensorboardX import SummaryWriter

__all__ = ["METRICS_FILE", "MetricsWriter", "Progress", "device_memory", "read_metrics"]

METRICS_FILE = "metrics.jsonl"
Scalar = float | int | bool | np.ndarray | np.generic | jax.Array


class MetricsWriter:
    """Appends scalar metrics to ``out_dir/metrics.jsonl`` and, with `tensorboard`,
    to TensorBoard event files under ``out_dir/tensorboard/``.

    Each line is flushed as it is written, so a crash loses no finished `write`.
    Write from one process only (process 0 in multi-host training).
    """

    def __init__(self, out_dir: str | Path, tensorboard: bool = True) -> None:
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.path = self.out_dir / METRICS_FILE
        cut_short = self.path.exists() and self.path.stat().st_size > 0 and _last_byte(self.path) != b"\n"
        self._file: TextIO | None = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 (open until close)
        if cut_short:  # a crash mid-line: end that line, so it stays the only bad one
            self._file.write("\n")
        self._use_tensorboard = tensorboard
        self._tensorboard: SummaryWriter | None = None  # made at the first write, which knows the step

    def write(self, step: int, metrics: Mapping[str, Scalar]) -> None:
        """Logs scalar `metrics` at `step`. Device arrays are fetched in one transfer.

        Raises:
          ValueError: a metric is not a scalar (size 1), or is named "step".
        """
        if self._file is None:
            raise RuntimeError(f"MetricsWriter for {self.out_dir} is closed")
        if "step" in metrics:
            raise ValueError('"step" is reserved for the step number; rename that metric')
        values = {name: _to_float(name, value) for name, value in jax.device_get(dict(metrics)).items()}
        self._file.write(json.dumps({"step": int(step), **values}) + "\n")
        self._file.flush()
        if self._use_tensorboard:
            if self._tensorboard is None:
                self._tensorboard = _tensorboard_writer(self.out_dir / "tensorboard", int(step))
            for name, value in values.items():
                self._tensorboard.add_scalar(name, value, global_step=int(step))

    def close(self) -> None:
        """Flushes and closes the files; further writes raise. Safe to call twice."""
        if self._file is not None:
            self._file.close()
            self._file = None
        if self._tensorboard is not None:
            self._tensorboard.close()
            self._tensorboard = None
        self._use_tensorboard = False

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_metrics(path: str | Path) -> list[dict[str, float]]:
    """Reads a metrics.jsonl (or the one in directory `path`) into a list of records.

    A line a crash cut short is skipped with a warning. When the step goes backwards
    (a run resumed from an earlier checkpoint and appended), the records of the
    abandoned run from that step on are dropped, so each step appears as the resumed
    run logged it.
    """
    path = Path(path)
    if path.is_dir():
        path = path / METRICS_FILE
    records: list[dict[str, float]] = []
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, start=1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
            except json.JSONDecodeError:
                message = f"{path}:{number}: skipping a line that is not JSON (cut short by a crash?)"
                warnings.warn(message, stacklevel=2)
                continue
            if records and record["step"] < records[-1]["step"]:
                records = [r for r in records if r["step"] < record["step"]]
            records.append(record)
    return records


def device_memory(devices: Sequence[Any] | None = None) -> tuple[dict[str, float], list[str]]:
    """Device memory in use, for the metrics: ``memory/<device>/bytes_in_use`` and
    ``memory/<device>/peak_bytes_in_use`` of each of `devices` (default: this
    process's, `jax.local_devices()`), named platform and id (``gpu0``: TensorBoard
    tags allow no colon), and the names of the devices that report no statistics
    (``memory_stats()`` is None on XLA's CPU)."""
    values: dict[str, float] = {}
    silent: list[str] = []
    for device in jax.local_devices() if devices is None else devices:
        name = f"{device.platform}{device.id}"
        stats = device.memory_stats()
        if not stats:
            silent.append(name)
            continue
        for field in ("bytes_in_use", "peak_bytes_in_use"):
            if field in stats:
                values[f"memory/{name}/{field}"] = float(stats[field])
    return values, silent


def _tensorboardx() -> Any:
    """tensorboardX, imported without PyTorch: its writer imports torch where installed
    (only to accept torch tensors), which costs seconds of every launch."""
    if "tensorboardX" in sys.modules or "torch" in sys.modules:
        import tensorboardX

        return tensorboardX
    sys.modules["torch"] = None  # `import torch` raises ImportError, which tensorboardX expects
    try:
        import tensorboardX
    finally:
        del sys.modules["torch"]
    return tensorboardX


def _tensorboard_writer(directory: Path, first_step: int) -> SummaryWriter:
    """A writer into `directory`. If an earlier run logged there, TensorBoard is told to
    hide its events from `first_step` on (``purge_step``), as `read_metrics` does."""
    resumed = directory.is_dir() and any(directory.glob("events.out.tfevents.*"))
    return _tensorboardx().SummaryWriter(
        str(directory),
        purge_step=first_step if resumed else None,
        flush_secs=10,
        # File names hold the time in whole seconds and are opened with "wb": without
        # this, a run restarted within the same second would erase its predecessor's.
        filename_suffix=f".{time.time_ns()}",
    )


def _last_byte(path: Path) -> bytes:
    with open(path, "rb") as f:
        f.seek(-1, 2)
        return f.read(1)


def _to_float(name: str, value: Any) -> float:
    array = np.asarray(value)
    if array.size != 1:
        raise ValueError(f"metric {name!r} must be a scalar, got shape {array.shape}: reduce it first")
    return float(array.reshape(()))


class Progress:
    """A progress bar over training steps: done/total, steps/s, time left, and the
    latest `fields` passed to `update`.

    Time spent inside `paused()` (evaluation, videos) is left out of steps/s, which so
    stays the training rate, and kept in the time left, which is wall-clock.

    On a terminal (or in Jupyter) it is a live `rich` bar. Otherwise (CI logs, output
    piped to a file) it prints one compact line at most every `min_interval` seconds,
    plus the first and the last update, instead of redrawing.

    Args:
      total_steps: the step count at which training is done.
      description: a label shown before the counts.
      file: where to write; default stdout.
      min_interval: seconds between two printed lines when not on a terminal.
    """

    def __init__(
        self, total_steps: int, description: str = "train", *, file: TextIO | None = None, min_interval: float = 5.0
    ) -> None:
        self.total_steps = int(total_steps)
        self.description = description
        self._file = file
        self._min_interval = min_interval
        self._paused = 0.0  # seconds spent in `paused` so far
        self._last: tuple[float, float, int] | None = None  # (time, paused, step) of the last printed line
        self._previous: tuple[float, int] | None = None  # (training time, step) of the last update
        self._pending: str | None = None  # the latest line not yet printed
        console = rich.console.Console(file=file)
        self._bar: rich.progress.Progress | None = None
        if console.is_interactive or console.is_jupyter:
            self._bar = rich.progress.Progress(
                rich.progress.TextColumn("[bold]{task.description}"),
                rich.progress.BarColumn(),
                rich.progress.MofNCompleteColumn(),
                _RateColumn(),
                rich.progress.TimeElapsedColumn(),
                rich.progress.TextColumn("eta"),
                rich.progress.TimeRemainingColumn(),
                rich.progress.TextColumn("{task.fields[fields]}"),
                console=console,
            )
            self._task = self._bar.add_task(description, total=self.total_steps, fields="")
            self._bar.start()

    def update(self, step: int, **fields: Any) -> None:
        """Shows that `step` steps are done, with `fields` (numbers or text) beside."""
        text = " ".join(f"{name}={_fmt(value)}" for name, value in fields.items())
        now = time.monotonic()
        if self._bar is not None:
            trained, previous = now - self._paused, self._previous
            rate = _rate(int(step) - previous[1], trained - previous[0]) if previous else None
            self._previous = (trained, int(step))
            self._bar.update(self._task, completed=int(step), fields=text, rate=rate)
            return
        line = self._line(now, int(step), text)
        if self._last is None or now - self._last[0] >= self._min_interval or step >= self.total_steps:
            self._print(line)
            self._last, self._pending = (now, self._paused, int(step)), None
        else:
            self._pending = line

    def note(self, text: str) -> None:
        """Prints one line of news (above the live bar, if there is one)."""
        if self._bar is not None:
            self._bar.console.print(text, markup=False, highlight=False)
        else:
            self._print(text)

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        """Time spent inside is no training: steps/s leaves it out."""
        start = time.monotonic()
        try:
            yield
        finally:
            self._paused += time.monotonic() - start

    def close(self) -> None:
        """Stops the bar, or prints the last update not yet printed."""
        if self._bar is not None:
            self._bar.stop()
            self._bar = None
        elif self._pending is not None:
            self._print(self._pending)
            self._pending = None

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _line(self, now: float, step: int, text: str) -> str:
        share = f" ({100 * step / self.total_steps:.0f}%)" if self.total_steps > 0 else ""
        parts = [f"{self.description}: {step:,}/{self.total_steps:,} steps{share}"]
        if self._last is not None and now > self._last[0] and step > self._last[2]:
            then, paused, done = self._last  # since the last printed line
            rate = _rate(step - done, now - then - (self._paused - paused))
            if rate is not None:
                parts.append(f"{rate:,.0f} steps/s")
            parts.append(f"eta {_duration(max(self.total_steps - step, 0) * (now - then) / (step - done))}")
        if text:
            parts.append(text)
        return " | ".join(parts)

    def _print(self, line: str) -> None:
        print(line, file=self._file if self._file is not None else sys.stdout, flush=True)


def _rate(steps: int, seconds: float) -> float | None:
    return steps / seconds if seconds > 0 and steps > 0 else None


class _RateColumn(rich.progress.ProgressColumn):
    """Training steps per second over the last update (time in `Progress.paused` left
    out), else as rich estimates it over its recent updates."""

    def render(self, task: rich.progress.Task) -> rich.text.Text:
        speed = task.fields.get("rate") or task.speed
        return rich.text.Text(f"{speed:,.0f} steps/s" if speed else "- steps/s", style="progress.data.speed")


def _fmt(value: Any) -> str:
    array = np.asarray(value)
    if array.size != 1 or array.dtype.kind not in "biuf":
        return str(value)
    if array.dtype.kind in "biu":
        return str(array.reshape(()).item())
    return f"{float(array.reshape(())):.4g}"


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    minutes, secs = divmod(int(seconds), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}"
