"""The viewer: a viser server, its GUI, and the loop that advances a source and draws it.

One background thread does both: while playing it advances the source by whole jitted
calls as simulated time falls due (speed x wall time; "max": back to back), and at most
`display_hz` times a second it sends the shown bodies' poses, the planner's traces, the
reward plot and the camera. Between displayed frames nothing is sent. GUI callbacks
run on viser's threads and take the same lock, so a slider's number reaches the source
between two jitted calls.
"""

from __future__ import annotations

import collections
import threading
import time
from typing import Any

import numpy as np
import viser

from mjzoo.harness.distributed import free_port
from mjzoo.harness.viewer import gui
from mjzoo.harness.viewer.scene import Scene
from mjzoo.harness.viewer.sources import Frame

__all__ = ["Viewer", "SAMPLES_RGB", "PLAN_RGB"]

_BEHIND_LIMIT_S = 0.25  # simulated time a slow source may fall behind before it is let go
_PLOT_PERIOD_S = 0.2  # the reward plot at 5 Hz: plots cost more to send than poses
SAMPLES_RGB, PLAN_RGB = (150, 150, 160), (230, 40, 40)  # a planner's traces: its samples, its plan


class Viewer:
    """A running viewer of `source` (see `mjzoo.harness.viewer.serve`).

    Attributes:
      server: the viser server; scene: the bodies (`Scene.handles`); controls: the GUI
      handles by name (`gui.Controls`); frames_shown: displayed frames so far;
      recorded: (qpos [nq], mocap_pos, mocap_quat) of environment `shown` per displayed
      frame, when `record` (models side by side: a tuple of them, one per model).
    """

    def __init__(
        self,
        source: Any,
        port: int = 8080,
        host: str = "0.0.0.0",
        *,
        display_hz: float = 30.0,
        speed: float | str = 1.0,
        playing: bool = True,
        track_body: str | None = None,
        record: bool = False,
        label: str = "mjzoo view",
    ):
        self.source, self.display_hz, self.record = source, display_hz, record
        self.server = viser.ViserServer(host=host, port=port or free_port(), label=label, verbose=False)
        self.lock = threading.RLock()
        models = getattr(source, "models", source.mj_model)  # several: a side by side of different models
        self.scene = Scene(self.server, models, source.num_envs, getattr(source, "spacing", 0.0))
        self.speed, self.playing, self.shown, self.track = speed, playing, None, None
        self.frames_shown, self.recorded, self.sim_seconds = 0, [], 0.0
        self.history: collections.deque = collections.deque(maxlen=300)
        self.trace_handles: dict[str, Any] = {}
        self.rate = _Rate()
        self.controls = gui.build(self, track_body)
        self._stop, self._last_plot = threading.Event(), 0.0
        self.display()
        self._thread = threading.Thread(target=self._loop, name="mjzoo-viewer", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return self.server.get_port()

    # --- what the GUI and Python call ------------------------------------------------

    def step(self, calls: int = 1) -> None:
        """Advances the source by `calls` jitted calls and displays the result (for use
        from Python and tests; pause first so the loop does not advance it as well)."""
        with self.lock:
            for _ in range(calls):
                self._advance()
            self.display()

    def reset(self, seed: int = 0) -> None:
        with self.lock:
            self.source.reset(seed)
            self.history.clear()
            self.display()

    def stop(self) -> None:
        """Stops the loop and the server (idempotent)."""
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=10)
        self.server.stop()

    def wait(self, seconds: float | None = None) -> None:
        """Blocks until `seconds` of simulated time have been shown (None: until Ctrl-C
        or `stop`)."""
        try:
            while not self._stop.is_set() and (seconds is None or self.sim_seconds < seconds):
                time.sleep(0.05)
        except KeyboardInterrupt:
            pass

    def stats(self) -> dict[str, float]:
        """steps_per_s (control steps of all shown envs per wall second while playing),
        display_hz, and a planner's plan_hz and plan_latency_ms."""
        found = {"steps_per_s": self.rate.per_second() * self.source.num_envs, "display_hz": self.rate.displays()}
        if hasattr(self.source, "latency_ms"):
            found.update(plan_hz=self.rate.calls_per_second(), plan_latency_ms=self.source.latency_ms())
        return found

    # --- the loop ----------------------------------------------------------------------

    def _loop(self) -> None:
        period, behind, last = 1.0 / self.display_hz, 0.0, time.perf_counter()
        next_display = last
        while not self._stop.is_set():
            now = time.perf_counter()
            with self.lock:
                if self.playing:
                    behind = self._catch_up(behind + (now - last) * self._speed_factor(), next_display)
                else:
                    behind = 0.0  # a pause forgives what was due
                last = now
                if now >= next_display and self.playing:  # paused: the actions display what they change
                    self.display()
                    next_display = max(next_display + period, time.perf_counter())  # no bursts after a slow call
            if not (self.playing and self.speed == "max"):
                time.sleep(max(0.0, min(next_display - time.perf_counter(), 0.005)))

    def _speed_factor(self) -> float:
        return float("inf") if self.speed == "max" else float(self.speed)

    def _catch_up(self, behind: float, deadline: float) -> float:
        """Advances while simulated time is due (`behind`, seconds) until the next
        display is (`deadline`): a source slower than the speed asked for drops time
        rather than frames. Returns what is still due. "max" speed: one call a turn."""
        if self.speed == "max":
            self._advance()
            return 0.0
        while behind > 0 and self.playing and time.perf_counter() < deadline:
            behind -= self._advance() * self.source.dt
        return min(behind, _BEHIND_LIMIT_S)

    def _advance(self) -> int:
        start = time.perf_counter()
        steps = self.source.advance()
        self.sim_seconds += steps * self.source.dt
        self.rate.add(steps, time.perf_counter() - start)
        return steps

    # --- drawing -----------------------------------------------------------------------

    def display(self) -> Frame:
        """Sends the current frame: body poses, traces, plot, camera and GUI readouts."""
        with self.lock:
            frame = self.source.frame()
            self.scene.update(frame.xpos, frame.xquat)
            if frame.traces is not None:
                self._draw_traces(frame.traces, self.scene.offsets[0])
            env = self.shown or 0
            self.history.append((self.sim_seconds, {k: float(v[env]) for k, v in frame.terms.items()}))
            if self.record:
                shown = range(self.source.num_envs) if hasattr(self.source, "models") else [env]
                entries = [(frame.qpos[e], frame.mocap_pos[e], frame.mocap_quat[e]) for e in shown]
                self.recorded.append(entries[0] if len(entries) == 1 else tuple(entries))
            self._follow(frame, env)
            now = time.perf_counter()
            if now - self._last_plot >= _PLOT_PERIOD_S:
                self._last_plot = now
                gui.refresh(self, frame)
            self.frames_shown += 1
            self.rate.displayed()
            return frame

    def _draw_traces(self, points: np.ndarray, offset: np.ndarray) -> None:
        """Sampled rollouts (grey) and the chosen plan (red) as line segments of a
        fixed width on screen (a robot seen from afar keeps them): points [S + 1, H, P, 3]
        of P traced points, the plan last."""
        for name, part, color in (("samples", points[:-1], SAMPLES_RGB), ("plan", points[-1:], PLAN_RGB)):
            segments = np.stack([part[:, :-1], part[:, 1:]], axis=-2).reshape(-1, 2, 3) + offset
            colors = np.broadcast_to(np.array(color, np.uint8), segments.shape)
            handle = self.trace_handles.get(name)
            if handle is None:
                width = 1.5 if name == "samples" else 4.0  # pixels
                self.trace_handles[name] = self.server.scene.add_line_segments(
                    f"/traces/{name}", segments.astype(np.float32), colors, thickness=width, thickness_units="screen"
                )
            else:
                handle.points, handle.colors = segments.astype(np.float32), colors

    def _follow(self, frame: Frame, env: int) -> None:
        """Keeps each client's camera at its offset from the tracked body."""
        if self.track is None:
            return
        if hasattr(self.source, "models"):
            env = 0  # models side by side: the tracked body is the first model's
        target = frame.xpos[env][self.track] + self.scene.offsets[env]
        for client in self.server.get_clients().values():
            camera = client.camera
            offset = np.asarray(camera.position) - np.asarray(camera.look_at)
            with client.atomic():
                camera.look_at, camera.position = target, target + offset


class _Rate:
    """Control steps, jitted calls and displays over the last few seconds."""

    def __init__(self, window: float = 3.0):
        self.window, self.calls, self.shows = window, collections.deque(), collections.deque()

    def add(self, steps: int, seconds: float) -> None:
        self.calls.append((time.perf_counter(), steps))
        self._trim(self.calls)

    def displayed(self) -> None:
        self.shows.append((time.perf_counter(), 1))
        self._trim(self.shows)

    def _trim(self, events: collections.deque) -> None:
        while events and events[0][0] < time.perf_counter() - self.window:
            events.popleft()

    def _per_second(self, events: collections.deque, count: bool) -> float:
        if len(events) < 2:
            return 0.0
        span = events[-1][0] - events[0][0]
        total = len(events) - 1 if count else sum(n for _, n in list(events)[1:])
        return total / span if span > 0 else 0.0

    def per_second(self) -> float:
        return self._per_second(self.calls, False)

    def calls_per_second(self) -> float:
        return self._per_second(self.calls, True)

    def displays(self) -> float:
        return self._per_second(self.shows, True)
