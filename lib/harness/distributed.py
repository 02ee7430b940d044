"""Training on several hosts: one process per host (or per accelerator), joined by
`jax.distributed`. Every process runs the same program; `mjzoo.harness.devices` splits
the env batch over the devices of all of them, and only process 0 writes files.

    from mjzoo.harness import distributed
    distributed.initialize("10.0.0.1:1234", num_processes=2, process_id=0)  # first, before any JAX computation
    distributed.initialize()  # or from the environment (below); False: one process, nothing done

Where the arguments are not given, the environment says: JAX_COORDINATOR_ADDRESS (read
by JAX itself), JAX_NUM_PROCESSES and JAX_PROCESS_ID, or a launcher that JAX
recognizes starting several processes (SLURM's srun, Open MPI's mpirun), whose
missing values JAX then fills in. A single process (no argument, no such variable) is
left alone: a one-task SLURM job runs as before.

On CPUs the processes exchange data through Gloo (JAX's default), so a run can be
tried on one machine: tests/harness/test_distributed.py trains two processes on
localhost. `barrier`, `agree` and `fetch` keep the training loop in step: every process
must call them alike (with one process they cost nothing).
"""

from __future__ import annotations

import os
import socket
from typing import Any

import jax
import numpy as np
from jax.experimental import multihost_utils

__all__ = ["initialize", "is_primary", "barrier", "agree", "fetch", "free_port"]

# Each argument's environment variable (JAX reads the first itself, but not the others).
_VARIABLES = {
    "coordinator": "JAX_COORDINATOR_ADDRESS",
    "num_processes": "JAX_NUM_PROCESSES",
    "process_id": "JAX_PROCESS_ID",
}


def initialize(
    coordinator: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
    local_device_ids: int | list[int] | None = None,
) -> bool:
    """Joins this process to a multi-process run (`jax.distributed.initialize`) when the
    arguments or the environment ask for one; returns whether this is one (True also
    when JAX was already initialized so, e.g. by an earlier call with the same values).

    Args:
      coordinator: HOST:PORT of process 0, which every process reaches (process 0
        listens on PORT).
      num_processes: how many processes take part (>= 1).
      process_id: this one's number, 0 .. num_processes - 1.
      local_device_ids: which of this host's devices this process uses (default: all).

    Raises:
      ValueError: a malformed or out-of-range value, or only some of the three given
        without a launcher to supply the others (named by argument or variable).
      RuntimeError: JAX has already started on this process's devices alone.
    """
    values: dict[str, Any] = {}
    for name, given in (("coordinator", coordinator), ("num_processes", num_processes), ("process_id", process_id)):
        variable = _VARIABLES[name]
        if given is not None:
            values[name] = _checked(name, given, f"{name}={given!r}")
        elif os.environ.get(variable):
            values[name] = _checked(name, os.environ[variable], f"{variable}={os.environ[variable]!r}")
    launcher = _launcher()
    if not values and launcher is None:
        return jax.distributed.is_initialized()
    if (count := values.get("num_processes")) is not None and values.get("process_id", -1) >= count:
        raise ValueError(
            f"distributed: process_id={values['process_id']} is out of range for "
            f"num_processes={count}: it must be 0 .. {count - 1}"
        )
    if launcher is None and (missing := [n for n in _VARIABLES if n not in values]):
        raise ValueError(
            f"distributed: {' and '.join(missing)} missing; give coordinator, num_processes and "
            f"process_id together (or set {', '.join(_VARIABLES.values())})"
        )
    if jax.distributed.is_initialized():  # idempotent, but not with other values
        now = {"num_processes": jax.process_count(), "process_id": jax.process_index()}
        if clash := [f"{n}={values[n]} (it is {now[n]})" for n in now if n in values and values[n] != now[n]]:
            raise ValueError(f"distributed: already initialized otherwise: {', '.join(clash)}")
        return True
    try:
        jax.distributed.initialize(
            values.get("coordinator"), values.get("num_processes"), values.get("process_id"), local_device_ids
        )
    except RuntimeError as e:
        if "must be called before" not in str(e):
            raise
        raise RuntimeError(
            "distributed: JAX already runs on this process's devices alone; initialize first, "
            "before any JAX computation (jax.devices() included)"
        ) from None
    return True


def _checked(name: str, value: Any, shown: str) -> str | int:
    """`value` (an argument, or a variable's text) as a HOST:PORT or an int, or one ValueError."""
    if name == "coordinator":
        host, colon, port = str(value).rpartition(":")
        if not (colon and host and port.isdigit() and 0 < int(port) < 65536):
            raise ValueError(f"distributed: {shown} is not HOST:PORT (e.g. 10.0.0.1:1234, port 1 .. 65535)")
        return str(value)
    lowest = 1 if name == "num_processes" else 0
    try:
        number = int(value) if isinstance(value, str) else value
    except ValueError:
        number = None
    if isinstance(number, bool) or not isinstance(number, (int, np.integer)) or number < lowest:
        raise ValueError(f"distributed: {shown} must be an int >= {lowest}")
    return int(number)


def _launcher() -> str | None:
    """The launcher that started several processes of this program, as JAX's own cluster
    detection reads it (the variables it needs): "slurm", "ompi", or None."""
    env = os.environ

    def several(name: str) -> bool:
        return env.get(name, "1").isdigit() and int(env.get(name, "1")) > 1

    slurm = ("SLURM_JOB_ID", "SLURM_NODELIST", "SLURM_PROCID", "SLURM_LOCALID")
    if all(v in env for v in slurm) and several("SLURM_NTASKS"):
        return "slurm"
    if "OMPI_MCA_orte_hnp_uri" in env and several("OMPI_COMM_WORLD_SIZE"):
        return "ompi"
    return None


def is_primary() -> bool:
    """Whether this is process 0, the one that writes a run's files and shows progress."""
    return jax.process_index() == 0


def barrier(name: str) -> None:
    """Waits until every process has reached the barrier `name`."""
    if jax.process_count() > 1:
        multihost_utils.sync_global_devices(name)


def agree(value: Any) -> Any:
    """Process 0's `value` (a pytree of scalars or arrays) on every process: a decision
    that reads a clock must come out the same everywhere, or the processes part ways."""
    if jax.process_count() == 1:
        return value
    return jax.tree.map(lambda x: x.item() if np.ndim(x) == 0 else x, multihost_utils.broadcast_one_to_all(value))


def fetch(tree: Any) -> Any:
    """NumPy copies of a pytree's arrays on this host. Arrays split over several
    processes are gathered whole (a collective), replicated ones read locally."""

    def one(x: Any) -> Any:
        if isinstance(x, jax.Array) and not x.is_fully_addressable:
            return multihost_utils.process_allgather(x, tiled=True)
        return jax.device_get(x)  # (process_allgather would stack a local array with the others' copies)

    return jax.tree.map(one, tree)


def free_port(host: str = "") -> int:
    """A TCP port of `host` (default: every interface) no one listens on now, for a
    coordinator on localhost or a viewer (the OS picks one for port 0)."""
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]
