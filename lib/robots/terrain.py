"""Terrain: heightfield tiles in one grid, laid into a robot's scene, read back as a
height scan, and a curriculum that moves each environment to harder tiles.

    grid = terrain.grid(("flat", "rough", "slope_up", "stairs_down"), rows=6)   # numpy, pure
    spec = terrain.add_to_spec(mujoco.MjSpec.from_file(...), grid)             # one model for all envs
    scan = terrain.height_scan(mj_model, spacing=0.1, size=(11, 7))            # a catalog observation

All tiles share one heightfield (the approach Isaac Lab and mjlab take): one model, so
every environment of a batch simulates the same arrays, and an environment's difficulty
is only where it starts. Rows are difficulty levels (row 0 easiest), columns the kinds;
each tile has a flat platform at its centre where episodes start (`start_on_tile`).

Tile kinds (`KINDS`; ``d`` is the row's difficulty in [0, 1]):
  flat            level ground
  rough           uniform random bumps of ±(0.02 + 0.08 d) m on a 0.2 m lattice
  slope_up/down   a pyramid rising (falling) from the tile's edge to its platform, grade 0.4 d
  stairs_up/down  a pyramid of steps 0.3 m deep, 0.04 + 0.16 d m high
  stepping_stones square stones (1.0 - 0.6 d m) over pits 1 m deep, gaps 0.05 + 0.35 d m
  gaps            the platform ringed by a pit 1 m deep and 0.1 + 0.5 d m wide

The height scan reads the heightfield the physics uses (``model.hfield_data``) by
bilinear interpolation, with no ray casting, so it is one gather on MJX's JAX and Warp
implementations alike.
"""

from __future__ import annotations

import dataclasses
from typing import Callable
from typing import Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import names
from mjzoo import tree
from mjzoo.catalog import curriculum
from mjzoo.types import State

__all__ = [
    "KINDS",
    "Terrain",
    "tile",
    "grid",
    "add_to_spec",
    "heights_at",
    "height_scan",
    "start_on_tile",
    "by_walked_distance",
]

Array = jax.Array
PIT = 1.0  # m: the depth of stepping stones' and gaps' pits
PLATFORM = 1.0  # m: the side of each tile's flat centre, where episodes start


def _flat(d, x, y, rng):
    return np.zeros_like(x)


def _rough(d, x, y, rng):
    amplitude, lattice = 0.02 + 0.08 * d, 0.2
    size = x.max() - x.min()
    n = int(np.ceil(size / lattice)) + 2
    bumps = rng.uniform(-amplitude, amplitude, (n, n))
    i = np.clip(np.round((y - y.min()) / lattice).astype(int), 0, n - 1)
    j = np.clip(np.round((x - x.min()) / lattice).astype(int), 0, n - 1)
    return bumps[i, j]


def _ring(x, y):
    """Distance outward from the platform's edge (0 on it), Chebyshev: square rings."""
    return np.maximum(np.maximum(np.abs(x), np.abs(y)) - PLATFORM / 2, 0.0)


def _slope(sign):
    def make(d, x, y, rng):
        outside = _ring(x, y)
        return sign * 0.4 * d * (outside.max() - outside)

    return make


def _stairs(sign):
    def make(d, x, y, rng):
        depth, height = 0.3, 0.04 + 0.16 * d
        steps = np.ceil(_ring(x, y) / depth)
        return sign * height * (steps.max() - steps)

    return make


def _stepping_stones(d, x, y, rng):
    stone, gap = 1.0 - 0.6 * d, 0.05 + 0.35 * d
    period = stone + gap
    in_stone = (np.mod(x + stone / 2, period) < stone) & (np.mod(y + stone / 2, period) < stone)
    on_platform = _ring(x, y) == 0
    return np.where(in_stone | on_platform, 0.0, -PIT)


def _gaps(d, x, y, rng):
    width = 0.1 + 0.5 * d
    outside = _ring(x, y)
    return np.where((outside > 0.5) & (outside <= 0.5 + width), -PIT, 0.0)


