"""A trained policy out of JAX: an ONNX model or a serialized `jax.export` artifact, each
carrying its deployment contract (`mjzoo.interop.deployment`).

    policy = export.Deployable(apply, obs_size=45, action_size=17)     # apply(obs [k], carry) -> (action [A], carry)
    contract = export.describe(task, policy)                       # checked against the task's own observation
    export.write_onnx(policy, contract, "policy.onnx")             # or write_jax(..., "policy.jaxexport")
    act, contract = export.load("policy.onnx")                     # onnxruntime (or JAX) behind one callable
    action = act(obs)                    # [B, k] -> [B, A];  recurrent: act(obs, carry) -> (action, carry)

`mjzoo export RUN --format onnx|jax` does this for a trained PPO or AMP run
(`mjzoo.harness.cli.exporting`). The exported function is the deterministic policy with
the observation normalization inside it: observation [B, obs_size] float32 in (the batch
size B is dynamic), action [B, action_size] in [-1, 1] out (tanh of the Gaussian's mean);
a recurrent policy also takes its carry [B, carry_size] and returns the next one (zeros
at an episode's start). `contract["action"]` says how the action becomes ctrl.

The ONNX model (written by jax2onnx, opset 23) holds the contract in its metadata_props,
one JSON value per section (``mjzoo.observation``, ``mjzoo.action``, ...); the jax.export
artifact (lowered for CPU and CUDA) has it in a JSON file beside it, ``<path>.json``.
Both need ``pip install 'mjzoo[export]'`` only to be written; running the ONNX model needs
onnxruntime, and running the jax artifact needs JAX alone.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.extend.core import jaxpr_as_fun

from mjzoo.interop import deployment
from mjzoo.types import Task

__all__ = ["Deployable", "Loaded", "describe", "write_onnx", "write_jax", "load", "sidecar", "INPUTS", "OUTPUTS"]

Array = jax.Array
INPUTS, OUTPUTS = ("obs", "carry"), ("action", "next_carry")  # tensor names; the carry only when recurrent
_PREFIX = "mjzoo."
_OPSET = 23


class Deployable(NamedTuple):
    """A deterministic policy for ONE observation, its parameters closed over; exported
    batched (vmapped over a dynamic batch size).

    Attributes:
      apply: ``(obs [obs_size], carry [carry_size] | None) -> (action [action_size],
        next carry [carry_size] | None)``, float32, the normalization inside.
      obs_size, action_size: the flat observation's and the action's lengths.
      carry_size: a recurrent policy's carry length; 0: feed-forward (carry None).
    """

    apply: Callable[[Array, Array | None], tuple[Array, Array | None]]
    obs_size: int
    action_size: int
    carry_size: int = 0

    @property
    def recurrent(self) -> bool:
        return self.carry_size > 0


class Loaded(NamedTuple):
    """An exported policy read back: ``act(obs)`` -> action, or for a recurrent one
    ``act(obs, carry)`` -> (action, next carry), NumPy in and out ([B, ...], or one
    unbatched [k] observation), and its contract (a dict, `describe`'s)."""

    act: Callable[..., Any]
    contract: dict[str, Any]
    path: Path


def describe(
    task: Task,
    policy: Deployable,
    *,
    source: dict[str, Any] | None = None,
    key: Array | None = None,
    check_steps: int = 8,
    obs_key: str | None = None,
) -> dict[str, Any]:
    """The deployment contract of `policy` on `task`: model names and ranges, physics
    timing, the observation layout, the action mapping, the policy's inputs and outputs.

    The layout is checked: `check_steps` transitions from a reset (random actions) run in
    MJX, and the observation rebuilt from each state by `contract.frame` must equal the
    task's own (one compile of the task's transition). The measured control step fills
    ``physics.control_dt``. Of a dict observation the policy reads the entry `obs_key`
    (PPO's ``policy_obs_key``), which the contract describes.

    Raises:
      contract.ContractError: a term the vocabulary cannot describe, a dict observation
        without `obs_key`, or a layout that does not reproduce the task's observation (naming the terms).
      ValueError: the policy's sizes differ from the task's.
    """
    terms = deployment.observation_terms(task)
    check = deployment.check_observation(task, terms, jax.random.key(0) if key is None else key, check_steps, obs_key)
    size = check.history * deployment.frame_size(terms)
    if (policy.obs_size, policy.action_size) != (size, task.action_size):
        raise ValueError(
            f"export.describe: the policy takes {policy.obs_size} observations and gives "
            f"{policy.action_size} actions; the task has {size} and {task.action_size}"
        )
    observation = dict(
        **({"key": obs_key} if obs_key is not None else {}),
        size=size,
        frame_size=deployment.frame_size(terms),
        history=check.history,
        history_order="newest first; every frame is the first one at an episode's start",
        normalization="inside the model",
        terms=terms,
        checked=dict(steps=check_steps, max_abs_error=check.max_error),
    )
    inputs = [dict(name=INPUTS[0], shape=["B", size])]
    outputs = [dict(name=OUTPUTS[0], shape=["B", task.action_size], range=[-1.0, 1.0])]
    if policy.recurrent:
        inputs.append(dict(name=INPUTS[1], shape=["B", policy.carry_size], initial="zeros"))
        outputs.append(dict(name=OUTPUTS[1], shape=["B", policy.carry_size]))
    action = deployment.action_mapping(task)
    action["policy_output"] = "deterministic action in [-1, 1]: tanh of the Gaussian policy's mean"
    return dict(
        format=deployment.FORMAT,
        model=deployment.model_section(task.mj_model),
        physics=deployment.physics_section(task.mj_model, check.control_dt),
        observation=observation,
        action=action,
        policy=dict(recurrent=policy.recurrent, carry_size=policy.carry_size, inputs=inputs, outputs=outputs),
        source=dict(source or {}),
    )


def sidecar(path: str | os.PathLike) -> Path:
    """Where the contract of a jax.export artifact lives: ``<path>.json``."""
    return Path(f"{path}.json")


def _refuse(paths: list[Path], overwrite: bool) -> None:
    existing = [str(p) for p in paths if p.exists()]
    if existing and not overwrite:
        raise FileExistsError(
            f"{', '.join(existing)} already exist{'s' if len(existing) == 1 else ''}; "
            "pass overwrite=True (--overwrite) to replace"
        )


def _specs(policy: Deployable, *batch) -> list[jax.ShapeDtypeStruct]:
    sizes = [policy.obs_size] + ([policy.carry_size] if policy.recurrent else [])
    return [jax.ShapeDtypeStruct((*batch, size), jnp.float32) for size in sizes]


def _flat(policy: Deployable) -> Callable:
    """`policy.apply` as a function of its tensors only: (obs[, carry]) -> action[, next carry]."""

    def fn(obs, carry=None):
        action, next_carry = policy.apply(obs, carry)
        return (action, next_carry) if policy.recurrent else action

    return fn


def write_onnx(
    policy: Deployable, contract: dict[str, Any], path: str | os.PathLike, *, overwrite: bool = False
) -> Path:
    """Converts `policy` to ONNX with jax2onnx (batch dim "B" dynamic), stores `contract`
    in its metadata_props (one JSON value per section, keys ``mjzoo.<section>``) and
    writes it atomically to `path`. Raises FileExistsError unless `overwrite`.

    The policy is traced for one observation here, in plain JAX, and jax2onnx converts
    that jaxpr vmapped: jax2onnx replaces ``jnp.shape`` by a traced op while it traces,
    which Python shape checks in network code cannot take.
    """
    import onnx

    with _quiet("jax2onnx"):  # it logs a warning per optional plugin whose library is absent
        import jax2onnx

    path = Path(path)
    _refuse([path], overwrite)
    one = jax.make_jaxpr(_flat(policy))(*_specs(policy))

    def batched(*tensors):
        outs = jax.vmap(jaxpr_as_fun(one))(*tensors)
        return tuple(outs) if policy.recurrent else outs[0]

    names_in, names_out = INPUTS[: 1 + policy.recurrent], OUTPUTS[: 1 + policy.recurrent]
    with _quiet("jax2onnx"):
        model = jax2onnx.to_onnx(
            batched,
            [("B", s.shape[0]) for s in _specs(policy)],
            model_name="mjzoo_policy",
            opset=_OPSET,
            input_names=list(names_in),
            output_names=list(names_out),
            return_mode="proto",
        )
    del model.metadata_props[:]
    for section, value in contract.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = _PREFIX + section, json.dumps(value)
    model.producer_name = "mjzoo"
    onnx.checker.check_model(model)
    _atomic(path, model.SerializeToString())
    return path


def write_jax(
    policy: Deployable,
    contract: dict[str, Any],
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    platforms: tuple[str, ...] = ("cpu", "cuda"),
) -> Path:
    """Serializes `policy`, vmapped over a symbolic batch size, with `jax.export`
    (lowered for `platforms`) to `path` and its contract to ``<path>.json``. Raises
    FileExistsError unless `overwrite`."""
    path = Path(path)
    _refuse([path, sidecar(path)], overwrite)
    (batch,) = jax.export.symbolic_shape("B")
    exported = jax.export.export(jax.jit(jax.vmap(_flat(policy))), platforms=platforms)(*_specs(policy, batch))
    _atomic(path, bytes(exported.serialize()))
    _atomic(sidecar(path), json.dumps(contract, indent=1).encode())
    return path


@contextlib.contextmanager
def _quiet(logger: str):
    log = logging.getLogger(logger)
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


def _atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def _batched(run: Callable, recurrent: bool) -> Callable:
    """NumPy in and out, an unbatched [k] observation (and [H] carry) allowed."""

    def act(obs, carry=None):
        obs = np.asarray(obs, np.float32)
        single = obs.ndim == 1
        if recurrent and carry is None:
            raise ValueError("this policy is recurrent: call act(obs, carry), carry zeros at an episode's start")
        args = [obs[None] if single else obs]
        if recurrent:
            carry = np.asarray(carry, np.float32)
            args.append(carry[None] if single else carry)
        out = [np.asarray(x) for x in run(*args)]
        out = [x[0] for x in out] if single else out
        return (out[0], out[1]) if recurrent else out[0]

    return act


def load(path: str | os.PathLike) -> Loaded:
    """Reads an exported policy, ONNX (by onnxruntime, on the CPU) or a jax.export
    artifact (by JAX: its ``.json`` contract beside it), as a callable and its contract.

    Raises:
      FileNotFoundError: no such file (or no contract beside a jax artifact).
      ValueError: the file is neither, or carries no mjzoo contract.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"export.load: no such file {path}")
    if path.suffix == ".onnx":
        return _load_onnx(path)
    if not sidecar(path).is_file():
        raise FileNotFoundError(
            f"export.load: {path} is not .onnx, and has no contract beside it ({sidecar(path)}); "
            "expected an ONNX model or a jax.export artifact written by mjzoo"
        )
    contract = json.loads(sidecar(path).read_text())
    try:
        exported = jax.export.deserialize(bytearray(path.read_bytes()))
    except Exception as e:  # noqa: BLE001 (flatbuffers raise assorted errors on foreign bytes)
        raise ValueError(f"export.load: {path} is not a jax.export artifact ({type(e).__name__})") from None

    @jax.jit
    def run(*args):
        out = exported.call(*args)
        return out if isinstance(out, tuple) else (out,)

    return Loaded(_batched(run, contract["policy"]["recurrent"]), contract, path)


def _load_onnx(path: Path) -> Loaded:
    import onnx
    import onnxruntime

    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception as e:  # noqa: BLE001 (protobuf's DecodeError and others)
        raise ValueError(f"export.load: {path} is not an ONNX model ({type(e).__name__})") from None
    contract = {p.key[len(_PREFIX) :]: json.loads(p.value) for p in model.metadata_props if p.key.startswith(_PREFIX)}
    if "policy" not in contract:
        raise ValueError(f"export.load: {path} carries no mjzoo contract in its metadata (not written by mjzoo export)")
    session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    inputs = [i.name for i in session.get_inputs()]
    return Loaded(
        _batched(lambda *args: session.run(None, dict(zip(inputs, args))), contract["policy"]["recurrent"]),
        contract,
        path,
    )
