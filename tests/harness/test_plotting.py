"""Learning-curve plots from metrics.jsonl."""

from __future__ import annotations

import subprocess
import sys

import imageio.v3 as iio
import numpy as np

from mjzoo.harness.metrics import MetricsWriter
from mjzoo.harness.metrics import read_metrics
from mjzoo.harness.plotting import DEFAULT_KEYS
from mjzoo.harness.plotting import _panels
from mjzoo.harness.plotting import plot_curves
from mjzoo.harness.rendering import RenderConfig

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def write_run(directory) -> None:
    with MetricsWriter(directory, tensorboard=False) as log:
        for i in range(40):
            step = 1000 * i
            metrics = {
                "train/episode_return": 100 * (1 - np.exp(-i / 10)),
                "loss/policy": np.exp(-i / 8),
                "loss/value": 2 * np.exp(-i / 15),
                "other": float(i),
            }
            if i % 10 == 0:
                metrics["eval/return"] = 90 * (1 - np.exp(-i / 10))
            log.write(step, metrics)


def image(path) -> np.ndarray:
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    return iio.imread(path)


def test_default_keys_make_a_grid_of_panels(tmp_path):
    write_run(tmp_path)
    out = plot_curves(tmp_path / "metrics.jsonl", tmp_path / "plots" / "curves.png")
    assert out == tmp_path / "plots" / "curves.png" and out.stat().st_size > 0
    # eval/return beside train/episode_return, loss/policy, loss/value: 1 x 3 at 100 dpi.
    assert image(out).shape[:2] == (300, 1350)


def test_chosen_keys_and_missing_keys_are_skipped(tmp_path):
    write_run(tmp_path)
    one = plot_curves(tmp_path, tmp_path / "one.png", keys=["other", "no/such_key"])
    assert image(one).shape[:2] == (300, 450)  # only "other": one panel
    picture = image(one)
    assert len(np.unique(picture.reshape(-1, picture.shape[-1]), axis=0)) > 10  # something is drawn

    none = plot_curves(tmp_path, tmp_path / "none.png", keys=["no/such_key"])
    assert none.stat().st_size > 0 and image(none).shape[:2] == (300, 450)


def test_import_selects_no_matplotlib_backend():
    code = "import mjzoo.harness.plotting, sys; print('matplotlib.pyplot' in sys.modules)"
    # close_fds=False lets Python use posix_spawn: no fork of this multithreaded (JAX) process.
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, close_fds=False)
    assert result.stdout.strip() == "False"


def write_terms(directory, terms: int) -> None:
    """reward/t0 .. reward/t<terms-1>, term i of size i + 1, plus their total."""
    with MetricsWriter(directory, tensorboard=False) as log:
        for i in range(20):
            log.write(100 * i, {"reward": float(i), **{f"reward/t{k}": (k + 1) * (1 + 0.01 * i) for k in range(terms)}})


def has_colour(picture: np.ndarray, hex_colour: str) -> bool:
    """Whether some pixels are (within antialiasing) this matplotlib colour, e.g. "#1f77b4"."""
    rgb = np.array([int(hex_colour[i : i + 2], 16) for i in (1, 3, 5)])
    return int(np.sum(np.abs(picture[..., :3].astype(int) - rgb).max(-1) < 12)) > 5


def test_figsize_is_per_subplot(tmp_path):
    write_run(tmp_path)
    one = plot_curves(tmp_path, tmp_path / "one.png", keys=["other"], config=RenderConfig(plot_figsize=(2.0, 1.5)))
    assert image(one).shape[:2] == (150, 200)  # at 100 dpi
    three = plot_curves(tmp_path, tmp_path / "three.png", config=RenderConfig(plot_figsize=(2.0, 1.5)))
    assert image(three).shape[:2] == (150, 600)  # 1 x 3 subplots


def test_a_group_draws_its_largest_series_up_to_the_cap(tmp_path):
    write_terms(tmp_path, terms=6)
    records = read_metrics(tmp_path)
    present = sorted(k for k in records[0] if k != "step")
    # "reward" is a metric of its own; "reward/" is the group of its terms.
    assert _panels(records, present, ["reward", "reward/"], cap=8) == [
        ("reward", ["reward"]),
        ("reward/", [f"reward/t{k}" for k in range(6)]),
    ]
    assert _panels(records, present, ["reward/"], cap=3) == [
        ("reward/ (3 largest of 6)", ["reward/t3", "reward/t4", "reward/t5"])
    ]

    # In the picture: the first three colours of matplotlib's cycle, never the fourth.
    cycle = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"]
    capped = image(plot_curves(tmp_path, tmp_path / "capped.png", ["reward/"], RenderConfig(max_series_per_plot=3)))
    assert [has_colour(capped, c) for c in cycle] == [True, True, True, False]
    full = image(plot_curves(tmp_path, tmp_path / "full.png", ["reward/"], RenderConfig(max_series_per_plot=4)))
    assert [has_colour(full, c) for c in cycle] == [True, True, True, True]


def test_default_keys_include_the_reward_terms(tmp_path):
    write_terms(tmp_path, terms=2)
    assert image(plot_curves(tmp_path, tmp_path / "curves.png")).shape[:2] == (300, 450)  # one subplot: reward/


def test_the_evaluation_return_is_drawn_beside_the_training_return(tmp_path):
    """One subplot holds both: the evaluations' few points read against the training
    episodes' return of every chunk (matplotlib's first two colours)."""
    write_run(tmp_path)
    records = read_metrics(tmp_path)
    present = sorted({k for r in records for k in r if k != "step"})
    assert _panels(records, present, DEFAULT_KEYS, cap=8)[0] == (
        "eval/return and train/episode_return",
        ["eval/return", "train/episode_return"],
    )
    picture = image(plot_curves(tmp_path, tmp_path / "curves.png", keys=DEFAULT_KEYS))
    assert picture.shape[:2] == (300, 450)  # one subplot: write_run has no reward/ terms
    assert has_colour(picture, "#1f77b4") and has_colour(picture, "#ff7f0e")