KINDS: dict[str, Callable] = {
    "flat": _flat,
    "rough": _rough,
    "slope_up": _slope(1.0),
    "slope_down": _slope(-1.0),
    "stairs_up": _stairs(1.0),
    "stairs_down": _stairs(-1.0),
    "stepping_stones": _stepping_stones,
    "gaps": _gaps,
}


def tile(kind: str, difficulty: float, size: float = 8.0, resolution: float = 0.1, seed: int = 0) -> np.ndarray:
    """One square tile's heights, m: [n, n] with n = size / resolution + 1 (vertices,
    row i at y = -size/2 + i * resolution, column j likewise in x), its edge at 0 on
    average (so neighbouring tiles meet without a cliff)."""
    if kind not in KINDS:
        raise ValueError(f"terrain kind {kind!r} is unknown; the kinds: {sorted(KINDS)}")
    if not 0.0 <= difficulty <= 1.0:
        raise ValueError(f"terrain difficulty={difficulty!r} must lie in [0, 1]")
    if not (resolution > 0 and size >= 2 * PLATFORM and float(size / resolution).is_integer()):
        raise ValueError(
            f"terrain tile size={size!r} m must be >= {2 * PLATFORM} m and a whole number of resolution={resolution!r} m"
        )
    n = round(size / resolution) + 1
    axis = np.linspace(-size / 2, size / 2, n)
    x, y = np.meshgrid(axis, axis)  # [n, n]: x varies along columns, y along rows
    heights = KINDS[kind](difficulty, x, y, np.random.default_rng(seed))
    edge = np.concatenate([heights[0], heights[-1], heights[1:-1, 0], heights[1:-1, -1]])
    return (heights - edge.mean()).astype(np.float32)


@dataclasses.dataclass(frozen=True)
class Terrain:
    """A grid of tiles in one heightfield (host data, numpy).

    Attributes:
      heights: [rows * (n - 1) + 1 + 2 * border_cells, cols * (n - 1) + 1 + 2 * border_cells]
        vertex heights, m; row index along +y, column index along +x, centred on the
        world origin.
      resolution: m between vertices.
      tile_size: m, a tile's side.
      kinds: [cols] the kind of each column.
      origins: [rows, cols, 3] world position of each tile's platform centre (its
        height included), m.
    """

    heights: np.ndarray
    resolution: float
    tile_size: float
    kinds: tuple[str, ...]
    origins: np.ndarray

    @property
    def rows(self) -> int:
        return self.origins.shape[0]

    @property
    def extent(self) -> tuple[float, float]:
        """Half-sizes (x, y) of the whole heightfield, m."""
        ny, nx = self.heights.shape
        return (nx - 1) * self.resolution / 2, (ny - 1) * self.resolution / 2


