"""wpctrl's torque-level modes for a ManiSkill arm: operational-space control and joint impedance of the arm of its
end-effector mode, next to the mode's other controllers (gripper, body, base)."""

from __future__ import annotations

import copy

from ..config.ee import PDEEPoseControllerConfig
from ..robots.impedance_modes import impedance_modes

SOURCE_MODE = "pd_ee_delta_pose"
"""The agent's mode the impedance modes are made from (its ``arm``: joints, ``ee_link``, URDF, force limit)."""


def add_impedance_modes(modes: dict) -> dict:
    """Add ``osc_ee_delta_pose``, ``osc_ee_pose`` and ``joint_impedance_delta_pos`` to a ManiSkill agent's modes (as
    wpctrl configs, in place; returns ``modes``) when it has a ``pd_ee_delta_pose`` mode whose ``arm`` names an
    ``ee_link``: the arm becomes the impedance controller (:func:`wpctrl.robots.impedance_modes.impedance_modes`'
    gains, the arm's force limit), every other child is copied. A name the agent defines itself is left alone."""
    src = modes.get(SOURCE_MODE)
    if not isinstance(src, dict) or not isinstance(src.get("arm"), PDEEPoseControllerConfig):
        return modes
    arm = src["arm"]
    if not arm.ee_link:
        return modes
    new = impedance_modes(
        arm.joint_names,
        None,
        ee_link=arm.ee_link,
        urdf_path=arm.urdf_path,
        force_limit=copy.deepcopy(arm.force_limit),
        root_link_name=arm.root_link_name,
    )
    for name, children in new.items():
        if name in modes:
            continue
        modes[name] = {k: (children["arm"] if k == "arm" else copy.deepcopy(v)) for k, v in src.items()}
    return modes
