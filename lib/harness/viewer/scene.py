"""A MuJoCo model as viser meshes, grouped per body: sent once, then moved by poses.

Each body with visible geoms becomes one viser frame ``/env{E}/{body}`` whose children
are its geoms' meshes in the body's own frame; a displayed frame then sends only each
body's position and orientation (wxyz), never a vertex. Several environments of a
batch are drawn side by side, each shifted along x by `spacing`, and so are several
models (a retargeted clip beside its source): environment e is then model e.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import mujoco
import numpy as np
import trimesh
import viser

__all__ = ["Geom", "BodyGroup", "body_groups", "geom_mesh", "Scene"]

_PLANE_HALF = 10.0  # metres: an infinite plane (size 0) drawn as 20 m x 20 m
_VISIBLE_GROUPS = (0, 1, 2)  # MuJoCo's default: groups 3-5 hold collision-only geoms


@dataclasses.dataclass(frozen=True)
class Geom:
    """One geom's mesh in its body's frame: vertices [V, 3], faces [F, 3], rgba [4] in 0..1."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    rgba: np.ndarray
    pos: np.ndarray  # [3] in the body frame
    quat: np.ndarray  # [4] wxyz in the body frame


@dataclasses.dataclass(frozen=True)
class BodyGroup:
    """A body and its visible geoms (the unit moved as one per displayed frame)."""

    body_id: int
    name: str
    geoms: tuple[Geom, ...]


def body_groups(mj_model: mujoco.MjModel) -> list[BodyGroup]:
    """Every body that has a visible geom (geom group 0-2, alpha > 0), world body included."""
    per_body: dict[int, list[Geom]] = {}
    for g in range(mj_model.ngeom):
        rgba = _rgba(mj_model, g)
        if mj_model.geom_group[g] not in _VISIBLE_GROUPS or rgba[3] <= 0:
            continue
        mesh = geom_mesh(mj_model, g)
        if mesh is None:
            continue
        name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}"
        geom = Geom(
            name,
            np.asarray(mesh.vertices, np.float32),
            np.asarray(mesh.faces, np.uint32),
            rgba,
            mj_model.geom_pos[g].copy(),
            mj_model.geom_quat[g].copy(),
        )
        per_body.setdefault(int(mj_model.geom_bodyid[g]), []).append(geom)
    return [BodyGroup(b, _body_name(mj_model, b), tuple(geoms)) for b, geoms in sorted(per_body.items())]


def geom_mesh(mj_model: mujoco.MjModel, g: int) -> trimesh.Trimesh | None:
    """Geom `g`'s shape centred in its own frame (MuJoCo's axes: capsules and cylinders
    along z); None for a height field (not drawn)."""
    kind, size = mj_model.geom_type[g], mj_model.geom_size[g]
    types = mujoco.mjtGeom
    if kind == types.mjGEOM_PLANE:
        half = [s if s > 0 else _PLANE_HALF for s in size[:2]]
        return trimesh.creation.box(extents=(2 * half[0], 2 * half[1], 0.002), transform=_shifted_z(-0.001))
    if kind == types.mjGEOM_SPHERE:
        return trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    if kind == types.mjGEOM_ELLIPSOID:
        sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        return sphere.apply_scale(size[:3])
    if kind == types.mjGEOM_CAPSULE:
        return trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=(12, 12))
    if kind == types.mjGEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=16)
    if kind == types.mjGEOM_BOX:
        return trimesh.creation.box(extents=2 * size[:3])
    if kind == types.mjGEOM_MESH:
        return _model_mesh(mj_model, int(mj_model.geom_dataid[g]))
    return None


def _model_mesh(mj_model: mujoco.MjModel, mesh: int) -> trimesh.Trimesh:
    """A mesh asset's vertices and faces (MuJoCo stores them in the geom's frame)."""
    v0, nv = mj_model.mesh_vertadr[mesh], mj_model.mesh_vertnum[mesh]
    f0, nf = mj_model.mesh_faceadr[mesh], mj_model.mesh_facenum[mesh]
    return trimesh.Trimesh(mj_model.mesh_vert[v0 : v0 + nv], mj_model.mesh_face[f0 : f0 + nf], process=False)


def _shifted_z(dz: float) -> np.ndarray:
    transform = np.eye(4)
    transform[2, 3] = dz
    return transform


def _rgba(mj_model: mujoco.MjModel, g: int) -> np.ndarray:
    """The geom's colour: its material's where it has one (MuJoCo's rule)."""
    material = mj_model.geom_matid[g]
    return np.array(mj_model.mat_rgba[material] if material >= 0 else mj_model.geom_rgba[g], np.float32)


