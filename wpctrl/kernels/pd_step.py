"""The per-step PD kernels (``set_action`` and the solver substep), specialised at compile time on the row layout.

Private module. One thread per env runs every row of the control mode, with the rows unrolled: a row's kind, flags,
action columns, mimic source, acceleration-drive flag and (for replicated worlds) its coordinate / DOF index in env 0
are compile-time constants of the kernel (:class:`StepLayout`, ``wp.static``). So a thread issues all its loads at
once (its action row, then the measured coordinates of every row, no chain of table loads), checks its action row for
NaN/Inf once, keeps a mimic source's fresh target in a register for its followers, and runs no branch on row tables.
What stays a runtime array: the per-row float bounds ``row_f`` (one ``(rows, 8)`` table read uniformly by every
thread, so configs that differ only in bounds share a kernel), the per-env drive properties and Newton's arrays.
A control mode compiles its two kernels once (Warp's kernel cache keeps them across runs); modes with the same layout
share them.

Every kernel body is written as: all loads, then the arithmetic, then the stores grouped by array. The compiler may not
move a load above a store to another array that might alias it, so interleaving them row by row would cost a memory
round trip per row (and, at 1M envs, re-fetch the sectors evicted in between). The controller's own
``(num_envs, rows)`` arrays are column-major views (``_Engine``'s ``per_env``), so a warp's access of one row is 32
consecutive values; Newton's per-world arrays are read and written where they are.

Row float table ``row_f[r]``: ``lo, hi`` (action bounds of the row's position / velocity column), ``vlo, vhi`` (the
velocity column of a position-velocity row), ``mimic_mul, mimic_off`` (a follower's coupling), ``qlo, qhi`` (joint
limits [rad or m], for ``clip_targets``).

Semantics are those of ManiSkill's controllers (``kernels/pd.py`` states the state arrays' meaning):

- ``set_action``: an env whose action holds NaN/Inf is left untouched and counted; its substep counter keeps counting
  (``host_substeps`` carries the substeps the host counted for an elided substep launch). Otherwise every position
  row snapshots the measured coordinate (``start_qpos``) and computes its target (normalise, clip, absolute / delta
  from the measured coordinate / delta on the previous target, optional clamp to the joint limits); a follower takes
  ``target[source] * mul + off``; velocity columns set the velocity targets. Without per-substep work the kernel also
  writes the drive targets into the Control (``joint_target_q_out`` / ``joint_target_qd_out`` given).
- ``substep``: bumps the env's substep counter ``k`` (ManiSkill's ``_step``), interpolates ``start + k (target -
  start) / K`` (held at K) on interpolating rows, pushes / pops the command delay ring, writes the drive targets and,
  for explicit actuation, the clamped PD torque (naive, or stable: on the end-of-step state of a semi-implicit step).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import warp as wp

from ..config import rows as _cfg
from .pd import _bidx, _interp, _scale

# Columns of the row float table ``row_f``.
ROW_F_LO = wp.constant(0)
ROW_F_HI = wp.constant(1)
ROW_F_VLO = wp.constant(2)
ROW_F_VHI = wp.constant(3)
ROW_F_MUL = wp.constant(4)
ROW_F_OFF = wp.constant(5)
ROW_F_QLO = wp.constant(6)
ROW_F_QHI = wp.constant(7)
ROW_F_WIDTH = 8


class StepLayout(NamedTuple):
    """What the step kernels are compiled for: the control mode's rows (tuples of ints, one entry per row) and its
    options. ``q_off`` / ``qd_off`` are env 0's coordinate / DOF index of each row for a replicated layout (env e at
    ``+ e * stride``), or ``None``: per-env ``(num_envs, rows)`` index tables."""

    kind: tuple
    flags: tuple
    act_col: tuple
    vel_col: tuple
    mimic_src: tuple
    accel: tuple
    q_off: tuple | None
    qd_off: tuple | None
    action_dim: int
    clip: bool = False
    explicit: int = 0  # 0 off (implicit or coupled), 1 naive, 2 stable
    delay: bool = False
    delay_vel: bool = False  # the delay ring also holds velocity targets
    effort: bool = False
    # Ego-centric base rows (set_action only): yaw source row, axis (0 x, 1 y, -1 none), vx / vy action columns.
    yaw_row: tuple = ()
    base_axis: tuple = ()
    bx_col: tuple = ()
    by_col: tuple = ()


def row_float_table(rows: _cfg.Rows, qlimits: np.ndarray) -> np.ndarray:
    """``(rows, 8)`` float32: the per-row bounds, mimic coupling and joint limits the step kernels read."""
    t = np.zeros((rows.count, ROW_F_WIDTH), np.float32)
    t[:, ROW_F_LO], t[:, ROW_F_HI] = rows.lo, rows.hi
    t[:, ROW_F_VLO], t[:, ROW_F_VHI] = rows.vlo, rows.vhi
    t[:, ROW_F_MUL], t[:, ROW_F_OFF] = rows.mimic_mul, rows.mimic_off
    t[:, ROW_F_QLO], t[:, ROW_F_QHI] = qlimits[:, 0], qlimits[:, 1]
    return t


_SET_ACTION: dict[StepLayout, wp.Kernel] = {}
_SUBSTEP: dict[StepLayout, wp.Kernel] = {}


def set_action_kernel(layout: StepLayout) -> wp.Kernel:
    """The set_action kernel of ``layout`` (compiled once per layout and process; Warp caches it on disk)."""
    k = _SET_ACTION.get(layout)
    if k is None:
        k = _SET_ACTION[layout] = _make_set_action_kernel(layout)
    return k


def substep_kernel(layout: StepLayout) -> wp.Kernel:
    """The substep kernel of ``layout``; set_action-only fields of the layout are ignored."""
    key = layout._replace(
        act_col=(), vel_col=(), mimic_src=(), action_dim=0, clip=False, yaw_row=(), base_axis=(), bx_col=(), by_col=()
    )
    k = _SUBSTEP.get(key)
    if k is None:
        k = _SUBSTEP[key] = _make_substep_kernel(key)
    return k


def _make_row_indices(L: StepLayout):
    """``row_indices(env, ...) -> (qi, di)``: every row's coordinate / DOF index in Newton's flat arrays for ``env``,
    as ``env * stride`` plus env 0's (compile-time) index for a replicated layout, else from the index tables."""
    R = len(L.kind)
    STRIDED = L.q_off is not None
    QOFF = L.q_off if STRIDED else (0,) * R
    QDOFF = L.qd_off if STRIDED else (0,) * R
    vec_ri = wp.types.vector(length=max(R, 1), dtype=wp.int32)

    @wp.func
    def row_indices(env: int, q_idx: wp.array2d[wp.int32], qd_idx: wp.array2d[wp.int32], q_stride: int, qd_stride: int):
        qi = vec_ri()
        di = vec_ri()
        for r in range(wp.static(R)):
            if wp.static(STRIDED):
                qi[r] = env * q_stride + wp.static(QOFF[r])
                di[r] = env * qd_stride + wp.static(QDOFF[r])
            else:
                qi[r] = q_idx[env, r]
                di[r] = qd_idx[env, r]
        return qi, di

    return row_indices


