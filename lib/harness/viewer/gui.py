"""The viewer's GUI panel: playback, which environment, camera tracking, live readouts,
and sliders: the task's numbers (no recompile), slider controls, a planner's Config
(recompiles) and a recording's timeline.

Every handle is kept by name in the dict `build` returns, e.g. ``controls["play"]``,
``controls["param/upright_weight"]`` (``NAME[i]`` for a vector's entries),
``controls["ctrl/torque"]``, ``controls["config/temperature"]``, ``controls["scrubber"]``:
setting ``.value`` from Python runs the same callback a browser's change does.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING
from typing import Any

import mujoco
import numpy as np
from viser import GuiSliderHandle
from viser import GuiTextHandle
from viser import uplot

from mjzoo.harness.viewer.sources import slider_range

if TYPE_CHECKING:
    from mjzoo.harness.viewer.app import Viewer
    from mjzoo.harness.viewer.sources import Frame

__all__ = ["build", "refresh", "SPEEDS"]

SPEEDS = ("0.25", "0.5", "1", "2", "4", "max")
_COLORS = ("#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6", "#9a6324")


def build(viewer: Viewer, track_body: str | None) -> dict[str, Any]:
    """Adds every folder the source calls for; returns the handles by name."""
    controls: dict[str, Any] = {}
    _playback(viewer, controls, track_body)
    source = viewer.source
    if hasattr(source, "seek"):
        _timeline(viewer, controls)
    if getattr(source, "control_sliders", False):
        _control_sliders(viewer, controls)
    if source.parameters():
        _parameter_sliders(viewer, controls)
    if hasattr(source, "set_config"):
        _config_sliders(viewer, controls)
    _reward_plot(viewer, controls)
    return controls


def _playback(viewer: Viewer, controls: dict[str, Any], track_body: str | None) -> None:
    g, source = viewer.server.gui, viewer.source
    with g.add_folder("Playback"):
        controls["play"] = g.add_button("Pause" if viewer.playing else "Play")
        controls["step"] = g.add_button("Step")
        controls["reset"] = g.add_button("Reset")
        speed = str(viewer.speed).rstrip("0").rstrip(".") if viewer.speed != "max" else "max"
        controls["speed"] = g.add_dropdown("Speed", SPEEDS, initial_value=speed if speed in SPEEDS else "1")
        if source.num_envs > 1:
            controls["env"] = g.add_dropdown("Show env", ("all", *map(str, range(source.num_envs))))
        names = [
            "none",
            *(
                mujoco.mj_id2name(source.mj_model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
                for b in range(1, source.mj_model.nbody)
            ),
        ]
        controls["track"] = g.add_dropdown("Camera tracks", names, initial_value=track_body or "none")
        controls["status"] = g.add_markdown("")

    def play(_) -> None:
        viewer.playing = not viewer.playing
        controls["play"].label = "Pause" if viewer.playing else "Play"

    controls["play"].on_click(play)
    controls["step"].on_click(lambda _: viewer.step())
    controls["reset"].on_click(lambda _: viewer.reset())
    controls["speed"].on_update(lambda _: setattr(viewer, "speed", _speed(controls["speed"].value)))
    if "env" in controls:
        controls["env"].on_update(lambda _: _show_env(viewer, controls["env"].value))
    controls["track"].on_update(lambda _: _track(viewer, controls["track"].value))
    _track(viewer, controls["track"].value)


def _speed(value: str) -> float | str:
    return value if value == "max" else float(value)


def _show_env(viewer: Viewer, value: str) -> None:
    """One environment shown (the others hidden; the camera and plot follow it), or all."""
    with viewer.lock:
        viewer.shown = None if value == "all" else int(value)
        for (env, _), handle in viewer.scene.handles.items():
            handle.visible = viewer.shown is None or env == viewer.shown
        viewer.history.clear()


def _track(viewer: Viewer, name: str) -> None:
    if name == "none":
        viewer.track = None
        return
    found = mujoco.mj_name2id(viewer.source.mj_model, mujoco.mjtObj.mjOBJ_BODY, name)
    viewer.track = int(found) if found >= 0 else int(name.removeprefix("body"))


def _timeline(viewer: Viewer, controls: dict[str, Any]) -> None:
    g, source = viewer.server.gui, viewer.source
    with g.add_folder("Recording"):
        controls["scrubber"] = g.add_slider("Frame", 0, source.num_frames - 1, 1, source.index)
        controls["loop"] = g.add_checkbox("Loop", source.loop)

    def seek(event) -> None:
        if getattr(viewer, "_syncing", False):
            return  # the loop moving the scrubber along, not a user
        with viewer.lock:
            source.seek(int(controls["scrubber"].value))
            viewer.display()

    controls["scrubber"].on_update(seek)
    controls["loop"].on_update(lambda _: setattr(source, "loop", bool(controls["loop"].value)))


def _control_sliders(viewer: Viewer, controls: dict[str, Any]) -> None:
    """One slider per actuator, in its action's range: the actions every env applies."""
    g, source, model = viewer.server.gui, viewer.source, viewer.source.mj_model
    low, high = source.control_range
    with g.add_folder("Controls"):
        for a in range(model.nu):
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or f"actuator{a}"
            start = float(np.asarray(source.act_params)[a])
            handle = g.add_slider(name, float(low[a]), float(high[a]), float(high[a] - low[a]) / 200, start)
            controls[f"ctrl/{name}"] = handle
            handle.on_update(lambda _, a=a, h=handle: _set_control(viewer, a, h.value))


