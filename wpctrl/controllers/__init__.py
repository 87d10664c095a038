"""Controllers: the ManiSkill-shaped API over one control mode's device engine.

:mod:`.base_controller` (:class:`BaseController`: the per-step API, the combined controller), :mod:`.joint` (joint
controllers), :mod:`.mobile_base` (mobile-base controllers), :mod:`.ee` (end-effector controllers),
:mod:`.impedance` (operational-space and joint-impedance controllers), :mod:`.drive_properties` (per-env drive
properties, delay and effort readout), :mod:`.inputs` (action and env-id conversion), :mod:`.build`
(``build_controller``).
"""

from .base_controller import BaseController, CombinedController
from .build import build_controller
from .ee import PDEEPosController, PDEEPoseController
from .impedance import JointImpedanceController, OperationalSpaceController
from .joint import (
    JointEffortController,
    PassiveController,
    PDJointPosController,
    PDJointPosMimicController,
    PDJointPosVelController,
    PDJointVelController,
)
from .mobile_base import PDBaseForwardVelController, PDBaseVelController

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