def grid(
    kinds: Sequence[str] = ("flat", "rough", "slope_up", "slope_down", "stairs_up", "stairs_down"),
    rows: int = 6,
    tile_size: float = 8.0,
    resolution: float = 0.1,
    border: float = 2.0,
    seed: int = 0,
) -> Terrain:
    """Tiles laid as a grid: column j of kind ``kinds[j]``, row i of difficulty
    i / (rows - 1) (a single row: difficulty 1), with a flat border of `border` m.
    Deterministic in `seed`."""
    if not kinds or rows < 1:
        raise ValueError(f"terrain grid needs at least one kind and one row, got kinds={kinds!r} rows={rows!r}")
    cells = round(tile_size / resolution)
    edge = round(border / resolution)
    heights = np.zeros((rows * cells + 1 + 2 * edge, len(kinds) * cells + 1 + 2 * edge), np.float32)
    for i in range(rows):
        for j, kind in enumerate(kinds):
            difficulty = i / (rows - 1) if rows > 1 else 1.0
            block = tile(kind, difficulty, tile_size, resolution, seed=seed * 100_003 + i * len(kinds) + j)
            heights[edge + i * cells : edge + (i + 1) * cells + 1, edge + j * cells : edge + (j + 1) * cells + 1] = (
                block
            )
    half = (np.array(heights.shape[::-1]) - 1) * resolution / 2  # (x, y)
    centres = np.stack(np.meshgrid(np.arange(len(kinds)), np.arange(rows)), -1)  # [rows, cols, (j, i)]
    xy = (edge + centres * cells + cells / 2) * resolution - half
    platform = heights[edge + cells // 2 + centres[..., 1] * cells, edge + cells // 2 + centres[..., 0] * cells]
    origins = np.concatenate([xy, platform[..., None]], -1).astype(np.float32)
    return Terrain(heights, float(resolution), float(tile_size), tuple(kinds), origins)


def add_to_spec(
    spec: mujoco.MjSpec, terrain: Terrain, name: str = "terrain", replace: str | None = "floor", depth: float = 1.0
) -> mujoco.MjSpec:
    """Adds `terrain` to `spec` as heightfield `name` and a world geom using it: the geom
    `replace` takes its place, keeping its name (sensors may refer to it), material,
    friction and contact settings; with no such geom the new one is called `name`.
    Returns `spec`, edited in place."""
    low, high = float(terrain.heights.min()), float(terrain.heights.max())
    span = max(high - low, 1e-3)
    hx, hy = terrain.extent
    field = spec.add_hfield(name=name, size=[hx, hy, span, depth])
    field.nrow, field.ncol = terrain.heights.shape
    field.userdata = ((terrain.heights - low) / span).ravel().tolist()
    old = next((g for g in spec.geoms if g.name == replace), None) if replace else None
    geom = spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname=name, pos=[0, 0, low])
    if old is not None:
        geom.material, geom.friction, geom.priority = old.material, old.friction, old.priority
        geom.contype, geom.conaffinity, geom.condim = old.contype, old.conaffinity, old.condim
        spec.delete(old)
    geom.name = replace if old is not None else name
    return spec


# --- reading the heightfield in JAX ------------------------------------------------------


def heights_at(model: mjx.Model, hfield: int, nrow: int, ncol: int, position: Array, xy: Array) -> Array:
    """Terrain height under world points `xy` [..., 2] (m) of heightfield `hfield` (a
    Python int, as are its `nrow` and `ncol`), whose geom sits at `position` [3]: bilinear
    in the vertex heights; points outside the field read its nearest edge. Returns [...], m."""
    size = jnp.asarray(model.hfield_size)[hfield]  # (half x, half y, elevation range, base depth)
    start = int(np.asarray(model.hfield_adr)[hfield])  # `hfield` is static: the layout is the model's
    data = jnp.asarray(model.hfield_data)[start : start + nrow * ncol].reshape(nrow, ncol)
    u = jnp.clip((xy[..., 0] - position[0] + size[0]) / (2 * size[0]) * (ncol - 1), 0, ncol - 1)
    v = jnp.clip((xy[..., 1] - position[1] + size[1]) / (2 * size[1]) * (nrow - 1), 0, nrow - 1)
    j, i = jnp.minimum(jnp.floor(u), ncol - 2).astype(jnp.int32), jnp.minimum(jnp.floor(v), nrow - 2).astype(jnp.int32)
    fu, fv = u - j, v - i
    top = data[i, j] * (1 - fu) + data[i, j + 1] * fu
    bottom = data[i + 1, j] * (1 - fu) + data[i + 1, j + 1] * fu
    return position[2] + size[2] * (top * (1 - fv) + bottom * fv)


def _hfield_geom(mj_model: mujoco.MjModel, hfield: str) -> tuple[int, int]:
    field = names.index(mj_model, "hfield", hfield, "terrain")
    geoms = np.flatnonzero((mj_model.geom_type == mujoco.mjtGeom.mjGEOM_HFIELD) & (mj_model.geom_dataid == field))
    if geoms.size != 1:
        raise ValueError(f"terrain: heightfield {hfield!r} must be used by exactly one geom, found {geoms.size}")
    return field, int(geoms[0])


