"""Browser check of `mjzoo view`: start a viewer, open it in headless Chromium (WebGL on
SwiftShader, the CPU), wait for the scene, save a screenshot and check that the canvas
is not blank.

    python scripts/viewer_screenshot.py --out /tmp/viewer.png [--env pendulum_swingup --num-envs 3]
    python scripts/viewer_screenshot.py --out /tmp/planner.png --planner mppi   # traces drawn

Needs Chromium (Debian: ``apt-get install -y chromium``). Talks to it over the Chrome
DevTools Protocol (``websockets``, a viser dependency). Exit status 0 when the canvas
shows a scene, 1 when it stays blank, 2 without Chromium. Prints one JSON line:
the path, the seconds it took and the pixel statistics checked.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import io
import json
import shutil
import subprocess
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mjzoo.harness.distributed import free_port

CHROMIUM = ("chromium", "chromium-browser", "google-chrome")
PANEL_PX = 340  # viser's control panel on the right: not part of the canvas


def find_chromium() -> str | None:
    return next((p for p in map(shutil.which, CHROMIUM) if p), None)


def canvas_stats(png: bytes) -> dict[str, float]:
    """Pixel statistics of the canvas area (the page less the panel): the std of its
    pixels and the fraction that differ (> 40 in some channel) from the most common
    colour, the background."""
    import imageio.v3 as iio

    image = iio.imread(io.BytesIO(png))[..., :3].astype(np.int16)
    canvas = image[:, : max(1, image.shape[1] - PANEL_PX)].reshape(-1, 3)
    colours, counts = np.unique(canvas, axis=0, return_counts=True)
    background = colours[np.argmax(counts)]
    differ = np.any(np.abs(canvas - background) > 40, axis=1)
    return {"std": float(canvas.std()), "non_background": float(differ.mean())}


def not_blank(stats: dict[str, float]) -> bool:
    return stats["std"] > 5.0 and stats["non_background"] > 0.01


@contextlib.contextmanager
def chromium(binary: str, width: int, height: int) -> Iterator[str]:
    """A headless Chromium with the DevTools protocol on a free port; yields the
    websocket address of its page."""
    port = free_port("127.0.0.1")
    with tempfile.TemporaryDirectory() as profile:
        args = [
            binary,
            "--headless=new",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--ignore-gpu-blocklist",
            f"--remote-debugging-port={port}",
            f"--user-data-dir={profile}",
            f"--window-size={width},{height}",
            "--no-first-run",
            "about:blank",
        ]
        process = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            yield _page_socket(port)
        finally:
            process.terminate()
            process.wait(timeout=10)


def _page_socket(port: int, timeout: float = 20.0) -> str:
    deadline = time.time() + timeout
    while True:
        try:
            pages = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=2))
            return next(p["webSocketDebuggerUrl"] for p in pages if p.get("type") == "page")
        except (OSError, StopIteration, ValueError):
            if time.time() > deadline:
                raise
            time.sleep(0.2)


class DevTools:
    """The few DevTools calls needed: navigate, screenshot."""

    def __init__(self, address: str):
        from websockets.sync.client import connect

        self.socket, self.next_id = connect(address, max_size=64 * 2**20), 0

    def call(self, method: str, **params) -> dict:
        self.next_id += 1
        self.socket.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self.socket.recv(timeout=60))
            if reply.get("id") == self.next_id:
                return reply.get("result", {})

    def screenshot(self) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])


def shoot(url: str, out: Path, binary: str, connected, timeout: float = 40.0, size=(1280, 800)) -> dict:
    """Opens `url`, waits until `connected()` and the canvas is drawn (or `timeout`
    seconds), writes the screenshot to `out`; returns its stats and whether it shows a scene."""
    start = time.time()
    with chromium(binary, *size) as address:
        tools = DevTools(address)
        tools.call("Page.enable")
        tools.call("Page.navigate", url=url)
        png, stats = b"", {}
        while time.time() - start < timeout:
            time.sleep(1.0)
            if not connected():
                continue
            png = tools.screenshot()
            stats = canvas_stats(png)
            if not_blank(stats):
                time.sleep(1.0)  # let the meshes finish arriving, then the picture kept
                png = tools.screenshot()
                stats = canvas_stats(png)
                break
        tools.socket.close()
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(png)
    return {"path": str(out), "seconds": round(time.time() - start, 1), **stats, "ok": bool(png) and not_blank(stats)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("viewer_screenshot.png"))
    parser.add_argument("--env", default="pendulum_swingup")
    parser.add_argument("--num-envs", type=int, default=3)
    parser.add_argument("--planner", choices=("predictive_sampling", "cem", "mppi"), help="plan the env live instead")
    parser.add_argument("--timeout", type=float, default=40.0)
    args = parser.parse_args()
    binary = find_chromium()
    if binary is None:
        print(json.dumps({"error": "no Chromium: apt-get install -y chromium"}))
        return 2
    import mjzoo
    from mjzoo.harness import viewer

    begin = time.time()
    if args.planner:
        import importlib

        module = importlib.import_module(f"mjzoo.algorithms.{args.planner}")
        source = viewer.planner(mjzoo.envs.closed_loop_problem(args.env, module, module.Config()))
    else:
        source = viewer.env(mjzoo.envs.make(args.env), controls="random", num_envs=args.num_envs)
    shown = viewer.serve(source, port=0, host="127.0.0.1")
    try:
        result = shoot(
            f"http://127.0.0.1:{shown.port}",
            args.out,
            binary,
            lambda: bool(shown.server.get_clients()) and shown.frames_shown > 30,
            args.timeout,
        )
    finally:
        shown.stop()
    print(json.dumps({**result, "total_seconds": round(time.time() - begin, 1)}))
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
