"""The G1 motion clips in envs/assets/motions/g1/: pybullet's DeepMimic clips retargeted
onto Playground's Unitree G1 (`mjzoo.motion.retarget`, on the CPU).

    python scripts/retarget_g1.py                          # prints the quality table, writes the clips that pass
    mjzoo view envs/assets/motions/g1/walk.npz --source walk         # a written clip beside its source, live
    MUJOCO_GL=egl python scripts/retarget_g1.py --pictures /tmp/g1   # and a picture per clip: source | G1

Each clip of `CLIPS` is retargeted with `retarget.DEEPMIMIC_TO_G1` (pelvis and feet held
in place and orientation; knees steering along the human leg from the hip, relative to
the pelvis; elbows and hands following the human arm from the shoulder, relative to the
torso; the chest turning the torso) at the ratio of the two pelvis heights. A clip is written (``<clip>.npz``, a `mjzoo.motion` clip of
``scenes.spec("g1")``, loaded with ``motion.load(path, model)``) when it passes
`THRESHOLDS`: foot skating, ground penetration, the share of joint values at a limit,
the mean IK residual of the bodies held in place (pelvis, feet) and of the hands. The
other DeepMimic clips (backflip, cartwheel, crawl, roll, get-ups) put hands, knees or
the back on the floor, which a feet-only contact model does not handle.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent.parent / "envs" / "assets" / "motions" / "g1"
CLIPS = ("walk", "run", "jump", "kick", "punch", "spin", "spinkick", "dance_a", "dance_b")
HELD = ("pelvis", "right_ankle_roll_link", "left_ankle_roll_link")  # bodies that must reach their targets
HANDS = ("right_wrist_yaw_link", "left_wrist_yaw_link")
THRESHOLDS = dict(
    foot_skating_cm=3.0,  # the longest slide of a foot during one contact phase
    penetration_cm=0.5,  # the deepest sole under the floor
    limit_fraction=0.05,  # joint values within motion.retarget.LIMIT_MARGIN of a limit
    held_residual_cm=5.0,  # mean distance of a held body from its target
    hand_residual_cm=5.0,  # mean distance of a hand from its target (the human arm's shape)
)


def measures(quality) -> dict[str, float]:
    """The clip's values of `THRESHOLDS`' measures."""
    return dict(
        foot_skating_cm=quality.foot_skating_cm,
        penetration_cm=quality.penetration_cm,
        limit_fraction=quality.limit_fraction,
        held_residual_cm=max(quality.residual_mean_cm[b] for b in HELD),
        hand_residual_cm=max(quality.residual_mean_cm[b] for b in HANDS),
    )


def failures(quality) -> list[str]:
    """What of `THRESHOLDS` the clip's quality misses ([] when it passes)."""
    values = measures(quality)
    return [f"{k} {values[k]:.3g} > {limit}" for k, limit in THRESHOLDS.items() if values[k] > limit]


def picture(path: Path, human, g1, source, target, count: int = 4) -> None:
    """A PNG of `count` frames: the source clip (left) beside the G1's (right), seen from the side."""
    from PIL import Image

    from mjzoo.harness import rendering
    from mjzoo.harness.render_config import RenderConfig

    rows = np.linspace(0, source.num_frames - 1, count).round().astype(int)
    columns = []
    for model, clip, body in ((human, source, "root"), (g1, target, "pelvis")):
        config = RenderConfig(width=320, height=320, track_body=body, distance=2.6, azimuth=90.0, elevation=-10.0)
        images = rendering.render_frames(model, clip.qpos[rows], config=config)
        if images is None:
            return
        columns.append(np.concatenate(list(images), axis=1))
    Image.fromarray(np.concatenate(columns, axis=0)).save(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clips", nargs="+", default=list(CLIPS), help="DeepMimic clip names")
    parser.add_argument("--out", type=Path, default=OUT, help="folder the passing clips go to")
    parser.add_argument("--pictures", type=Path, help="folder for a PNG per clip: source (top) and G1 (bottom)")
    args = parser.parse_args()

    from mjzoo import motion
    from mjzoo.envs import deepmimic
    from mjzoo.motion import retarget
    from mjzoo.robots import scenes

    human, g1 = deepmimic.humanoid_model(), scenes.spec("g1").compile()
    config = retarget.Config(feet=retarget.DEEPMIMIC_FEET)
    print(retarget.Quality.HEADER + "  held cm  hands cm  verdict")
    for name in args.clips:
        try:
            source = motion.deepmimic_format.load(deepmimic.motion_path(name), human, deepmimic.character_joints())
        except ValueError as e:
            raise SystemExit(str(e)) from None
        out = retarget.retarget(source, human, g1, retarget.DEEPMIMIC_TO_G1, config, name=name)
        missed, values = failures(out.quality), measures(out.quality)
        verdict = "written" if not missed else "skipped: " + "; ".join(missed)
        print(f"{out.quality.row()}  {values['held_residual_cm']:7.2f}  {values['hand_residual_cm']:8.2f}  {verdict}")
        if not missed:
            motion.save(args.out / f"{name}.npz", out.clip)
        if args.pictures:
            args.pictures.mkdir(parents=True, exist_ok=True)
            picture(args.pictures / f"{name}.png", human, g1, source, out.clip)


if __name__ == "__main__":
    main()
