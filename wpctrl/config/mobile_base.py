"""Mobile-base controller configs (ManiSkill 3's ``pd_base_vel.py``): ego-centric planar velocity control.

Both take the fields of :class:`~wpctrl.config.joint.PDJointVelControllerConfig`. The controller's first three joints
are the base's world-frame x and y (prismatic) and yaw (revolute) joints; the planar part of the action is a velocity
in the base's own frame, rotated into the world frame by the **measured** yaw (the third joint's position at
``set_action``), as ManiSkill does. Host only.
"""

from __future__ import annotations

from dataclasses import dataclass

from .joint import ControllerClass, PDJointVelControllerConfig


@dataclass
class PDBaseVelControllerConfig(PDJointVelControllerConfig):
    """Ego-centric base velocity: action ``[vx, vy, w, ...]`` (one column per joint, bounds per joint, as
    PDJointVel); velocity targets ``[c vx - s vy, s vx + c vy, w, ...]`` with ``c, s = cos, sin`` of the measured yaw
    [rad/s or m/s]."""

    controller_cls = ControllerClass("wpctrl.controllers.mobile_base", "PDBaseVelController")


@dataclass
class PDBaseForwardVelControllerConfig(PDJointVelControllerConfig):
    """Forward-only ego-centric base velocity: action ``[v, w]`` (``lower``/``upper`` broadcast to 2 values);
    velocity targets ``[c v, s v, w]`` of the base's x, y and yaw joints (exactly 3 joints)."""

    controller_cls = ControllerClass("wpctrl.controllers.mobile_base", "PDBaseForwardVelController")
