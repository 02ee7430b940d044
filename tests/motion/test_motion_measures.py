"""`motion.nearest_window_error`: hand-computed examples, a brute-force comparison, speed."""

from __future__ import annotations

import time

import numpy as np
import pytest

from mjzoo import motion

# Reference column 0: 0, 1, 2, 3 (windows of 2: (0,1), (1,2), (2,3)); column 1 all 0.
REF = np.array([[0.0, 0], [1, 0], [2, 0], [3, 0]])
# Simulated column 0: 0.5, 1.5, 3.0 (windows (0.5,1.5), (1.5,3.0)); column 1 all 1.
SIM = np.array([[0.5, 1], [1.5, 1], [3.0, 1]])


def test_by_hand_one_column():
    # (0.5,1.5): 0.5 to (0,1) and to (1,2), 1.5 to (2,3) -> 0.5.
    # (1.5,3.0): (1.5+2)/2 to (0,1), (0.5+1)/2 to (1,2), (0.5+0)/2 = 0.25 to (2,3) -> 0.25.
    assert motion.nearest_window_error(REF, SIM, [0], window=2) == pytest.approx((0.5 + 0.25) / 2)


def test_by_hand_two_columns():
    # Column 1 adds |1 - 0| per frame: window errors (sum col 0 + 2) / 4 -> 0.75 and 0.625.
    assert motion.nearest_window_error(REF, SIM, [0, 1], window=2) == pytest.approx((0.75 + 0.625) / 2)


def test_window_one_and_exact_stretches():
    # Window 1: each frame to its nearest reference frame: 0.5, 0.5, 0 -> 1/3.
    assert motion.nearest_window_error(REF, SIM, [0], window=1) == pytest.approx(1 / 3)
    rng = np.random.default_rng(0)
    ref = rng.normal(size=(60, 5))
    assert motion.nearest_window_error(ref, ref[10:30], [0, 2, 4], window=7) == 0.0


def test_matches_brute_force():
    rng = np.random.default_rng(1)
    ref, sim, index, w = rng.normal(size=(23, 6)), rng.normal(size=(17, 6)), [1, 3, 4], 5
    best = [
        min(np.mean(np.abs(sim[s : s + w][:, index] - ref[r : r + w][:, index])) for r in range(23 - w + 1))
        for s in range(17 - w + 1)
    ]
    assert motion.nearest_window_error(ref, sim, index, w) == pytest.approx(np.mean(best), rel=1e-12)


def test_fast_enough_for_a_thousand_frames():
    rng = np.random.default_rng(2)
    ref, sim = rng.normal(size=(1000, 27)), rng.normal(size=(1000, 27))
    start = time.perf_counter()
    motion.nearest_window_error(ref, sim, np.arange(7, 27), window=10)
    assert time.perf_counter() - start < 5.0  # 0.8 s measured on a loaded 2-core machine


def test_bad_arguments():
    with pytest.raises(ValueError, match=r"window=4 must be an integer in \[1, min\(T, M\) = 3\]"):
        motion.nearest_window_error(REF, SIM, [0], window=4)
    with pytest.raises(ValueError, match="qpos_index=.* must be column indices in"):
        motion.nearest_window_error(REF, SIM, [2], window=2)
    with pytest.raises(ValueError, match="must be \\[M, nq\\] and \\[T, nq\\]"):
        motion.nearest_window_error(REF, SIM[:, :1], [0], window=2)
