"""ManiSkill-shaped impedance controller classes: operational-space control and joint impedance, torque out.

Both are effort controllers over the shared engine (:mod:`wpctrl.engine.parts.impedance`): the action sets a target
(a pose, or joint positions) and, with variable impedance, the gains; before every solver substep the torque is
computed from the measured state and written to ``Control.joint_f``, clamped to ``force_limit`` (delay, effort
readout and NaN holding as for every row).
"""

from __future__ import annotations

import warp as wp

from .ee import PDEEPosController
from .joint import JointEffortController


class JointImpedanceController(JointEffortController):
    """Joint impedance ``τ = [M] (Kp (q* − q) − Kd q̇) + g`` toward the joint targets of the action (absolute, delta
    from the measured positions, or delta on the last target). ``stiffness`` / ``damping`` are the per-env gains."""

    @property
    def target_qpos(self) -> wp.array:
        """(num_envs, n_joints) joint targets [rad or m] (live view; a reset sets them to the measured positions)."""
        return self._view(self._engine.target_qpos)

    @property
    def _uses_target(self) -> bool:
        return bool(self.config.use_delta and self.config.use_target)


class OperationalSpaceController(JointEffortController):
    """Operational-space control of ``ee_link`` toward the target pose of the action: ``τ = Jᵀ Λ (Kp ∘ e − Kd ∘ ẋ)``
    (+ null-space posture, + gravity), see :class:`wpctrl.OperationalSpaceControllerConfig`."""

    target_pose = PDEEPosController.target_pose
    ee_pose = PDEEPosController.ee_pose
    fk_jacobian = PDEEPosController.fk_jacobian
    get_state = PDEEPosController.get_state
    set_state = PDEEPosController.set_state

    @property
    def _uses_target(self) -> bool:
        return bool(self.config.use_target)

    @property
    def target_qpos(self) -> wp.array:
        """(num_envs, n_joints) the null-space posture [rad or m] when ``nullspace_target`` is None (live view,
        writable; a reset sets it to the measured positions)."""
        return self._view(self._engine.target_qpos)

    @property
    def task_stiffness(self) -> wp.array:
        """(num_envs, 6) task stiffness Kp per env and axis (x, y, z, rx, ry, rz) (live, writable; variable impedance
        writes it from the action)."""
        return self._ee.task_stiffness

    @property
    def task_damping(self) -> wp.array:
        """(num_envs, 6) task damping Kd per env and axis (live, writable)."""
        return self._ee.task_damping

    def __repr__(self) -> str:
        inner = ", ".join(self.joint_names)
        return (
            f"{type(self).__name__}(dof={self.action_dim}, num_envs={self.num_envs}, end_link={self.config.ee_link}, "
            f"joints=({inner}))"
        )
