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

The contract describes the observation in a small vocabulary of catalog terms, so a
task that observes with a function of its own has none. `end_to_end` exports any
task's policy with its observation inside instead: the task's own step, its physics
replaced by the state given, then the policy and the mapping to the task's action.

    e2e = export.end_to_end(task, policy)     # inputs: the MjData fields (and state entries) the observation reads
    export.write_end_to_end(e2e, "policy.jaxexport")      # a jax.export artifact, its description in .json beside
    out = jax.export.deserialize(data).call({"qpos": [B, nq], ...})   # plain JAX: {"action": [B, A], "obs": ...}

Its inputs are found by tracing the observation: exactly the leaves it reads, by name:
``mjx.Data`` fields as MuJoCo names them (``qpos``, ``site_xpos``, ``sensordata``: C
MuJoCo's ``MjData`` after ``mj_step``, which MJX's step leaves alike), the task's state
entries (``info['goal']``, fed back from the outputs ``next info['goal']``),
``previous_action`` and a recurrent policy's ``carry``.
"""

from __future__ import annotations

import contextlib
import dataclasses
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
from jax.interpreters import partial_eval
from mujoco import mjx

from mjzoo import physics
from mjzoo.interop import deployment
from mjzoo.learning import to_controls
from mjzoo.running import reset
from mjzoo.types import State
from mjzoo.types import Task

__all__ = [
    "Deployable",
    "Loaded",
    "EndToEnd",
    "describe",
    "end_to_end",
    "write_onnx",
    "write_jax",
    "write_end_to_end",
    "inputs_of",
    "load",
    "sidecar",
    "INPUTS",
    "OUTPUTS",
    "END_TO_END",
]

Array = jax.Array
INPUTS, OUTPUTS = ("obs", "carry"), ("action", "next_carry")  # tensor names; the carry only when recurrent
_PREFIX = "mjzoo."
_OPSET = 23
END_TO_END = "mjzoo.end_to_end/1"  # the format of an `end_to_end` artifact's description
PREVIOUS_ACTION, CARRY, NEXT = "previous_action", "carry", "next "


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


# --- end to end: from the physics state to the task's action ------------------------------------------------------


class EndToEnd(NamedTuple):
    """A task's policy from the physics state, its observation inside (`end_to_end`).

    Attributes:
      apply: ``(inputs) -> outputs`` for ONE environment, both dicts of arrays named as
        ``contract["inputs"]`` and ``contract["outputs"]`` list them: outputs ``action``
        [action_size] (the task's action), ``obs`` [obs_size] (the observation the policy
        saw), ``next <entry>`` for each state entry among the inputs, ``next_carry``.
      inputs: each input's shape and dtype, for one environment.
      contract: the JSON-ready description written beside the artifact.
    """

    apply: Callable[[dict[str, Array]], dict[str, Array]]
    inputs: dict[str, jax.ShapeDtypeStruct]
    contract: dict[str, Any]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class _Given(physics.StandIn):
    """Physics whose every substep ends in the given state: the task's step then only observes."""

    model: mjx.Model
    data: mjx.Data

    def substep(self, data: mjx.Data) -> mjx.Data:
        return self.data


def _unguarded_step(inner: Task, model, state: State, action: Array, key: Array) -> State:
    return inner.step(model, state, action, key)


def _unguarded(task: Task) -> Task:
    """`task`'s step without its divergence guard, whose fallback to the previous state would
    make the previous observation and the reward inputs of the observation."""

    def strip(node: Any) -> Any:
        if isinstance(node, Task):
            return node.replace(step=strip(node.step))
        if not isinstance(node, jax.tree_util.Partial):
            return node
        if deployment.function_key(node.func) == "mjzoo.combinators:_guard_step":
            return jax.tree_util.Partial(_unguarded_step, strip(node.args[-1]))
        return jax.tree_util.Partial(node.func, *[strip(arg) for arg in node.args], **node.keywords)

    return strip(task)


def _name(path) -> str:
    return jax.tree_util.keystr(path).removeprefix(".")


def _placeholder(spec: jax.ShapeDtypeStruct) -> Array:
    """A value for a leaf the observation does not read (traced away)."""
    if jax.dtypes.issubdtype(spec.dtype, jax.dtypes.prng_key):
        return jnp.broadcast_to(jax.random.key(0), spec.shape)
    return jnp.zeros(spec.shape, spec.dtype)


def _source(name: str, data_fields: set[str], spec: jax.ShapeDtypeStruct) -> str:
    if name == PREVIOUS_ACTION:
        return "the task action of the previous control step (this artifact's last action); zeros at an episode's start"
    if name == CARRY:
        return "the recurrent policy's carry: zeros at an episode's start, then the output next_carry"
    if name in data_fields:
        field = "" if name.startswith("_impl") else f"; C MuJoCo: MjData.{name} reshaped to {list(spec.shape)}"
        return f"mjx.Data.{name} after the control step's last mjx.step (mj_forward at an episode's start){field}"
    return (
        f"the task's state entry State.{name}: at an episode's start its value after the task's reset, then "
        f"the output '{NEXT}{name}'"
    )