def _make_set_action_kernel(L: StepLayout) -> wp.Kernel:
    R = len(L.kind)
    A = L.action_dim
    KIND, FLAGS, COL, VCOL, SRC = L.kind, L.flags, L.act_col, L.vel_col, L.mimic_src
    CLIP = bool(L.clip)
    POS, VEL = _cfg.ROW_POS, _cfg.ROW_VEL
    NORM = tuple(int(f & _cfg.FLAG_NORMALIZE != 0) for f in FLAGS)
    DELTA = tuple(int(f & _cfg.FLAG_DELTA != 0) for f in FLAGS)
    TARGET = tuple(int(f & _cfg.FLAG_TARGET != 0) for f in FLAGS)
    IS_POS = tuple(int(k == POS) for k in KIND)
    # Position rows that own their target (followers take their source's), and those that read the previous one.
    LEAD = tuple(int(KIND[r] == POS and SRC[r] < 0) for r in range(R))
    READ_T = tuple(int(LEAD[r] and (COL[r] < 0 or (DELTA[r] and TARGET[r]))) for r in range(R))
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
                x[c] = _scale(a[c], row_f[r, ROW_F_LO], row_f[r, ROW_F_HI], wp.static(NORM[r]))
                if wp.static(DELTA[r] and TARGET[r]):
                    t[r] = t[r] + x[c]
                elif wp.static(DELTA[r]):
                    t[r] = q[r] + x[c]
                else:
                    t[r] = x[c]
                if wp.static(CLIP):  # the joint's limits: a virtual target cannot run past them
                    t[r] = wp.clamp(t[r], row_f[r, ROW_F_QLO], row_f[r, ROW_F_QHI])
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
            if wp.static(c in COL or c in VSRC):
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
        if joint_target_q_out:
            for r in range(wp.static(R)):
                if wp.static(IS_POS[r]):
                    joint_target_q_out[qi[r]] = t[r]
        if joint_target_qd_out:
            for r in range(wp.static(R)):
                if wp.static(HAS_VT[r]):
                    joint_target_qd_out[di[r]] = vt[r]

    return wp.kernel(set_action, name="wpctrl_set_action", enable_backward=False, module="unique")


