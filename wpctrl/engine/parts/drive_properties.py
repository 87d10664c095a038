"""Per-env drive properties and their mirror in the model (as ManiSkill's ``set_drive_property``): the part and its
set / randomise kernels.

``kp``/``kd``/``force_limit``/``friction`` are ``(num_envs, rows)``, initialised from the config and used by the
explicit law, the acceleration gains and the model mirror; ``nominal`` holds the config's values for "scale" draws.
Setting and randomising them writes the selected envs' rows and mirrors them into Newton's per-DOF model arrays
(gains only with implicit actuation: explicit keeps the built-in drive off), then notifies the attached solver.

The kernels run one thread per (selected env, row of the controller or child) (:mod:`wpctrl.kernels.env_selection`).
The four drive properties are handled together, indexed ``p`` = 0 stiffness [N·m/rad or N/m], 1 damping
[N·m·s/rad or N·s/m], 2 force limit [N·m or N], 3 friction [N·m or N]; ``enabled[p]`` selects which are written.
"""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from ...config.rows import FLAG_VEL_TARGET, ROW_EFFORT, ROW_PASSIVE, ROW_POS, ROW_VEL
from ...kernels.env_selection import MODE_SCALE, _bump_counter_kernel, _select
from .part import Part

wp.set_module_options({"enable_backward": False})

DRIVE_FIELDS = ("stiffness", "damping", "force_limit", "friction")
"""The per-env drive properties, in the order of the kernels' property index p."""


@wp.func
def _store(
    env: int,
    r: int,
    p: int,
    value: float,
    kp_out: wp.array2d[float],
    kd_out: wp.array2d[float],
    force_limit_out: wp.array2d[float],
    friction_out: wp.array2d[float],
    row_accel: wp.array[wp.int32],
    row_qd_off: wp.array[wp.int32],
    env_qd_base: wp.array[wp.int32],
    response_in: wp.array2d[float],
    joint_target_ke_out: wp.array[float],
    joint_target_kd_out: wp.array[float],
    joint_effort_limit_out: wp.array[float],
    joint_friction_out: wp.array[float],
):
    """Write one property of (env, row) into its per-env array and mirror it into Newton's per-DOF model array.
    Gains reach the model only with implicit actuation (the ke/kd outputs are None otherwise); an acceleration row
    hands the solver Kp / r, Kd / r."""
    if p == 0:
        kp_out[env, r] = value
    elif p == 1:
        kd_out[env, r] = value
    elif p == 2:
        force_limit_out[env, r] = value
    else:
        friction_out[env, r] = value
    di = env_qd_base[env] + row_qd_off[r]
    if p < 2:
        if joint_target_ke_out:
            g = value
            if row_accel[r] != 0:
                g = value / response_in[wp.min(env, response_in.shape[0] - 1), r]
            if p == 0:
                joint_target_ke_out[di] = g
            else:
                joint_target_kd_out[di] = g
    elif p == 2:
        joint_effort_limit_out[di] = value
    else:
        joint_friction_out[di] = value


@wp.kernel
def _randomize_drive_kernel(
    # Rows:
    row_accel: wp.array[wp.int32],
    row_qd_off: wp.array[wp.int32],
    row0: int,
    num_rows: int,
    # Envs:
    env_qd_base: wp.array[wp.int32],
    # Draw:
    seed: int,
    mode: int,
    enabled: wp.vec4i,
    lo: wp.vec4,
    hi: wp.vec4,
    # In:
    env_ids_in: wp.array[wp.int32],  # optional: thread block i draws for env env_ids_in[i]
    env_mask_in: wp.array[wp.bool],  # optional: only where True
    nominal_in: wp.array2d[float],  # (4, rows) the config's values
    rng_counter_in: wp.array[wp.int32],  # (1,)
    response_in: wp.array2d[float],  # (num_envs, rows) r, for acceleration rows
    # Out:
    kp_out: wp.array2d[float],  # (num_envs, rows)
    kd_out: wp.array2d[float],
    force_limit_out: wp.array2d[float],
    friction_out: wp.array2d[float],
    joint_target_ke_out: wp.array[float],  # optional (implicit actuation)
    joint_target_kd_out: wp.array[float],  # optional
    joint_effort_limit_out: wp.array[float],
    joint_friction_out: wp.array[float],
):
    """value = nominal * U(lo, hi) ("scale") or U(lo, hi) ("abs"); lo == hi gives exactly nominal * lo (no rounding
    of the draw can enter: (hi - lo) * u == 0)."""
    tid = wp.tid()
    env, rl, i = _select(tid, num_rows, env_ids_in, env_mask_in, kp_out.shape[0])
    if env < 0:
        return
    r = row0 + rl
    key = wp.randi(wp.rand_init(seed, rng_counter_in[0]))
    state = wp.rand_init(key, env * kp_out.shape[1] + r)
    for p in range(4):
        u = wp.randf(state)  # drawn for every p, so a property's values do not depend on which others are enabled
        if enabled[p] != 0:
            x = lo[p] + (hi[p] - lo[p]) * u
            if mode == MODE_SCALE:
                x = nominal_in[p, r] * x
            _store(
                env,
                r,
                p,
                x,
                kp_out,
                kd_out,
                force_limit_out,
                friction_out,
                row_accel,
                row_qd_off,
                env_qd_base,
                response_in,
                joint_target_ke_out,
                joint_target_kd_out,
                joint_effort_limit_out,
                joint_friction_out,
            )


