"""Torque-level control modes (operational space, joint impedance) for an arm with an end effector, in the shape of
ManiSkill's modes: ``{"arm": <impedance config>, "gripper": <the robot's gripper config>}``.

Used for the Panda's modes (:func:`wpctrl.robots.panda_control_modes`) and for ManiSkill's arms with an ``ee_link``
(:func:`wpctrl.maniskill.load_robot`). The gains are in decoupled units (per unit inertia: [1/s²], [1/s]), so the
same numbers suit arms of any size.
"""

from __future__ import annotations

import copy

from ..impedance.config import JointImpedanceControllerConfig, OperationalSpaceControllerConfig

IMPEDANCE_MODE_NAMES = ("osc_ee_delta_pose", "osc_ee_pose", "joint_impedance_delta_pos")

OSC_STIFFNESS = 200.0
"""[1/s²] task stiffness of the OSC modes on every axis (natural frequency 14 rad/s), critically damped."""
OSC_NULLSPACE_STIFFNESS = 10.0
"""[1/s²] the OSC modes' posture stiffness (the reset pose), critically damped."""
JOINT_STIFFNESS = 400.0
"""[1/s²] joint impedance stiffness (20 rad/s), critically damped, with inertial compensation."""


def impedance_modes(arm_joints, gripper, *, ee_link: str, urdf_path=None, force_limit=100.0, root_link_name=None):
    """``{mode: {"arm": config, "gripper": gripper copy}}`` for ``osc_ee_delta_pose`` (pose increments of ±0.1 m /
    ±0.1 rad from the measured TCP pose per control step), ``osc_ee_pose`` (absolute poses in the root frame, not
    normalised) and ``joint_impedance_delta_pos`` (±0.1 rad from the measured positions).

    OSC: full inertial decoupling, gravity compensation, null-space posture (arms of more than 6 joints). Joint
    impedance: inertial and gravity compensation. ``gripper`` may be None (no gripper child)."""
    arm = list(arm_joints)
    osc = dict(
        stiffness=OSC_STIFFNESS,
        damping_ratio=1.0,
        force_limit=force_limit,
        ee_link=ee_link,
        urdf_path=urdf_path,
        root_link_name=root_link_name,
        nullspace_control="position" if len(arm) > 6 else "none",
        nullspace_stiffness=OSC_NULLSPACE_STIFFNESS,
    )
    modes = {
        "osc_ee_delta_pose": OperationalSpaceControllerConfig(arm, -0.1, 0.1, -0.1, 0.1, **osc),
        "osc_ee_pose": OperationalSpaceControllerConfig(
            arm, None, None, None, None, use_delta=False, normalize_action=False, **osc
        ),
        "joint_impedance_delta_pos": JointImpedanceControllerConfig(
            arm, -0.1, 0.1, JOINT_STIFFNESS, use_delta=True, force_limit=force_limit, inertial_compensation=True
        ),
    }
    out = {}
    for name, cfg in modes.items():
        out[name] = {"arm": cfg}
        if gripper is not None:
            out[name]["gripper"] = copy.deepcopy(gripper)
    return out
