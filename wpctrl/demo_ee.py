"""The demo's end-effector part: a scripted policy in EE action space, the EE tracking error, and its plot.

The desired motion is the joint-space demo's (per-env sinusoids around the rest pose, a gripper that opens and
closes) mapped through the controller's own FK to a desired TCP pose; the policy expresses it in the mode's action
space (delta from the measured pose, delta on the target pose, or absolute pose; ManiSkill's rotation sign), and the
score is the distance between the measured and desired TCP positions [m].
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


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
    """Batched "XYZ" Euler angles of wxyz quaternions (R = Rx Ry Rz), as ManiSkill's pytorch3d convention."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    r02 = 2 * (x * z + w * y)
    r12 = 2 * (y * z - w * x)
    r22 = 1 - 2 * (x * x + y * y)
    r01 = 2 * (x * y - w * z)
    r00 = 1 - 2 * (y * y + z * z)
    return np.stack([np.arctan2(-r12, r22), np.arcsin(np.clip(r02, -1, 1)), np.arctan2(-r01, r00)], axis=-1)


class EEPolicy:
    """Same interface as the demo's joint policy (``desired``, ``action``), plus EE scoring and a plot."""

    def __init__(self, joint_policy, mode_name: str, ctrl, model):
        self.joint = joint_policy
        self.mode = mode_name
        self.ctrl = ctrl
        self.arm = ctrl["arm"]
        self.scratch = model.state()
        self.coord = ctrl._engine.binding.coord_index[:, self.arm._rows]
        cfg = self.arm.config
        # Normalised increments: processed = a * half range (ManiSkill's symmetric Panda bounds).
        self.pos_scale = float(np.max(np.asarray(cfg.pos_upper, float))) if cfg.normalize_action else 1.0
        rl = getattr(cfg, "rot_lower", None)
        self.rot_scale = float(np.asarray(rl, float).ravel()[0]) if (rl is not None and cfg.normalize_action) else 1.0
        self.hist_t, self.hist_des, self.hist_meas, self.hist_tgt = [], [], [], []
        self.err_sq = 0.0
        self.err_max = 0.0
        self.count = 0

    def desired(self, t: float):
        return self.joint.desired(t)

    def _pose(self, arm_q: np.ndarray) -> np.ndarray:
        q = self.scratch.joint_q.numpy()
        q[self.coord] = arm_q
        self.scratch.joint_q.assign(q)
        return self.arm.fk_jacobian(self.scratch)[0].numpy().astype(np.float64)

    def desired_pose(self, t: float) -> np.ndarray:
        return self._pose(self.joint.desired(t)[0])

    def measured_pose(self, state) -> np.ndarray:
        return self.arm.fk_jacobian(state)[0].numpy().astype(np.float64)

    def action(self, t_next: float, q: np.ndarray) -> np.ndarray:
        des = self.desired_pose(t_next)
        _, _, grip = self.joint.desired(t_next)
        g = np.clip((grip - 0.015) / 0.025, -1, 1)[:, None]
        cfg = self.arm.config
        pose_mode = des.shape[1] == 7 and self.arm.action_dim == 6
        if not cfg.use_delta:  # absolute pose in the root frame
            arm = np.concatenate([des[:, :3], _euler_xyz(des[:, 3:])], axis=1) if pose_mode else des[:, :3]
        else:
            ref = self.arm.target_pose.numpy() if cfg.use_target else self._pose(q[:, :7])
            dp = (des[:, :3] - ref[:, :3]) / self.pos_scale
            arm = dp
            if pose_mode:  # root-aligned rotation increment: q_des = dq * q_ref, rotation action times rot_lower
                dr = _euler_xyz(_qmul(des[:, 3:], _conj(ref[:, 3:]))) / self.rot_scale
                arm = np.concatenate([dp, dr], axis=1)
        return np.concatenate([arm, g], axis=1).astype(np.float32)

    def record(self, t: float, state, live: np.ndarray) -> None:
        """Score the measured TCP position against the desired one at time ``t`` (envs in ``live``)."""
        des = self.desired_pose(t)
        meas = self.measured_pose(state)
        err = np.linalg.norm(meas[:, :3] - des[:, :3], axis=1)
        if live.any():
            self.err_sq += float((err[live] ** 2).sum())
            self.err_max = max(self.err_max, float(err[live].max()))
            self.count += int(live.sum())
        self.hist_t.append(t)
        self.hist_des.append(des[0, :3])
        self.hist_meas.append(meas[0, :3])
        cfg = self.arm.config
        if cfg.use_target or not cfg.use_delta:  # a composed target pose
            tgt = self.arm.target_pose.numpy()[0, :3].copy()
        else:  # one DLS step towards the measured pose plus the increment (root_translation)
            tgt = self.arm.ee_pose.numpy()[0, :3] + self.arm.processed_action.numpy()[0, :3]
        self.hist_tgt.append(tgt)

    def summary(self) -> dict:
        return {
            "ee_tracking_rms_m": math.sqrt(self.err_sq / max(self.count, 1)),
            "ee_tracking_max_m": self.err_max,
            "ee_ik_failures": int((self.arm.ik_success.numpy() == 0).sum()),
        }

    def plot(self, path: Path, title: str) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        t = np.array(self.hist_t)
        des, meas = np.array(self.hist_des), np.array(self.hist_meas)
        fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
        for k, ax in enumerate(axes):
            ax.plot(t, des[:, k], "k--", lw=1, label="desired (policy)")
            ax.plot(t, np.array(self.hist_tgt)[:, k], color="tab:orange", lw=1, label="EE target (wpctrl)")
            ax.plot(t, meas[:, k], color="tab:blue", lw=1.5, label="measured")
            ax.set_title(f"TCP {'xyz'[k]} [m]", fontsize=9)
            ax.set_xlabel("t [s]", fontsize=8)
            ax.tick_params(labelsize=7)
        axes[0].legend(fontsize=7)
        fig.suptitle(title, fontsize=10)
        fig.savefig(path, dpi=90)
        plt.close(fig)


def summary_rows(s: dict) -> list[tuple[str, str]]:
    if "ee_tracking_rms_m" not in s:
        return []
    return [
        (
            "EE tracking",
            f"RMS {1e3 * s['ee_tracking_rms_m']:.2f} mm, max {1e3 * s['ee_tracking_max_m']:.2f} mm (TCP position)",
        )
    ]
