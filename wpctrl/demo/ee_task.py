"""The demo's end-effector task (``pd_ee_*`` modes): a scripted policy in EE action space, TCP tracking, its plot.

The desired motion is the joint-space task's (per-env sinusoids around the rest pose, a gripper that opens and
closes) mapped through the controller's own FK to a desired TCP pose; the policy expresses it in the mode's action
space (delta from the measured pose, delta on the target pose, or absolute pose; ManiSkill's rotation sign). Tracked:
the TCP position [m] (measured, desired, and wpctrl's EE target: the composed target pose, or the measured pose plus
the increment) and the fingers. Same interface as :class:`wpctrl.demo.joint_task.JointTask`.
"""

from __future__ import annotations

import numpy as np

from .joint_task import JointTask


def _qmul(a, b):
    """Batched wxyz quaternion product."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def _conj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _euler_xyz(q):
    """Batched "XYZ" Euler angles of wxyz quaternions (R = Rx Ry Rz), ManiSkill's pytorch3d convention."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    r02 = 2 * (x * z + w * y)
    r12 = 2 * (y * z - w * x)
    r22 = 1 - 2 * (x * x + y * y)
    r01 = 2 * (x * y - w * z)
    r00 = 1 - 2 * (y * y + z * z)
    return np.stack([np.arctan2(-r12, r22), np.arcsin(np.clip(r02, -1, 1)), np.arctan2(-r01, r00)], axis=-1)


class EETask:
    """End-effector modes: the joint task's motion as TCP poses, tracked on the TCP position."""

    tracking_label = "measured TCP position vs the policy's desired TCP position"
    plot_subject = "TCP position and gripper fingers"
    groups = {"ee": (slice(0, 3), "m", "mm", 1e3), "gripper": (slice(3, 5), "m", "mm", 1e3)}

    def __init__(self, mode_name: str, ctrl, model, rest: np.ndarray, num_envs: int, rng: np.random.Generator):
        self.joint = JointTask(mode_name, ctrl, model, rest, num_envs, rng)
        self.mode = mode_name
        self.ctrl = ctrl
        self.arm = ctrl["arm"]
        self.coord = ctrl.coord_index
        self.arm_coord = self.arm.coord_index
        self.grip_coord = ctrl["gripper"].coord_index
        self.scratch = model.state()
        cfg = self.arm.config
        # Normalised increments: processed = action * half range (ManiSkill's symmetric Panda bounds).
        self.pos_scale = float(np.max(np.asarray(cfg.pos_upper, float))) if cfg.normalize_action else 1.0
        rl = getattr(cfg, "rot_lower", None)
        self.rot_scale = float(np.asarray(rl, float).ravel()[0]) if (rl is not None and cfg.normalize_action) else 1.0
        self.names = ["TCP x", "TCP y", "TCP z", *ctrl["gripper"].joint_names]

    def _pose(self, arm_q: np.ndarray) -> np.ndarray:
        q = self.scratch.joint_q.numpy()
        q[self.arm_coord] = arm_q
        self.scratch.joint_q.assign(q)
        return self.arm.fk_jacobian(self.scratch)[0].numpy().astype(np.float64)

    def desired(self, t: float):
        """Desired TCP poses (num_envs, 7) [x, y, z, qw, qx, qy, qz] and finger openings [m] at ``t`` [s]."""
        q_des, _, grip = self.joint.desired(t)
        return self._pose(q_des), grip

    def action(self, t_next: float, state) -> np.ndarray:
        des, grip = self.desired(t_next)
        g = np.clip((grip - 0.015) / 0.025, -1, 1)[:, None]  # gripper [-0.01, 0.04] m normalised
        cfg = self.arm.config
        pose_mode = self.arm.action_dim == 6
        if not cfg.use_delta:  # absolute pose in the root frame
            arm = np.concatenate([des[:, :3], _euler_xyz(des[:, 3:])], axis=1) if pose_mode else des[:, :3]
        else:
            ref = self.arm.target_pose.numpy() if cfg.use_target else self._pose(state.joint_q.numpy()[self.arm_coord])
            arm = (des[:, :3] - ref[:, :3]) / self.pos_scale
            if pose_mode:  # root-aligned increment: q_des = dq * q_ref; ManiSkill multiplies the action by rot_lower
                dr = _euler_xyz(_qmul(des[:, 3:], _conj(ref[:, 3:]))) / self.rot_scale
                arm = np.concatenate([arm, dr], axis=1)
        return np.concatenate([arm, g], axis=1).astype(np.float32)

    def tracked(self, t: float, state, control):
        """(measured, desired, EE target) TCP positions [m] and finger positions [m], each (num_envs, 5)."""
        des, grip = self.desired(t)
        measured = self.arm.fk_jacobian(state)[0].numpy()[:, :3]
        cfg = self.arm.config
        if cfg.use_target or not cfg.use_delta:  # a composed target pose
            target = self.arm.target_pose.numpy()[:, :3]
        else:  # one DLS step towards the measured pose plus the increment (root_translation)
            target = self.arm.ee_pose.numpy()[:, :3] + self.arm.processed_action.numpy()[:, :3]
        q = state.joint_q.numpy()
        drive = control.joint_target_q.numpy()
        return (
            np.concatenate([measured, q[self.grip_coord]], axis=1),
            np.concatenate([des[:, :3], grip[:, None], grip[:, None]], axis=1),
            np.concatenate([target, drive[self.grip_coord]], axis=1),
        )
