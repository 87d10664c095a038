"""What the demo does for a family of control modes: the scripted policy, the tracked quantities, the plotted trace.

:func:`wpctrl.demo.run.make_task` picks the task for a mode; :class:`JointTask` covers ManiSkill's joint-space modes.
"""

from __future__ import annotations

import math

import numpy as np


class JointTask:
    """Joint-space modes: per-env sinusoids around the rest pose for the arm, a gripper that opens and closes.

    The action comes from the desired trajectory (q_des, qd_des) and the measured state, so every part of the mode
    is used: absolute, delta from the measured position, delta on the virtual target, velocity and
    position+velocity actions, normalisation (clipped at the bounds) and the mimic gripper. Tracking is measured on
    the joint positions against the policy's desired trajectory (not against wpctrl's targets).
    """

    tracking_label = "measured joint positions vs the policy's desired trajectory"
    plot_subject = "every joint position"
    #: group -> (columns of tracked(), SI unit (summary.json), unit shown, scale from SI to the unit shown)
    groups = {"arm": (slice(0, 7), "rad", "rad", 1.0), "gripper": (slice(7, 9), "m", "mm", 1e3)}

    def __init__(self, mode_name: str, ctrl, model, rest: np.ndarray, num_envs: int, rng: np.random.Generator):
        self.mode = mode_name
        self.ctrl = ctrl
        self.coord = ctrl._engine.binding.coord_index
        self.rest = rest.astype(np.float64)
        self.amp = rng.uniform(0.1, 0.3, (num_envs, 7))  # [rad]
        self.freq = rng.uniform(0.2, 0.6, (num_envs, 7))  # [Hz]: peak speed < 1.2 rad/s, inside every mode's bounds
        self.phase = rng.uniform(0, 2 * math.pi, (num_envs, 7))
        self.grip_period = rng.uniform(1.0, 2.0, num_envs)  # [s]
        self.names = list(ctrl.joint_names)

    def desired(self, t: float):
        w = 2 * math.pi * self.freq
        q = self.rest[None, :7] + self.amp * np.sin(w * t + self.phase)
        qd = self.amp * w * np.cos(w * t + self.phase)
        closed = (t % self.grip_period) > 0.5 * self.grip_period
        grip = np.where(closed, 0.0, 0.04)  # finger opening [m]
        return q, qd, grip

    def action(self, t_next: float, state) -> np.ndarray:
        """Action for the control step that ends at ``t_next`` [s], from the measured ``state``."""
        q = state.joint_q.numpy()[self.coord]
        q_des, qd_des, grip = self.desired(t_next)
        arm_sp = self.ctrl["arm"]
        g = np.clip((grip - 0.015) / 0.025, -1, 1)[:, None]  # gripper [-0.01, 0.04] m normalised
        m = self.mode
        if m == "pd_joint_pos":
            arm = q_des
        elif m in ("pd_joint_delta_pos", "joint_impedance_delta_pos"):
            arm = (q_des - q[:, :7]) / 0.1
        elif m == "pd_joint_target_delta_pos":
            arm = (q_des - arm_sp.target_qpos.numpy()) / 0.1
        elif m == "pd_joint_vel":
            arm = qd_des + 2.0 * (q_des - q[:, :7])  # [rad/s], normalised by the ±1 rad/s bound
        elif m == "pd_joint_pos_vel":
            arm = np.concatenate([q_des, qd_des], axis=1)
        elif m == "pd_joint_delta_pos_vel":
            arm = np.concatenate([(q_des - q[:, :7]) / 0.1, qd_des], axis=1)
        else:  # pragma: no cover - the parser validates the mode
            raise ValueError(m)
        return np.concatenate([arm, g], axis=1).astype(np.float32)

    def tracked(self, t: float, state, control):
        """(measured, desired, drive target) of the tracked quantities, each (num_envs, d), at time ``t``."""
        q = state.joint_q.numpy()[self.coord]
        q_des, _, grip = self.desired(t)
        des = np.concatenate([q_des, grip[:, None], grip[:, None]], axis=1)
        return q, des, control.joint_target_q.numpy()[self.coord]
