"""`RenderConfig`: how every video and image mjzoo writes is drawn, and how learning
curves are plotted (KSim's render options), checked when it is made. Drawing is
`mjzoo.harness.rendering`'s; this module needs neither MuJoCo nor OpenGL."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from mjzoo import checks

__all__ = ["RenderConfig"]

_FREE_CAMERA = ("distance", "azimuth", "elevation", "lookat", "track_body")


@dataclasses.dataclass(frozen=True, kw_only=True)
class RenderConfig:
    """How every video and image mjzoo writes is drawn (end of training, `mjzoo eval`,
    `mjzoo plan`, the viewer's recordings) and how learning curves are plotted; KSim's
    render options. From the CLI: ``--render.NAME VALUE``. Values are checked here;
    camera and body names when a model is drawn."""

    width: int = 640
    """Video width in pixels."""
    height: int = 480
    """Video height in pixels."""
    small_width: int = 320
    """Width of small renders (previews, thumbnails) in pixels."""
    small_height: int = 240
    """Height of small renders in pixels."""
    length_seconds: float | None = None
    """Simulated seconds drawn, from the start; None: the whole trajectory."""
    fps: float | None = None
    """Frames per simulated second (rows are skipped or repeated); None: real time, one frame per row."""
    slowdown: float = 1.0
    """Slow motion: the file plays at fps / slowdown frames per second (2.0: half speed)."""
    shadows: bool = True
    """Draw shadows (off: several times faster on CPU renderers)."""
    reflections: bool = True
    """Draw reflections on reflective materials."""
    contact_forces: bool = False
    """Draw contact force arrows."""
    contact_points: bool = False
    """Draw contact points."""
    inertia: bool = False
    """Draw each body's equivalent-inertia box."""
    markers: bool = False
    """Draw debug markers: site frames and centres of mass."""
    camera: int | str | None = None  # int first: the CLI then reads "0" as an id
    """A model camera, by id or name; None: a free camera (the fields below)."""
    distance: float | None = None
    """Free camera: metres from the point looked at; None: MuJoCo's fit to the model."""
    azimuth: float | None = None
    """Free camera: azimuth in degrees; None: MuJoCo's default (90)."""
    elevation: float | None = None
    """Free camera: elevation in degrees; None: MuJoCo's default (-45)."""
    lookat: tuple[float, float, float] | None = None
    """Free camera: the point looked at (m); None: the model's centre."""
    track_body: int | str | None = None
    """Free camera that follows this body (id or name), looking at its subtree's centre of mass."""
    max_series_per_plot: int = 8
    """Learning curves: most series one subplot draws (a group such as reward/ keeps the largest)."""
    plot_figsize: tuple[float, float] = (4.5, 3.0)
    """Learning curves: width and height of one subplot, in inches (100 dpi)."""

    def __post_init__(self) -> None:
        for name in ("lookat", "plot_figsize"):  # JSON gives lists back
            if isinstance(getattr(self, name), list):
                object.__setattr__(self, name, tuple(getattr(self, name)))
        counts = ("width", "height", "small_width", "small_height", "max_series_per_plot")
        lengths = ("length_seconds", "fps", "distance")
        checks.fields(
            "RenderConfig",
            self,
            {
                **{n: (checks.is_count(getattr(self, n)), "an integer >= 1") for n in counts},
                **{n: (getattr(self, n) is None or _positive(getattr(self, n)), "> 0 or None") for n in lengths},
                "slowdown": (_positive(self.slowdown), "> 0"),
                "lookat": (self.lookat is None or _vector(self.lookat, 3), "3 finite numbers or None"),
                "plot_figsize": (_vector(self.plot_figsize, 2) and min(self.plot_figsize) > 0, "2 numbers > 0"),
            },
        )
        if self.lookat is not None and self.track_body is not None:
            raise ValueError("RenderConfig: lookat and track_body both choose the point looked at - give one")
        free = ", ".join(f for f in _FREE_CAMERA if getattr(self, f) is not None)
        if self.camera not in (None, -1) and free:
            message = f"camera={self.camera!r} is a model camera; {free} set a free camera - give one or the other"
            raise ValueError(f"RenderConfig: {message}")

    @property
    def free_camera(self) -> bool:
        """Whether any free-camera field is set."""
        return any(getattr(self, f) is not None for f in _FREE_CAMERA)


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _positive(value: Any) -> bool:
    return _finite(value) and value > 0


def _vector(value: Any, size: int) -> bool:
    return isinstance(value, tuple) and len(value) == size and all(map(_finite, value))
