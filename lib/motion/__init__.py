"""Motion references: recorded trajectories a policy should move like.

Clips are host data (numpy) checked against the MuJoCo model they were recorded for;
a `Reference` is a JAX pytree, every clip resampled to a task's control step, that AMP
is given (`amp.make(config, reference)`), not the task. AMP's discriminator, reference-state initialization
(`mjzoo.catalog.resets.reference_state`) and style measures read it.

    clips        the `Clip` type and its .npz file format (`save`, `load_file`)
    checking     `check` a clip against a model, `load` a checked clip, velocities from positions
    resampling   `resample` to another frame rate (linear, slerp for quaternions)
    references   the `Reference` pytree, `reference`, `sample_frame`, `frames`, `check_reference`
    formats      public formats: IsaacLab humanoid-AMP .npz (`isaaclab_npz`)
    deepmimic_format    DeepMimic's motion text files (`deepmimic_format.load`), y-up to z-up
    measures     style measures: `nearest_window_error`
    retarget     a clip onto another character (a human's onto a robot) by inverse
                 kinematics with mink, and its quality (loaded on first use: needs mink,
                 ``pip install 'mjzoo[mocap]'``)
"""

from mjzoo import lazy
from mjzoo.motion import checking
from mjzoo.motion import clips
from mjzoo.motion import deepmimic_format
from mjzoo.motion import formats
from mjzoo.motion import measures
from mjzoo.motion import references
from mjzoo.motion import resampling
from mjzoo.motion.checking import check
from mjzoo.motion.checking import load
from mjzoo.motion.checking import velocities_from_positions
from mjzoo.motion.clips import Clip
from mjzoo.motion.clips import load_file
from mjzoo.motion.clips import save
from mjzoo.motion.formats import isaaclab_npz
from mjzoo.motion.measures import nearest_window_error
from mjzoo.motion.references import Reference
from mjzoo.motion.references import check_reference
from mjzoo.motion.references import frame_index
from mjzoo.motion.references import frames
from mjzoo.motion.references import reference
from mjzoo.motion.references import sample_frame
from mjzoo.motion.resampling import resample
from mjzoo.motion.resampling import slerp

__all__ = [
    "Clip",
    "Reference",
    "check",
    "check_reference",
    "checking",
    "clips",
    "deepmimic_format",
    "formats",
    "frame_index",
    "frames",
    "isaaclab_npz",
    "load",
    "load_file",
    "measures",
    "nearest_window_error",
    "reference",
    "references",
    "resample",
    "resampling",
    "retarget",
    "sample_frame",
    "save",
    "slerp",
    "velocities_from_positions",
]

__getattr__, __dir__ = lazy.submodules(__name__, ("retarget",))
