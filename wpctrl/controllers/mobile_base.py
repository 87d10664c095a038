"""Mobile-base controller classes (ManiSkill's ``pd_base_vel.py``): ego-centric planar velocity control; the configs
are :mod:`wpctrl.config.mobile_base`.
"""

from __future__ import annotations

from .joint import PDJointVelController


class PDBaseVelController(PDJointVelController):
    """Ego-centric base velocity (ManiSkill's PDBaseVelController): the action's ``[vx, vy]`` is rotated by the
    measured yaw (the third joint's position at ``set_action``) into the world frame of the base's x / y joints."""


class PDBaseForwardVelController(PDJointVelController):
    """Forward-only ego-centric base velocity (ManiSkill's PDBaseForwardVelController): action ``[v, w]``, velocity
    targets ``[v cos(yaw), v sin(yaw), w]`` with the measured yaw."""
