"""Batches of simulated worlds on either MJX implementation, and the one reader of
MuJoCo Warp's private Data fields.

MuJoCo Warp keeps the contacts of every world of one vmapped call in one pool, whose
size is static: whoever forms a batch of B worlds sizes it first (`sized`), and code
that merges, indexes or compares batched states uses `where` and `own`, which know what
is shared and what is each world's. `contacts` and `overflow` read one world's contacts
and Warp's overflow flags; `probe_capacity` sizes one world's share at load time. On
MJX's JAX implementation every batch function here is the plain operation (or the identity).
"""

from __future__ import annotations

import dataclasses
from typing import Any
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.sharding import PartitionSpec
from mujoco import mjx

from mjzoo.tree import where as leafwise_where

__all__ = ["AXIS", "sized", "own", "where", "Contacts", "contacts", "overflow"]

# MuJoCo Warp's overflow bits (mujoco_warp OverflowType): capacities a run outgrew (its
# physics then drops contacts or constraints) and solver iteration limits (it stops early).
OVERFLOW_CAPACITY = 1 | 2 | 4 | 8 | 16 | 32 | 64 | 128 | 256 | 4096  # nefc, nnz, broad/narrowphase, ccd, ...
OVERFLOW_SOLVER = 512 | 1024  # iterations, line-search iterations
_WARP_SCRATCH = {"actuator_moment", "moment_colind", "moment_rowadr"}  # sparse, filled in atomic order
AXIS = "envs"  # the mesh axis a batch of worlds is split along (mjzoo.harness.devices)


def _is_data(x: Any) -> bool:
    return isinstance(x, mjx.Data)


def sized(tree: Any, worlds: int) -> Any:
    """`tree` (a Task, a State, a Data, any pytree) with every Warp Data in it holding a
    contact pool for `worlds` simulated worlds: what a batch of `worlds` needs before it
    is vmapped (resets from the task's template, or one state broadcast over planner
    samples). The pools' contents are dropped: the next step recomputes them. Warp
    sizes its pool statically, so the caller who knows the batch sizes it; identity on
    JAX."""
    return jax.tree.map(lambda x: _sized(x, worlds) if _is_data(x) else x, tree, is_leaf=_is_data)


def _sized(data: mjx.Data, worlds: int) -> mjx.Data:
    impl = data._impl
    if data.impl != mjx.Impl.WARP or impl.nworld == worlds:
        return data
    per_world = impl.naconmax // impl.nworld
    pool = {
        name: jnp.zeros((per_world * worlds,) + value.shape[1:], value.dtype) for name, value in _pool(data).items()
    }
    return _counted(data.replace(_impl=impl.replace(**pool)), worlds)


def _pool(data: mjx.Data) -> dict[str, jax.Array]:
    """Warp's contact pool: the fields of `data._impl` with a row per contact slot."""
    impl = data._impl
    return {
        f.name: getattr(impl, f.name)
        for f in dataclasses.fields(impl)
        if f.name.startswith("contact__") and np.shape(getattr(impl, f.name))[:1] == (impl.naconmax,)
    }


def _counted(data: mjx.Data, worlds: int) -> mjx.Data:
    """`data` with Warp's static counts (worlds, pool slots) said for `worlds` worlds; the
    arrays untouched (the caller gives them that size)."""
    impl = data._impl
    if data.impl != mjx.Impl.WARP or impl.nworld == worlds:
        return data
    naconmax = impl.naconmax // impl.nworld * worlds
    naccdmax = impl.naccdmax // impl.nworld * worlds if impl.naccdmax else impl.naccdmax
    return data.replace(_impl=impl.replace(naconmax=naconmax, naccdmax=naccdmax, nworld=worlds))


def own(tree: Any) -> Any:
    """`tree` with only each world's own state in every Warp Data: without the contact
    pool the batch shares, and without the sparse actuator layouts Warp's kernels fill in
    a varying order (both recomputed by every step; their fields become None). Every
    leaf then has the batch's axes and compares across runs: for indexing or comparing
    batched states. Identity on JAX."""
    return jax.tree.map(lambda x: _own_fields(x) if _is_data(x) else x, tree, is_leaf=_is_data)


