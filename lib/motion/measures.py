"""Style measures: how much a simulated motion looks like its reference.

A policy trained with a motion prior should move like the clips, not replay them in
step: its joint trajectory should be close, window by window, to SOME stretch of the
reference. `nearest_window_error` is the mean joint-angle error to the nearest
reference window:

    err = motion.nearest_window_error(ref_qpos, sim_qpos, qpos_index=hinges, window=10)

Host numpy, vectorized: the per-frame distances between every simulated and every
reference frame are computed once (in row chunks), then summed along diagonals, so a
window costs one add per frame pair. T = M = 1000, J = 20, window = 10 or 50 took 0.8 s
on a busy 2-core machine.
"""

from __future__ import annotations

import numpy as np

__all__ = ["nearest_window_error"]

_CHUNK_ELEMENTS = 1 << 22  # frame pairs x joints per chunk of the distance matrix (32 MiB)


def nearest_window_error(reference_qpos, qpos, qpos_index, window: int) -> float:
    """The mean joint-angle error to the nearest reference window (rad, or m for slides).

    Args:
      reference_qpos: [M, nq] the reference's positions.
      qpos: [T, nq] the simulated positions.
      qpos_index: int [J] the qpos columns compared (e.g. the hinge joints').
      window: frames per window, 1 <= window <= min(T, M).

    Returns:
      The average over the T - window + 1 simulated windows of the smallest, over the
      M - window + 1 reference windows, mean absolute error over the window's frames
      and the J columns.
    """
    who = "motion.nearest_window_error"
    ref, sim = np.asarray(reference_qpos, np.float64), np.asarray(qpos, np.float64)
    index = np.asarray(qpos_index, np.int64).reshape(-1)
    if ref.ndim != 2 or sim.ndim != 2 or ref.shape[1] != sim.shape[1]:
        raise ValueError(f"{who}: reference_qpos {ref.shape} and qpos {sim.shape} must be [M, nq] and [T, nq]")
    if index.size == 0 or index.min() < 0 or index.max() >= ref.shape[1]:
        raise ValueError(f"{who}: qpos_index={qpos_index!r} must be column indices in [0, {ref.shape[1]})")
    shortest = min(sim.shape[0], ref.shape[0])
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or not 1 <= window <= shortest:
        raise ValueError(f"{who}: window={window!r} must be an integer in [1, min(T, M) = {shortest}]")
    distance = _frame_distances(sim[:, index], ref[:, index])  # [T, M] summed |error| over J
    num_sim, num_ref = sim.shape[0] - window + 1, ref.shape[0] - window + 1
    total = np.zeros((num_sim, num_ref))
    for i in range(window):  # window sums along the diagonals: frame s+i against frame r+i
        total += distance[i : i + num_sim, i : i + num_ref]
    return float(np.mean(total.min(axis=1)) / (window * index.size))


def _frame_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[T, M]: sum over columns of |a[t] - b[m]| for a [T, J], b [M, J]."""
    out = np.empty((a.shape[0], b.shape[0]))
    rows = max(1, _CHUNK_ELEMENTS // max(1, b.shape[0] * a.shape[1]))
    for lo in range(0, a.shape[0], rows):
        out[lo : lo + rows] = np.abs(a[lo : lo + rows, None, :] - b[None, :, :]).sum(axis=-1)
    return out