def _body_name(mj_model: mujoco.MjModel, b: int) -> str:
    name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
    return name.replace("/", "_")  # viser's scene names are paths


class Scene:
    """The bodies of `num_envs` environments in a viser scene: of one model, or of
    `mj_model[e]` for environment e when given a sequence of models.

    Attributes:
      handles: {(env, body name): viser frame} one per body group per environment.
      offsets: [E, 3] where each environment's origin is drawn.
      groups: the first model's body groups; `slots`: [E] each environment's.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        mj_model: mujoco.MjModel | Sequence[mujoco.MjModel],
        num_envs: int,
        spacing: float = 0.0,
    ):
        models = list(mj_model) if isinstance(mj_model, Sequence) else [mj_model] * num_envs
        if len(models) != num_envs:
            raise ValueError(f"Scene: {len(models)} models for {num_envs} environments")
        built = {id(m): body_groups(m) for m in models}  # one model's meshes are made once
        self.server, self.slots = server, [built[id(m)] for m in models]
        self.groups = self.slots[0]
        self.spacing = spacing or max(_spacing(m) for m in models)
        self.offsets = np.zeros((num_envs, 3), np.float32)
        self.offsets[:, 0] = self.spacing * (np.arange(num_envs) - (num_envs - 1) / 2)
        centre = np.mean([np.asarray(m.stat.center) + o for m, o in zip(models, self.offsets)], axis=0)
        extent = max(float(m.stat.extent) for m in models)
        _stage(server, centre, extent, float(self.offsets[-1, 0] - self.offsets[0, 0]))
        self.ids = {(e, g.name): g.body_id for e, groups in enumerate(self.slots) for g in groups}
        self.handles: dict[tuple[int, str], viser.FrameHandle] = {}
        for env, groups in enumerate(self.slots):
            for group in groups:
                self.handles[(env, group.name)] = self._add(env, group)

    def _add(self, env: int, group: BodyGroup) -> viser.FrameHandle:
        frame = self.server.scene.add_frame(f"/env{env}/{group.name}", show_axes=False, position=self.offsets[env])
        for geom in group.geoms:
            floor = group.body_id == 0 and _is_plane(geom)
            if floor and env > 0:
                continue  # one floor under all environments (overlapping copies flicker)
            name = f"/floor/{geom.name}" if floor else f"/env{env}/{group.name}/{geom.name}"
            color = tuple(int(255 * c) for c in geom.rgba[:3])
            opacity = float(geom.rgba[3]) if geom.rgba[3] < 1 else None
            self.server.scene.add_mesh_simple(
                name, geom.vertices, geom.faces, color=color, opacity=opacity, position=geom.pos, wxyz=geom.quat
            )
        return frame

    def update(self, xpos: np.ndarray | Sequence[np.ndarray], xquat: np.ndarray | Sequence[np.ndarray]) -> None:
        """Moves every body: xpos [E, nbody, 3], xquat [E, nbody, 4] (wxyz), world frame
        (or lists of E such [nbody_e, ...] arrays for several models). One batch of pose
        messages (`server.atomic`), so a client never draws half a frame."""
        with self.server.atomic():
            for (env, name), handle in self.handles.items():
                body = self.ids[(env, name)]
                handle.position = xpos[env][body] + self.offsets[env]
                handle.wxyz = xquat[env][body]


def _is_plane(geom: Geom) -> bool:
    """A plane geom's mesh: a thin box (see `geom_mesh`)."""
    return len(geom.vertices) == 8 and float(np.ptp(geom.vertices[:, 2])) < 0.01


def _spacing(mj_model: mujoco.MjModel) -> float:
    """Side-by-side distance: the model's extent (its statistic), at least 1 m."""
    return float(max(1.0, 2.5 * mj_model.stat.extent))


def _stage(server: viser.ViserServer, centre: np.ndarray, extent: float, width: float) -> None:
    """MuJoCo's z up, plain lights (no image-based lighting: its HDRI comes from the
    internet, and washes colours out), and a first camera framing every environment:
    looking at `centre`, the middle of them all, from far enough for a model `extent`
    across and `width` metres of environments side by side."""
    server.scene.set_up_direction("+z")
    server.scene.configure_environment_map(None)
    server.scene.configure_default_lights(enabled=False)
    server.scene.add_light_hemisphere(
        "/lights/sky", sky_color=(255, 255, 255), ground_color=(90, 90, 100), intensity=1.2
    )
    server.scene.add_light_directional("/lights/sun", intensity=1.8, wxyz=(0.92, 0.2, -0.2, 0.25), position=(0, 0, 5))
    distance = 1.0 * extent + 0.45 * width
    server.initial_camera.look_at = centre
    server.initial_camera.position = centre + distance * np.array([0.0, -1.0, 0.35])
