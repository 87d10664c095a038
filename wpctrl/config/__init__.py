"""Configs: host dataclasses that mirror ManiSkill 3's controller configs, and the per-joint rows they become.

Never touches a device. :mod:`.errors` (:class:`ConfigError`, :class:`MimicJointError`), :mod:`.family` (what every
config class declares: its controller class and its family, how it becomes rows and which engine part runs it),
:mod:`.joint` (joint controllers) and :mod:`.joint_rows` (their rows), :mod:`.mobile_base` (mobile-base
controllers), :mod:`.ee` (end-effector controllers), :mod:`.actuator_models` (actuator models) and :mod:`.networks`
(actuator network files), :mod:`.options` (the option groups of a control mode), :mod:`.validate` (the per-field
checks), :mod:`.rows` (the flat per-joint tables one kernel launch handles). The operational-space and
joint-impedance configs live with the rest of their controllers in :mod:`wpctrl.impedance` and are exported here too.
"""

from ..impedance.config import IMPEDANCE_CONFIGS, JointImpedanceControllerConfig, OperationalSpaceControllerConfig
from ..impedance.spec import ImpedanceSpec, impedance_rows
from .actuator_models import ActuatorNet, DCMotor, PositionBasedEffortLimit
from .ee import EE_CONFIGS, MAX_EE_DOF, EESpec, PDEEPosControllerConfig, PDEEPoseControllerConfig, ee_rows
from .errors import ConfigError, MimicJointError
from .family import ControllerConfig, Family
from .joint import (
    JointEffortControllerConfig,
    PassiveControllerConfig,
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointPosVelControllerConfig,
    PDJointVelControllerConfig,
)
from .mobile_base import PDBaseForwardVelControllerConfig, PDBaseVelControllerConfig
from .options import Actuation, ControllerOptions, Delay, Diagnostics
from .rows import (
    FLAG_BINARY,
    FLAG_DELTA,
    FLAG_EMA,
    FLAG_INTERPOLATE,
    FLAG_NORMALIZE,
    FLAG_TARGET,
    FLAG_VEL_TARGET,
    ROW_EFFORT,
    ROW_PASSIVE,
    ROW_POS,
    ROW_VEL,
    Rows,
    check_mode_dict,
    config_rows,
    controller_rows,
)
from .validate import DriveMode

__all__ = [
    "Actuation",
    "ControllerOptions",
    "Delay",
    "Diagnostics",
    "ActuatorNet",
    "DCMotor",
    "EE_CONFIGS",
    "FLAG_BINARY",
    "FLAG_EMA",
    "JointEffortControllerConfig",
    "IMPEDANCE_CONFIGS",
    "ImpedanceSpec",
    "JointImpedanceControllerConfig",
    "OperationalSpaceControllerConfig",
    "impedance_rows",
    "PositionBasedEffortLimit",
    "ROW_EFFORT",
    "FLAG_DELTA",
    "FLAG_INTERPOLATE",
    "FLAG_NORMALIZE",
    "FLAG_TARGET",
    "FLAG_VEL_TARGET",
    "MAX_EE_DOF",
    "ROW_PASSIVE",
    "ROW_POS",
    "ROW_VEL",
    "ConfigError",
    "ControllerConfig",
    "DriveMode",
    "EESpec",
    "MimicJointError",
    "PDBaseForwardVelControllerConfig",
    "PDBaseVelControllerConfig",
    "PDEEPosControllerConfig",
    "PDEEPoseControllerConfig",
    "PDJointPosControllerConfig",
    "PDJointPosMimicControllerConfig",
    "PDJointPosVelControllerConfig",
    "PDJointVelControllerConfig",
    "PassiveControllerConfig",
    "Rows",
    "check_mode_dict",
    "config_rows",
    "controller_rows",
    "ee_rows",
    "Family",
]
