"""Writes docs/images/go1_flat.gif, the README's picture: frames of the trained Go1's
video (benchmarks/results/robots/go1_flat.mp4, drawn by mjzoo.harness.rendering during
its evaluation), scaled down and thinned so the GIF stays well under 2 MB.

    python scripts/readme_gif.py [--start 2.0] [--seconds 4.0] [--fps 12.5] [--width 320]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
VIDEO = ROOT / "benchmarks" / "results" / "robots" / "go1_flat.mp4"
GIF = ROOT / "docs" / "images" / "go1_flat.gif"


def frames(start_s: float, seconds: float, fps: float, width: int) -> list[Image.Image]:
    """The video's frames from `start_s` for `seconds`, every 1/fps s, `width` pixels wide."""
    reader = imageio.get_reader(VIDEO)
    source_fps = reader.get_meta_data()["fps"]
    every = max(1, round(source_fps / fps))
    first, last = round(start_s * source_fps), round((start_s + seconds) * source_fps)
    picked = []
    for i, frame in enumerate(reader):
        if first <= i < last and (i - first) % every == 0:
            image = Image.fromarray(np.asarray(frame))
            picked.append(image.resize((width, round(image.height * width / image.width)), Image.LANCZOS))
    reader.close()
    if not picked:
        raise SystemExit(f"readme_gif: no frames between {start_s} s and {start_s + seconds} s of {VIDEO}")
    return picked


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--start", type=float, default=2.0, help="first second of the video to use")
    parser.add_argument("--seconds", type=float, default=4.0, help="how many seconds of video")
    parser.add_argument("--fps", type=float, default=12.5, help="GIF frames per second")
    parser.add_argument("--width", type=int, default=320, help="GIF width in pixels")
    args = parser.parse_args()
    picked = frames(args.start, args.seconds, args.fps, args.width)
    palette = picked[len(picked) // 2].quantize(colors=128)  # one palette: no flicker between frames
    quantized = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in picked]
    GIF.parent.mkdir(parents=True, exist_ok=True)
    quantized[0].save(GIF, save_all=True, append_images=quantized[1:], duration=round(1000 / args.fps), loop=0)
    print(f"wrote {GIF}: {len(quantized)} frames, {GIF.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
