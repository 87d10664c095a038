"""Robot models built in code, and ManiSkill's control-mode dicts for them: :mod:`.panda_model` (the Panda from its URDF
numbers, no file read at run time) and :mod:`.panda_modes` (ManiSkill's Panda control modes)."""

from .panda_model import (
    PANDA_ARM_JOINTS,
    PANDA_BODIES,
    PANDA_FRAMES,
    PANDA_GRIPPER_JOINTS,
    PANDA_INITIAL_Q,
    PANDA_JOINTS,
    PANDA_REST_QPOS,
    panda,
)
from .panda_modes import PANDA_CONTROL_MODES, panda_control_modes

__all__ = [
    "PANDA_ARM_JOINTS",
    "PANDA_BODIES",
    "PANDA_CONTROL_MODES",
    "PANDA_FRAMES",
    "PANDA_GRIPPER_JOINTS",
    "PANDA_INITIAL_Q",
    "PANDA_JOINTS",
    "PANDA_REST_QPOS",
    "panda",
    "panda_control_modes",
]