@wp.kernel
def _set_drive_kernel(
    # Rows:
    row_accel: wp.array[wp.int32],
    row_qd_off: wp.array[wp.int32],
    row0: int,
    num_rows: int,
    # Envs:
    env_qd_base: wp.array[wp.int32],
    enabled: wp.vec4i,
    # In:
    env_ids_in: wp.array[wp.int32],  # optional
    env_mask_in: wp.array[wp.bool],  # optional
    values_in: wp.array3d[float],  # (4, 1 | len(env_ids) | num_envs, num_rows): row 0 broadcasts
    response_in: wp.array2d[float],
    # Out:
    kp_out: wp.array2d[float],
    kd_out: wp.array2d[float],
    force_limit_out: wp.array2d[float],
    friction_out: wp.array2d[float],
    joint_target_ke_out: wp.array[float],  # optional (implicit actuation)
    joint_target_kd_out: wp.array[float],  # optional
    joint_effort_limit_out: wp.array[float],
    joint_friction_out: wp.array[float],
):
    """Copy given values into the per-env drive arrays (and the model) for the selected envs."""
    tid = wp.tid()
    env, rl, i = _select(tid, num_rows, env_ids_in, env_mask_in, kp_out.shape[0])
    if env < 0:
        return
    r = row0 + rl
    b = 0
    if values_in.shape[1] > 1:
        b = i
        if env_mask_in:
            b = env  # a mask selects from values of shape (num_envs, n)
    for p in range(4):
        if enabled[p] != 0:
            x = values_in[p, b, rl]
            _store(
                env,
                r,
                p,
                x,
                kp_out,
                kd_out,
                force_limit_out,
                friction_out,
                row_accel,
                row_qd_off,
                env_qd_base,
                response_in,
                joint_target_ke_out,
                joint_target_kd_out,
                joint_effort_limit_out,
                joint_friction_out,
            )


class DriveProperties(Part):
    name = "drive_properties"

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
                _set_drive_kernel,
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
                _randomize_drive_kernel,
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
            wp.launch(_bump_counter_kernel, dim=1, inputs=[c.rng_counter], device=engine.device)
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
    vel_target = np.isin(rows.kind, (ROW_VEL, ROW_PASSIVE)) | (
        (rows.kind == ROW_POS) & ((rows.flags & FLAG_VEL_TARGET) != 0)
    )
    if plan.explicit:
        row_mode = np.full(plan.num_rows, int(newton.JointTargetMode.EFFORT), np.int32)
        ke[dof] = 0.0
        kd[dof] = 0.0
    else:
        row_mode = np.where(
            rows.kind == ROW_POS,
            np.where(vel_target, int(newton.JointTargetMode.POSITION_VELOCITY), int(newton.JointTargetMode.POSITION)),
            int(newton.JointTargetMode.VELOCITY),
        ).astype(np.int32)
        ke[dof] = rows.kp[None, :]
        kd[dof] = rows.kd[None, :]
    effort = rows.kind == ROW_EFFORT  # commanded efforts: the built-in drive off in both actuations
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
    pos = rows.kind == ROW_POS
    tq[coord[:, pos]] = q0[coord[:, pos]]
    tq[coord[:, ~pos]] = 0.0
    tqd[dof[:, vel_target]] = 0.0
    m.joint_target_q.assign(tq)
    m.joint_target_qd.assign(tqd)
    return bool((old_mode != mode).any())
