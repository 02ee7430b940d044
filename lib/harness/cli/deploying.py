"""`mjzoo sim2sim`: a run's exported policy in C MuJoCo under another simulation
configuration, its velocity tracking and falls beside the training simulator's
(`mjzoo.interop.tracking`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import jax
import tyro

from mjzoo.harness.cli.arguments import EnvOverrides
from mjzoo.harness.cli.arguments import Overwrite
from mjzoo.harness.cli.arguments import RunTask
from mjzoo.harness.cli.arguments import UsageError
from mjzoo.harness.cli.arguments import as_usage_errors
from mjzoo.harness.cli.exporting import load_run
from mjzoo.harness.cli.exporting import policy

__all__ = ["sim2sim"]


def sim2sim(
    run: Annotated[Path, tyro.conf.Positional],
    policy_file: Annotated[Path | None, tyro.conf.arg(name="policy")] = None,
    episodes: int = 4,
    seconds: float = 20.0,
    timestep: float | None = None,
    iterations: int | None = None,
    ls_iterations: int | None = None,
    latency: int = 1,
    push: float = 0.5,
    seed: int = 0,
    out: Path | None = None,
    overwrite: Overwrite = False,
    task: RunTask = None,
    env_overrides: EnvOverrides = (),
) -> None:
    """Drive RUN's exported ONNX policy (--policy, default RUN/policy.onnx: `mjzoo export
    RUN` writes it) in C MuJoCo for --episodes episodes of --seconds, its observation
    built from MjData as a robot builds it (gyro, gravity, encoders, its last action, the
    command), at the training control rate but with the physics --timestep, --iterations
    and --ls-iterations given, actions --latency control steps late and velocity pushes
    of up to --push m/s; commands drawn from the task's ranges. The same policy runs as
    many episodes in the training simulator (MJX, the task's own noise, randomization and
    pushes). Prints the tracking errors and falls of both and writes them to --out
    (default RUN/sim2sim.json; an existing file only with --overwrite). For tasks with a
    velocity command (the joysticks).

    Args:
      run: the run's directory (`mjzoo train --out`).
      policy_file: the exported ONNX policy; default RUN/policy.onnx.
      episodes: episodes in each simulator.
      seconds: simulated seconds per episode.
      timestep: C MuJoCo's physics step in seconds; default: the task's.
      iterations: C MuJoCo's solver iterations; default: the task's.
      ls_iterations: C MuJoCo's line-search iterations; default: the task's.
      latency: control steps between an observation and its action.
      push: largest velocity push, in m/s.
      seed: the random seed of the commands and pushes.
      out: the JSON report; default RUN/sim2sim.json.
    """
    from mjzoo.interop import tracking

    policy_file = policy_file or run / "policy.onnx"
    out = out or run / "sim2sim.json"
    if not policy_file.is_file():
        raise UsageError(f"{policy_file}: no exported policy; run `mjzoo export {run}` first (or pass --policy)")
    if out.exists() and not overwrite:
        raise UsageError(f"{out} already exists; pass --overwrite to replace it")
    for name, value, low in (("episodes", episodes, 1), ("latency", latency, 0)):
        if value < low:
            raise UsageError(f"--{name} {value}: must be >= {low}")
    if seconds <= 0 or push < 0 or (timestep is not None and timestep <= 0):
        raise UsageError("--seconds and --timestep must be > 0 and --push >= 0")
    from mjzoo.interop import export

    with as_usage_errors():
        loaded = export.load(policy_file)
    if loaded.contract.get("format") == export.END_TO_END:
        raise UsageError(
            f"{policy_file}: an end-to-end artifact (--format jax); sim2sim gives a joystick its command "
            f"through the ONNX contract: run `mjzoo export {run} --format onnx`"
        )
    trained, state = load_run(run, task, env_overrides)
    if tracking.velocity_command(trained.task) is None:
        raise UsageError(f"{trained.spec}: its task has no velocity command; sim2sim measures a joystick's tracking")
    deployable = policy(trained.module, trained.cfg, trained.task, trained.module.policy_params(state))
    contract = loaded.contract
    key = jax.random.key(seed)
    trained_sim = tracking.in_task(
        trained.task,
        lambda obs: deployable.apply(obs, None)[0],
        key,
        num_envs=episodes,
        seconds=seconds,
        control_dt=contract["physics"]["control_dt"],
        obs_key=contract["observation"].get("key"),
    )
    options = dict(timestep=timestep, iterations=iterations, ls_iterations=ls_iterations)
    with as_usage_errors():
        deployed = tracking.in_mujoco(
            loaded, trained.task, episodes=episodes, seconds=seconds, seed=seed, latency=latency, push=push, **options
        )
    physics = contract["physics"]
    c_options = {
        "timestep": timestep or physics["physics_dt"],
        "iterations": iterations or physics["iterations"],
        "ls_iterations": ls_iterations or physics["ls_iterations"],
        "latency": latency,
        "push": push,
    }
    ratio = {k: getattr(deployed, k) / max(getattr(trained_sim, k), 1e-9) for k in ("linear_error", "yaw_error")}
    report = dict(
        run=str(run),
        env=trained.spec,
        policy=str(policy_file),
        training=trained_sim.summary(),
        mujoco=dict(deployed.summary(), options=c_options),
        ratio=ratio,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"{trained.spec}: {episodes} episodes of {seconds:g} s each")
    print(f"{'':28s} {'|v_xy - cmd| m/s':>17s} {'|w_z - cmd| rad/s':>18s} {'falls':>6s}")
    for label, t in (("training simulator (MJX)", trained_sim), ("C MuJoCo", deployed)):
        print(f"{label:28s} {t.linear_error:17.3f} {t.yaw_error:18.3f} {t.falls:4d}/{t.episodes}")
    print(f"{'ratio C / MJX':28s} {ratio['linear_error']:17.2f} {ratio['yaw_error']:18.2f}")
    print(f"C MuJoCo options: {', '.join(f'{k}={v}' for k, v in c_options.items())}; report: {out}")
