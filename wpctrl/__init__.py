"""wpctrl: ManiSkill 3's joint and end-effector controllers as Warp kernels on Newton's arrays, for many envs.

Public import path: ``import wpctrl``.
"""

from typing import TYPE_CHECKING

from .config import (
    Actuation,
    ActuatorNet,
    ConfigError,
    ControllerConfig,
    ControllerOptions,
    DCMotor,
    Delay,
    Diagnostics,
    JointEffortControllerConfig,
    JointImpedanceControllerConfig,
    MimicJointError,
    OperationalSpaceControllerConfig,
    PassiveControllerConfig,
    PDBaseForwardVelControllerConfig,
    PDBaseVelControllerConfig,
    PDEEPosControllerConfig,
    PDEEPoseControllerConfig,
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointPosVelControllerConfig,
    PDJointVelControllerConfig,
    PositionBasedEffortLimit,
)

# The controllers (which import newton, ~4 s) load on first use, so that ``python -m wpctrl demo`` can say what it is
# doing before the heavy imports and kernel compilation start.
_LAZY = set(
    "BaseController CombinedController JointEffortController JointImpedanceController OperationalSpaceController "
    "PassiveController PDBaseForwardVelController PDBaseVelController PDEEPosController PDEEPoseController "
    "PDJointPosController PDJointPosMimicController PDJointPosVelController PDJointVelController "
    "build_controller".split()
)

if TYPE_CHECKING:
    from .controllers import (
        BaseController,
        CombinedController,
        JointImpedanceController,
        OperationalSpaceController,
        PassiveController,
        PDBaseForwardVelController,
        PDBaseVelController,
        PDEEPosController,
        PDEEPoseController,
        PDJointPosController,
        PDJointPosMimicController,
        PDJointPosVelController,
        PDJointVelController,
        build_controller,
    )


def __getattr__(name: str):
    if name == "distributed":  # wpctrl.distributed: torchrun helpers (torch imported only under torchrun)
        import importlib

        return importlib.import_module(".distributed", __name__)
    if name in _LAZY:
        from . import controllers

        return getattr(controllers, name)
    raise AttributeError(f"module 'wpctrl' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | _LAZY | {"distributed"})


__version__ = "0.1.0"

__all__ = [
    "Actuation",
    "ActuatorNet",
    "BaseController",
    "CombinedController",
    "ConfigError",
    "ControllerConfig",
    "ControllerOptions",
    "DCMotor",
    "Delay",
    "Diagnostics",
    "JointEffortController",
    "JointEffortControllerConfig",
    "JointImpedanceController",
    "JointImpedanceControllerConfig",
    "MimicJointError",
    "OperationalSpaceController",
    "OperationalSpaceControllerConfig",
    "PDBaseForwardVelController",
    "PDBaseForwardVelControllerConfig",
    "PDBaseVelController",
    "PDBaseVelControllerConfig",
    "PDEEPosController",
    "PDEEPosControllerConfig",
    "PDEEPoseController",
    "PDEEPoseControllerConfig",
    "PDJointPosController",
    "PDJointPosControllerConfig",
    "PDJointPosMimicController",
    "PDJointPosMimicControllerConfig",
    "PDJointPosVelController",
    "PDJointPosVelControllerConfig",
    "PDJointVelController",
    "PDJointVelControllerConfig",
    "PassiveController",
    "PassiveControllerConfig",
    "PositionBasedEffortLimit",
    "build_controller",
]
