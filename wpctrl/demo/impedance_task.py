"""The demo's tasks for the impedance modes (``osc_*``, ``joint_impedance_*``): the end-effector or joint task's
policy and tracking, plus the arm's joint torques (commanded, and applied after the force-limit clamp) in the plot."""

from __future__ import annotations

import numpy as np

from .ee_task import EETask
from .joint_task import JointTask


class _Torques:
    """The arm's torques as extra plot panels: ``extra(state, control) -> (applied, commanded)``."""

    extra_unit = "N·m"

    def _init_torques(self, ctrl):
        self._arm = ctrl["arm"]
        self._dof = ctrl._engine.binding.dof_index[:, self._arm._rows]
        self.extra_names = [f"{j} torque" for j in self._arm.joint_names]

    def extra(self, state, control):
        return control.joint_f.numpy()[self._dof], self._arm.target_effort.numpy()


class OSCTask(_Torques, EETask):
    """Operational-space modes: the EE task's TCP motion as pose actions (OSC scales a normalised rotation by the half
    range, so a positive action rotates positively), tracked on the TCP position against the target pose."""

    plot_subject = "TCP position, fingers and arm joint torques"

    def __init__(self, mode_name: str, ctrl, model, rest: np.ndarray, num_envs: int, rng: np.random.Generator):
        super().__init__(mode_name, ctrl, model, rest, num_envs, rng)
        cfg = self.arm.config
        if cfg.normalize_action:
            self.rot_scale = float(0.5 * (np.max(np.asarray(cfg.rot_upper, float)) - np.min(cfg.rot_lower)))
        self._init_torques(ctrl)

    def tracked(self, t: float, state, control):
        measured, desired, target = super().tracked(t, state, control)
        target[:, :3] = self.arm.target_pose.numpy()[:, :3]
        return measured, desired, target


class JointImpedanceTask(_Torques, JointTask):
    """Joint-impedance modes: the joint task (its delta policy), tracked against the controller's joint targets."""

    plot_subject = "every joint position and the arm joint torques"

    def __init__(self, mode_name: str, ctrl, model, rest: np.ndarray, num_envs: int, rng: np.random.Generator):
        super().__init__(mode_name, ctrl, model, rest, num_envs, rng)
        self._init_torques(ctrl)

    def tracked(self, t: float, state, control):
        measured, desired, target = super().tracked(t, state, control)
        target[:, self._arm._rows] = self._arm.target_qpos.numpy()
        return measured, desired, target
