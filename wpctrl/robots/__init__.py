"""Robot models built in code, and ManiSkill's control-mode dicts for them: :mod:`.panda_model` (the Panda from its URDF
numbers, no file read at run time) and :mod:`.panda_modes` (ManiSkill's Panda control modes)."""

from .panda_model import *  # noqa: F403 (its __all__)
from .panda_model import __all__ as _MODEL_NAMES
from .panda_modes import PANDA_CONTROL_MODES as PANDA_CONTROL_MODES
from .panda_modes import panda_control_modes as panda_control_modes

__all__ = sorted([*_MODEL_NAMES, "PANDA_CONTROL_MODES", "panda_control_modes"])