def height_scan(
    mj_model: mujoco.MjModel,
    hfield: str = "terrain",
    spacing: float = 0.1,
    size: tuple[int, int] = (11, 7),
    body: str | None = None,
) -> Partial:
    """Observation: the base's height above the terrain at a grid of `size` (x, y)
    points `spacing` m apart, centred under the base and turned with its heading (yaw
    only, as a scanner fixed to a level frame): [size_x * size_y], m, row-major in y.
    Noise is the task's (`mjzoo.with_observation_noise`)."""
    field, geom = _hfield_geom(mj_model, hfield)
    nx, ny = size
    gx, gy = np.meshgrid((np.arange(nx) - (nx - 1) / 2) * spacing, (np.arange(ny) - (ny - 1) / 2) * spacing)
    pattern = jnp.asarray(np.stack([gx, gy], -1).reshape(-1, 2), jnp.float32)
    layout = (field, geom, int(mj_model.hfield_nrow[field]), int(mj_model.hfield_ncol[field]))
    return Partial(_scan, tree.StaticValue(layout), jnp.int32(names.base_body(mj_model, body, "height_scan")), pattern)


def _scan(layout, body, pattern, model, state: State) -> Array:
    field, geom, nrow, ncol = layout.value
    base = state.data.xpos[body]
    forward = state.data.xmat[body][:2, 0]
    c, s = forward / jnp.maximum(jnp.linalg.norm(forward), 1e-6)
    xy = base[:2] + pattern @ jnp.array([[c, s], [-s, c]])
    ground = heights_at(model, field, nrow, ncol, model.geom_pos[geom], xy)
    return (base[2] - ground).astype(jnp.float32)


# --- starts and the curriculum -------------------------------------------------------------


def start_on_tile(mj_model: mujoco.MjModel, terrain: Terrain, level: float = 0.0, spread: float = 0.3) -> Partial:
    """A reset item: puts the free base over the platform of a tile of row
    ``round(level * (rows - 1))`` and a column drawn uniformly, shifted by U(±`spread`)
    m in x and y, its height raised by the platform's. `level` is a leaf a curriculum
    moves (`mjzoo.catalog.curriculum.with_curriculum`)."""
    qpos = names.free_joint_addresses(mj_model, None, "start_on_tile")[0]
    return Partial(
        _start_on_tile,
        jnp.asarray(qpos[:3]),
        jnp.asarray(terrain.origins),
        jnp.float32(level),
        jnp.float32(spread),
    )


def _start_on_tile(qpos, origins, level, spread, model, data, key):
    rows, cols = origins.shape[:2]
    row = jnp.clip(jnp.round(level * (rows - 1)), 0, rows - 1).astype(jnp.int32)
    k_col, k_xy = jax.random.split(key)
    col = jax.random.randint(k_col, (), 0, cols)
    shift = jnp.concatenate([jax.random.uniform(k_xy, (2,), minval=-spread, maxval=spread), jnp.zeros(1)])
    return data.replace(qpos=data.qpos.at[qpos].add(origins[row, col] + shift))


def by_walked_distance(
    mj_model: mujoco.MjModel, target: float, rows: int, initial: float = 0.0, body: str | None = None
) -> curriculum.Rule:
    """The terrain curriculum's rule: at each episode end, one row harder if the base
    walked at least `target` m from its start, one row easier if the episode ended by a
    termination (a fall) short of that, else unchanged (a time-out short of it)."""
    if not target > 0 or rows < 2:
        raise ValueError(f"by_walked_distance: target={target!r} must be > 0 m and rows={rows!r} >= 2")
    step = 1.0 / (rows - 1)
    return curriculum.by_distance(mj_model, target, up=step, down=step, initial=initial, body=body, only_falls=True)
