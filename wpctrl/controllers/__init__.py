"""Controllers: the ManiSkill-shaped API over one control mode's device engine.

:mod:`.base` (joint controllers, the combined controller), :mod:`.ee` (end-effector controllers), :mod:`.impedance`
(operational-space and joint-impedance controllers), :mod:`.actuation` (per-env drive properties, delay and effort
readout), :mod:`.inputs` (action and env-id conversion), :mod:`.build` (``build_controller``).
"""

from .base import (
    BaseController,
    CombinedController,
    JointEffortController,
    PassiveController,
    PDBaseForwardVelController,
    PDBaseVelController,
    PDJointPosController,
    PDJointPosMimicController,
    PDJointPosVelController,
    PDJointVelController,
)
from .build import build_controller
from .ee import PDEEPosController, PDEEPoseController
from .impedance import JointImpedanceController, OperationalSpaceController

__all__ = [
    "BaseController",
    "CombinedController",
    "JointEffortController",
    "JointImpedanceController",
    "OperationalSpaceController",
    "PDBaseForwardVelController",
    "PDBaseVelController",
    "PDEEPosController",
    "PDEEPoseController",
    "PDJointPosController",
    "PDJointPosMimicController",
    "PDJointPosVelController",
    "PDJointVelController",
    "PassiveController",
    "build_controller",
]
