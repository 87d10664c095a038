"""Controllers: the ManiSkill-shaped API over one control mode's device engine.

:mod:`.base_controller` (:class:`BaseController`: the per-step API, the combined controller), :mod:`.mode` (a control
mode's configs made into one engine through their families), :mod:`.joint` (joint controllers), :mod:`.mobile_base`
(mobile-base controllers), :mod:`.ee` (end-effector controllers), :mod:`.drive_properties` (per-env drive
properties, delay and effort readout), :mod:`.introspection` (the options that run, the joints' indices, the plan),
:mod:`.inputs` (action and env-id conversion), :mod:`.build` (``build_controller``). The operational-space and
joint-impedance controllers live with their family in :mod:`wpctrl.impedance.controllers` (which imports this
package) and are exported here on first use.
"""

import importlib

from .base_controller import BaseController, CombinedController
from .build import build_controller
from .ee import PDEEPosController, PDEEPoseController
from .joint import (
    JointEffortController,
    PassiveController,
    PDJointPosController,
    PDJointPosMimicController,
    PDJointPosVelController,
    PDJointVelController,
)
from .mobile_base import PDBaseForwardVelController, PDBaseVelController

_IMPEDANCE = ("JointImpedanceController", "OperationalSpaceController")


def __getattr__(name: str):
    if name in _IMPEDANCE:
        return getattr(importlib.import_module("wpctrl.impedance.controllers"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
