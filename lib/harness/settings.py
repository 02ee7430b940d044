"""How a training run is driven: `Settings` (KSim's validation, logging and rendering
options among them) and the evaluation schedule they give. What is learned is the
algorithm's config; `mjzoo.harness.training.run` takes both."""

from __future__ import annotations

import dataclasses
import math
import numbers
from pathlib import Path
from typing import Any

import numpy as np

from mjzoo import checks
from mjzoo.harness import rendering

__all__ = ["Settings", "EvalSchedule", "checkpoint_due", "config_dict", "hyperparams_dict"]


@dataclasses.dataclass(frozen=True, kw_only=True)
class Settings:
    """How a run is driven (not what is learned). KSim's RLConfig names in brackets.

    Evaluation schedule (`EvalSchedule`): the run's last chunk always evaluates, so a run
    ends with an eval/return. Any other chunk evaluates when `eval_first_seconds` (if
    set) have passed since `run` was called and one trigger fires: its number is a
    multiple of `eval_every` (counted over the whole run, so a resumed run evaluates at
    the same steps); with `eval_every=None` (the default), it passes one of `eval_count`
    marks evenly spaced over the run's updates (chunks are cut shorter where a run would
    have fewer), so a curve has that many points whatever they cost (the first waits
    for the evaluation's compile, as the last evaluation would: once), or the
    evaluations so far and one more at the last one's cost stay within `eval_budget` of
    the wall-clock time since launch and the evaluation has compiled (the first chance
    evaluates, to learn that cost; one still compiling in the background is put off,
    rather than stopping training for its compile), so the budget adds evaluations where
    they are cheap; `eval_every_seconds` have passed since the last evaluation began (or
    since the launch); or it is the first chance after `eval_first_seconds` (KSim's
    "first validation after M seconds"). On an H200 a cart-pole evaluation (500 steps)
    takes 0.85 s for 4 or 64 envs alike: 20 of them are 6% of a 5-minute run, and more
    than the budget of a shorter one (`eval_count=0`: the budget alone).
    Metrics lines of chunks that do not evaluate lack eval/*. Evaluating with
    `eval_every=0` and no seconds: only at the end.

    Checkpoints (`checkpoint_due`): the last chunk always saves one, unless
    `checkpoint_every=0` (never); any other chunk saves when its number is a multiple of
    `checkpoint_every` or `checkpoint_every_seconds` have passed since the last save (or
    the launch). A save stops training while it writes, so the default is one a minute,
    not one a chunk (cart-pole's 0.1 s chunks trained a third slower saving each).
    """

    out_dir: Path | None = None
    seed: int = 0
    updates_per_chunk: int = 10  # updates per jitted chunk (fewer where eval_count asks for more chunks)
    eval_envs: int = 16  # envs per evaluation, one deterministic episode each
    eval_steps: int | None = None  # evaluation length in control steps; None: eval_seconds, else the episode's
    eval_seconds: float | None = None  # [rollout_length_seconds] episode length in seconds (/ mjzoo.control_dt)
    eval_every: int | None = None  # [valid_every_n_steps] chunks between evaluations; 0: none; None: eval_count
    eval_count: int = 20  # with eval_every=None: at least this many evaluations, evenly spaced; 0: by eval_budget
    eval_budget: float = 0.05  # with eval_every=None: more evaluations while they take at most this share of time
    eval_every_seconds: float | None = None  # [valid_every_n_seconds] wall-clock trigger
    eval_first_seconds: float | None = None  # [valid_first_n_seconds] no evaluation before, the first one after
    video: bool = True  # out/eval.mp4 of the final evaluation (where an OpenGL backend works)
    video_every: int = 0  # [render_full_every_n_steps] also videos/eval_<step>.mp4 every N evaluations; 0: never
    render: rendering.RenderConfig = dataclasses.field(default_factory=rendering.RenderConfig)  # how videos are drawn
    log_train_metrics: bool = True  # [log_train_metrics] False: metrics lines hold only eval/*, perf/* (memory/*)
    log_every: int = 1  # [epochs_per_log_step] chunks between metrics lines; evaluating chunks always write one
    profile_memory: bool = False  # [profile_memory] memory/<device>/{bytes_in_use,peak_bytes_in_use} per chunk
    checkpoint_every: int | None = None  # chunks between checkpoints; 0: never; None: by checkpoint_every_seconds
    checkpoint_every_seconds: float | None = 60.0  # wall-clock trigger (with checkpoint_every; None: none)
    resume: bool = False  # continue the run in out_dir from its newest intact checkpoint
    overwrite: bool = False  # replace a run already in out_dir: its files are deleted first
    progress: bool = True  # a progress bar (and, on a CPU, the line that says how long the run will take)
    compile_cache: bool = True  # JAX's persistent compilation cache (`compilation.enable_cache`: a CPU by default)

    def __post_init__(self):
        budget = self.eval_budget
        checks.fields(
            "training.Settings",
            self,
            {
                **{name: _in_range(name, getattr(self, name)) for name in _LOWEST},
                "eval_budget": (
                    not isinstance(budget, bool) and isinstance(budget, numbers.Real) and 0 < budget <= 1,
                    "a share of the time, in (0, 1]",
                ),
                "render": (isinstance(self.render, rendering.RenderConfig), "a mjzoo.harness.rendering.RenderConfig"),
            },
        )
        checks.fields(  # between fields
            "training.Settings",
            self,
            {
                "eval_seconds": (
                    self.eval_steps is None or self.eval_seconds is None,
                    "None with eval_steps: both give the evaluation's length",
                ),
                "video_every": (not (self.video_every and not self.video), "0 with video=False"),
            },
        )
        for name in _LOWEST:  # NumPy scalars as Python's: config.json is written with `json`
            value = getattr(self, name)
            if isinstance(value, numbers.Number) and type(value) not in (int, float):
                object.__setattr__(self, name, int(value) if isinstance(value, numbers.Integral) else float(value))


