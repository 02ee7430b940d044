"""mjzoo and other ecosystems.

    brax         an mjzoo Task as a Brax `Env`, so Brax's trainers run on it
                 (``mjzoo.interop.brax.to_brax_env``), and any Brax `Env` as an mjzoo
                 Task (``mjzoo.interop.brax.task``)
    playground   a MuJoCo Playground env as an mjzoo Task (``mjzoo.interop.playground.task``;
                 needs ``pip install 'mjzoo[playground]'``)
    export       a trained policy out of JAX: ONNX (``write_onnx``; needs ``pip install
                 'mjzoo[export]'``) or a serialized jax.export artifact (``write_jax``),
                 each carrying its deployment contract; any task's policy from the
                 physics state, its own observation inside (``end_to_end``); ``load``
    deployment   the deployment contract: names, control ranges, the action mapping and the
                 observation as terms computable from ``mujoco.MjData``
    sim2sim      an exported policy driving plain C MuJoCo from its contract
                 (``run_in_mujoco``: commands, latency, pushes, other physics options),
                 scored by the task's own reward (``replay``)
    tracking     a joystick policy's velocity tracking and falls, in the training
                 simulator (``in_task``, ``closed_loop``) and in C MuJoCo (``in_mujoco``)

Each module loads on first use and imports the other library only then, so the core never
needs it.
"""

from mjzoo import lazy

__all__ = ["brax", "playground", "export", "deployment", "sim2sim", "tracking"]

__getattr__, __dir__ = lazy.submodules(__name__, __all__)
