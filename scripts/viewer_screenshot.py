"""Screenshot of `mjzoo view` in headless Chromium (WebGL on SwiftShader, the CPU): start
a viewer, open it, wait until its bodies are drawn and save the page.

    python scripts/viewer_screenshot.py --out /tmp/viewer.png [--env pendulum_swingup --num-envs 3]
    python scripts/viewer_screenshot.py --out /tmp/planner.png --planner mppi   # traces drawn

Needs Chromium (Debian: ``apt-get install -y chromium``); drives it with
`mjzoo.harness.viewer.browser`. Exit status 0 when the scene shows each saturated
colour of the model, 1 when it does not, 2 without Chromium. Prints one JSON line: the path, the
seconds it took and the pixels of each colour found.
"""

from __future__ import annotations

import argparse
import importlib
import json
import time
from pathlib import Path

import numpy as np


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("viewer_screenshot.png"))
    parser.add_argument("--env", default="pendulum_swingup")
    parser.add_argument("--num-envs", type=int, default=3)
    parser.add_argument(
        "--planner",
        choices=("predictive_sampling", "cem", "mppi", "dial", "cma_es", "ilqr"),
        help="plan the env live instead",
    )
    parser.add_argument("--timeout", type=float, default=60.0)
    args = parser.parse_args()
    import mjzoo
    from mjzoo.harness import viewer
    from mjzoo.harness.viewer import browser

    if browser.find_chromium() is None:
        print(json.dumps({"error": "no Chromium: apt-get install -y chromium"}))
        return 2
    begin = time.time()
    if args.planner:
        module = importlib.import_module(f"mjzoo.algorithms.{args.planner}")
        source = viewer.planner(mjzoo.envs.closed_loop_problem(args.env, module, module.Config()))
    else:
        source = viewer.env(mjzoo.envs.make(args.env), controls="random", num_envs=args.num_envs)
    shown = viewer.serve(source, port=0, host="127.0.0.1")
    # the model's saturated colours (a grey one cannot be told from shading)
    colours = {tuple(int(255 * c) for c in g.rgba[:3]) for group in shown.scene.groups for g in group.geoms}
    colours = {c for c in colours if np.ptp(c) > 0.3 * max(c)}
    counts = dict.fromkeys(map(str, colours), 0)
    try:
        with browser.chromium() as page:
            page.open(f"http://127.0.0.1:{shown.port}")
            found = lambda image: counts.update({str(c): int(browser.colored(image, c).sum()) for c in colours})
            try:
                page.until(
                    lambda image: found(image) or all(n > 20 for n in counts.values()), args.timeout, settled=False
                )
            except TimeoutError:
                pass
            page.dismiss_notices()
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_bytes(page.png())
    finally:
        shown.stop()
    ok = all(n > 20 for n in counts.values())
    print(json.dumps({"path": str(args.out), "seconds": round(time.time() - begin, 1), "pixels": counts, "ok": ok}))
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
