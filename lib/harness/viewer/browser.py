"""The viewer's page in headless Chromium, driven as a user drives it: Chromium draws
the scene with WebGL on SwiftShader (the CPU), this module clicks buttons and slider
tracks with real mouse events and reads screenshots, over the Chrome DevTools Protocol
(``websockets``, a viser dependency). Used by the browser check and
``scripts/viewer_screenshot.py``; needs Chromium (Debian: ``apt-get install -y chromium``).

    with browser.chromium() as page:
        page.open(f"http://127.0.0.1:{shown.port}")
        image = page.until(lambda im: colored(im, (230, 102, 25)).sum() > 50)  # the bodies arrived
        page.move_slider("torque", 1.0)   # the slider's right end: its maximum
        page.click_button("Step")
"""

from __future__ import annotations

import base64
import colorsys
import contextlib
import io
import json
import shutil
import subprocess
import tempfile
import time
import urllib.request
from collections.abc import Callable
from collections.abc import Iterator
from typing import Any

import imageio.v3 as iio
import numpy as np

from mjzoo.harness.distributed import free_port

__all__ = ["find_chromium", "chromium", "Page", "colored"]

CHROMIUM = ("chromium", "chromium-browser", "google-chrome")

# The left edge of viser's control panel, which floats over the right half of the canvas.
_PANEL_LEFT = "Math.min(...[...document.querySelectorAll('.mantine-Paper-root')].map(e => e.getBoundingClientRect().left).filter(x => x > innerWidth / 2))"
_GIZMO_PX = 80


def find_chromium() -> str | None:
    """The first Chromium on PATH, or None."""
    return next((p for p in map(shutil.which, CHROMIUM) if p), None)


@contextlib.contextmanager
def chromium(width: int = 1280, height: int = 560, binary: str | None = None) -> Iterator[Page]:
    """A headless Chromium (a fresh profile, the DevTools protocol on a free port) and
    its one tab, `width` x `height` page pixels; closed on exit. The default is wide:
    viser's panel covers the right 340 pixels, and environments side by side spread in x."""
    binary = binary or find_chromium()
    if binary is None:
        raise FileNotFoundError("no Chromium on PATH (Debian: apt-get install -y chromium)")
    port = free_port("127.0.0.1")
    with tempfile.TemporaryDirectory() as profile:
        args = [
            binary,
            "--headless=new",
            "--no-sandbox",  # CI runs as root, where Chromium's sandbox refuses to start
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--ignore-gpu-blocklist",
            "--hide-scrollbars",
            f"--remote-debugging-port={port}",
            f"--user-data-dir={profile}",
            f"--window-size={width},{height}",
            "--no-first-run",
            "about:blank",
        ]
        process = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            page = Page(_page_socket(port, process))
            # the window's size less the browser's own bars is the page's: set the page's
            page.call(
                "Emulation.setDeviceMetricsOverride", width=width, height=height, deviceScaleFactor=1, mobile=False
            )
            try:
                yield page
            finally:
                page.socket.close()
        finally:
            process.terminate()
            process.wait(timeout=10)


def _page_socket(port: int, process: subprocess.Popen, timeout: float = 30.0) -> str:
    """The websocket address of Chromium's tab, once its DevTools endpoint answers."""
    deadline = time.time() + timeout
    while True:
        try:
            pages = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=2))
            return next(p["webSocketDebuggerUrl"] for p in pages if p.get("type") == "page")
        except (OSError, StopIteration, ValueError):
            if process.poll() is not None:
                raise RuntimeError(f"Chromium exited with status {process.returncode} at start") from None
            if time.time() > deadline:
                raise
            time.sleep(0.2)


