"""A live browser viewer (viser) for tasks, trained policies, sampling planners and
recordings: `mjzoo view` from the command line.

    from mjzoo.harness import viewer
    task = mjzoo.envs.make("pendulum_swingup")
    v = viewer.serve(viewer.env(task, controls="sliders", num_envs=4), port=8080)  # open http://localhost:8080
    v.controls["param/upright_weight"].value = 2.0   # what the slider does: task.with_params, no recompile
    v.wait(10.0); v.stop()                          # 10 simulated seconds, then stop

    viewer.serve(viewer.policy(task, ppo.policy(config, task), params))           # a trained policy
    viewer.serve(viewer.planner(mjzoo.envs.closed_loop_problem("pendulum_swingup", mppi, mppi.Config())))
    viewer.serve(viewer.recording(task.mj_model, datasets.load("data/walk"), episodes=4))
    viewer.serve(viewer.side_by_side([(g1, g1_walk), (human, walk)]))             # a retargeted clip beside its source

The browser gets each body's meshes once (MuJoCo geoms grouped per body) and then, at
most 30 times a second, only body poses. The simulation runs in a background thread,
one jitted `lax.scan` over a few control steps per call, paced to the chosen speed
(0.25x to 4x, or as fast as it goes). The panel: play / pause / step / reset, speed,
which environment of a batch to show (all side by side, shifted in x, or one), a
camera that tracks a body, a live plot of each weighted reward term, a slider for every
float the task names (`mjzoo.params`; applied with `Task.with_params`, so nothing
compiles again; an infinite bound is shown as text), one slider per actuator (``controls="sliders"``), a planner's Config
floats (a separate folder: they are static, so a change compiles the planner again,
keeping its state), and a recording's timeline, loop switch and speed. Clips of
different models (a robot's retargeted clip and the human clip it came from) play in
step in one scene, side by side.

`mjzoo.harness.viewer.browser` opens a viewer's page in headless Chromium and clicks
it as a user would (the browser check in the tests; ``scripts/viewer_screenshot.py``).

Sources are built from objects: this package sits in the harness layer and names no
env or algorithm; `mjzoo view` (`mjzoo.harness.cli.viewing`) resolves names and run
directories into these calls.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from mjzoo import motion
from mjzoo.harness.viewer.app import Viewer
from mjzoo.harness.viewer.planning import Planning
from mjzoo.harness.viewer.recording import Recording
from mjzoo.harness.viewer.recording import SideBySide
from mjzoo.harness.viewer.recording import from_clip
from mjzoo.harness.viewer.recording import from_dataset
from mjzoo.harness.viewer.sources import Simulation
from mjzoo.harness.viewer.sources import controls as make_controls
from mjzoo.planning.realtime import Problem
from mjzoo.types import Task

__all__ = ["serve", "env", "policy", "planner", "recording", "side_by_side", "Viewer"]


def env(task: Task, controls: str = "zero", num_envs: int = 1, seed: int = 0) -> Simulation:
    """`num_envs` copies of `task` under "zero", "random" (uniform in each actuator's
    range) or "sliders" (one GUI slider per actuator) controls."""
    if num_envs < 1:
        raise ValueError(f"viewer.env: num_envs must be >= 1, got {num_envs}")
    act, params = make_controls(controls, task)
    source = Simulation(task, act, params, num_envs, seed)
    source.control_sliders = controls == "sliders"
    return source


def policy(task: Task, act: Any, params: Any, num_envs: int = 1, seed: int = 0) -> Simulation:
    """A deployable policy ``act(params, obs, key) -> action`` (e.g. `ppo.policy`) on `task`."""
    return Simulation(task, act, params, num_envs, seed)


def planner(
    problem: Problem, seed: int = 0, num_traces: int = 16, trace: str | Sequence[str] | None = None
) -> Planning:
    """`problem`'s sampling planner closed loop, drawing `num_traces` of its samples and
    its plan as the paths of the bodies or sites `trace` names (default: the first site,
    else the last body)."""
    return Planning(problem, seed, num_traces, trace)


def recording(mj_model: Any, data: Any, episodes: int = 1) -> Recording:
    """A `datasets.Dataset` (its first `episodes` episodes) or a `motion.Clip`, played back."""
    if isinstance(data, motion.Clip):
        return from_clip(mj_model, data)
    return from_dataset(mj_model, data, episodes)


def side_by_side(clips: Sequence[tuple[Any, motion.Clip]], spacing: float = 0.0) -> SideBySide:
    """Motion clips of different models, ``[(mj_model, clip), ...]``, played in step in one
    scene, each beside the one before along x, `spacing` metres apart (0: about a body's
    height): a retargeted clip beside the clip it came from. Each clip is checked against
    its model's joints; the first clip's frame rate sets the timeline."""
    return SideBySide([from_clip(m, clip) for m, clip in clips], spacing)


def serve(source: Task | Simulation | Planning | Recording | SideBySide, port: int = 8080, **options: Any) -> Viewer:
    """Starts a viewer of `source` (a `Task` means `env(task)`) on `port` (0: any free
    port) and returns its handle: ``.step()``, ``.stop()``, ``.wait(seconds)``,
    ``.controls``, ``.scene``, ``.stats()``. Options: host, display_hz (30), speed
    (0.25-4 or "max"), playing (True), track_body (a body name), record (keep each
    displayed frame's qpos in ``.recorded``)."""
    if isinstance(source, Task):
        source = env(source)
    return Viewer(source, port, **options)
