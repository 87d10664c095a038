"""Per-env drive properties of the engine: device-side set / randomise, the model mirror and the solver notice.

A mixin of :class:`wpctrl.engine._Engine` (it uses the engine's arrays: ``kp``/``kd``/``force_limit``/``friction``
(num_envs, rows), ``nominal``, ``rng_counter``, ``response``, the row and env tables, ``model`` and ``solver``).
"""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from ..config import rows as cfg
from ..kernels import actuation as KA

DRIVE_FIELDS = ("stiffness", "damping", "force_limit", "friction")
"""The per-env drive properties, in the order of the actuation kernels' property index p."""


class _DrivePropertiesMixin:
    """Per-env drive properties (issue 10) and the model's drive properties (as ManiSkill's set_drive_property)."""

    # -- per-env drive properties ---------------------------------------------------------------------------------

    def _drive_outputs(self) -> list:
        """The per-env arrays and the model arrays they mirror (gains only with implicit actuation: explicit keeps
        the built-in drive off)."""
        m = self.model
        return [
            self.kp,
            self.kd,
            self.force_limit,
            self.friction,
            None if self.explicit else m.joint_target_ke,
            None if self.explicit else m.joint_target_kd,
            m.joint_effort_limit,
            m.joint_friction,
        ]

    def set_drive(self, values: wp.array, enabled, env_ids, env_mask, row0: int, num_rows: int) -> None:
        """Copy ``values`` (4, 1 | selected | num_envs, num_rows) into rows [row0, row0 + num_rows) of the selected
        envs and mirror them into the model; then notify the attached solver."""
        dim = (self.num_envs if env_ids is None else env_ids.shape[0]) * num_rows
        if dim:
            wp.launch(
                KA._set_drive_kernel,
                dim=dim,
                inputs=[
                    self.row_accel,
                    self.row_qd_off,
                    row0,
                    num_rows,
                    self.env_qd_base,
                    wp.vec4i(*enabled),
                    env_ids,
                    env_mask,
                    values,
                    self.response,
                    *self._drive_outputs(),
                ],
                device=self.device,
            )
        self.notify_solver()

    def randomize_drive(self, lo, hi, enabled, mode_abs: bool, seed: int, env_ids, env_mask, row0, num_rows) -> None:
        """Draw the enabled properties on the device (two launches: the draw, then the counter bump); capturable
        unless the attached solver's notice is not."""
        dim = (self.num_envs if env_ids is None else env_ids.shape[0]) * num_rows
        if dim:
            wp.launch(
                KA._randomize_drive_kernel,
                dim=dim,
                inputs=[
                    self.row_accel,
                    self.row_qd_off,
                    row0,
                    num_rows,
                    self.env_qd_base,
                    int(seed),
                    int(mode_abs),
                    wp.vec4i(*enabled),
                    wp.vec4(*lo),
                    wp.vec4(*hi),
                    env_ids,
                    env_mask,
                    self.nominal,
                    self.rng_counter,
                    self.response,
                    *self._drive_outputs(),
                ],
                device=self.device,
            )
            wp.launch(KA._bump_counter_kernel, dim=1, inputs=[self.rng_counter], device=self.device)
        self.notify_solver()

    def notify_solver(self) -> None:
        """Tell the attached solver that per-DOF drive properties changed (MuJoCo, Steel and Kamino copy them into
        their own model; XPBD, Featherstone and SemiImplicit read Newton's arrays at every step)."""
        if self.solver is not None:
            self.solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES)

    # -- model drive properties -----------------------------------------------------------------------------------

    def apply_drive_properties(self) -> bool:
        """Write gains, target modes, effort limits and friction into the model (as ManiSkill's set_drive_property).

        Returns:
            Whether any ``joint_target_mode`` changed (solvers such as MuJoCo fix actuators at construction).
        """
        m = self.model
        rows = self.rows
        dof = self.binding.dof_index  # (E, R)
        coord = self.binding.coord_index
        ke = m.joint_target_ke.numpy()
        kd = m.joint_target_kd.numpy()
        mode = m.joint_target_mode.numpy()
        eff = m.joint_effort_limit.numpy()
        fric = m.joint_friction.numpy()
        old_mode = mode.copy()
        vel_target = (rows.kind != cfg.ROW_POS) | ((rows.flags & cfg.FLAG_VEL_TARGET) != 0)
        if self.explicit:
            row_mode = np.full(self.num_rows, int(newton.JointTargetMode.EFFORT), np.int32)
            ke[dof] = 0.0
            kd[dof] = 0.0
        else:
            row_mode = np.where(
                rows.kind == cfg.ROW_POS,
                np.where(
                    vel_target, int(newton.JointTargetMode.POSITION_VELOCITY), int(newton.JointTargetMode.POSITION)
                ),
                int(newton.JointTargetMode.VELOCITY),
            ).astype(np.int32)
            ke[dof] = rows.kp[None, :]
            kd[dof] = rows.kd[None, :]
        mode[dof] = row_mode[None, :]
        eff[dof] = rows.force_limit[None, :]
        fric[dof] = rows.friction[None, :]
        m.joint_target_ke.assign(ke)
        m.joint_target_kd.assign(kd)
        m.joint_target_mode.assign(mode)
        m.joint_effort_limit.assign(eff)
        m.joint_friction.assign(fric)
        # Initial targets of Model.control(): position rows hold the model's initial pose; rows without a position
        # drive (stiffness 0) get 0, PhysX's default target, as in ManiSkill; velocity targets are 0.
        tq = m.joint_target_q.numpy()
        tqd = m.joint_target_qd.numpy()
        q0 = m.joint_q.numpy()
        pos = rows.kind == cfg.ROW_POS
        tq[coord[:, pos]] = q0[coord[:, pos]]
        tq[coord[:, ~pos]] = 0.0
        tqd[dof[:, vel_target]] = 0.0
        m.joint_target_q.assign(tq)
        m.joint_target_qd.assign(tqd)
        return bool((old_mode != mode).any())
