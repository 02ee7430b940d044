"""Learning-curve plots from metrics.jsonl."""

from __future__ import annotations

import subprocess
import sys

import imageio.v3 as iio
import numpy as np

from mjzoo.harness.metrics import MetricsWriter
from mjzoo.harness.plotting import plot_curves

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
    # eval/return, train/episode_return, loss/policy, loss/value: a 2 x 3 grid at 100 dpi.
    assert image(out).shape[:2] == (600, 1350)


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
