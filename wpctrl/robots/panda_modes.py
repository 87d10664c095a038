"""ManiSkill's control modes for the Panda (``mani_skill/agents/robots/panda/panda.py``, 3.0.1) as wpctrl configs."""

from __future__ import annotations

import copy

from ..config import (
    ControllerConfig,
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointPosVelControllerConfig,
    PDJointVelControllerConfig,
)
from ..config.ee import PDEEPosControllerConfig, PDEEPoseControllerConfig
from .impedance_modes import impedance_modes
from .panda_model import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS

__all__ = ["PANDA_CONTROL_MODES", "panda_control_modes"]

_ARM_STIFFNESS = 1e3
_ARM_DAMPING = 1e2
_ARM_FORCE_LIMIT = 100
_GRIPPER_STIFFNESS = 1e3
_GRIPPER_DAMPING = 1e2
_GRIPPER_FORCE_LIMIT = 100
_EE_LINK = "panda_hand_tcp"


def panda_control_modes() -> dict[str, dict[str, ControllerConfig]]:
    """ManiSkill 3's Panda control modes, as fresh configs on every call.

    The joint-space modes first, in ManiSkill's relative order: ``pd_joint_delta_pos`` (the default),
    ``pd_joint_pos``, ``pd_joint_target_delta_pos``, ``pd_joint_vel``, ``pd_joint_pos_vel``, ``pd_joint_delta_pos_vel``;
    then the end-effector modes, in ManiSkill's relative order: ``pd_ee_delta_pos``, ``pd_ee_delta_pose``,
    ``pd_ee_pose``, ``pd_ee_target_delta_pos``, ``pd_ee_target_delta_pose``; then wpctrl's torque-level modes
    (not in ManiSkill): ``osc_ee_delta_pose``, ``osc_ee_pose``, ``joint_impedance_delta_pos``
    (:func:`wpctrl.robots.impedance_modes.impedance_modes`: the TCP, force limit 100 [N·m]).
    Each is ``{"arm": <arm config>, "gripper": <gripper config>}``, and every config object is a separate copy.

    EE modes (``ee_link="panda_hand_tcp"``, the site :func:`~wpctrl.robots.panda` keeps; ``urdf_path=None``: a Panda
    loaded with ``add_urdf(collapse_fixed_joints=True)`` needs ``urdf_path`` set to its URDF): delta position bounds
    ±0.1 [m], delta rotation bounds ±0.1 [rad]; ``pd_ee_pose`` takes absolute poses (no bounds, not normalised).

    Arm: stiffness 1e3 [N·m/rad], damping 1e2 [N·m·s/rad], force limit 100 [N·m]; delta bounds ±0.1 [rad], velocity
    bounds ±1 [rad/s]. Gripper (all modes): a mimic position controller on both fingers, bounds [-0.01, 0.04] [m]
    (ManiSkill's "trick to have force when the object is thin"), stiffness 1e3 [N/m], damping 1e2 [N·s/m], force limit
    100 [N], finger 2 mimicking finger 1.

    Returns:
        ``{mode: {"arm": config, "gripper": config}}``.
    """
    arm = PANDA_ARM_JOINTS
    arm_pd_joint_pos = PDJointPosControllerConfig(
        list(arm), None, None, _ARM_STIFFNESS, _ARM_DAMPING, _ARM_FORCE_LIMIT, normalize_action=False
    )
    arm_pd_joint_delta_pos = PDJointPosControllerConfig(
        list(arm), -0.1, 0.1, _ARM_STIFFNESS, _ARM_DAMPING, _ARM_FORCE_LIMIT, use_delta=True
    )
    arm_pd_joint_target_delta_pos = copy.deepcopy(arm_pd_joint_delta_pos)
    arm_pd_joint_target_delta_pos.use_target = True
    arm_pd_joint_vel = PDJointVelControllerConfig(list(arm), -1.0, 1.0, _ARM_DAMPING, _ARM_FORCE_LIMIT)
    arm_pd_joint_pos_vel = PDJointPosVelControllerConfig(
        list(arm), None, None, _ARM_STIFFNESS, _ARM_DAMPING, _ARM_FORCE_LIMIT, normalize_action=False
    )
    arm_pd_joint_delta_pos_vel = PDJointPosVelControllerConfig(
        list(arm), -0.1, 0.1, _ARM_STIFFNESS, _ARM_DAMPING, _ARM_FORCE_LIMIT, use_delta=True
    )
    gripper_pd_joint_pos = PDJointPosMimicControllerConfig(
        list(PANDA_GRIPPER_JOINTS),
        lower=-0.01,
        upper=0.04,
        stiffness=_GRIPPER_STIFFNESS,
        damping=_GRIPPER_DAMPING,
        force_limit=_GRIPPER_FORCE_LIMIT,
        mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}},
    )
    ee = dict(
        stiffness=_ARM_STIFFNESS, damping=_ARM_DAMPING, force_limit=_ARM_FORCE_LIMIT, ee_link=_EE_LINK, urdf_path=None
    )
    arm_pd_ee_delta_pos = PDEEPosControllerConfig(list(arm), pos_lower=-0.1, pos_upper=0.1, **ee)
    arm_pd_ee_delta_pose = PDEEPoseControllerConfig(
        list(arm), pos_lower=-0.1, pos_upper=0.1, rot_lower=-0.1, rot_upper=0.1, **ee
    )
    arm_pd_ee_pose = PDEEPoseControllerConfig(
        list(arm), pos_lower=None, pos_upper=None, use_delta=False, normalize_action=False, **ee
    )
    arm_pd_ee_target_delta_pos = copy.deepcopy(arm_pd_ee_delta_pos)
    arm_pd_ee_target_delta_pos.use_target = True
    arm_pd_ee_target_delta_pose = copy.deepcopy(arm_pd_ee_delta_pose)
    arm_pd_ee_target_delta_pose.use_target = True
    modes = {
        "pd_joint_delta_pos": {"arm": arm_pd_joint_delta_pos, "gripper": gripper_pd_joint_pos},
        "pd_joint_pos": {"arm": arm_pd_joint_pos, "gripper": gripper_pd_joint_pos},
        "pd_joint_target_delta_pos": {"arm": arm_pd_joint_target_delta_pos, "gripper": gripper_pd_joint_pos},
        "pd_joint_vel": {"arm": arm_pd_joint_vel, "gripper": gripper_pd_joint_pos},
        "pd_joint_pos_vel": {"arm": arm_pd_joint_pos_vel, "gripper": gripper_pd_joint_pos},
        "pd_joint_delta_pos_vel": {"arm": arm_pd_joint_delta_pos_vel, "gripper": gripper_pd_joint_pos},
        "pd_ee_delta_pos": {"arm": arm_pd_ee_delta_pos, "gripper": gripper_pd_joint_pos},
        "pd_ee_delta_pose": {"arm": arm_pd_ee_delta_pose, "gripper": gripper_pd_joint_pos},
        "pd_ee_pose": {"arm": arm_pd_ee_pose, "gripper": gripper_pd_joint_pos},
        "pd_ee_target_delta_pos": {"arm": arm_pd_ee_target_delta_pos, "gripper": gripper_pd_joint_pos},
        "pd_ee_target_delta_pose": {"arm": arm_pd_ee_target_delta_pose, "gripper": gripper_pd_joint_pos},
    }
    for name, children in impedance_modes(
        arm, gripper_pd_joint_pos, ee_link=_EE_LINK, force_limit=_ARM_FORCE_LIMIT
    ).items():
        modes[name] = children
    # As ManiSkill's deepcopy_dict: every value is copied on its own, so no two modes share a config object.
    return {mode: {uid: copy.deepcopy(cfg) for uid, cfg in children.items()} for mode, children in modes.items()}


PANDA_CONTROL_MODES: dict[str, dict[str, ControllerConfig]] = panda_control_modes()
"""ManiSkill's Panda control modes (one shared instance; call :func:`panda_control_modes` for copies)."""
