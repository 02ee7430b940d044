"""Where a run's arrays live: the env batch of a train state split over the devices,
everything else replicated; XLA then splits the work that follows the envs (the learner
too, where `learning.learn` splits its minibatches over the env mesh).

The devices are `jax.devices()`: in a multi-process run (`mjzoo.harness.distributed`)
those of every process. Each process then passes the same whole value (same seed, same
init) and keeps the shards on its own devices."""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec
from mujoco import mjx

from mjzoo import batching

WARP_GPUS = "MJZOO_WARP_SEVERAL_GPUS"  # =1: let Warp physics train over several GPUs (it crashed XLA)

__all__ = ["shard_envs", "check_split", "replicate", "env_mesh"]


def shard_envs(train_state: Any, per_env_fields: Sequence[str], devices: list | None = None) -> Any:
    """Places the leaves of a train state's `per_env_fields` (an algorithm's
    `PER_ENV_FIELDS`) across devices (leading axis), the rest replicated, as
    `env_shardings` says. Under jit, XLA then splits the env batch
    (and, on Warp, each device steps its own worlds: `mjzoo.batching.partition`).

    On one device this commits the state to it: jit compiles separately for
    uncommitted inputs and for its own (committed) outputs, which would cost a second
    compile on the second chunk."""
    devices = devices or jax.devices()
    if len(devices) == 1:
        return jax.device_put(train_state, devices[0])
    _check_warp_gpus(train_state, devices)
    return jax.tree.map(_put, train_state, env_shardings(train_state, per_env_fields, devices))


def env_shardings(train_state: Any, per_env_fields: Sequence[str], devices: list | None = None) -> Any:
    """The sharding of each leaf of a train state (arrays, or `jax.ShapeDtypeStruct`s to
    compile for ahead) as `shard_envs` places it. Empty per-env arrays (no contacts in a
    model) are replicated, as XLA returns them: placed otherwise, the second chunk would
    compile again for their new sharding."""
    devices = devices or jax.devices()
    if len(devices) == 1:
        return jax.tree.map(lambda _: jax.sharding.SingleDeviceSharding(devices[0]), train_state)
    mesh = env_mesh(devices)
    whole = NamedSharding(mesh, PartitionSpec())

    def place(node: Any, paths: list[list[str]]) -> Any:
        if [] in paths:  # this node is per-env
            specs = batching.partition(node)
            _check_even(node, specs, devices)
            return jax.tree.map(
                lambda x, spec: NamedSharding(mesh, spec) if np.prod(np.shape(x)) else whole, node, specs
            )
        if not paths or not dataclasses.is_dataclass(node):
            return jax.tree.map(lambda _: whole, node)
        return dataclasses.replace(
            node,
            **{
                f.name: place(getattr(node, f.name), [p[1:] for p in paths if p[0] == f.name])
                for f in dataclasses.fields(node)
            },
        )

    return place(train_state, [path.split(".") for path in per_env_fields])


def check_split(num_envs: int, devices: list | None = None) -> None:
    """Raises one ValueError naming the fix where `num_envs` envs do not split evenly
    over `devices` (default `jax.devices()`; JAX's own error names a sharding and a shape)."""
    count = len(devices or jax.devices())
    if num_envs % count:
        raise ValueError(
            f"{num_envs} envs do not split evenly over {count} devices; make num_envs a "
            f"multiple of {count}, or use fewer devices (CUDA_VISIBLE_DEVICES)"
        )


def _check_even(node: Any, specs: Any, devices: list) -> None:
    """`check_split` of the envs of a per-env node: the shortest leading axis of its split
    leaves (Warp's contact pool has a multiple of it)."""
    split = jax.tree.leaves(specs, is_leaf=lambda s: isinstance(s, PartitionSpec))
    rows = [np.shape(x)[0] for x, spec in zip(jax.tree.leaves(node), split) if len(spec) and np.prod(np.shape(x))]
    if rows:
        check_split(min(rows), devices)


def _check_warp_gpus(train_state: Any, devices: list) -> None:
    """Refuses Warp physics split over several GPUs: compiling a program that steps Warp
    under `jax.shard_map` on more than one GPU segfaults in XLA's GPU compiler (JAX
    0.11.2, mujoco-mjx 3.17, warp-lang 1.18, two H200s), whether one process drives both
    GPUs or each has its own, and with every Warp graph mode
    (`benchmarks/warp_multi_gpu_probe.py`). The same programs run on CPU devices."""
    gpus = [d for d in devices if d.platform == "gpu"]
    data = template_data(train_state)
    if len(gpus) > 1 and data is not None and data.impl == mjx.Impl.WARP and os.environ.get(WARP_GPUS) != "1":
        raise NotImplementedError(
            f"training on MuJoCo Warp over {len(gpus)} GPUs crashes XLA's GPU compiler (JAX 0.11.2, mujoco-mjx "
            f"3.17, in one process or one per GPU): use impl='jax' to train on several GPUs, or one GPU; "
            f"{WARP_GPUS}=1 tries it anyway"
        )


def env_mesh(devices: list | None = None) -> jax.sharding.Mesh:
    """The one-axis mesh (`mjzoo.batching.AXIS`) that env batches are split along."""
    devices = devices or jax.devices()
    return jax.sharding.Mesh(np.array(devices), (batching.AXIS,), axis_types=(jax.sharding.AxisType.Auto,))


def env_mesh_scope(devices: list | None = None) -> contextlib.AbstractContextManager:
    """While a jitted function traces, `env_mesh` as the abstract mesh (for
    `mjzoo.batching.vmap_transition`); nothing on one device. Outside jit,
    ``jax.set_mesh(env_mesh())`` does the same for your own calls."""
    devices = devices or jax.devices()
    if len(devices) == 1:
        return contextlib.nullcontext()
    return jax.sharding.use_abstract_mesh(env_mesh(devices).abstract_mesh)


def replicate(tree: Any, devices: list | None = None) -> Any:
    """Copies every array of `tree` (e.g. a Task) onto all `devices`, to run beside a
    state placed by `shard_envs`."""
    devices = devices or jax.devices()
    if len(devices) == 1:
        return jax.device_put(tree, devices[0])
    whole = NamedSharding(env_mesh(devices), PartitionSpec())
    return jax.tree.map(lambda x: _put(x, whole), tree)


def _put(x: Any, sharding: NamedSharding) -> Any:
    """`jax.device_put`. In a multi-process run, an array on this process's own devices
    would be taken for a transfer between hosts (which CPUs cannot do): each process
    places its shards of the whole value from a host copy instead (a typed PRNG key as
    its raw data). Not `device_put` of that copy, which insists that every process hold
    the same bits: Warp's GPU physics is not bitwise deterministic, so two processes'
    initial states differ in their last bits, and each shard is one process's anyway."""
    if sharding.is_fully_addressable or not isinstance(x, jax.Array) or not x.is_fully_addressable:
        return jax.device_put(x, sharding)
    if jnp.issubdtype(x.dtype, jax.dtypes.prng_key):
        return jax.random.wrap_key_data(_put(jax.random.key_data(x), sharding), impl=jax.random.key_impl(x))
    host = np.asarray(x)
    return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])


def template_data(tree: Any) -> mjx.Data | None:
    """The first Data in a pytree (a task's load-time template; None if it holds none)."""
    found = [x for x in jax.tree.leaves(tree, is_leaf=lambda x: isinstance(x, mjx.Data)) if isinstance(x, mjx.Data)]
    return found[0] if found else None
