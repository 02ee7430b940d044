"""Physics randomizers for `mjzoo.with_domain_randomization`: ``(model, key) -> {field: value}``.

Each constructor takes the host `mujoco.MjModel` (``task.mj_model``), the names of the
elements to perturb (None: all of them) and a range ``[low, high]``, resolves the names
to indices once and returns ``Partial(fn, indices, low, high)``: indices and ranges are
pytree leaves, so new ranges do not retrace. Every element gets its own uniform draw per
episode, independent of the others. A randomizer always receives the task's nominal
model (`with_domain_randomization` draws from ``task.model`` at every reset), so draws
never compound across episodes; a zero-width range reproduces the nominal model exactly.

    randomize = randomizers.combine(
        randomizers.scale_friction(mj_model, 0.5, 1.5, geoms=["floor"]),
        randomizers.add_masses(mj_model, -1.0, 1.0, bodies=["torso"]),
        randomizers.shift_com(mj_model, -0.02, 0.02, bodies=["torso"]),
    )
    task = mjzoo.with_domain_randomization(task, randomize)

Quantities MuJoCo derives from the nominal model at compile time (``body_subtreemass``,
``body_invweight0``, ``dof_invweight0``, ``actuator_acc0``) are not recomputed. In MJX
they scale constraint softness and feed the subtree momentum sensors only; like
MuJoCo's own ``*0`` quantities they describe the reference model.
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.tree_util import Partial
from mujoco import mjx

from mjzoo import names
from mjzoo.tree import StaticValue

__all__ = [
    "Randomizer",
    "scale_friction",
    "scale_armature",
    "scale_damping",
    "scale_masses",
    "add_masses",
    "shift_com",
    "scale_position_gains",
    "combine",
]

Array = jax.Array
Randomizer = Callable[[mjx.Model, Array], dict[str, Array]]
Names = names.Names | None


# --- construction-time checks ----------------------------------------------------------


def _range(who: str, low, high, minimum: float, *, strict: bool = False, shape: tuple = ()) -> tuple[Array, Array]:
    """`low` and `high` as float32 leaves of `shape`, checked: finite, low <= high, low >= minimum."""
    problem = f"{who}: the range low={low!r}, high={high!r} must be finite numbers with low <= high"
    try:
        lo, hi = (np.broadcast_to(np.asarray(v, np.float64), shape) for v in (low, high))
    except (ValueError, TypeError):
        raise ValueError(f"{problem}, each a number{f' or {shape[0]} numbers' if shape else ''}") from None
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()) or (lo > hi).any():
        raise ValueError(problem)
    if (lo <= minimum).any() if strict else (lo < minimum).any():
        raise ValueError(f"{who}: low={low!r} must be {'>' if strict else '>='} {minimum}")
    return jnp.asarray(lo, jnp.float32), jnp.asarray(hi, jnp.float32)


def _dofs(mj_model: mujoco.MjModel, joints: Names, who: str) -> np.ndarray:
    """The dof indices of the named joints (a free joint has 6, a ball joint 3); None: all."""
    if joints is None:
        return np.arange(mj_model.nv, dtype=np.int32)
    return names.joint_addresses(mj_model, names.ids(mj_model, "joint", joints, who), velocity=True)


# --- the draws -------------------------------------------------------------------------


def _scale_field(field: StaticValue, ids, low, high, model, key) -> dict[str, Array]:
    """`field` with its rows `ids` multiplied by one U(low, high) factor each."""
    value = getattr(model, field.value)
    factor = jax.random.uniform(key, ids.shape, minval=low, maxval=high)
    factor = factor.reshape(ids.shape + (1,) * (value.ndim - 1)).astype(value.dtype)
    return {field.value: value.at[ids].multiply(factor)}


# --- friction, armature, damping --------------------------------------------------------


def scale_friction(mj_model: mujoco.MjModel, low: float = 0.5, high: float = 1.5, geoms: Names = None) -> Randomizer:
    """Multiplies the friction of each named geom (None: every geom), and of each explicit
    contact pair (``<pair>``) that involves one, by U(low, high).

    Edits ``geom_friction`` [ngeom, 3] (sliding, torsional, rolling) and, where the model
    has such pairs, ``pair_friction`` [npair, 5]: a pair's contact takes its friction
    from the pair, not its geoms (Playground's robots touch the floor only through
    pairs). Whole rows are scaled, so their ratios are kept; one factor per geom and
    one per pair. Unitless factors, low >= 0. MuJoCo gives a geom-geom contact the larger
    friction of its two geoms, so to randomize the ground the floor alone
    (``geoms=["floor"]``) suffices only if it is the more frictional of the pair.
    """
    who = "scale_friction"
    ids = names.ids(mj_model, "geom", geoms, who)
    pairs = np.flatnonzero(np.isin(mj_model.pair_geom1, ids) | np.isin(mj_model.pair_geom2, ids)).astype(np.int32)
    return Partial(_scale_friction, jnp.asarray(ids), jnp.asarray(pairs), *_range(who, low, high, 0.0))


def _scale_friction(geoms, pairs, low, high, model, key) -> dict[str, Array]:
    geom_key, pair_key = jax.random.split(key)
    fields = _scale_field(StaticValue("geom_friction"), geoms, low, high, model, geom_key)
    if pairs.size:  # a static shape: known when the randomizer is built
        fields |= _scale_field(StaticValue("pair_friction"), pairs, low, high, model, pair_key)
    return fields


def scale_armature(mj_model: mujoco.MjModel, low: float = 0.8, high: float = 1.2, joints: Names = None) -> Randomizer:
    """Multiplies the armature (rotor inertia reflected to the joint, kg m^2 or kg) of every
    dof of the named joints (None: all dofs) by U(low, high), low >= 0.

    Edits ``dof_armature`` [nv]. One factor per dof.
    """
    who = "scale_armature"
    return Partial(
        _scale_field,
        StaticValue("dof_armature"),
        jnp.asarray(_dofs(mj_model, joints, who)),
        *_range(who, low, high, 0.0),
    )


def scale_damping(mj_model: mujoco.MjModel, low: float = 0.8, high: float = 1.2, joints: Names = None) -> Randomizer:
    """Multiplies the passive damping (N m s/rad or N s/m) of every dof of the named joints
    (None: all dofs) by U(low, high), low >= 0.

    Edits ``dof_damping`` [nv]. One factor per dof. A dof with no nominal damping stays
    undamped.
    """
    who = "scale_damping"
    return Partial(
        _scale_field,
        StaticValue("dof_damping"),
        jnp.asarray(_dofs(mj_model, joints, who)),
        *_range(who, low, high, 0.0),
    )


# --- masses and centres of mass ---------------------------------------------------------


def scale_masses(mj_model: mujoco.MjModel, low: float = 0.9, high: float = 1.1, bodies: Names = None) -> Randomizer:
    """Multiplies the mass and the inertia of each named body (None: every body but the
    world) by one factor U(low, high) per body, low > 0: the body keeps its shape and
    its density changes, so its inertia scales with its mass.

    Edits ``body_mass`` [nbody] (kg) and ``body_inertia`` [nbody, 3] (kg m^2).
    """
    who = "scale_masses"
    return Partial(
        _scale_masses,
        jnp.asarray(names.ids(mj_model, "body", bodies, who, world=False)),
        *_range(who, low, high, 0.0, strict=True),
    )


def _scale_masses(ids, low, high, model, key) -> dict[str, Array]:
    factor = jax.random.uniform(key, ids.shape, minval=low, maxval=high)
    return {
        "body_mass": model.body_mass.at[ids].multiply(factor),
        "body_inertia": model.body_inertia.at[ids].multiply(factor[:, None]),
    }


def add_masses(mj_model: mujoco.MjModel, low: float = -0.5, high: float = 0.5, bodies: Names = None) -> Randomizer:
    """Adds U(low, high) kg to the mass of each named body (None: every body but the world).

    Edits ``body_mass`` [nbody] only: the added mass is a point mass at the body's
    centre of mass, which leaves the inertia about that centre unchanged. Every body
    must stay heavier than 0 kg: nominal mass + low > 0, checked here.
    """
    who = "add_masses"
    ids = names.ids(mj_model, "body", bodies, who, world=False)
    low, high = _range(who, low, high, -np.inf)
    lightest = ids[np.argmin(mj_model.body_mass[ids])]
    if mj_model.body_mass[lightest] + float(low) <= 0:
        name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_BODY, lightest)
        raise ValueError(
            f"{who}: low={float(low)} kg would leave body {name!r} "
            f"({mj_model.body_mass[lightest]:.4g} kg) without positive mass"
        )
    return Partial(_add_masses, jnp.asarray(ids), low, high)


def _add_masses(ids, low, high, model, key) -> dict[str, Array]:
    delta = jax.random.uniform(key, ids.shape, minval=low, maxval=high)
    return {"body_mass": model.body_mass.at[ids].add(delta.astype(model.body_mass.dtype))}


def shift_com(mj_model: mujoco.MjModel, low=-0.02, high=0.02, bodies: Names = None) -> Randomizer:
    """Moves the centre of mass of each named body (None: every body but the world) by
    U(low, high) metres along each axis of the body frame.

    `low` and `high` are scalars or [3] (per axis x, y, z). Edits ``body_ipos``
    [nbody, 3] (m); the inertia about the centre of mass is unchanged.
    """
    who = "shift_com"
    return Partial(
        _shift_com,
        jnp.asarray(names.ids(mj_model, "body", bodies, who, world=False)),
        *_range(who, low, high, -np.inf, shape=(3,)),
    )


def _shift_com(ids, low, high, model, key) -> dict[str, Array]:
    shift = jax.random.uniform(key, ids.shape + (3,), minval=low, maxval=high)
    return {"body_ipos": model.body_ipos.at[ids].add(shift.astype(model.body_ipos.dtype))}


# --- actuator gains ---------------------------------------------------------------------


def scale_position_gains(
    mj_model: mujoco.MjModel, low: float = 0.9, high: float = 1.1, actuators: Names = None
) -> Randomizer:
    """Multiplies the stiffness kp of each named position actuator (None: all actuators)
    by U(low, high), low > 0.

    A MuJoCo position actuator applies ``kp * ctrl - kp * q - kv * qdot``: kp sits in
    ``actuator_gainprm[:, 0]`` and, negated, in ``actuator_biasprm[:, 1]``. Both are
    scaled, so the actuator still holds its target (zero force at q = ctrl); kv is kept.
    Every selected actuator must have that form (fixed gain, affine bias with
    biasprm[1] = -gainprm[0] > 0), checked here.
    """
    who = "scale_position_gains"
    ids = names.ids(mj_model, "actuator", actuators, who)
    for i in ids:
        kp = mj_model.actuator_gainprm[i, 0]
        if (
            mj_model.actuator_gaintype[i] != mujoco.mjtGain.mjGAIN_FIXED
            or mj_model.actuator_biastype[i] != mujoco.mjtBias.mjBIAS_AFFINE
            or not kp > 0
            or mj_model.actuator_biasprm[i, 1] != -kp
        ):
            name = mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_ACTUATOR, i)
            raise ValueError(
                f"{who}: actuator {name!r} is not a position actuator (fixed gain kp > 0, "
                f"affine bias with biasprm[1] = -kp); select position actuators by name"
            )
    return Partial(_scale_position_gains, jnp.asarray(ids), *_range(who, low, high, 0.0, strict=True))


def _scale_position_gains(ids, low, high, model, key) -> dict[str, Array]:
    factor = jax.random.uniform(key, ids.shape, minval=low, maxval=high)
    return {
        "actuator_gainprm": model.actuator_gainprm.at[ids, 0].multiply(factor),
        "actuator_biasprm": model.actuator_biasprm.at[ids, 1].multiply(factor),
    }


# --- composition ------------------------------------------------------------------------


def combine(*randomizers: Randomizer) -> Randomizer:
    """One randomizer applying `randomizers` in order, each to the model as the previous
    ones left it, with its own key (``fold_in(key, position)``).

    Two randomizers may edit the same field; they compose rather than clash:
    ``combine(scale_masses(...), add_masses(...))`` draws ``mass * f + delta``. The
    result holds every field any of them edited.
    """
    if not randomizers:
        raise ValueError("combine: give at least one randomizer")
    for i, fn in enumerate(randomizers):
        if not callable(fn):
            raise TypeError(f"combine: randomizer {i} must be callable, got {type(fn).__name__}")
    wrapped = tuple(fn if isinstance(fn, jax.tree_util.Partial) else jax.tree_util.Partial(fn) for fn in randomizers)
    return Partial(_combined, wrapped)


def _combined(randomizers, model, key) -> dict[str, Array]:
    drawn: dict[str, Array] = {}
    for i, fn in enumerate(randomizers):
        drawn.update(fn(model.replace(**drawn), jax.random.fold_in(key, i)))
    return drawn
