"""Mobile-base controller configs (ManiSkill 3's ``pd_base_vel.py``): ego-centric planar velocity control.

Both take the fields of :class:`~wpctrl.config.joint.PDJointVelControllerConfig`. The controller's first three joints
are the base's world-frame x and y (prismatic) and yaw (revolute) joints; the planar part of the action is a velocity
in the base's own frame, rotated into the world frame by the **measured** yaw (the third joint's position at
``set_action``), as ManiSkill does. Host only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ConfigError
from .family import ControllerClass, Family
from .joint import PDJointVelControllerConfig
from .joint_rows import _action_box, _vel_rows
from .rows import Rows
from .validate import _joint_names, _name


def _base_rows(config, forward: bool) -> Rows:
    """Rows of a mobile base: velocity rows whose x / y targets are the planar action rotated by the measured yaw."""
    names = _joint_names(config)
    n = len(names)
    if n < 3 or (forward and n != 3):
        want = "exactly 3 joints" if forward else "at least 3 joints"
        raise ConfigError(
            f"{_name(config)}.joint_names: expected {want} (the base's x, y and yaw joints, in that order), got {n}: "
            f"{names}"
        )
    if forward:
        # ManiSkill's forward base: action [v, w], bounds broadcast to 2 (not one per joint).
        a_lo, a_hi = _action_box(config, 2, ["forward velocity", "yaw rate"])
        rows = _vel_rows(config, bounds=(np.array([a_lo[0], 0, a_lo[1]]), np.array([a_hi[0], 0, a_hi[1]])))
        rows.act_col[:] = [0, -1, 1]
        rows.action_low, rows.action_high, rows.action_dim = a_lo, a_hi, 2
        rows.bx_col[:2] = 0
    else:
        rows = _vel_rows(config)
        rows.bx_col[:2] = 0
        rows.by_col[:2] = 1
    rows.yaw_row[:2] = 2
    rows.base_axis[:2] = [0, 1]
    return rows


@dataclass
class PDBaseVelControllerConfig(PDJointVelControllerConfig):
    """Ego-centric base velocity: action ``[vx, vy, w, ...]`` (one column per joint, bounds per joint, as
    PDJointVel); velocity targets ``[c vx - s vy, s vx + c vy, w, ...]`` with ``c, s = cos, sin`` of the measured yaw
    [rad/s or m/s]."""

    controller_cls = ControllerClass("wpctrl.controllers.mobile_base", "PDBaseVelController")
    family = Family(lambda config, qlimits: _base_rows(config, forward=False))


@dataclass
class PDBaseForwardVelControllerConfig(PDJointVelControllerConfig):
    """Forward-only ego-centric base velocity: action ``[v, w]`` (``lower``/``upper`` broadcast to 2 values);
    velocity targets ``[c v, s v, w]`` of the base's x, y and yaw joints (exactly 3 joints)."""

    controller_cls = ControllerClass("wpctrl.controllers.mobile_base", "PDBaseForwardVelController")
    family = Family(lambda config, qlimits: _base_rows(config, forward=True))