def end_to_end(
    task: Task, policy: Deployable, *, obs_key: str | None = None, source: dict[str, Any] | None = None
) -> EndToEnd:
    """`policy` on `task` from the physics state: the task's own observation (any
    function: no contract's vocabulary involved), then the policy (normalization inside),
    then `mjzoo.learning.to_controls`: the task's action.

    The observation is the task's step with its physics replaced by the state given and
    observation noise off (the divergence guard, which only acts on a non-finite state,
    left out). Its inputs are the leaves that observation reads (found by tracing it,
    once): ``mjx.Data`` fields by name, the task's state entries (``info[...]``, a
    combinator's record) and ``previous_action``; a recurrent policy adds ``carry``. Of a
    dict observation the policy reads the entry `obs_key`. One compile measures the
    control step for ``contract["physics"]``.

    Raises:
      ValueError: the observation (its entry) is not one flat array of the policy's size,
        or the policy's action size is not the task's.
    """
    clean = deployment.without_observation_noise(task)
    shape = jax.eval_shape(lambda key: reset(clean, key), jax.random.key(0))
    observing = _unguarded(clean)
    data_leaves, data_def = jax.tree_util.tree_flatten_with_path(shape.data)
    rest_leaves, rest_def = jax.tree_util.tree_flatten_with_path(shape.replace(data=None))
    names = [_name(p) for p, _ in data_leaves] + [_name(p) for p, _ in rest_leaves] + [PREVIOUS_ACTION]
    specs = [leaf for _, leaf in data_leaves + rest_leaves] + [jax.ShapeDtypeStruct((task.action_size,), jnp.float32)]
    n_data, n_rest = len(data_leaves), len(rest_leaves)

    def observed(leaves: list) -> tuple[Any, State]:
        data = jax.tree.unflatten(data_def, leaves[:n_data])
        state = jax.tree.unflatten(rest_def, leaves[n_data : n_data + n_rest]).replace(data=data)
        after = observing.step(_Given(observing.model, data), state, leaves[-1], jax.random.key(0))
        obs = after.obs
        return (obs.get(obs_key) if isinstance(obs, dict) and obs_key is not None else obs), after

    closed, obs = jax.make_jaxpr(lambda *leaves: observed(list(leaves))[0], return_shape=True)(*specs)
    if not isinstance(obs, jax.ShapeDtypeStruct) or obs.ndim != 1 or obs.shape[0] != policy.obs_size:
        raise ValueError(
            f"export.end_to_end: the task observes {jax.tree.map(lambda x: x.shape, obs)}; the policy takes one "
            f"flat array of {policy.obs_size}"
            + ("; of a dict observation give obs_key (PPO's policy_obs_key)" if isinstance(obs, dict) else "")
        )
    if policy.action_size != task.action_size:
        raise ValueError(
            f"export.end_to_end: the policy gives {policy.action_size} actions; the task takes {task.action_size}"
        )
    _, used = partial_eval.dce_jaxpr(closed.jaxpr, [True] * len(closed.jaxpr.outvars))
    read = {name: spec for name, spec, u in zip(names, specs, used) if u}
    entries = [name for name in names[n_data : n_data + n_rest] if name in read]
    inputs = {**read, **({CARRY: jax.ShapeDtypeStruct((policy.carry_size,), jnp.float32)} if policy.recurrent else {})}

    def apply(given: dict[str, Array]) -> dict[str, Array]:
        leaves = [given[n] if n in read else _placeholder(s) for n, s in zip(names, specs)]
        obs, after = observed(leaves)
        raw, next_carry = policy.apply(obs.astype(jnp.float32), given.get(CARRY))
        after = {_name(p): x for p, x in jax.tree_util.tree_flatten_with_path(after.replace(data=None))[0]}
        out = {"action": to_controls(task, raw), "obs": obs, **{NEXT + e: after[e] for e in entries}}
        return {**out, **({"next_carry": next_carry} if policy.recurrent else {})}

    outputs = {
        "action": jax.ShapeDtypeStruct((task.action_size,), jnp.float32),
        "obs": obs,
        **{NEXT + e: read[e] for e in entries},
        **({"next_carry": inputs[CARRY]} if policy.recurrent else {}),
    }
    data_fields = set(names[:n_data])

    def listed(specs: dict[str, jax.ShapeDtypeStruct], described: bool) -> list[dict[str, Any]]:
        return [
            dict(
                name=n,
                shape=["B", *s.shape],
                dtype=str(s.dtype),
                **({"source": _source(n, data_fields, s)} if described else {}),
            )
            for n, s in specs.items()
        ]

    try:
        to_ctrl = deployment.action_mapping(task)["to_ctrl"]
    except deployment.ContractError as e:
        to_ctrl = dict(type="own", formula=f"the task's own actuator maps the action to ctrl at every substep ({e})")
    contract = dict(
        format=END_TO_END,
        call="jax.export.deserialize(bytearray(file bytes)).call(inputs) -> outputs, dicts of arrays by name, "
        "each with a leading batch axis B",
        inputs=listed(inputs, True),
        outputs=listed(outputs, False),
        model=deployment.model_section(task.mj_model),
        physics=deployment.physics_section(task.mj_model, _control_dt(observing, shape)),
        action=dict(
            size=task.action_size,
            output="the task's action: mjzoo.learning.to_controls of the policy's deterministic output in [-1, 1]",
            to_ctrl=to_ctrl,
        ),
        observation=dict(**({"key": obs_key} if obs_key is not None else {}), size=policy.obs_size),
        policy=dict(recurrent=policy.recurrent, carry_size=policy.carry_size),
        source=dict(source or {}),
    )
    return EndToEnd(apply, inputs, contract)


