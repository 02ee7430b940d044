"""mjzoo and other ecosystems.

    brax         an mjzoo Task as a Brax `Env`, so Brax's trainers run on it
                 (``mjzoo.interop.brax.to_brax_env``), and any Brax `Env` as an mjzoo
                 Task (``mjzoo.interop.brax.task``)
    playground   a MuJoCo Playground env as an mjzoo Task (``mjzoo.interop.playground.task``;
                 needs ``pip install 'mjzoo[playground]'``)

Each module loads on first use and imports the other library only then, so the core never
needs it.
"""

from mjzoo import lazy

__all__ = ["brax", "playground"]

__getattr__, __dir__ = lazy.submodules(__name__, __all__)
