"""What a terrain costs: the robot joysticks' scenes with and without the heightfield grid.

Per robot and terrain (``--variants go1:flat go1:rough ...``) and physics implementation
(``--impl jax warp``), in one process:

  build_s      the scene assembled (Playground's MJCF plus, on a terrain, the tile grid as
               one heightfield) and compiled by MuJoCo, then put on the device (`mjx.put_model`)
  compile_s    XLA's compile of ``--num-envs`` environments stepping ``--steps`` control
               steps in a `lax.scan` (raw physics: the servo targets held at the standing pose)
  steps_per_s  environment control steps per second of that program, best of 3
  hfield       the heightfield's rows x columns (0 on flat ground)

The robots start where their task puts them (`mjzoo.reset`: on a terrain, on a tile of
the middle row), so their feet touch the heightfield while stepping. Users report
multi-minute heightfield compiles on MuJoCo Warp; this is the measurement.

    python benchmarks/terrain_cost.py --variants go1:flat go1:rough --num-envs 4096   # a GPU
    python benchmarks/terrain_cost.py --variants go1:flat go1:rough --num-envs 8 --steps 10   # a CPU

Results merge into ``benchmarks/results/robots/terrain_cost_<card>.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

sys.path.insert(0, str(Path(__file__).parent))
from cards import card_name  # noqa: E402

import mjzoo  # noqa: E402
from mjzoo import physics as physics_lib  # noqa: E402
from mjzoo.envs import robot_joystick  # noqa: E402

OUT = Path(__file__).parent / "results" / "robots"


def measure(variant: str, impl: str, num_envs: int, steps: int) -> dict:
    robot, terrain = variant.split(":")
    robot_joystick._scene.cache_clear()  # the build is what is timed
    start = time.perf_counter()
    task = robot_joystick.robot_joystick(robot, terrain=terrain, level=0.5, impl=impl)
    build = time.perf_counter() - start
    physics_model, m = task.model, task.mj_model
    n_substeps = round(0.02 / m.opt.timestep)
    data = jax.jit(jax.vmap(lambda k: mjzoo.reset(task, k).data))(jax.random.split(jax.random.key(0), num_envs))
    ctrl = jnp.broadcast_to(jnp.asarray(m.key_ctrl[0], jnp.float32), (num_envs, m.nu))

    def run(data):
        def body(data, _):
            return jax.vmap(lambda d, c: physics_lib.step(physics_model, d, c, n_substeps))(data, ctrl), None

        return jax.lax.scan(body, data, None, length=steps)[0]

    start = time.perf_counter()
    compiled = jax.jit(run).lower(data).compile()
    compile_s = time.perf_counter() - start
    times = []
    for _ in range(3):
        start = time.perf_counter()
        jax.block_until_ready(compiled(data).qpos)
        times.append(time.perf_counter() - start)
    return {
        "variant": variant,
        "impl": impl,
        "num_envs": num_envs,
        "steps": steps,
        "n_substeps": n_substeps,
        "build_s": build,
        "compile_s": compile_s,
        "steps_per_s": num_envs * steps / min(times),
        "hfield": [int(m.hfield_nrow.sum()), int(m.hfield_ncol.sum())] if m.nhfield else [0, 0],
        "device": jax.devices()[0].device_kind,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variants", nargs="+", default=["go1:flat", "go1:rough", "g1:flat", "g1:rough"])
    parser.add_argument("--impl", nargs="+", default=["jax"], choices=["jax", "warp"])
    parser.add_argument("--num-envs", type=int, default=4096)
    parser.add_argument("--steps", type=int, default=100)
    args = parser.parse_args()
    path = OUT / f"terrain_cost_{card_name()}.json"
    rows = json.loads(path.read_text())["rows"] if path.is_file() else []
    for impl in args.impl:
        for variant in args.variants:
            row = measure(variant, impl, args.num_envs, args.steps)
            rows = [r for r in rows if (r["variant"], r["impl"], r["num_envs"]) != (variant, impl, args.num_envs)]
            rows.append(row)
            OUT.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({"rows": rows}, indent=1) + "\n")
            print(
                f"{variant:22s} {impl:5s} build {row['build_s']:6.1f} s  compile {row['compile_s']:6.1f} s  "
                f"{row['steps_per_s']:12,.0f} steps/s  hfield {row['hfield']}",
                flush=True,
            )


if __name__ == "__main__":
    main()
