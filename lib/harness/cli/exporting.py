"""`mjzoo export`: a trained run's deterministic policy as an ONNX model with its
deployment contract, or as a jax.export artifact from the physics state, the task's own
observation inside (`mjzoo.interop.export`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING
from typing import Annotated
from typing import Any
from typing import Literal

import jax
import jax.numpy as jnp
import tyro

import mjzoo
from mjzoo.harness.cli import runs
from mjzoo.harness.cli.arguments import EnvOverrides
from mjzoo.harness.cli.arguments import Overwrite
from mjzoo.harness.cli.arguments import RunTask
from mjzoo.harness.cli.arguments import UsageError
from mjzoo.harness.cli.arguments import as_usage_errors

if TYPE_CHECKING:
    from mjzoo.interop import export

__all__ = ["export", "policy", "load_run", "SUFFIXES"]

SUFFIXES = {"onnx": ".onnx", "jax": ".jaxexport"}


def policy(module: ModuleType, cfg: Any, task: mjzoo.Task, params: dict[str, Any]) -> export.Deployable:
    """The deterministic policy of PPO or AMP `params` (``module.policy_params(state)``:
    {"policy": network params, "obs_stats": `RunningStats`}) as an `export.Deployable` for one
    observation: `ppo.acting` (the normalization, the network, tanh of the mean, so
    [-1, 1]), the carry explicit. AMP's policy sees the task's own observation; where
    PPO's policy sees the entry ``policy_obs_key`` of a dict observation (an asymmetric
    critic's privileged view beside it), the exported policy takes that entry alone.
    """
    from mjzoo.algorithms import ppo
    from mjzoo.interop import export

    if module.__name__.endswith(".amp"):
        cfg = dataclasses.replace(cfg, policy_obs_key=None, value_obs_key=None)
    elif cfg.policy_obs_key is not None:  # the policy's entry alone, as if it were the whole observation
        stats, key = params["obs_stats"], cfg.policy_obs_key
        params = {**params, "obs_stats": stats.replace(mean=stats.mean[key], var=stats.var[key])}
        cfg = dataclasses.replace(cfg, policy_obs_key=None, value_obs_key=None)
    # With action_dim set, to_controls passes the action through: the output stays in [-1, 1].
    act = ppo.acting(cfg, task.replace(action_dim=task.action_size), params, deterministic=True)
    obs_size = int(jax.tree.leaves(params["obs_stats"].mean)[0].shape[-1])

    def apply(obs: jax.Array, carry: jax.Array | None) -> tuple[jax.Array, jax.Array | None]:
        # The carry is explicit (zeros start an episode), so `start` stays False; deterministic: no key.
        next_carry, action, _ = act(carry if cfg.recurrent else (), obs, jnp.zeros((), bool), None)
        return action, (next_carry if cfg.recurrent else None)

    return export.Deployable(apply, obs_size, task.action_size, cfg.gru_hidden_size if cfg.recurrent else 0)


def load_run(run: Path, task: str | None = None, env_overrides: tuple[str, ...] = ()) -> tuple[runs.Trained, Any]:
    """(run read back on MJX's JAX physics, its newest train state). Raises `UsageError`."""
    with as_usage_errors():
        saved, _ = runs.read_run(run)
        spec = task or (saved or {}).get("env")
        jax_physics = ("impl=jax",) if spec and ":" not in spec else ()  # C and the check replay MJX-JAX states
        trained = runs.load(run, task, (*env_overrides, *jax_physics))
    return trained, runs.restore(run, trained)


def export(
    run: Annotated[Path, tyro.conf.Positional],
    format: Literal["onnx", "jax"] = "onnx",
    out: Path | None = None,
    task: RunTask = None,
    env_overrides: EnvOverrides = (),
    overwrite: Overwrite = False,
) -> None:
    """Export RUN's deterministic policy (PPO or AMP, recurrent ones included) to --out
    (default RUN/policy.onnx or RUN/policy.jaxexport).

    --format onnx: an ONNX model from the observation (jax2onnx; the observation
    normalization inside, a dynamic batch size, a recurrent carry as an input and an
    output) with its deployment contract in its metadata_props: names, control ranges,
    the action mapping, the observation as catalog terms computable from MjData (checked
    against the task's own first), the control and physics steps, PD gains. A task that
    observes with a function of its own has no contract: use --format jax.
    --format jax: any task's policy end to end, a serialized jax.export artifact from
    the physics state (the MjData fields and the task's state entries its observation
    reads, by name) to the task's action, the task's own observation function inside;
    its inputs and outputs described in OUT.json. --task and --env-overrides as for
    `mjzoo eval`. An existing file is replaced only with --overwrite. Needs `pip install
    'mjzoo[export]'` for ONNX.

    Args:
      run: the run's directory (`mjzoo train --out`).
      format: onnx (an ONNX model) or jax (a jax.export artifact).
      out: the file to write; default RUN/policy.onnx or RUN/policy.jaxexport.
    """
    from mjzoo.interop import deployment
    from mjzoo.interop import export as exporting

    out = out or run / f"policy{SUFFIXES[format]}"
    if out.is_dir():
        raise UsageError(f"--out {out}: is a directory; give a file path")
    targets = [out] + ([exporting.sidecar(out)] if format == "jax" else [])
    existing = [str(p) for p in targets if p.exists()]
    if existing and not overwrite:
        raise UsageError(f"{', '.join(existing)} already exists; pass --overwrite to replace it")
    if format == "onnx":
        _need_onnx()
    trained, state = load_run(run, task, env_overrides)
    fn = policy(trained.module, trained.cfg, trained.task, trained.module.policy_params(state))
    source = dict(
        run=str(run),
        env=trained.spec,
        overrides=trained.overrides,
        algorithm=trained.module.__name__,
        step=int(state.updates),
    )
    obs_key = None if trained.module.__name__.endswith(".amp") else trained.cfg.policy_obs_key
    carry = f", carry {fn.carry_size}" if fn.recurrent else ""
    if format == "jax":
        with as_usage_errors():
            e2e = exporting.end_to_end(trained.task, fn, obs_key=obs_key, source=source)
        path = exporting.write_end_to_end(e2e, out, overwrite=overwrite)
        inputs = ", ".join(f"{i['name']} {i['shape'][1:]}" for i in e2e.contract["inputs"])
        print(f"{path}: {trained.spec}, from {inputs} to action [{fn.action_size}]{carry}, the observation inside")
        print(f"inputs and outputs: {exporting.sidecar(path)}")
        return
    with as_usage_errors(deployment.ContractError):
        described = exporting.describe(trained.task, fn, source=source, obs_key=obs_key)
    path = exporting.write_onnx(fn, described, out, overwrite=overwrite)
    obs = described["observation"]
    print(
        f"{path}: {trained.spec}, obs {obs['size']} ({len(obs['terms'])} terms x {obs['history']} frames), "
        f"action {fn.action_size}{carry}; observation layout checked (max error {obs['checked']['max_abs_error']:.2g})"
    )


def _need_onnx() -> None:
    try:
        import jax2onnx  # noqa: F401
        import onnx  # noqa: F401
    except ImportError as e:
        raise UsageError(f"--format onnx needs {e.name}: pip install 'mjzoo[export]'") from None