class Page:
    """One Chromium tab: navigate, screenshot, evaluate, and mouse input at page pixels."""

    def __init__(self, address: str):
        from websockets.sync.client import connect

        self.socket, self.next_id = connect(address, max_size=64 * 2**20), 0

    def call(self, method: str, **params: Any) -> dict:
        """One DevTools command; its result (an error reply raises)."""
        self.next_id += 1
        self.socket.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self.socket.recv(timeout=60))
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def open(self, url: str, timeout: float = 30.0) -> None:
        """Loads `url` and waits for its load event."""
        self.call("Page.enable")
        self.call("Page.navigate", url=url)
        deadline = time.time() + timeout
        while self.evaluate("document.readyState") != "complete":
            if time.time() > deadline:
                raise TimeoutError(f"{url} did not load within {timeout:.0f} s")
            time.sleep(0.1)

    def evaluate(self, expression: str) -> Any:
        """A JavaScript expression's value (JSON-able)."""
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression[:80]}: {result['exceptionDetails'].get('text')}")
        return result["result"].get("value")

    def png(self) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])

    def screenshot(self) -> np.ndarray:
        """The page as RGB [H, W, 3] uint8."""
        return iio.imread(io.BytesIO(self.png()))[..., :3]

    def scene(self) -> np.ndarray:
        """The screenshot's part left of the control panel, less the axes gizmo in its
        bottom-left corner (white there), notices closed: RGB [H, W', 3]."""
        self.dismiss_notices()
        image = self.screenshot()
        left = self.evaluate(_PANEL_LEFT)
        image = image[:, : int(left)] if isinstance(left, int | float) and 0 < left < image.shape[1] else image
        image[-_GIZMO_PX:, :_GIZMO_PX] = 255
        return image

    def until(
        self, done: Callable[[np.ndarray], bool], timeout: float = 60.0, period: float = 0.25, settled: bool = True
    ) -> np.ndarray:
        """The first `scene()` for which `done` holds and, when `settled`, that the next
        one repeats (the browser has finished drawing what it was sent; a playing viewer
        never settles); TimeoutError after `timeout` s."""
        deadline, last = time.time() + timeout, None
        while time.time() < deadline:
            image = self.scene()
            if (not settled or np.array_equal(image, last)) and done(image):
                return image
            last = image
            time.sleep(period)
        raise TimeoutError(f"the page did not show what was waited for within {timeout:.0f} s")

    def click(self, x: float, y: float) -> None:
        """A left click at page pixel (x, y): press and release, as a mouse does."""
        for kind in ("mouseMoved", "mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", buttons=1, clickCount=1)

    def rect(self, expression: str) -> dict[str, float]:
        """The page box (x, y, width, height) of the element `expression` evaluates to."""
        box = self.evaluate(
            f"(() => {{ const r = ({expression}).getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; }})()"
        )
        return dict(zip(("x", "y", "width", "height"), box))

    def click_button(self, text: str) -> None:
        """Clicks the GUI button labelled `text`."""
        box = self.rect(
            f"[...document.querySelectorAll('button')].find(b => b.textContent.trim() === {json.dumps(text)})"
        )
        self.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)

    def move_slider(self, label: str, fraction: float) -> None:
        """Drags the slider labelled `label` to `fraction` of its track (0: its left end,
        its minimum; 1: its right end, its maximum), as a hand does: press inside the
        track, move, release. An end is dragged past, so the slider's clamp, not a
        pixel's rounding at the track's edge, decides the value."""
        slider = f"document.getElementById([...document.querySelectorAll('label')].find(l => l.textContent.trim() === {json.dumps(label)}).htmlFor)"
        box = self.rect(f"{slider}.querySelector('.mantine-Slider-track')")
        y, overshoot = box["y"] + box["height"] / 2, 20.0 * ((fraction >= 1) - (fraction <= 0))
        x = box["x"] + fraction * box["width"] + overshoot
        self.call("Input.dispatchMouseEvent", type="mouseMoved", x=box["x"] + box["width"] / 2, y=y, buttons=0)
        self.call(
            "Input.dispatchMouseEvent",
            type="mousePressed",
            x=box["x"] + box["width"] / 2,
            y=y,
            button="left",
            buttons=1,
            clickCount=1,
        )
        self.call("Input.dispatchMouseEvent", type="mouseMoved", x=x, y=y, button="left", buttons=1)
        self.call("Input.dispatchMouseEvent", type="mouseReleased", x=x, y=y, button="left", buttons=1, clickCount=1)

    def dismiss_notices(self) -> None:
        """Closes viser's notifications (e.g. "Software WebGL rendering detected"), which cover the scene."""
        self.evaluate("document.querySelectorAll('.mantine-Notification-closeButton').forEach(b => b.click())")


def colored(image: np.ndarray, rgb: tuple[int, int, int], hue_tolerance: float = 8.0) -> np.ndarray:
    """Which pixels of `image` [H, W, 3] show the saturated colour `rgb` under some
    light: hue within `hue_tolerance` degrees, saturation and value not far below
    `rgb`'s (shading darkens and whitens a colour, it does not turn its hue). [H, W] bool."""
    hue, saturation, value = colorsys.rgb_to_hsv(*(c / 255 for c in rgb))
    if saturation < 0.3:
        raise ValueError(f"colored: {rgb} is too grey to tell from its shading")
    pixels = image.astype(np.float32) / 255
    high, low = pixels.max(-1), pixels.min(-1)
    chroma = high - low
    r, g, b = np.moveaxis(pixels, -1, 0)
    safe = np.where(chroma > 0, chroma, 1)
    h = np.where(high == r, (g - b) / safe % 6, np.where(high == g, (b - r) / safe + 2, (r - g) / safe + 4)) / 6
    distance = np.abs((h - hue + 0.5) % 1 - 0.5) * 360
    return (distance < hue_tolerance) & (chroma > 0.4 * saturation * value) & (high > 0.3 * value)
