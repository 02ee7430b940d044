"""The `mjzoo` command line (also `python -m mjzoo`).

    mjzoo envs                    # list the registered tasks and their overrides
    mjzoo demo --steps 200        # random policy on every env, batched, prints returns
    mjzoo train ppo cartpole_balance --out runs/cb --config num_envs=128  # --resume runs/cb goes on
    mjzoo train ppo my_pkg.tasks:make_reach --env-overrides mass=2.0    # your own task factory
    mjzoo eval runs/cb            # reload the checkpoint, evaluate, write a video
    mjzoo eval runs/py --task my_pkg.tasks:make_reach    # a run trained from Python
    mjzoo plan mppi pendulum_swingup --offline  # a sampling planner, closed loop
    mjzoo collect runs/cb --out data/cb --episodes 32  # a dataset of the policy's episodes (or a planner's)
    mjzoo train amp humanoid_amp_walk             # adversarial motion priors: move like a reference
    mjzoo view pendulum_swingup --controls sliders --num-envs 4  # a live browser viewer (also runs, planners, datasets)
    mjzoo export runs/cb --format onnx   # the policy as ONNX (or a jax.export artifact) with its deployment contract
    mjzoo sim2sim runs/g1 --timestep 0.002 --latency 1   # the exported joystick in C MuJoCo: tracking and falls
    mjzoo new my_task --mjcf robot.xml   # my_task.py: a task on your model to start from (my_task:make_task)

Wherever a task is named, ``package.module:factory`` names a function returning a
`mjzoo.Task` (importable from the current directory, as with ``python -m``), and
--env-overrides are its keyword arguments (`mjzoo.envs.make`).

A user's mistake (an unknown env or factory, a bad --config or --env-overrides value, a
missing or incomplete run, an --out that holds a run, only damaged checkpoints) ends the
command with one line on stderr, ``mjzoo COMMAND: what is wrong``, and exit status 2,
before anything is written or (but for checkpoints) compiled. Other exceptions are
bugs, with tracebacks.
"""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
from collections.abc import Iterator

import tyro

from mjzoo.harness import compilation
from mjzoo.harness.cli.arguments import UsageError
from mjzoo.harness.cli.commands import demo
from mjzoo.harness.cli.commands import envs
from mjzoo.harness.cli.commands import evaluate
from mjzoo.harness.cli.commands import plan
from mjzoo.harness.cli.commands import train
from mjzoo.harness.cli.deploying import sim2sim
from mjzoo.harness.cli.exporting import export
from mjzoo.harness.cli.scaffolding import new
from mjzoo.harness.cli.trajectories import collect
from mjzoo.harness.cli.viewing import view

__all__ = [
    "main",
    "demo",
    "envs",
    "train",
    "evaluate",
    "plan",
    "collect",
    "view",
    "export",
    "sim2sim",
    "new",
    "UsageError",
]

COMMANDS = {
    "demo": demo,
    "envs": envs,
    "train": train,
    "eval": evaluate,
    "plan": plan,
    "collect": collect,
    "view": view,
    "export": export,
    "sim2sim": sim2sim,
    "new": new,
}


def main(argv: list[str] | None = None) -> None:
    """Runs one command. A `UsageError` becomes one line `mjzoo COMMAND: message` on
    stderr and exit status 2; tyro reports its own parse errors, also with status 2."""
    args = sys.argv[1:] if argv is None else list(argv)
    command = next((a for a in args if not a.startswith("-")), "")
    if command != "train":  # train's run enables it, after jax.distributed starts (if it does)
        compilation.enable_cache()  # a second launch of the same run skips most compiling
    try:
        with _one_line_warnings(command), _importable_from_cwd():
            tyro.extras.subcommand_cli_from_dict(COMMANDS, prog="mjzoo", args=args)
        sys.stdout.flush()  # a reader that went away shows here, not at exit
    except UsageError as e:
        print(f"mjzoo {command}: {' '.join(str(e).split())}", file=sys.stderr)
        raise SystemExit(2) from None
    except BrokenPipeError:  # `mjzoo envs | head -1`: stop quietly, as Python's docs advise
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the exit's flush writes nowhere
        raise SystemExit(1) from None


@contextlib.contextmanager
def _importable_from_cwd() -> Iterator[None]:
    """The current directory first on sys.path, as `python -m` has it: `mjzoo train ppo
    tasks:make` finds ./tasks.py (the `mjzoo` script alone would not)."""
    cwd = os.getcwd()
    sys.path.insert(0, cwd)
    try:
        yield
    finally:
        sys.path.remove(cwd)


@contextlib.contextmanager
def _one_line_warnings(command: str) -> Iterator[None]:
    """The library's own warnings (e.g. checkpoints.DamagedCheckpointWarning) are news for
    the user: one line each, `mjzoo COMMAND: warning: ...`; others keep Python's format."""
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        if category.__module__.startswith("mjzoo."):
            print(f"mjzoo {command}: warning: {' '.join(str(message).split())}", file=sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = shown
