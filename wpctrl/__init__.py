"""wpctrl: ManiSkill 3's PD joint controllers as Warp kernels on Newton's arrays, for thousands of parallel envs.

Public import path: ``import wpctrl``.
"""

from .config import (
    ConfigError,
    ControllerConfig,
    MimicJointError,
    PassiveControllerConfig,
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointPosVelControllerConfig,
    PDJointVelControllerConfig,
)
from .config_ee import PDEEPosControllerConfig, PDEEPoseControllerConfig
from .controllers import (
    BaseController,
    CombinedController,
    PassiveController,
    PDJointPosController,
    PDJointPosMimicController,
    PDJointPosVelController,
    PDJointVelController,
    build_controller,
)
from .controllers_ee import PDEEPosController, PDEEPoseController

__version__ = "0.1.0"

__all__ = [
    "BaseController",
    "CombinedController",
    "ConfigError",
    "ControllerConfig",
    "MimicJointError",
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
    "build_controller",
]
