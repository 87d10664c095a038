"""The ``set_action`` kernel of a control mode, generated for its :class:`~.step_layout.StepLayout` (see
:mod:`wpctrl.kernels.pd_step` for what it computes). Private module."""

from __future__ import annotations

import warp as wp

from ..config.rows import FLAG_BINARY, FLAG_DELTA, FLAG_EMA, FLAG_NORMALIZE, FLAG_TARGET, ROW_EFFORT, ROW_POS, ROW_VEL
from .pd import _scale
from .step_layout import (
    ROW_F_ALPHA,
    ROW_F_HI,
    ROW_F_LO,
    ROW_F_MUL,
    ROW_F_OFF,
    ROW_F_QHI,
    ROW_F_QLO,
    ROW_F_VLO,
    StepLayout,
    _make_row_indices,
)


def _make_set_action_kernel(L: StepLayout) -> wp.Kernel:
    R = len(L.kind)
    A = L.action_dim
    KIND, FLAGS, COL, VCOL, SRC = L.kind, L.flags, L.act_col, L.vel_col, L.mimic_src
    CLIP = bool(L.clip)
    POS, VEL = ROW_POS, ROW_VEL
    NORM = tuple(int(f & FLAG_NORMALIZE != 0) for f in FLAGS)
    DELTA = tuple(int(f & FLAG_DELTA != 0) for f in FLAGS)
    TARGET = tuple(int(f & FLAG_TARGET != 0) for f in FLAGS)
    IS_POS = tuple(int(k == POS) for k in KIND)
    EMA = tuple(int(f & FLAG_EMA != 0) for f in FLAGS)
    BINARY = tuple(int(f & FLAG_BINARY != 0) for f in FLAGS)
    # Position rows that own their target (followers take their source's), and those that read the previous one.
    LEAD = tuple(int(KIND[r] == POS and SRC[r] < 0) for r in range(R))
    READ_T = tuple(int(LEAD[r] and (COL[r] < 0 or (DELTA[r] and TARGET[r]) or EMA[r])) for r in range(R))
    # Effort rows (JointEffortController): the scaled action column is the commanded effort.
    ESRC = tuple(COL[r] if KIND[r] == ROW_EFFORT else -1 for r in range(R))
    WRITE_T = tuple(int(IS_POS[r] and not (SRC[r] < 0 and COL[r] < 0)) for r in range(R))
    # Velocity targets: a velocity row's column, or a position-velocity row's second column.
    VSRC = tuple(COL[r] if (KIND[r] == VEL and SRC[r] < 0) else (VCOL[r] if LEAD[r] else -1) for r in range(R))
    # Ego-centric base rows: (vx, vy) rotated by the measured yaw of row YAW[r] (ManiSkill's pd_base_vel).
    BASE = L.base_axis or (-1,) * R
    YAW = L.yaw_row or (-1,) * R
    BX = L.bx_col or (-1,) * R
    BY = L.by_col or (-1,) * R
    HAS_VT = tuple(int(VSRC[r] >= 0 or BASE[r] >= 0) for r in range(R))
    YAW_SRC = {YAW[r] for r in range(R) if BASE[r] >= 0}
    READ_Q = tuple(int(IS_POS[r] or r in YAW_SRC) for r in range(R))
    VBOUND = tuple(ROW_F_LO if KIND[r] == VEL else ROW_F_VLO for r in range(R))  # row_f column of the velocity bounds
    vec_a = wp.types.vector(length=max(A, 1), dtype=wp.float32)
    vec_r = wp.types.vector(length=max(R, 1), dtype=wp.float32)
    row_indices = _make_row_indices(L)

    def set_action(
        # Rows:
        row_f: wp.array2d[float],
        # Envs x rows:
        q_idx: wp.array2d[wp.int32],  # (num_envs, rows) for a non-replicated layout; unused otherwise
        qd_idx: wp.array2d[wp.int32],
        q_stride: int,
        qd_stride: int,
        host_substeps: int,
        # In:
        action_in: wp.array2d[float],  # (num_envs, action_dim)
        joint_q_in: wp.array[float],  # [rad or m]
        # Out:
        processed_action_out: wp.array2d[float],
        start_qpos_out: wp.array2d[float],  # [rad or m]
        target_qpos_out: wp.array2d[float],  # in/out: the previous (virtual) target [rad or m]
        target_qvel_out: wp.array2d[float],  # [rad/s or m/s]
        target_effort_out: wp.array2d[float],  # with effort rows: the commanded effort [N·m or N]
        step_out: wp.array[wp.int32],  # in/out (held envs)
        bad_action_count_out: wp.array[wp.int32],  # in/out
        joint_target_q_out: wp.array[float],  # optional: the drive targets, when no substep launch writes them
        joint_target_qd_out: wp.array[float],  # optional
    ):
        env = wp.tid()
        # Loads first, all of them (one pass over each array's sectors), then the arithmetic, then the stores grouped
        # by array: the compiler cannot move a load above a store to another array (they might alias).
        a = vec_a()
        ok = int(1)
        for c in range(wp.static(A)):
            a[c] = action_in[env, c]
            ok = ok & int(wp.isfinite(a[c]))
        if ok == 0:  # hold the whole env; count it; its substep counter keeps counting
            bad_action_count_out[env] = bad_action_count_out[env] + 1
            step_out[env] = step_out[env] + host_substeps
            return
        qi, di = row_indices(env, q_idx, qd_idx, q_stride, qd_stride)
        q = vec_r()
        t = vec_r()
        for r in range(wp.static(R)):
            if wp.static(READ_Q[r]):
                q[r] = joint_q_in[qi[r]]
            if wp.static(READ_T[r]):
                t[r] = target_qpos_out[env, r]
        # Targets of the rows that own one, then their followers: target[m] = target[source] * mul + off.
        x = vec_a()
        for r in range(wp.static(R)):
            if wp.static(LEAD[r] and COL[r] >= 0):
                c = wp.static(COL[r])
                tp = t[r]  # the previous target (EMA)
                if wp.static(BINARY[r]):  # the action's sign: open (upper) for a >= 0, close (lower) below
                    if a[c] < 0.0:
                        x[c] = row_f[r, ROW_F_LO]
                    else:
                        x[c] = row_f[r, ROW_F_HI]
                else:
                    x[c] = _scale(a[c], row_f[r, ROW_F_LO], row_f[r, ROW_F_HI], wp.static(NORM[r]))
                if wp.static(DELTA[r] and TARGET[r]):
                    t[r] = t[r] + x[c]
                elif wp.static(DELTA[r]):
                    t[r] = q[r] + x[c]
                else:
                    t[r] = x[c]
                if wp.static(EMA[r]):  # alpha * target + (1 - alpha) * previous, within the joint's limits
                    al = row_f[r, ROW_F_ALPHA]
                    t[r] = wp.clamp(al * t[r] + (1.0 - al) * tp, row_f[r, ROW_F_QLO], row_f[r, ROW_F_QHI])
                if wp.static(CLIP):  # the joint's limits: a virtual target cannot run past them
                    t[r] = wp.clamp(t[r], row_f[r, ROW_F_QLO], row_f[r, ROW_F_QHI])
            if wp.static(ESRC[r] >= 0):
                c = wp.static(ESRC[r])
                x[c] = _scale(a[c], row_f[r, ROW_F_LO], row_f[r, ROW_F_HI], wp.static(NORM[r]))
            if wp.static(VSRC[r] >= 0):
                c = wp.static(VSRC[r])
                x[c] = _scale(
                    a[c], row_f[r, wp.static(VBOUND[r])], row_f[r, wp.static(VBOUND[r] + 1)], wp.static(NORM[r])
                )
        for r in range(wp.static(R)):
            if wp.static(IS_POS[r] and SRC[r] >= 0):
                t[r] = t[wp.static(max(SRC[r], 0))] * row_f[r, ROW_F_MUL] + row_f[r, ROW_F_OFF]
                if wp.static(CLIP):
                    t[r] = wp.clamp(t[r], row_f[r, ROW_F_QLO], row_f[r, ROW_F_QHI])
        # Velocity targets: the scaled action column, or for a base row the planar action in the world frame,
        # R(yaw) [vx, vy] with R = [[c, -s], [s, c]] of the measured yaw (a missing vy column is 0: forward-only base).
        vt = vec_r()
        for r in range(wp.static(R)):
            if wp.static(BASE[r] >= 0):
                yaw = q[wp.static(max(YAW[r], 0))]
                cy = wp.cos(yaw)
                sy = wp.sin(yaw)
                ax = float(0.0)
                ay = float(0.0)
                if wp.static(BX[r] >= 0):
                    ax = x[wp.static(max(BX[r], 0))]
                if wp.static(BY[r] >= 0):
                    ay = x[wp.static(max(BY[r], 0))]
                if wp.static(BASE[r] == 0):
                    vt[r] = cy * ax + (-sy) * ay
                else:
                    vt[r] = sy * ax + cy * ay
            elif wp.static(VSRC[r] >= 0):
                vt[r] = x[wp.static(max(VSRC[r], 0))]
        step_out[env] = 0
        for c in range(wp.static(A)):
            if wp.static(c in COL or c in VSRC or c in ESRC):
                processed_action_out[env, c] = x[c]
        for r in range(wp.static(R)):
            if wp.static(IS_POS[r]):
                start_qpos_out[env, r] = q[r]
        for r in range(wp.static(R)):
            if wp.static(WRITE_T[r]):
                target_qpos_out[env, r] = t[r]
        for r in range(wp.static(R)):
            if wp.static(HAS_VT[r]):
                target_qvel_out[env, r] = vt[r]
        for r in range(wp.static(R)):
            if wp.static(ESRC[r] >= 0):
                target_effort_out[env, r] = x[wp.static(max(ESRC[r], 0))]
        if joint_target_q_out:
            for r in range(wp.static(R)):
                if wp.static(IS_POS[r]):
                    joint_target_q_out[qi[r]] = t[r]
        if joint_target_qd_out:
            for r in range(wp.static(R)):
                if wp.static(HAS_VT[r]):
                    joint_target_qd_out[di[r]] = vt[r]

    return wp.kernel(set_action, name="wpctrl_set_action", enable_backward=False, module="unique")
