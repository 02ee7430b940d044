"""Run directories on the command line: refusing an --out that holds a run, reading one
back (config.json, task.json, a checkpoint) and restoring its trained state."""

from __future__ import annotations

import json
from pathlib import Path
from types import ModuleType
from typing import Any
from typing import NamedTuple

import jax

import mjzoo
from mjzoo.harness import checkpoints
from mjzoo.harness import training
from mjzoo.harness.cli.arguments import UsageError
from mjzoo.harness.cli.arguments import algorithm_module
from mjzoo.harness.cli.arguments import as_usage_errors
from mjzoo.harness.cli.arguments import build_algorithm
from mjzoo.harness.cli.arguments import imitated
from mjzoo.harness.cli.arguments import parse_assignments

__all__ = ["Trained", "refuse_existing", "read_run", "load", "restore", "policy_prior"]

# What each file of a run must hold (config.json is `training.run`'s, task.json `mjzoo train`'s).
_KEYS = {"config.json": ("algorithm", "config"), "task.json": ("env", "overrides")}


def refuse_existing(out: Path, markers: tuple[str, ...], hint: str) -> None:
    """Refuses an --out that is a file or holds a run, before anything is written to it."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: is a file, not a directory")
    found = training.existing(out, markers)
    if found:
        raise UsageError(f"--out {out} already holds a run ({', '.join(found)}): {hint}")


def read_run(run: Path, flag: str = "") -> tuple[dict | None, dict]:
    """(task.json or None, config.json) of a run directory, checked complete (a
    checkpoint included) before anything is built from them. A run trained from Python
    (`training.run(ppo.make(config), task, Settings(out_dir=...))`) has no task.json."""
    where = f"{flag}{run}"
    if not run.is_dir():
        raise UsageError(f"{where}: {'not a directory' if run.exists() else 'no such run directory'}")
    if not (run / "config.json").is_file():
        raise UsageError(f"{where}: not a complete run, it has no config.json (training writes one)")
    info = _read_json(run / "config.json", where)
    saved = _read_json(run / "task.json", where) if (run / "task.json").is_file() else None
    if checkpoints.latest_step(run / "checkpoints") is None:
        raise UsageError(f"{where}: not a complete run, it has no checkpoint in {run / 'checkpoints'}")
    return saved, info


def _read_json(path: Path, where: str) -> dict:
    try:
        loaded = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise UsageError(f"{where}: {path.name} is not valid JSON ({e})") from None
    keys = _KEYS[path.name]
    if not isinstance(loaded, dict) or not all(isinstance(loaded.get(k), (str, dict)) for k in keys):
        raise UsageError(f"{where}: {path.name} lacks {' or '.join(keys)} (not written by mjzoo?)")
    return loaded


class Trained(NamedTuple):
    """A run read back for use: its algorithm module, config and hyperparameters, and the
    task to run it on."""

    module: ModuleType
    cfg: Any
    hyperparams: Any
    spec: str
    overrides: dict[str, Any]
    task: mjzoo.Task
    data: tuple[Any, ...] = ()  # what the module takes beside its config (`arguments.imitated`): AMP's reference


def load(run: Path, task: str | None, env_overrides: tuple[str, ...]) -> Trained:
    """RUN's algorithm and config, on the task its task.json names, or --task's instead;
    the saved overrides apply to the run's own task, --env-overrides on top. Raises a
    `UsageError` (call inside `checking`)."""
    saved, info = read_run(run)
    if task is None and saved is None:
        raise UsageError(
            f"{run}: has no task.json (trained from Python?): name its task with --task "
            "ENV_OR_MODULE:FACTORY, and its --env-overrides if it had any"
        )
    spec = task or saved["env"]
    own = saved["overrides"] if saved is not None and saved["env"] == spec else {}
    overrides = {**own, **parse_assignments(env_overrides, "--env-overrides")}
    module = algorithm_module(info["algorithm"])
    saved_values = {**info["config"], **info.get("hyperparams", {})}
    cfg, hyperparams = build_algorithm(module, spec, saved_values, str(run / "config.json"))
    task = mjzoo.envs.make(spec, **overrides)
    return Trained(module, cfg, hyperparams, spec, overrides, task, imitated(module, spec, task, overrides))


def restore(run: Path, trained: Trained) -> Any:
    """The newest intact checkpoint's train state (a one-line warning for each damaged
    newer one; a `UsageError` if none is intact or they hold another network)."""
    template = trained.module.init(trained.cfg, trained.task, *trained.data, trained.hyperparams, jax.random.key(0))
    with as_usage_errors(checkpoints.CheckpointError):
        state, _, _ = checkpoints.restore_newest_intact(run / "checkpoints", like=template)
    return state


def policy_prior(run: Path, task: mjzoo.Task) -> Any:
    """RUN's trained policy (deterministic) and, for PPO, its critic in the task's reward
    units, as a `mjzoo.planning.prior.PolicyPrior` for planning on `task` (whose
    observation the run's networks must take). Raises a `UsageError`."""
    from mjzoo.planning import prior

    trained = load(run, None, ())
    guide = prior.from_learner(trained.module, trained.cfg, trained.task, restore(run, trained))
    obs = jax.eval_shape(lambda: mjzoo.reset(task, jax.random.key(0)).obs)
    try:
        jax.eval_shape(guide.act, obs)
    except (ValueError, TypeError) as e:
        raise UsageError(f"--prior {run}: its policy does not take this task's observation ({e})") from None
    return guide
