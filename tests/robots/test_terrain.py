"""Terrain (`mjzoo.robots.terrain`): tiles and their grid against hand-worked heights,
the JAX height reader against C MuJoCo's own ray casts, the height scan, starts on tiles."""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import mjzoo
from mjzoo import physics
from mjzoo.robots import terrain

XML = """
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="0 0 1" friction="0.7"/>
    <body name="base" pos="0 0 1"><freejoint/><geom type="box" size=".1 .1 .1" mass="1"/></body>
  </worldbody>
</mujoco>
"""
GRID = terrain.grid(("slope_up", "stairs_down", "rough"), rows=2, tile_size=4.0, resolution=0.1, border=1.0)


def _physics(grid=GRID):
    spec = mujoco.MjSpec.from_string(XML)
    terrain.add_to_spec(spec, grid)
    return physics.of_spec(spec)


PHYSICS = _physics()


def test_tiles_by_hand():
    # 4 m tiles at 0.2 m: 21 x 21 vertices, the platform (1 m square) in the middle.
    stairs = terrain.tile("stairs_up", 1.0, size=4.0, resolution=0.2)
    assert stairs.shape == (21, 21)
    # Steps 0.3 m deep and 0.2 m high (difficulty 1) from the platform's edge (0.5 m from
    # the centre) outward: at the tile's edge (1.5 m out) ceil(1.5 / 0.3) = 5 steps down.
    assert stairs[10, 10] - stairs[10, 0] == pytest.approx(5 * 0.2, abs=1e-6)
    assert stairs[10, 10] == stairs[10, 12] == stairs[12, 8]  # the platform: |x|, |y| <= 0.5 m flat
    edge = np.concatenate([stairs[0], stairs[-1], stairs[1:-1, 0], stairs[1:-1, -1]])
    assert abs(edge.mean()) < 1e-6  # edges meet the neighbours at 0
    np.testing.assert_allclose(terrain.tile("stairs_down", 1.0, 4.0, 0.2), -stairs, atol=1e-6)
    # Slope: grade 0.4 d, 1.5 m of run at difficulty 0.5 -> 0.3 m of rise.
    slope = terrain.tile("slope_up", 0.5, 4.0, 0.2)
    assert slope[10, 10] - slope[0, 10] == pytest.approx(0.3, abs=1e-6)
    # Rough: bumps of at most +-(0.02 + 0.08 d) m.
    rough = terrain.tile("rough", 1.0, 4.0, 0.1, seed=3)
    assert 0.1 < np.ptp(rough) <= 0.2 + 1e-6
    np.testing.assert_array_equal(rough, terrain.tile("rough", 1.0, 4.0, 0.1, seed=3))
    assert np.all(terrain.tile("flat", 1.0, 4.0, 0.1) == 0)
    # Stepping stones and gaps: pits 1 m below the stones / the platform.
    for kind in ("stepping_stones", "gaps"):
        t = terrain.tile(kind, 1.0, 4.0, 0.05)
        assert np.ptp(t) == pytest.approx(terrain.PIT) and np.mean(t == t.max()) > 0.3
    # Harder rows are harder: the stones' gaps widen.
    tiles = [terrain.tile("stepping_stones", d, 4.0, 0.05) for d in (0.0, 0.5, 1.0)]
    pits = [np.mean(t < t.max() - 0.5) for t in tiles]
    assert pits[0] < pits[1] < pits[2]


def test_tile_errors():
    with pytest.raises(ValueError, match="kind 'lava' is unknown"):
        terrain.tile("lava", 0.5)
    with pytest.raises(ValueError, match="difficulty=1.5"):
        terrain.tile("rough", 1.5)
    with pytest.raises(ValueError, match="whole number of resolution"):
        terrain.tile("rough", 0.5, size=4.0, resolution=0.3)


def test_grid_layout():
    # 2 rows x 3 columns of 4 m tiles at 0.1 m with a 1 m border: 2 * 40 + 1 + 20 vertices by 3 * 40 + 1 + 20.
    assert GRID.heights.shape == (101, 141) and GRID.rows == 2 and GRID.kinds == ("slope_up", "stairs_down", "rough")
    assert GRID.extent == pytest.approx((7.0, 5.0))
    # Tile (row 1, column 0) is centred at x = -7 + 1 + 2 = -4, y = -5 + 1 + 4 + 2 = 2.
    np.testing.assert_allclose(GRID.origins[1, 0, :2], [-4.0, 2.0])
    # Its platform: a 0.4 grade (difficulty 1) over 1.5 m of run, from its edge at 0.
    assert GRID.origins[1, 0, 2] == pytest.approx(0.6, abs=1e-5)
    assert GRID.origins[0, 0, 2] == pytest.approx(0.0, abs=1e-6)  # difficulty 0: no slope
    ij = np.round((GRID.origins[..., 1::-1] + GRID.extent[::-1]) / GRID.resolution).astype(int)  # (row, column)
    np.testing.assert_allclose(GRID.heights[ij[..., 0], ij[..., 1]], GRID.origins[..., 2])
    np.testing.assert_array_equal(GRID.heights, terrain.grid(GRID.kinds, 2, 4.0, 0.1, 1.0).heights)  # seeded


