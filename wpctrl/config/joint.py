"""Host-side joint-controller configs that mirror ManiSkill 3's dataclasses.

Class names, field names, field order and defaults are ManiSkill's, so a ManiSkill control-mode dict ports by
changing an import. This module never touches a device.

Each config class declares its controller class and its family (:mod:`.family`: the rows of
:mod:`.joint_rows`).

Units: positions in rad (revolute) or m (prismatic), velocities in rad/s or m/s, stiffness in N·m/rad (N/m),
damping in N·m·s/rad (N·s/m), force limits in N·m (N).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Union

from . import joint_rows
from .actuator_models import ActuatorNet, DCMotor, PositionBasedEffortLimit
from .family import ControllerClass, ControllerConfig, Family
from .validate import DriveMode

Actuator = Union[DCMotor, PositionBasedEffortLimit, ActuatorNet]


@dataclass
class PDJointPosControllerConfig(ControllerConfig):
    controller_cls = ControllerClass("wpctrl.controllers.joint", "PDJointPosController")
    family = Family(joint_rows.position_rows)

    lower: Union[None, float, Sequence[float]]
    """Lower action bound [rad or m] (a delta bound with ``use_delta``); None takes the joint's lower limit."""
    upper: Union[None, float, Sequence[float]]
    """Upper action bound [rad or m]; None takes the joint's upper limit."""
    stiffness: Union[float, Sequence[float]]
    """Drive stiffness Kp [N·m/rad or N/m]."""
    damping: Union[float, Sequence[float]]
    """Drive damping Kd [N·m·s/rad or N·s/m]."""
    force_limit: Union[float, Sequence[float]] = 1e10
    """Drive effort limit [N·m or N]."""
    friction: Union[float, Sequence[float]] = 0.0
    """Joint friction [N·m or N], written to ``Model.joint_friction``."""
    use_delta: bool = False
    """Action is a delta: added to the measured position (or to the virtual target with ``use_target``)."""
    use_target: bool = False
    """With ``use_delta``: accumulate deltas on the previous (virtual) target instead of the measured position."""
    interpolate: bool = False
    """Ramp the drive target linearly from the measured position to the target over the control step's substeps."""
    normalize_action: bool = True
    """Action in [-1, 1] is clipped, then mapped affinely onto [lower, upper]."""
    drive_mode: Union[Sequence[DriveMode], DriveMode] = "force"
    """"force" or "acceleration", for all joints or per joint."""
    # Beyond ManiSkill (keyword-only: ManiSkill's positional fields keep their order in every subclass).
    actuator: Actuator | None = field(default=None, kw_only=True)
    """An actuator model that limits or replaces the PD torque (explicit actuation): :class:`wpctrl.DCMotor`,
    :class:`wpctrl.PositionBasedEffortLimit` or :class:`wpctrl.ActuatorNet`; None: ManiSkill's clamp to
    ``force_limit``."""
    ema: float | None = field(default=None, kw_only=True)
    """Action smoothing 0 < alpha <= 1 (Isaac Lab's ``EMAJointPositionToLimitsAction``): each commanding joint's
    target becomes ``alpha * target + (1 - alpha) * previous target``, clamped to the joint's limits; a reset sets the
    previous target to the measured position. None: off."""
    binary: bool = field(default=False, kw_only=True)
    """A binary command (Isaac Lab's ``BinaryJointPositionAction``): one action column whose sign picks the target,
    ``upper`` (open) for ``a >= 0`` and ``lower`` (close) for ``a < 0``, for every commanding joint."""


@dataclass
class PDJointPosMimicControllerConfig(PDJointPosControllerConfig):
    controller_cls = ControllerClass("wpctrl.controllers.joint", "PDJointPosMimicController")
    family = Family(joint_rows.mimic_rows)

    mimic: dict[str, dict[str, float]] = field(default_factory=dict)
    """``{mimic_joint: {"joint": control_joint, "multiplier": 1.0, "offset": 0.0}}``: the mimic joint's target is
    ``target[control] * multiplier + offset``. Empty with two joints: the second joint commands the first."""


@dataclass
class PDJointVelControllerConfig(ControllerConfig):
    controller_cls = ControllerClass("wpctrl.controllers.joint", "PDJointVelController")
    family = Family(joint_rows.velocity_rows)

    lower: Union[float, Sequence[float]]
    """Lower velocity bound [rad/s or m/s]."""
    upper: Union[float, Sequence[float]]
    """Upper velocity bound [rad/s or m/s]."""
    damping: Union[float, Sequence[float]]
    """Drive damping Kd [N·m·s/rad or N·s/m]; stiffness is 0."""
    force_limit: Union[float, Sequence[float]] = 1e10
    """Drive effort limit [N·m or N]."""
    friction: Union[float, Sequence[float]] = 0.0
    """Joint friction [N·m or N]."""
    normalize_action: bool = True
    """Action in [-1, 1] is clipped, then mapped affinely onto [lower, upper]."""
    drive_mode: Union[Sequence[DriveMode], DriveMode] = "force"
    """"force" or "acceleration", for all joints or per joint."""
    actuator: Actuator | None = field(default=None, kw_only=True)
    """An actuator model that limits the PD torque (explicit actuation): :class:`wpctrl.DCMotor` or
    :class:`wpctrl.PositionBasedEffortLimit`; None: ManiSkill's clamp to ``force_limit``."""


@dataclass
class PDJointPosVelControllerConfig(PDJointPosControllerConfig):
    controller_cls = ControllerClass("wpctrl.controllers.joint", "PDJointPosVelController")
    family = Family(joint_rows.pos_vel_rows)

    vel_lower: Union[float, Sequence[float]] = -1.0
    """Lower velocity-target bound [rad/s or m/s]."""
    vel_upper: Union[float, Sequence[float]] = 1.0
    """Upper velocity-target bound [rad/s or m/s]."""


@dataclass
class JointEffortControllerConfig(ControllerConfig):
    """Direct effort control (not in ManiSkill): the action, clipped and scaled as the joint configs do, is the joint
    effort [N·m or N], written to ``Control.joint_f`` before every substep (clamped to ``force_limit``); the joint's
    built-in drive is off (gains 0, target mode EFFORT) in both actuations."""

    controller_cls = ControllerClass("wpctrl.controllers.joint", "JointEffortController")
    family = Family(joint_rows.effort_rows)

    lower: Union[float, Sequence[float]]
    """Lower effort bound [N·m or N]."""
    upper: Union[float, Sequence[float]]
    """Upper effort bound [N·m or N]."""
    normalize_action: bool = True
    """Action in [-1, 1] is clipped, then mapped affinely onto [lower, upper]."""
    force_limit: Union[float, Sequence[float]] = 1e10
    """Effort limit [N·m or N] applied to the commanded effort."""
    friction: Union[float, Sequence[float]] = 0.0
    """Joint friction [N·m or N]."""


@dataclass
class PassiveControllerConfig(ControllerConfig):
    controller_cls = ControllerClass("wpctrl.controllers.joint", "PassiveController")
    family = Family(joint_rows.passive_rows)

    damping: Union[float, Sequence[float]]
    """Damping toward a zero velocity target [N·m·s/rad or N·s/m]; stiffness is 0."""
    force_limit: Union[float, Sequence[float]] = 1e10
    """Drive effort limit [N·m or N]."""
    friction: Union[float, Sequence[float]] = 0.0
    """Joint friction [N·m or N]."""
