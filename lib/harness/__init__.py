"""Running experiments: what turns the pure pieces into runs with files on disk.

    training      the host loop over jitted chunks of an RL algorithm's updates:
                  progress, evaluation, metrics, checkpoints, curves, video
    settings      how a run is driven: evaluation, logging and video schedules
    devices       the env batch split over the devices (of every process), the rest replicated
    distributed   several processes (hosts): jax.distributed set-up, process 0 writes
    compilation   the persistent compilation cache; compiling ahead in the background
    metrics       metrics.jsonl and TensorBoard writers, the progress bar
    checkpoints   atomic orbax checkpoints that resume exactly
    plotting      learning curves from metrics.jsonl
    rendering     MuJoCo frames and MP4 videos of trajectories
    render_config RenderConfig: how every video, image and curve is drawn
    plan_report   summary.json, plan.png and plan.mp4 of a planning run
    datasets      a policy's or a planner's recorded episodes on disk, with one
                  motion clip per episode (the references AMP imitates)
    viewer        a live browser viewer (viser) of tasks, policies, planners and
                  recordings, with sliders on the task's numbers
    cli           the `mjzoo` command: the application on top, the one module of the
                  package that reaches up to `mjzoo.envs` and `mjzoo.algorithms`

Submodules load on first use: ``mjzoo.harness.training`` imports orbax,
TensorBoard and matplotlib, which a planner on a robot does not need.
"""

from mjzoo import lazy

MODULES = (
    "training",
    "settings",
    "devices",
    "distributed",
    "compilation",
    "metrics",
    "checkpoints",
    "plotting",
    "rendering",
    "render_config",
    "plan_report",
    "datasets",
    "viewer",
    "cli",
)

__all__ = list(MODULES)

__getattr__, __dir__ = lazy.submodules(__name__, MODULES)
