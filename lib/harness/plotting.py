"""Learning curves from a run's metrics.jsonl, as one PNG.

    plot_curves("runs/a/metrics.jsonl", "runs/a/curves.png")

Draws on a bare `matplotlib.figure.Figure` with the Agg canvas instead of `pyplot`:
no global backend is selected, no figure registry is touched, and it works without a
display, in a training process or in a notebook alike.
"""

from __future__ import annotations

import math
from pathlib import Path
from collections.abc import Sequence

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mjzoo.harness.metrics import read_metrics

__all__ = ["plot_curves", "DEFAULT_KEYS"]

DEFAULT_KEYS = ("eval/return", "train/episode_return")  # then every "loss/..." key
_COLUMNS = 3
_PANEL_SIZE = (4.5, 3.0)  # inches per subplot


def plot_curves(metrics_path: str | Path, out_path: str | Path, keys: Sequence[str] | None = None) -> Path:
    """Plots metrics against "step", one subplot per key, and writes a PNG.

    Args:
      metrics_path: a metrics.jsonl written by `mjzoo.harness.metrics.MetricsWriter` (or its
        directory).
      out_path: the PNG to write; parent directories are created.
      keys: metric names to plot, in order; default `DEFAULT_KEYS` then the sorted
        "loss/..." keys. Keys the file does not hold are skipped.

    Returns:
      `out_path`. With none of the keys in the file, the PNG says so.
    """
    records = read_metrics(metrics_path)
    present = {k for r in records for k in r if k != "step"}
    if keys is None:
        keys = [*DEFAULT_KEYS, *sorted(k for k in present if k.startswith("loss/"))]
    requested, keys = list(keys), [k for k in dict.fromkeys(keys) if k in present]

    rows = max(1, math.ceil(len(keys) / _COLUMNS))
    columns = min(max(len(keys), 1), _COLUMNS)
    figure = Figure(figsize=(_PANEL_SIZE[0] * columns, _PANEL_SIZE[1] * rows), layout="constrained")
    FigureCanvasAgg(figure)  # attaches itself: this figure renders with Agg, whatever pyplot's backend
    if not keys:
        figure.text(0.5, 0.5, f"none of {requested}\nin {metrics_path}", ha="center", va="center", wrap=True)
    axes = figure.subplots(rows, columns, squeeze=False).flat if keys else []
    for ax, key in zip(axes, keys):
        points = [(r["step"], r[key]) for r in records if key in r]  # e.g. eval runs only every N steps
        steps, values = zip(*points, strict=True)
        ax.plot(steps, values, marker="o" if len(points) < 30 else None, markersize=3, linewidth=1.2)
        ax.set_title(key)
        ax.set_xlabel("step")
        ax.grid(True, alpha=0.3)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))
    for ax in list(figure.axes)[len(keys) :]:  # the unused cells of the last row
        ax.set_visible(False)

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out_path, format="png", dpi=100)
    return out_path