def test_heights_match_mujoco_ray_casts():
    mj, m = PHYSICS.mj_model, PHYSICS.model
    data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, data)
    floor = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    hx, hy = GRID.extent
    points = np.random.default_rng(0).uniform([-hx, -hy], [hx, hy], (300, 2)) * 0.999
    cast = np.array(
        [
            10.0
            - mujoco.mj_ray(
                mj, data, np.array([x, y, 10.0]), np.array([0, 0, -1.0]), None, 1, -1, np.zeros(1, np.int32)
            )
            for x, y in points
        ]
    )

    @jax.jit
    @chex.assert_max_traces(n=2)  # one per batch of points
    def heights(xy):
        return jax.vmap(lambda p: terrain.heights_at(m, 0, mj.hfield_nrow[0], mj.hfield_ncol[0], m.geom_pos[floor], p))(
            xy
        )

    ours = np.asarray(heights(jnp.asarray(points, jnp.float32)))
    # Bilinear in each cell; MuJoCo's surface is two triangles per cell: equal wherever the
    # cell is planar (slopes, steps' treads, the border), apart by < the cell's twist elsewhere.
    error = np.abs(ours - cast)
    assert np.median(error) < 1e-5 and np.mean(error < 1e-4) > 0.9 and error.max() < 0.1
    # At the vertices they agree exactly.
    rows, cols = np.random.default_rng(1).integers(0, GRID.heights.shape, (40, 2)).T
    xy = np.stack([cols * GRID.resolution - hx, rows * GRID.resolution - hy], -1)
    np.testing.assert_allclose(heights(jnp.asarray(xy, jnp.float32)), GRID.heights[rows, cols], atol=1e-5)


def test_height_scan_turns_with_the_heading():
    # A slope tile alone: height rises 0.4 m per m toward the centre, so 1 m east of the
    # centre (x = 1) the ground is 0.4 * (1.5 - 0.5) = 0.4 m below the platform (0.6).
    grid = terrain.grid(("slope_up",), rows=1, tile_size=4.0, resolution=0.1, border=0.0)
    p = _physics(grid)
    scan = terrain.height_scan(p.mj_model, spacing=0.5, size=(3, 1), body="base")
    data = mujoco.MjData(p.mj_model)
    yaw = np.pi / 2  # facing +y: the scan's points lie at y = 1.5 +- 0.5 (x = 1)
    data.qpos[:7] = [1.0, 1.5, 1.0, np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
    mujoco.mj_forward(p.mj_model, data)
    state = mjzoo.State.create(mujoco.mjx.put_data(p.mj_model, data), jnp.zeros(1))
    got = jax.jit(lambda s: scan(p.model, s))(state)
    ground = 0.6 - 0.4 * (np.maximum(np.abs([1.0, 1.0, 1.0]), np.abs([1.0, 1.5, 2.0])) - 0.5)
    np.testing.assert_allclose(got, 1.0 - ground, atol=1e-5)


def test_start_on_tile_follows_the_level():
    start = terrain.start_on_tile(PHYSICS.mj_model, GRID, spread=0.3)
    data = mujoco.mjx.put_data(PHYSICS.mj_model, mujoco.MjData(PHYSICS.mj_model))
    keys = jax.random.split(jax.random.key(0), 64)

    @jax.jit
    def starts(level):
        item = start.__class__(start.func, *start.args[:2], level, start.args[3])
        return jax.vmap(lambda k: item(PHYSICS.model, data, k).qpos[:3])(keys)

    for level, row in ((0.0, 0), (0.3, 0), (0.6, 1), (1.0, 1)):
        q = np.asarray(starts(jnp.float32(level)))
        shift = q[:, None, :] - (GRID.origins[row] + [0, 0, 1.0])  # [64, cols, 3]: from each tile of the row
        nearest = np.abs(shift[..., :2]).max(-1).argmin(-1)
        assert np.all(np.abs(shift[np.arange(64), nearest]) <= [0.3, 0.3, 1e-5])
        assert len(set(nearest)) == 3  # every column drawn


def test_by_walked_distance_errors():
    with pytest.raises(ValueError, match="rows=1"):
        terrain.by_walked_distance(PHYSICS.mj_model, 2.0, rows=1)
