"""mjzoo and other ecosystems.

    brax   an mjzoo Task as a Brax `Env`, so Brax's trainers run on it
           (``mjzoo.interop.brax.to_brax_env``)

Each module imports the other library only when it is loaded, so the core never needs it.
"""

from mjzoo.interop import brax

__all__ = ["brax"]