def _set_control(viewer: Viewer, index: int, value: float) -> None:
    with viewer.lock:
        params = np.array(viewer.source.act_params, np.float32)
        params[index] = value
        viewer.source.act_params = params  # same shape and dtype: no compile


def _parameter_sliders(viewer: Viewer, controls: dict[str, Any]) -> None:
    """The task's float parameters, a slider per scalar or vector entry (an infinite
    bound, which no slider range holds, is shown as text)."""
    g = viewer.server.gui
    with g.add_folder("Task parameters (no recompile)"):
        for name, value in viewer.source.parameters().items():
            for i, entry in enumerate(value.reshape(-1)):
                label = name if value.ndim == 0 else f"{name}[{i}]"
                handle = _number(viewer, label, float(entry))
                controls[f"param/{label}"] = handle
                if isinstance(handle, GuiSliderHandle):
                    handle.on_update(lambda _, n=name, i=i, h=handle: _set_parameter(viewer, n, i, h.value))


def _number(viewer: Viewer, label: str, value: float) -> GuiSliderHandle | GuiTextHandle:
    """A slider around `value`, or for a non-finite one (``inf``: a bound that never
    binds) its value as read-only text."""
    if not math.isfinite(value):
        return viewer.server.gui.add_text(label, f"{value:g}", disabled=True)
    return viewer.server.gui.add_slider(label, *slider_range(value), value)


def _set_parameter(viewer: Viewer, name: str, index: int, value: float) -> None:
    with viewer.lock:
        current = np.array(viewer.source.parameters()[name])
        current.reshape(-1)[index] = value
        viewer.source.set_parameters(**{name: current})


def _config_sliders(viewer: Viewer, controls: dict[str, Any]) -> None:
    """The planner's hyperparameters: a change runs at once (they are in its state)."""
    from mjzoo.harness.viewer.planning import config_floats

    g = viewer.server.gui
    with g.add_folder("Planner hyperparameters"):
        for name, value in config_floats(viewer.source.hyperparams).items():
            handle = controls[f"config/{name}"] = _number(viewer, name, value)
            if isinstance(handle, GuiSliderHandle):
                handle.on_update(lambda _, n=name, h=handle: _set_config(viewer, controls, n, h.value))


def _set_config(viewer: Viewer, controls: dict[str, Any], name: str, value: float) -> None:
    with viewer.lock:
        try:
            viewer.source.set_config(**{name: float(value)})
            viewer.message = ""
        except ValueError as e:  # the Hyperparams' own check, e.g. temperature must be > 0
            viewer.message = str(e)


def _reward_plot(viewer: Viewer, controls: dict[str, Any]) -> None:
    terms = list(viewer.source.frame().terms)
    if not terms:
        return
    series = (
        uplot.Series(label="t (s)"),
        *(uplot.Series(label=t, stroke=_COLORS[i % len(_COLORS)], width=1.5) for i, t in enumerate(terms)),
    )
    empty = tuple(np.zeros(0) for _ in range(len(terms) + 1))
    with viewer.server.gui.add_folder("Reward terms"):
        controls["plot"] = viewer.server.gui.add_uplot(empty, series, title="weighted reward terms", aspect=1.5)
    viewer.plot_terms = terms


def refresh(viewer: Viewer, frame: Frame) -> None:
    """The slower readouts (a few times a second): status line, reward plot, scrubber."""
    controls, stats = viewer.controls, viewer.stats()
    parts = [f"t = {frame.time:.2f} s", f"{stats['steps_per_s']:,.0f} steps/s", f"{stats['display_hz']:.0f} fps"]
    if "plan_hz" in stats:
        parts += [f"plan {stats['plan_hz']:.1f} Hz", f"latency {stats['plan_latency_ms']:.1f} ms"]
    message = getattr(viewer, "message", "")
    controls["status"].content = " · ".join(parts) + (f"\n\n**{message}**" if message else "")
    if "plot" in controls and viewer.history:
        times = np.array([t for t, _ in viewer.history])
        values = [np.array([v.get(k, np.nan) for _, v in viewer.history]) for k in viewer.plot_terms]
        controls["plot"].data = (times, *values)
    if "scrubber" in controls:
        viewer._syncing = True
        try:
            controls["scrubber"].value = viewer.source.index
        finally:
            viewer._syncing = False