def _control_dt(task: Task, shape: State) -> float:
    """Seconds per step of `task`, with physics that only advances the time (compiling none)."""
    from mjzoo.planning.native import _Recorder  # the native planner's stand-in, which measures its steps so

    start = jax.tree.map(_placeholder, shape)
    action, key = jnp.zeros(task.action_size), jax.random.key(0)
    return float(jax.jit(lambda: task.step(_Recorder(task.model), start, action, key).data.time - start.data.time)())


def inputs_of(e2e: EndToEnd, state: State, previous_action: Array | None = None, carry: Array | None = None) -> dict:
    """The inputs of `e2e` read from an mjzoo `State` of its task (leading batch axes
    kept): what the deployed side gives it, here taken from MJX."""
    values = {_name(p): leaf for p, leaf in jax.tree_util.tree_flatten_with_path(state.replace(data=None))[0]}
    values.update({_name(p): leaf for p, leaf in jax.tree_util.tree_flatten_with_path(state.data)[0]})
    if PREVIOUS_ACTION in e2e.inputs:
        zeros = jnp.zeros((*jnp.shape(state.data.qpos)[:-1], *e2e.inputs[PREVIOUS_ACTION].shape))
        values[PREVIOUS_ACTION] = zeros if previous_action is None else previous_action
    if CARRY in e2e.inputs:
        values[CARRY] = carry
    return {name: values[name] for name in e2e.inputs}


def write_end_to_end(
    e2e: EndToEnd, path: str | os.PathLike, *, overwrite: bool = False, platforms: tuple[str, ...] = ("cpu", "cuda")
) -> Path:
    """Serializes `e2e`, vmapped over a symbolic batch size B, with `jax.export` (lowered
    for `platforms`) to `path` and its contract to ``<path>.json``. The artifact needs
    JAX alone: ``jax.export.deserialize(...).call({name: [B, ...]})``. Raises
    FileExistsError unless `overwrite`."""
    path = Path(path)
    _refuse([path, sidecar(path)], overwrite)
    (batch,) = jax.export.symbolic_shape("B")
    specs = {n: jax.ShapeDtypeStruct((batch, *s.shape), s.dtype) for n, s in e2e.inputs.items()}
    exported = jax.export.export(jax.jit(jax.vmap(e2e.apply)), platforms=platforms)(specs)
    _atomic(path, bytes(exported.serialize()))
    _atomic(sidecar(path), json.dumps(e2e.contract, indent=1).encode())
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
    if contract.get("format") == END_TO_END:
        return Loaded(_by_name(jax.jit(exported.call), contract["inputs"]), contract, path)

    @jax.jit
    def run(*args):
        out = exported.call(*args)
        return out if isinstance(out, tuple) else (out,)

    return Loaded(_batched(run, contract["policy"]["recurrent"]), contract, path)


def _by_name(run: Callable, inputs: list[dict[str, Any]]) -> Callable:
    """An `end_to_end` artifact's call: a dict of NumPy arrays in ([B, ...], or one
    environment's without B), a dict out; a missing input is named."""

    def act(given: dict[str, Any]) -> dict[str, np.ndarray]:
        missing = [i["name"] for i in inputs if i["name"] not in given]
        if missing:
            raise ValueError(f"this policy also takes {missing}; its inputs: {[i['name'] for i in inputs]}")
        arrays = {i["name"]: np.asarray(given[i["name"]], i["dtype"]) for i in inputs}
        first = inputs[0]
        single = arrays[first["name"]].ndim == len(first["shape"]) - 1
        out = run({n: a[None] if single else a for n, a in arrays.items()})
        return {n: np.asarray(x)[0] if single else np.asarray(x) for n, x in out.items()}

    return act


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
