"""ManiSkill-shaped end-effector controller classes (PDEEPos / PDEEPose) over the shared engine.

An EE controller is a :class:`~wpctrl.controllers.PDJointPosController` whose targets come from the EE kernels
(:mod:`wpctrl.engine.parts.ee`); it adds ``target_pose``, ``ee_pose``, ``ik_success`` and the ``{"target_pose": ...}``
state.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .inputs import _as_rows_array
from .joint import PDJointPosController


class PDEEPosController(PDJointPosController):
    """End-effector position control: a position action (delta or absolute, root or EE axes) solved to joint
    position targets by damped least squares (one step, ManiSkill's GPU semantics) or CLIK (ManiSkill's CPU)."""

    _ee = None

    @staticmethod
    def _unit(engine, row0: int):
        """The end-effector part's chain of the controller whose rows start at ``row0``."""
        return engine.part("ee").parts.get(row0)

    @property
    def target_pose(self) -> wp.array:
        """(num_envs, 7) target EE pose ``[x, y, z, qw, qx, qy, qz]`` [m] in the root frame (live array); updated
        by ``set_action`` where a pose is composed (use_target, absolute actions, CLIK) and by resets with
        ``use_target``."""
        return self._ee.target_pose

    @property
    def ee_pose(self) -> wp.array:
        """(num_envs, 7) measured EE pose ``[x, y, z, qw, qx, qy, qz]`` in the root frame at the last set_action or
        reset (live array)."""
        return self._ee.ee_pose

    @property
    def ik_success(self) -> wp.array:
        """(num_envs,) int32: 1 where the last IK converged (always 1 with one solver iteration); 0 where CLIK did
        not converge and the env kept its measured joint positions as the target."""
        return self._ee.ik_success

    def fk_jacobian(self, state) -> tuple[wp.array, wp.array]:
        """EE poses (num_envs, 7) and geometric Jacobians (num_envs, 6, n_joints), rows [v; ω], root frame, at
        ``state.joint_q`` (allocates new arrays: for inspection, not for the per-step loop)."""
        return self._ee.fk_jacobian(state.joint_q)

    @property
    def _uses_target(self) -> bool:
        return bool(self.config.use_target)

    def get_state(self) -> dict:
        """``{"target_pose": (num_envs, 7) wp.array}`` (a live view) with ``use_target``, ``{}`` otherwise."""
        if self._uses_target:
            return {"target_pose": self.target_pose}
        return {}

    def set_state(self, state: dict | None) -> None:
        """Restore :meth:`get_state`'s result: ``target_pose`` (num_envs, 7) ``[x, y, z, qw, qx, qy, qz]``."""
        if not state or not self._uses_target:
            return
        new = _as_rows_array("target_pose", state["target_pose"], (self.num_envs, 7))
        q = new[:, 3:]
        nrm = np.linalg.norm(q, axis=1)
        if not np.isfinite(new).all() or (np.abs(nrm - 1.0) > 1e-3).any():
            raise ValueError("target_pose: expected finite rows [x, y, z, qw, qx, qy, qz] with unit quaternions")
        new[:, 3:] = q / nrm[:, None]
        self._ee.target_pose.assign(new)

    def __repr__(self) -> str:
        inner = ", ".join(self.joint_names)
        return (
            f"{type(self).__name__}(dof={self.action_dim}, num_envs={self.num_envs}, end_link={self.config.ee_link}, "
            f"joints=({inner}))"
        )


class PDEEPoseController(PDEEPosController):
    """End-effector pose control: position + rotation (Euler XYZ increments clipped by norm, ManiSkill's sign)."""