# Settings' numeric fields: the lowest value allowed; "> 0" where it is excluded.
_LOWEST = {
    "updates_per_chunk": 1,
    "eval_envs": 1,
    "eval_steps": 1,
    "eval_seconds": "> 0",
    "eval_every": 0,
    "eval_count": 0,
    "eval_every_seconds": "> 0",
    "eval_first_seconds": 0,
    "video_every": 0,
    "log_every": 1,
    "checkpoint_every": 0,
    "checkpoint_every_seconds": "> 0",
}
_OPTIONAL = (
    "eval_steps",
    "eval_seconds",
    "eval_every",
    "eval_every_seconds",
    "eval_first_seconds",
    "checkpoint_every",
    "checkpoint_every_seconds",
)  # None allowed


def _in_range(name: str, value: Any) -> tuple[bool, str]:
    """(whether Settings' numeric field `name` is valid, what it must be): seconds may be floats."""
    kind = numbers.Real if name.endswith("seconds") else numbers.Integral  # NumPy's too
    low = _LOWEST[name]
    expected = ("a finite number" if kind is numbers.Real else "an int") + (f" {low}" if low == "> 0" else f" >= {low}")
    expected += " or None" if name in _OPTIONAL else ""
    if value is None:
        return name in _OPTIONAL, expected
    if isinstance(value, bool) or not isinstance(value, kind) or not math.isfinite(value):
        return False, expected
    return bool(value > 0 if low == "> 0" else value >= low), expected


def checkpoint_due(settings: Settings, chunk: int, final: bool, since: float) -> bool:
    """Whether chunk number `chunk` (1-based) saves a checkpoint, `since` seconds after
    the last save (or the launch), by the rule in `Settings`' docstring."""
    every, seconds = settings.checkpoint_every, settings.checkpoint_every_seconds
    if every == 0:
        return False
    return final or bool(every and chunk % every == 0) or (seconds is not None and since >= seconds)


class EvalSchedule:
    """Which chunks evaluate, by the rule in `Settings`' docstring; `spent` records what
    each evaluation cost, for the budget."""

    def __init__(self, settings: Settings, launched: float, total_updates: int = 0) -> None:
        self.settings, self.launched, self.total_updates = settings, launched, total_updates
        self.last: float | None = None  # when the last evaluation of this launch began
        self.total, self.latest = 0.0, 0.0  # seconds of all evaluations so far, and of the latest

    def due(
        self, chunk: int, final: bool, now: float, compiled: bool = True, updates: tuple[int, int] = (0, 0)
    ) -> bool:
        """Whether chunk number `chunk` (1-based), ending at `now`, evaluates; if so,
        the clock trigger counts from now. `compiled`: whether the evaluation's program
        is ready. `updates`: the run's updates before and after the chunk, for
        `eval_count`'s marks. The budget fires only once it is; the other triggers fire
        anyway, and the evaluation then waits for its compile (which the run's last
        evaluation waits for in any case)."""
        s = self.settings
        waiting = s.eval_first_seconds is not None and now - self.launched < s.eval_first_seconds
        since = now - (self.launched if self.last is None else self.last)
        affordable = self.total + self.latest <= s.eval_budget * (now - self.launched)
        marked = s.eval_every is None and self._marks(updates[1]) > self._marks(updates[0])
        fires = (
            (s.eval_every is None and affordable and compiled)
            or marked
            or (bool(s.eval_every) and chunk % s.eval_every == 0)
            or (s.eval_every_seconds is not None and since >= s.eval_every_seconds)
            or (s.eval_first_seconds is not None and self.last is None)
        )
        if final or (fires and not waiting):
            self.last = now
            return True
        return False

    def _marks(self, updates: int) -> int:
        """How many of `eval_count`'s marks, evenly spaced over the run, `updates` has passed."""
        count = self.settings.eval_count
        return updates * count // self.total_updates if count and self.total_updates else 0

    def spent(self, seconds: float) -> None:
        """Records that an evaluation took `seconds` (not counting the wait for its compile)."""
        self.total, self.latest = self.total + seconds, seconds


def config_dict(config: Any) -> dict[str, Any]:
    """A dataclass config as JSON-ready data; user-supplied functions become their names.
    Not a dataclass (a user's algorithm without one): {}."""
    if not dataclasses.is_dataclass(config):
        return {}

    def plain(value):
        if isinstance(value, (bool, int, float, str)) or value is None:
            return value
        if isinstance(value, (tuple, list)):
            return [plain(v) for v in value]
        return f"<custom {type(value).__name__}>"

    return {f.name: plain(getattr(config, f.name)) for f in dataclasses.fields(config)}


def hyperparams_dict(hyperparams: Any) -> dict[str, Any]:
    """A hyperparameter dataclass pytree as one flat JSON-ready dict (what the algorithm's
    `configure` takes back): nested ones (AMP's `ppo`) merged in, scalars as floats, a
    batch of them as a list. Not a dataclass (a user's own pytree): {}."""
    if not dataclasses.is_dataclass(hyperparams):
        return {}
    flat: dict[str, Any] = {}
    for field in dataclasses.fields(hyperparams):
        value = getattr(hyperparams, field.name)
        if dataclasses.is_dataclass(value):
            flat.update(hyperparams_dict(value))
            continue
        array = np.asarray(value, dtype=np.float64)
        flat[field.name] = float(array) if array.ndim == 0 else array.tolist()
    return flat