def _own_fields(data: mjx.Data) -> mjx.Data:
    if data.impl != mjx.Impl.WARP:
        return data
    from mujoco.mjx.warp.types import DATA_NON_VMAP

    dropped = dict.fromkeys(_array_fields(data, DATA_NON_VMAP | _WARP_SCRATCH))
    return data.replace(_impl=data._impl.replace(**dropped))


def _array_fields(data: mjx.Data, names: set[str]) -> list[str]:
    """The fields of Warp's `data._impl` among `names` that hold arrays (not None)."""
    return [
        f.name
        for f in dataclasses.fields(data._impl)
        if f.name in names and isinstance(getattr(data._impl, f.name), jax.Array)
    ]


def shared(tree: Any) -> Any:
    """`tree` with a bool for each leaf: True for the contact pool and counters that the
    worlds of a Warp batch share (MJX keeps them unbatched under `jax.vmap`)."""

    def mark(x: Any) -> Any:
        flags = jax.tree.map(lambda _: False, x)
        if not _is_data(x) or x.impl != mjx.Impl.WARP:
            return flags
        from mujoco.mjx.warp.types import DATA_NON_VMAP

        return flags.replace(_impl=flags._impl.replace(**dict.fromkeys(_array_fields(x, DATA_NON_VMAP), True)))

    return jax.tree.map(mark, tree, is_leaf=_is_data)


def where(cond: jax.Array, on_true: mjx.Data, on_false: mjx.Data) -> mjx.Data:
    """`on_true` where `cond` (a scalar per world), else `on_false`, field by field.

    Warp's contact pool is shared by all worlds, not one world's: it is taken from
    `on_false`, which should be the running state (the one just stepped)."""
    if on_false.impl != mjx.Impl.WARP:
        return leafwise_where(cond, on_true, on_false)
    from mujoco.mjx.warp.types import DATA_NON_VMAP  # present where Warp data exists

    pick = lambda a, b: jnp.where(cond, a, b)  # noqa: E731
    impl = {  # per-world fields only: the pool and its counters are shared
        f.name: pick(getattr(on_true._impl, f.name), getattr(on_false._impl, f.name))
        for f in dataclasses.fields(on_false._impl)
        if f.name not in DATA_NON_VMAP and isinstance(getattr(on_false._impl, f.name), jax.Array)
    }
    public = {
        f.name: pick(getattr(on_true, f.name), getattr(on_false, f.name))
        for f in dataclasses.fields(on_false)
        if f.name != "_impl"
    }
    return on_false.replace(**public, _impl=on_false._impl.replace(**impl))


def mesh_devices() -> int:
    """The devices along `AXIS` of the current mesh (``jax.set_mesh``, or the abstract mesh
    the training harness sets while it traces); 1 without such a mesh."""
    mesh = jax.sharding.get_abstract_mesh()
    return 1 if mesh.empty or AXIS not in mesh.axis_names else mesh.shape[AXIS]


def partition(tree: Any, axis: str = AXIS) -> Any:
    """A `PartitionSpec` for each leaf of a batch of worlds (leading axis: the worlds), to
    split it over the devices of mesh axis `axis`: each world's leaves along that axis,
    and Warp's contact pool too (a device's share of the slots serves its own worlds; a
    step refills them); scalars and the rest of what Warp's worlds share whole.

    Returns:
      a pytree of `tree`'s structure with a PartitionSpec per leaf.
    """
    split, whole = PartitionSpec(axis), PartitionSpec()
    leaf = lambda x: split if jnp.ndim(x) else whole  # noqa: E731

    def data_specs(data: mjx.Data) -> mjx.Data:
        if data.impl != mjx.Impl.WARP:
            return jax.tree.map(leaf, data)
        from mujoco.mjx.warp.types import DATA_NON_VMAP

        pool = _pool(data)

        def spec(path: tuple, x: Any) -> PartitionSpec:
            name = path[-1].name if len(path) == 2 and path[0].name == "_impl" else None
            if name in DATA_NON_VMAP:  # shared by the batch: split only the pool's slots
                return split if name in pool else whole
            return leaf(x)

        return jax.tree_util.tree_map_with_path(spec, data)

    return jax.tree.map(lambda x: data_specs(x) if _is_data(x) else leaf(x), tree, is_leaf=_is_data)


