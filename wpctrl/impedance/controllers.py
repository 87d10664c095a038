"""ManiSkill-shaped impedance controller classes: operational-space control and joint impedance, torque out.

Both are effort controllers over the shared engine (:mod:`.engine_part`): the action sets a target
(a pose, or joint positions) and, with variable impedance, the gains; before every solver substep the torque is
computed from the measured state and written to ``Control.joint_f``, clamped to ``force_limit`` (delay, effort
readout and NaN holding as for every row).
"""

from __future__ import annotations

import warp as wp

from ..controllers.drive_properties import draw_options, draw_ranges
from ..controllers.ee import PDEEPosController
from ..controllers.joint import JointEffortController
from . import engine_part  # noqa: F401  (registers the impedance part with the engine)


def _impedance_unit(engine, row0: int):
    """The impedance part's unit of the controller whose rows start at ``row0``."""
    return engine.part("impedance").units.get(row0)


class JointImpedanceController(JointEffortController):
    """Joint impedance ``τ = [M] (Kp (q* − q) − Kd q̇) + g`` toward the joint targets of the action (absolute, delta
    from the measured positions, or delta on the last target). ``stiffness`` / ``damping`` are the per-env gains."""

    _unit = staticmethod(_impedance_unit)

    @property
    def target_qpos(self) -> wp.array:
        """(num_envs, n_joints) joint targets [rad or m] (live view; a reset sets them to the measured positions)."""
        return self._view(self._engine.core.target_qpos)

    @property
    def _uses_target(self) -> bool:
        return bool(self.config.use_delta and self.config.use_target)


class OperationalSpaceController(JointEffortController):
    """Operational-space control of ``ee_link`` toward the target pose of the action: ``τ = Jᵀ Λ (Kp ∘ e − Kd ∘ ẋ)``
    (+ null-space posture, + gravity), see :class:`wpctrl.OperationalSpaceControllerConfig`."""

    _unit = staticmethod(_impedance_unit)
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
        return self._view(self._engine.core.target_qpos)

    @property
    def task_stiffness(self) -> wp.array:
        """(num_envs, 6) task stiffness Kp per env and axis (x, y, z, rx, ry, rz) (live, writable; variable impedance
        writes it from the action)."""
        return self._ee.task_stiffness

    @property
    def task_damping(self) -> wp.array:
        """(num_envs, 6) task damping Kd per env and axis (live, writable)."""
        return self._ee.task_damping

    def randomize_task_impedance(self, env_ids=None, *, stiffness=None, damping=None, mode="scale", seed=0) -> None:
        """Draw the task gains uniformly on the device for ``env_ids`` (None: all envs), per env and axis, as
        :meth:`randomize_drive_properties` draws the joints' (which covers this controller's posture gains, force
        limits and friction): each of ``stiffness`` / ``damping`` None (untouched) or ``(lo, hi)``; ``"scale"``
        multiplies the config's value by U(lo, hi), ``"abs"`` sets U(lo, hi); keyed by ``seed`` and the device's
        draw counter (a captured graph draws anew on every replay). Variable impedance overwrites them at the next
        action. ``env_ids`` first, as in every per-env call; the rest by keyword. A bad value raises
        :class:`wpctrl.ConfigError`."""
        what = "randomize_task_impedance"
        draw_options(what, mode, seed)
        lo, hi, enabled = draw_ranges(("stiffness", "damping"), (stiffness, damping), mode, what)
        if not any(enabled):
            return
        ids, mask = self._selection(env_ids)
        self._ee.randomize_task(lo, hi, enabled, mode == "abs", int(seed), ids, mask)

    def __repr__(self) -> str:
        inner = ", ".join(self.joint_names)
        return (
            f"{type(self).__name__}(dof={self.action_dim}, num_envs={self.num_envs}, end_link={self.config.ee_link}, "
            f"joints=({inner}))"
        )