def _make_substep_kernel(L: StepLayout) -> wp.Kernel:
    R = len(L.kind)
    KIND, FLAGS, ACCEL = L.kind, L.flags, L.accel
    POS = _cfg.ROW_POS
    IS_POS = tuple(int(k == POS) for k in KIND)
    VT = tuple(int(k != POS or (f & _cfg.FLAG_VEL_TARGET) != 0) for k, f in zip(KIND, FLAGS))
    INTERP = tuple(int(f & _cfg.FLAG_INTERPOLATE != 0) for f in FLAGS)
    EXPLICIT, STABLE = L.explicit != 0, L.explicit == 2
    DELAY, DELAY_VEL, EFFORT = bool(L.delay), bool(L.delay_vel), bool(L.effort)
    TORQUE = EXPLICIT or EFFORT
    RESP = tuple(int(STABLE or ACCEL[r] != 0) for r in range(R))
    vec_r = wp.types.vector(length=max(R, 1), dtype=wp.float32)
    vec_ri = wp.types.vector(length=max(R, 1), dtype=wp.int32)
    row_indices = _make_row_indices(L)

    def substep(
        # Envs x rows:
        q_idx: wp.array2d[wp.int32],  # (num_envs, rows) for a non-replicated layout; unused otherwise
        qd_idx: wp.array2d[wp.int32],
        q_stride: int,
        qd_stride: int,
        # Drive properties (1 | num_envs, rows):
        kp: wp.array2d[float],  # [N·m/rad or N/m; 1/s² for an acceleration drive]
        kd: wp.array2d[float],  # [N·m·s/rad or N·s/m; 1/s]
        force_limit: wp.array2d[float],  # [N·m or N]
        num_substeps: int,
        dt: float,  # [s] one solver substep
        max_delay: int,  # [substeps]
        # In:
        joint_q_in: wp.array[float],  # [rad or m]
        joint_qd_in: wp.array[float],  # [rad/s or m/s]
        response_in: wp.array2d[float],  # (1 | num_envs, rows) r = (H^-1)_ii [1/(kg m²) or 1/kg]
        start_qpos_in: wp.array2d[float],
        target_qpos_in: wp.array2d[float],
        target_qvel_in: wp.array2d[float],
        delay_in: wp.array[wp.int32],  # with DELAY: (num_envs,) [substeps]
        # Out:
        step_out: wp.array[wp.int32],  # in/out: ManiSkill's _step
        delay_head_out: wp.array2d[wp.int32],  # in/out, with DELAY: each row's ring-buffer slot
        delay_q_out: wp.array3d[float],  # in/out, with DELAY: (max_delay + 1, num_envs, rows)
        delay_qd_out: wp.array3d[float],  # in/out, with DELAY_VEL
        joint_target_q_out: wp.array[float],
        joint_target_qd_out: wp.array[float],
        joint_f_out: wp.array[float],  # with explicit actuation [N·m or N]
        computed_effort_out: wp.array2d[float],  # with EFFORT: PD law before the clamp [N·m or N]
        applied_effort_out: wp.array2d[float],  # with EFFORT: after the clamp
        saturation_count_out: wp.array2d[wp.int32],  # with EFFORT, in/out: substeps with |computed| > limit
    ):
        env = wp.tid()
        # Loads first (each array's sectors in one pass), then the arithmetic, then the stores grouped by array.
        k = step_out[env] + 1
        qi, di = row_indices(env, q_idx, qd_idx, q_stride, qd_stride)
        tq = vec_r()
        tqd = vec_r()
        for r in range(wp.static(R)):
            if wp.static(IS_POS[r]):
                tq[r] = target_qpos_in[env, r]
        for r in range(wp.static(R)):
            if wp.static(VT[r]):
                tqd[r] = target_qvel_in[env, r]
        for r in range(wp.static(R)):
            if wp.static(INTERP[r]):
                tq[r] = _interp(start_qpos_in[env, r], tq[r], k, num_substeps)
        q = vec_r()
        qd = vec_r()
        kpe = vec_r()
        kde = vec_r()
        lim = vec_r()
        resp = vec_r()
        if wp.static(TORQUE):
            kb = _bidx(kp.shape[0], env)
            db = _bidx(kd.shape[0], env)
            lb = _bidx(force_limit.shape[0], env)
            rb = _bidx(response_in.shape[0], env)
            for r in range(wp.static(R)):
                if wp.static(IS_POS[r]):
                    q[r] = joint_q_in[qi[r]]
            for r in range(wp.static(R)):
                qd[r] = joint_qd_in[di[r]]
            for r in range(wp.static(R)):
                if wp.static(IS_POS[r]):
                    kpe[r] = kp[kb, r]
            for r in range(wp.static(R)):
                kde[r] = kd[db, r]
            for r in range(wp.static(R)):
                lim[r] = force_limit[lb, r]
            for r in range(wp.static(R)):
                if wp.static(RESP[r]):
                    resp[r] = response_in[rb, r]
        sat = vec_ri()
        if wp.static(EFFORT):
            for r in range(wp.static(R)):
                sat[r] = saturation_count_out[env, r]
        if wp.static(DELAY):
            # Push this substep's command, pop the one from delay[env] substeps ago (a reset filled the ring). Every
            # ring read comes before the writes: a pop from the slot being pushed (delay 0) takes the new command.
            d = wp.clamp(delay_in[env], 0, max_delay)
            hs = vec_ri()
            for r in range(wp.static(R)):
                h = delay_head_out[env, r] + 1
                if h > max_delay:
                    h = 0
                hs[r] = h
            old_q = vec_r()
            old_qd = vec_r()
            for r in range(wp.static(R)):
                sl = hs[r] - d
                if sl < 0:
                    sl = sl + max_delay + 1
                if sl != hs[r]:
                    old_q[r] = delay_q_out[sl, env, r]
                    if wp.static(DELAY_VEL):
                        old_qd[r] = delay_qd_out[sl, env, r]
                else:
                    old_q[r] = tq[r]
                    old_qd[r] = tqd[r]
            step_out[env] = k
            for r in range(wp.static(R)):
                delay_head_out[env, r] = hs[r]
            for r in range(wp.static(R)):
                delay_q_out[hs[r], env, r] = tq[r]
            if wp.static(DELAY_VEL):
                for r in range(wp.static(R)):
                    delay_qd_out[hs[r], env, r] = tqd[r]
            for r in range(wp.static(R)):
                tq[r] = old_q[r]
                if wp.static(DELAY_VEL):
                    tqd[r] = old_qd[r]
        else:
            step_out[env] = k
        for r in range(wp.static(R)):
            if wp.static(VT[r]):
                joint_target_qd_out[di[r]] = tqd[r]
        for r in range(wp.static(R)):
            if wp.static(IS_POS[r]):
                joint_target_q_out[qi[r]] = tq[r]
        if wp.static(TORQUE):
            u = vec_r()
            f = vec_r()
            for r in range(wp.static(R)):
                e = float(0.0)
                if wp.static(IS_POS[r]):
                    e = tq[r] - q[r]
                kpr = kpe[r]
                kdr = kde[r]
                if wp.static(ACCEL[r] != 0):  # acceleration drive: gains times the effective inertia 1/r
                    kpr = kpr / resp[r]
                    kdr = kdr / resp[r]
                if wp.static(STABLE):
                    # PD on the end-of-step state of a semi-implicit Euler step, solved with the joint's response r:
                    # u = Kp (q* - q - dt qd) + Kd (qd* - qd) over 1 + r dt (Kd + dt Kp)
                    u[r] = (kpr * (e - dt * qd[r]) + kdr * (tqd[r] - qd[r])) / (1.0 + resp[r] * dt * (kdr + dt * kpr))
                else:
                    u[r] = kpr * e + kdr * (tqd[r] - qd[r])
                f[r] = wp.clamp(u[r], -lim[r], lim[r])
            if wp.static(EXPLICIT):
                for r in range(wp.static(R)):
                    joint_f_out[di[r]] = f[r]
            if wp.static(EFFORT):
                for r in range(wp.static(R)):
                    computed_effort_out[env, r] = u[r]
                for r in range(wp.static(R)):
                    applied_effort_out[env, r] = f[r]
                for r in range(wp.static(R)):
                    if wp.abs(u[r]) > lim[r]:
                        saturation_count_out[env, r] = sat[r] + 1

    return wp.kernel(substep, name="wpctrl_substep", enable_backward=False, module="unique")