def vmap_transition(step: Any, task: Any, states: Any, *per_world: Any) -> Any:
    """``jax.vmap(step, in_axes=(None, 0, 0, ...))(task, states, *per_world)`` for a
    `step` that returns states of `states`' structure (`mjzoo.transition`).

    Under a mesh with axis `AXIS` over several devices (``jax.set_mesh``, or the abstract
    mesh the training harness sets) and on Warp, it runs under `jax.shard_map`: XLA cannot
    split Warp's one foreign call over the batch, so each device steps its own worlds with
    its share of the contact pool, and the pool's counters are summed over the devices.
    `states` must then be split as `partition` says (`mjzoo.harness.devices.shard_envs`)."""
    batched = jax.vmap(step, in_axes=(None,) + (0,) * (1 + len(per_world)))
    devices = mesh_devices()
    warp = [x for x in jax.tree.leaves(states, is_leaf=_is_data) if _is_data(x) and x.impl == mjx.Impl.WARP]
    if devices == 1 or not warp:
        return batched(task, states, *per_world)
    worlds = warp[0]._impl.nworld
    if worlds % devices:
        raise ValueError(f"vmap_transition: a batch of {worlds} worlds does not split over {devices} devices")

    def counted(tree: Any, n: int) -> Any:  # Warp's static counts said for n worlds
        return jax.tree.map(lambda x: _counted(x, n) if _is_data(x) else x, tree, is_leaf=_is_data)

    def summed(data: mjx.Data) -> mjx.Data:  # the pool's counters, as one call over the whole batch counts
        if data.impl != mjx.Impl.WARP:
            return data
        names = _array_fields(data, {"nacon", "ncollision"})
        return data.replace(_impl=data._impl.replace(**{n: jax.lax.psum(getattr(data._impl, n), AXIS) for n in names}))

    def local(task: Any, states: Any, *per_world: Any) -> Any:
        out = counted(batched(task, counted(states, worlds // devices), *per_world), worlds)
        return jax.tree.map(lambda x: summed(x) if _is_data(x) else x, out, is_leaf=_is_data)

    specs = partition(states)
    whole = jax.tree.map(lambda _: PartitionSpec(), task)
    return jax.shard_map(local, in_specs=(whole, specs, *map(partition, per_world)), out_specs=specs, check_vma=False)(
        task, states, *per_world
    )


class Contacts(NamedTuple):
    """One world's contacts as slots [C] (MJX-JAX: one per candidate geom pair; Warp: one
    per contact constraint row); inactive slots have ``active`` False and zero force."""

    geom1: jax.Array  # [C] int32
    geom2: jax.Array  # [C] int32
    active: jax.Array  # [C] bool
    normal_force: jax.Array | None  # [C] float32, N (a slot's share of its contact's); None without a model


def contacts(data: mjx.Data, model: mjx.Model | None = None) -> Contacts:
    """The contacts the last `mjx.step` / `mjx.forward` found, for ONE world; normal forces
    need `model` (on MJX-JAX, its cone type says how a contact's rows add up)."""
    if data.impl == mjx.Impl.WARP:
        return _warp_contacts(data)
    contact = data._impl.contact
    active = contact.dist < contact.includemargin
    address, dim = np.asarray(contact.efc_address), np.asarray(contact.dim)
    if model is None or address.size == 0:
        force = None if model is None else jnp.zeros(0, jnp.float32)
        return Contacts(contact.geom1, contact.geom2, active, force)
    # A contact's rows start at its (static) efc_address. Pyramidal cones: the normal force
    # is the sum of its 2 (condim - 1) edge forces (1 row for condim 1); elliptic: row 0.
    rows = np.where(dim == 1, 1, 2 * (dim - 1)) if model.opt.cone == mjx.ConeType.PYRAMIDAL else np.ones_like(dim)
    offsets = np.arange(rows.max())
    index = np.maximum(address, 0)[:, None] + np.minimum(offsets[None, :], rows[:, None] - 1)
    used = (offsets[None, :] < rows[:, None]) & (address[:, None] >= 0)
    force = jnp.sum(jnp.where(used, data._impl.efc_force[index], 0.0), axis=1).astype(jnp.float32)
    return Contacts(contact.geom1, contact.geom2, active, jnp.where(active, force, 0.0))


def _warp_contacts(data: mjx.Data) -> Contacts:
    # This world's contact constraint rows point (efc__id) into the pool shared by all
    # worlds. A pyramidal contact's normal force is the sum of its rows' forces; an
    # elliptic one's is its first row's.
    impl, kind = data._impl, mujoco.mjtConstraint
    rows = jnp.arange(impl.efc__type.shape[-1])
    valid = rows < impl.nefc.reshape(())
    frictionless = valid & (impl.efc__type == int(kind.mjCNSTR_CONTACT_FRICTIONLESS))
    pyramidal = valid & (impl.efc__type == int(kind.mjCNSTR_CONTACT_PYRAMIDAL))
    elliptic = valid & (impl.efc__type == int(kind.mjCNSTR_CONTACT_ELLIPTIC))
    cid = jnp.where(frictionless | pyramidal | elliptic, impl.efc__id, 0)
    elliptic &= impl.contact__efc_address[cid, 0] == rows
    active = frictionless | pyramidal | elliptic
    geoms = impl.contact__geom[cid]
    return Contacts(geoms[:, 0], geoms[:, 1], active, jnp.where(active, impl.efc__force, 0.0).astype(jnp.float32))


def overflow(data: mjx.Data) -> jax.Array:
    """[] int32 bitmask of what overflowed in this world since `mjzoo.physics.step` began (0 on JAX):
    `OVERFLOW_CAPACITY` bits mean ``max_contacts`` / ``max_constraints`` were too small,
    `OVERFLOW_SOLVER` bits that the solver stopped at its iteration limit."""
    if data.impl != mjx.Impl.WARP:
        return jnp.zeros((), jnp.int32)
    return jnp.asarray(data._impl.overflow).reshape(()).astype(jnp.int32)


def overflow_metrics(data: mjx.Data) -> dict[str, jax.Array]:
    """On Warp, [] float32 flags: whether this step outgrew the contact / constraint
    capacities (its physics dropped some) or stopped the solver at its iteration limit;
    nothing on JAX."""
    if data.impl != mjx.Impl.WARP:
        return {}
    flags = overflow(data)
    return {
        "physics/capacity_overflow": ((flags & OVERFLOW_CAPACITY) != 0).astype(jnp.float32),
        "physics/solver_limit": ((flags & OVERFLOW_SOLVER) != 0).astype(jnp.float32),
    }


def clear_overflow(data: mjx.Data) -> mjx.Data:
    """`data` with Warp's (sticky) overflow flags cleared; identity on JAX."""
    if data.impl != mjx.Impl.WARP:
        return data
    return data.replace(_impl=data._impl.replace(overflow=jnp.zeros_like(data._impl.overflow)))


def probe_capacity(mj_model: mujoco.MjModel, seconds: float = 3.0, seeds: int = 4) -> tuple[int, int]:
    """(contacts, constraint rows) per world to allocate for Warp: twice the most that C
    MuJoCo sees in `seeds` rollouts of `seconds` under uniformly random controls from
    qpos0 with random velocities (a robot thrashing, falling and lying down), plus room
    for Warp's own collision routines, which may report a few more contacts per pair."""
    data = mujoco.MjData(mj_model)
    steps = max(1, round(seconds / mj_model.opt.timestep))
    low, high = mj_model.actuator_ctrlrange.T if mj_model.nu else (np.zeros(0), np.zeros(0))
    limited = mj_model.actuator_ctrllimited.astype(bool)
    low, high = np.where(limited, low, -1.0), np.where(limited, high, 1.0)
    most_contacts, most_rows = 0, 0
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        mujoco.mj_resetData(mj_model, data)
        data.qvel[:] = rng.normal(0.0, 1.0, mj_model.nv)
        for i in range(steps):
            if i % 10 == 0:
                data.ctrl[:] = rng.uniform(low, high)
            mujoco.mj_step(mj_model, data)
            if not np.all(np.isfinite(data.qacc)):
                break
            most_contacts, most_rows = max(most_contacts, data.ncon), max(most_rows, data.nefc)
    return 2 * most_contacts + 8, 2 * most_rows + 8 * 6 + mj_model.neq * 6 + mj_model.njnt
