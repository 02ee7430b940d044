"""Learning curves from a run's metrics.jsonl, as one PNG.

    plot_curves("runs/a/metrics.jsonl", "runs/a/curves.png")
    plot_curves(run, "terms.png", keys=["reward/"], config=RenderConfig(max_series_per_plot=4, plot_figsize=(6, 4)))

A key names one metric (``"eval/return"``) or, ending in ``/``, a group drawn together
in one subplot (``"reward/"``: every ``"reward/<term>"``); a key that is no metric but
the prefix of some (``"reward"``) is a group too; a tuple of metric names is drawn in
one subplot (`RETURNS`: the evaluations' return beside the training episodes', whose
points come with every chunk, so the evaluation is read against a dense curve). A group draws at most
``config.max_series_per_plot`` series: those of largest mean magnitude, the ones that
move the total, and its title says how many were left out.

Draws on a bare `matplotlib.figure.Figure` with the Agg canvas instead of `pyplot`:
no global backend is selected, no figure registry is touched, and it works without a
display, in a training process or in a notebook alike.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from mjzoo.harness.metrics import read_metrics
from mjzoo.harness.render_config import RenderConfig

__all__ = ["DEFAULT_KEYS", "RETURNS", "plot_curves"]

RETURNS = ("eval/return", "train/episode_return")  # one subplot: deterministic evaluations, training episodes
DEFAULT_KEYS = (RETURNS, "reward/")  # then every "loss/..." key
_COLUMNS = 3


def plot_curves(
    metrics_path: str | Path,
    out_path: str | Path,
    keys: Sequence[str | tuple[str, ...]] | None = None,
    config: RenderConfig = RenderConfig(),  # noqa: B008 - frozen: one shared default is safe
) -> Path:
    """Plots metrics against "step", one subplot per key (or group of keys), and writes a PNG.

    Args:
      metrics_path: a metrics.jsonl written by `mjzoo.harness.metrics.MetricsWriter` (or its
        directory).
      out_path: the PNG to write; parent directories are created.
      keys: metric names or groups (see the module docstring) to plot, in order; default
        `DEFAULT_KEYS` then the sorted "loss/..." keys. Keys the file does not hold are skipped.
      config: ``plot_figsize`` (inches per subplot, drawn at 100 dpi) and
        ``max_series_per_plot``.

    Returns:
      `out_path`. With none of the keys in the file, the PNG says so.
    """
    records = read_metrics(metrics_path)
    present = sorted({k for r in records for k in r if k != "step"})
    if keys is None:
        keys = [*DEFAULT_KEYS, *(k for k in present if k.startswith("loss/"))]
    panels = _panels(records, present, keys, config.max_series_per_plot)

    rows = max(1, math.ceil(len(panels) / _COLUMNS))
    columns = min(max(len(panels), 1), _COLUMNS)
    width, height = config.plot_figsize
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # here: importing matplotlib costs a launch ~0.8 s
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width * columns, height * rows), layout="constrained")
    FigureCanvasAgg(figure)  # attaches itself: this figure renders with Agg, whatever pyplot's backend
    if not panels:
        figure.text(0.5, 0.5, f"none of {list(keys)}\nin {metrics_path}", ha="center", va="center", wrap=True)
    axes = figure.subplots(rows, columns, squeeze=False).flat if panels else []
    for ax, (title, series) in zip(axes, panels):
        _draw(ax, records, title, series)
    for ax in list(figure.axes)[len(panels) :]:  # the unused cells of the last row
        ax.set_visible(False)

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out_path, format="png", dpi=100)
    return out_path


def _panels(
    records: list[dict[str, float]], present: list[str], keys: Sequence[str | tuple[str, ...]], cap: int
) -> list[tuple[str, list[str]]]:
    """(title, metric names) per subplot, in the order of `keys`; at most `cap` names each."""
    panels = []
    for key in dict.fromkeys(keys):
        if isinstance(key, tuple):  # named metrics side by side: those present
            members = [k for k in key if k in present]
            if members:
                panels.append((" and ".join(members) if len(members) > 1 else members[0], members))
            continue
        if key in present:
            panels.append((key, [key]))
            continue
        prefix = key if key.endswith("/") else key + "/"
        members = [k for k in present if k.startswith(prefix)]
        if not members:
            continue
        if len(members) > cap:  # keep the largest: a term that hardly moves the total says least
            size = {k: np.mean([abs(r[k]) for r in records if k in r and np.isfinite(r[k])] or [0.0]) for k in members}
            kept = set(sorted(members, key=lambda k: -size[k])[:cap])
            key = f"{prefix} ({cap} largest of {len(members)})"
            members = [k for k in members if k in kept]
        panels.append((key, members))
    return panels


def _draw(ax, records: list[dict[str, float]], title: str, series: list[str]) -> None:
    """One subplot: each metric against step, a legend when there are several (named
    in full where they come from several groups)."""
    grouped = len({name.rpartition("/")[0] for name in series}) == 1
    for name in series:
        points = [(r["step"], r[name]) for r in records if name in r]  # e.g. eval runs only every N steps
        steps, values = zip(*points, strict=True)
        label = (name.rsplit("/", 1)[-1] if grouped else name) if len(series) > 1 else None
        ax.plot(steps, values, marker="o" if len(points) < 30 else None, markersize=3, linewidth=1.2, label=label)
    if len(series) > 1:
        ax.legend(fontsize="x-small", ncols=2 if len(series) > 4 else 1)
    ax.set_title(title)
    ax.set_xlabel("step")
    ax.grid(True, alpha=0.3)
    ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))
