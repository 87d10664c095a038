"""Joint controller classes (ManiSkill's ``pd_joint_pos.py``, ``pd_joint_vel.py``, ``pd_joint_pos_vel.py``,
``passive_controller.py``, and a direct effort controller): what each adds to :class:`~.base_controller.BaseController`
is which targets it sets and the views it offers.
"""

from __future__ import annotations

import warp as wp

from .base_controller import BaseController


class PDJointPosController(BaseController):
    """Position targets: absolute, delta from the measured position, or delta on a virtual target."""

    sets_target_qpos = True


class PDJointPosMimicController(PDJointPosController):
    """PDJointPos whose mimic joints follow ``target[control] * multiplier + offset``."""


class PDJointVelController(BaseController):
    """Velocity targets (stiffness 0): ``qd* = action`` once per control step."""

    sets_target_qvel = True

    @property
    def target_qpos(self):
        """A velocity controller has no position target (None)."""
        return None


class PDJointPosVelController(PDJointPosController):
    """Position targets as PDJointPos plus velocity targets from the second half of the action (never
    interpolated)."""

    sets_target_qvel = True


class JointEffortController(BaseController):
    """Direct effort control: the scaled action is the joint effort [N·m or N], written to ``Control.joint_f`` before
    every substep (clamped to ``force_limit``); the built-in drive is off for these joints."""

    @property
    def target_qpos(self):
        """An effort controller has no position target (None)."""
        return None

    @property
    def target_effort(self) -> wp.array:
        """(num_envs, n_joints) commanded effort [N·m or N] of the last accepted action (live view)."""
        return self._view(self._engine.part("effort_command").target_effort)


class PassiveController(BaseController):
    """No action: damping toward zero velocity (stiffness 0) and joint friction."""
