"""Per-env drive properties and their mirror in the model (as ManiSkill's ``set_drive_property``).

``kp``/``kd``/``force_limit``/``friction`` are ``(num_envs, rows)``, initialised from the config and used by the
explicit law, the acceleration gains and the model mirror; ``nominal`` holds the config's values for "scale" draws.
Setting and randomising them writes the selected envs' rows and mirrors them into Newton's per-DOF model arrays
(gains only with implicit actuation: explicit keeps the built-in drive off), then notifies the attached solver.
"""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from ...config import rows as cfg
from ...kernels import actuation as KA
from . import Part

DRIVE_FIELDS = ("stiffness", "damping", "force_limit", "friction")
"""The per-env drive properties, in the order of the actuation kernels' property index p."""


class DriveProperties(Part):
    name = "drive"

    @staticmethod
    def wanted(plan) -> bool:
        return True  # every mode: the per-env drive properties and their model mirror

    def __init__(self, plan, alloc):
        rows = plan.rows
        R = plan.num_rows
        # Gains reach the model with implicit actuation only (explicit: the built-in drive is off; effort rows are in
        # target mode EFFORT, where solvers ignore the gains).
        self.gains_off = plan.explicit
        self.kp = alloc.per_env(R, fill=rows.kp)
        self.kd = alloc.per_env(R, fill=rows.kd)
        self.force_limit = alloc.per_env(R, fill=rows.force_limit)
        self.friction = alloc.per_env(R, fill=rows.friction)
        self.nominal = alloc.up(np.stack([rows.kp, rows.kd, rows.force_limit, rows.friction]).reshape(4, R), wp.float32)

    def kernel_args(self) -> dict:
        return {"kp": self.kp, "kd": self.kd, "force_limit": self.force_limit}

    def build(self, engine, model, solver) -> None:
        self.mode_changed = apply_drive_properties(engine.plan, model)

    # -- set / randomise ------------------------------------------------------------------------------------------

    def _outputs(self, model) -> list:
        """The per-env arrays and the model arrays they mirror."""
        return [
            self.kp,
            self.kd,
            self.force_limit,
            self.friction,
            None if self.gains_off else model.joint_target_ke,
            None if self.gains_off else model.joint_target_kd,
            model.joint_effort_limit,
            model.joint_friction,
        ]

    def set(self, engine, values: wp.array, enabled, env_ids, env_mask, row0: int, num_rows: int) -> None:
        """Copy ``values`` (4, 1 | selected | num_envs, num_rows) into rows [row0, row0 + num_rows) of the selected
        envs and mirror them into the model; then notify the attached solver."""
        c = engine.core
        dim = (engine.num_envs if env_ids is None else env_ids.shape[0]) * num_rows
        if dim:
            wp.launch(
                KA._set_drive_kernel,
                dim=dim,
                inputs=[
                    c.row_accel,
                    c.row_qd_off,
                    row0,
                    num_rows,
                    c.env_qd_base,
                    wp.vec4i(*enabled),
                    env_ids,
                    env_mask,
                    values,
                    engine.response,
                    *self._outputs(engine.model),
                ],
                device=engine.device,
            )
        engine.notify_solver()

    def randomize(self, engine, lo, hi, enabled, mode_abs: bool, seed: int, env_ids, env_mask, row0, num_rows) -> None:
        """Draw the enabled properties on the device (two launches: the draw, then the counter bump); capturable
        unless the attached solver's notice is not."""
        c = engine.core
        dim = (engine.num_envs if env_ids is None else env_ids.shape[0]) * num_rows
        if dim:
            wp.launch(
                KA._randomize_drive_kernel,
                dim=dim,
                inputs=[
                    c.row_accel,
                    c.row_qd_off,
                    row0,
                    num_rows,
                    c.env_qd_base,
                    int(seed),
                    int(mode_abs),
                    wp.vec4i(*enabled),
                    wp.vec4(*lo),
                    wp.vec4(*hi),
                    env_ids,
                    env_mask,
                    self.nominal,
                    c.rng_counter,
                    engine.response,
                    *self._outputs(engine.model),
                ],
                device=engine.device,
            )
            wp.launch(KA._bump_counter_kernel, dim=1, inputs=[c.rng_counter], device=engine.device)
        engine.notify_solver()


def apply_drive_properties(plan, model: newton.Model) -> bool:
    """Write gains, target modes, effort limits and friction into the model (as ManiSkill's set_drive_property), and
    the initial drive targets of ``Model.control()``.

    Returns:
        Whether any ``joint_target_mode`` changed (solvers such as MuJoCo fix actuators at construction).
    """
    m = model
    rows = plan.rows
    dof = plan.binding.dof_index  # (E, R)
    coord = plan.binding.coord_index
    ke = m.joint_target_ke.numpy()
    kd = m.joint_target_kd.numpy()
    mode = m.joint_target_mode.numpy()
    eff = m.joint_effort_limit.numpy()
    fric = m.joint_friction.numpy()
    old_mode = mode.copy()
    vel_target = np.isin(rows.kind, (cfg.ROW_VEL, cfg.ROW_PASSIVE)) | (
        (rows.kind == cfg.ROW_POS) & ((rows.flags & cfg.FLAG_VEL_TARGET) != 0)
    )
    if plan.explicit:
        row_mode = np.full(plan.num_rows, int(newton.JointTargetMode.EFFORT), np.int32)
        ke[dof] = 0.0
        kd[dof] = 0.0
    else:
        row_mode = np.where(
            rows.kind == cfg.ROW_POS,
            np.where(vel_target, int(newton.JointTargetMode.POSITION_VELOCITY), int(newton.JointTargetMode.POSITION)),
            int(newton.JointTargetMode.VELOCITY),
        ).astype(np.int32)
        ke[dof] = rows.kp[None, :]
        kd[dof] = rows.kd[None, :]
    effort = rows.kind == cfg.ROW_EFFORT  # commanded efforts: the built-in drive off in both actuations
    row_mode[effort] = int(newton.JointTargetMode.EFFORT)
    ke[dof[:, effort]] = 0.0
    kd[dof[:, effort]] = 0.0
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
