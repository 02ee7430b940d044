"""Motion references: recorded trajectories a policy should move like.

    clips        the `Clip` type and its .npz file format (`save`, `load_file`)
"""

from mjzoo.motion.clips import Clip, load_file, save

__all__ = ["Clip", "load_file", "save"]
