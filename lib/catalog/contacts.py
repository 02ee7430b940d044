"""Contacts between named geoms, read through `mjzoo.batching.contacts`, for ONE environment.

MJX's JAX implementation keeps a fixed set of contact slots, one per candidate geom
pair, whether the geoms touch or not; MuJoCo Warp keeps the contacts of every world of a
batch in one pool, which a world reaches through its contact constraint rows.
`batching.contacts` gives both as slots with geom ids, an ``active`` mask (MuJoCo's test
for adding a contact constraint: distance below ``includemargin``) and a normal force.

Constructors check with `geom_sets` that the geoms they watch can collide at all
(contype / conaffinity bits or an explicit <pair>), so a typo in a collision mask fails
at construction instead of reading "never in contact". Parent-child filtering and
<exclude> are not checked.

Contact data is what the last `mjx.step` or `mjx.forward` computed: before integration,
one physics substep behind qpos and qvel.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjzoo import batching
from mjzoo import names

__all__ = ["can_touch", "geom_sets", "pairs", "touching", "normal_forces", "forces", "point_velocity"]

Array = jax.Array


def can_touch(mj_model: mujoco.MjModel, a: int, b: int) -> bool:
    """MuJoCo's collision filter for geoms `a` and `b`: compatible contype/conaffinity
    bits, or an explicit <pair> naming both."""
    ctype, caff = mj_model.geom_contype, mj_model.geom_conaffinity
    bits = (ctype[a] & caff[b]) | (ctype[b] & caff[a])
    paired = any({a, b} == {int(g1), int(g2)} for g1, g2 in zip(mj_model.pair_geom1, mj_model.pair_geom2))
    return bool(bits) or paired


def geom_sets(
    mj_model: mujoco.MjModel, geoms: names.Names, others: names.Names | None, who: str
) -> tuple[Array, Array]:
    """int32 indices of `geoms` [G] and `others` [O] (every geom if None), checked: each
    of `geoms` is not among `others` and can collide with at least one of them."""
    ids = names.ids(mj_model, "geom", geoms, who)
    other = np.arange(mj_model.ngeom, dtype=np.int32) if others is None else names.ids(mj_model, "geom", others, who)
    for g in ids:
        name = names.all_names(mj_model, "geom", [g])[0]
        if others is not None and g in other:
            raise ValueError(f"{who}: geom {name!r} is listed both as watched and as what it touches")
        if not any(can_touch(mj_model, g, o) for o in other if o != g):
            target = repr(others) if others is not None else "any geom"
            raise ValueError(
                f"{who}: geom {name!r} can never touch {target}: their contype/conaffinity bits "
                f"exclude it and no <pair> lists it"
            )
    return jnp.asarray(ids), jnp.asarray(other)


def pairs(data: mjx.Data, geoms: Array, others: Array) -> Array:
    """[G, C] bool: contact slot c is active and between geom ``geoms[g]`` and one of `others`."""
    return _pairs(batching.contacts(data), geoms, others)


def _pairs(contact: batching.Contacts, geoms: Array, others: Array) -> Array:
    other1 = jnp.any(contact.geom1[None, :] == others[:, None], axis=0)
    other2 = jnp.any(contact.geom2[None, :] == others[:, None], axis=0)
    between = ((contact.geom1 == geoms[:, None]) & other2) | ((contact.geom2 == geoms[:, None]) & other1)
    return between & contact.active


def touching(data: mjx.Data, geoms: Array, others: Array) -> Array:
    """[G] bool: geom ``geoms[g]`` has an active contact with one of `others` ([O] int32)."""
    return jnp.any(pairs(data, geoms, others), axis=1)


def normal_forces(model: mjx.Model, data: mjx.Data) -> Array:
    """[C] float32 normal force of every contact slot, N (0 when inactive)."""
    return batching.contacts(data, model).normal_force


def forces(model: mjx.Model, data: mjx.Data, geoms: Array, others: Array) -> Array:
    """[G] float32 total normal force on geom ``geoms[g]`` from `others`, N (0 apart)."""
    contact = batching.contacts(data, model)
    return jnp.sum(_pairs(contact, geoms, others) * contact.normal_force[None, :], axis=1)


def point_velocity(model: mjx.Model, data: mjx.Data, bodies: Array, points: Array) -> tuple[Array, Array]:
    """A helper, not an item: the world-frame linear velocity [n, 3] (m/s) of world
    points `points` [n, 3] fixed to `bodies` [n] (int32), and the bodies' world-frame
    angular velocity [n, 3] (rad/s). `cvel` is (angular, linear) about the subtree
    centre of mass of each body's root: v(p) = v(com) + w x (p - com)."""
    angular, linear = data.cvel[bodies, :3], data.cvel[bodies, 3:]
    com = data.subtree_com[jnp.asarray(model.body_rootid)[bodies]]
    return linear + jnp.cross(angular, points - com), angular
