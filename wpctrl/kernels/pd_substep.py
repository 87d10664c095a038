"""The solver-substep kernel of a control mode, generated for its :class:`~.step_layout.StepLayout` (see
:mod:`wpctrl.kernels.pd_step` for what it computes). Private module."""

from __future__ import annotations

import hashlib

import warp as wp

from ..config.actuator_models import ACT_DC_MOTOR, ACT_NET, ACT_NONE, ACT_POSITION_LIMIT
from ..config.rows import FLAG_INTERPOLATE, FLAG_VEL_TARGET, ROW_EFFORT, ROW_PASSIVE, ROW_POS, ROW_VEL
from .actuator_models import dc_motor_clamp
from .actuator_net import NetIO, net_kernel, read_row
from .actuator_net_unrolled import unrolled_row
from .pd import _bidx, _interp
from .step_layout import StepLayout, _make_row_indices


def _make_substep_kernel(L: StepLayout, net: tuple | None = None) -> wp.Kernel:
    """The substep kernel of ``layout``: one thread per env. With ``net`` = ``(NetLayout, weights, scales)``, the
    kernel also runs that actuator network's rows, unrolled, in the same launch (:mod:`.actuator_net_fused`): threads
    ``0 .. num_envs * rows - 1`` run a network row each, the next ``num_envs`` the envs. One signature for both: a
    kernel without the network takes ``row0``, ``io`` and ``hist_out`` and never reads them."""
    NET = net is not None
    if NET:
        NL, weights, scales = net
        row = unrolled_row(NL, weights, scales)
        N, Q_LIN, QD_LIN = NL.rows, NL.q_lin, NL.qd_lin
        vec_p = wp.types.vector(length=max(2 * NL.past, 1), dtype=wp.float32)
    else:
        row, N, Q_LIN, QD_LIN = None, 0, 0, 0
        vec_p = wp.types.vector(length=1, dtype=wp.float32)
    R = len(L.kind)
    KIND, FLAGS, ACCEL = L.kind, L.flags, L.accel
    POS, VEL, PASSIVE, EFF = ROW_POS, ROW_VEL, ROW_PASSIVE, ROW_EFFORT
    IS_POS = tuple(int(k == POS) for k in KIND)
    VT = tuple(int(k in (VEL, PASSIVE) or (k == POS and (f & FLAG_VEL_TARGET) != 0)) for k, f in zip(KIND, FLAGS))
    INTERP = tuple(int(f & FLAG_INTERPOLATE != 0) for f in FLAGS)
    EXPLICIT, STABLE = L.explicit != 0, L.explicit == 2
    DELAY, DELAY_VEL, EFFORT = bool(L.delay), bool(L.delay_vel), bool(L.effort)
    # Effort rows carry their commanded effort in the target register (so a delay delays it too).
    IS_EFF = tuple(int(k == EFF) for k in KIND)
    ACT = L.act_model or (ACT_NONE,) * R
    # Position tables as compile-time constants (kernels.actuator_models.table_constants), a placeholder without one.
    TAB = tuple(t or (0.0, 0.0, 0.0, ()) for t in (L.limit_table or ((),) * R))
    # Rows whose torque this kernel computes: PD rows with explicit actuation or the effort readout (not the rows of
    # an actuator network, whose own launch follows), and effort rows.
    TAU = tuple(int(IS_EFF[r] or ((EXPLICIT or EFFORT) and ACT[r] != ACT_NET)) for r in range(R))
    WRITE_F = tuple(int(IS_EFF[r] or (EXPLICIT and ACT[r] != ACT_NET)) for r in range(R))
    TORQUE = any(TAU)
    RESP = tuple(int(STABLE or ACCEL[r] != 0) for r in range(R))
    READ_Q = tuple(int(TAU[r] and (IS_POS[r] or ACT[r] == ACT_POSITION_LIMIT)) for r in range(R))
    HAS_DC = any(a == ACT_DC_MOTOR for a in ACT)
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
        sat_effort: wp.array2d[float],  # with DC motors: stall effort [N·m or N]
        vel_limit: wp.array2d[float],  # with DC motors: no-load speed [rad/s or m/s]
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
        target_effort_in: wp.array2d[float],  # with effort rows [N·m or N]
        delay_in: wp.array[wp.int32],  # with DELAY: (num_envs,) [substeps]
        # Out:
        step_out: wp.array[wp.int32],  # in/out: ManiSkill's _step
        delay_head_out: wp.array2d[wp.int32],  # in/out, with DELAY: each row's ring-buffer slot
        delay_q_out: wp.array3d[float],  # in/out, with DELAY: (max_delay + 1, num_envs, rows)
        delay_qd_out: wp.array3d[float],  # in/out, with DELAY_VEL
        joint_target_q_out: wp.array[float],
        joint_target_qd_out: wp.array[float],
        joint_f_out: wp.array[float],  # with explicit actuation or effort rows [N·m or N]
        computed_effort_out: wp.array2d[float],  # with EFFORT: PD law before the clamp [N·m or N]
        applied_effort_out: wp.array2d[float],  # with EFFORT: after the clamp
        saturation_count_out: wp.array2d[wp.int32],  # with EFFORT, in/out: substeps with |computed| > limit
        # With the network in this launch (actuator_net_fused): its first row, arrays and history; else unused:
        row0: int,
        io: NetIO,
        hist_out: wp.array[float],
    ):
        env = wp.tid()
        if wp.static(NET):  # threads 0 .. num_envs * N - 1 run the network's rows, the rest the envs
            num_envs = step_out.shape[0]
            if env < num_envs * wp.static(N):
                net_env = env // wp.static(N)
                j = env - net_env * wp.static(N)
                net_r = row0 + j
                net_qi, net_di, net_q, net_qd, net_lim, net_sat, net_vl = read_row(
                    io, wp.static(Q_LIN), wp.static(QD_LIN), net_env, net_r, j, joint_q_in, joint_qd_in
                )
                # the target from the mode's table: what the env threads write to joint_target_q in this launch
                net_err = target_qpos_in[net_env, net_r] - net_q
                row(env, net_env, net_r, net_di, net_err, net_qd, net_lim, net_sat, net_vl, io, hist_out, joint_f_out)
                return
            env = env - num_envs * wp.static(N)
        # Loads first (each array's sectors in one pass), then the arithmetic, then the stores grouped by array.
        k = step_out[env] + 1
        qi, di = row_indices(env, q_idx, qd_idx, q_stride, qd_stride)
        tq = vec_r()
        tqd = vec_r()
        for r in range(wp.static(R)):
            if wp.static(IS_POS[r]):
                tq[r] = target_qpos_in[env, r]
            elif wp.static(IS_EFF[r]):
                tq[r] = target_effort_in[env, r]
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
        sate = vec_r()
        vlim = vec_r()
        if wp.static(TORQUE):
            kb = _bidx(kp.shape[0], env)
            db = _bidx(kd.shape[0], env)
            lb = _bidx(force_limit.shape[0], env)
            rb = _bidx(response_in.shape[0], env)
            for r in range(wp.static(R)):
                if wp.static(READ_Q[r]):
                    q[r] = joint_q_in[qi[r]]
            for r in range(wp.static(R)):
                if wp.static(TAU[r] and not IS_EFF[r]):
                    qd[r] = joint_qd_in[di[r]]
            for r in range(wp.static(R)):
                if wp.static(TAU[r] and IS_POS[r]):
                    kpe[r] = kp[kb, r]
            for r in range(wp.static(R)):
                if wp.static(TAU[r] and not IS_EFF[r]):
                    kde[r] = kd[db, r]
            for r in range(wp.static(R)):
                if wp.static(TAU[r]):
                    lim[r] = force_limit[lb, r]
            for r in range(wp.static(R)):
                if wp.static(TAU[r] and RESP[r]):
                    resp[r] = response_in[rb, r]
            if wp.static(HAS_DC):
                for r in range(wp.static(R)):
                    if wp.static(TAU[r] and ACT[r] == ACT_DC_MOTOR):
                        sate[r] = sat_effort[env, r]
                        vlim[r] = vel_limit[env, r]
        sat = vec_ri()
        if wp.static(EFFORT):
            for r in range(wp.static(R)):
                if wp.static(TAU[r]):
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
                if wp.static(IS_EFF[r]):
                    u[r] = tq[r]  # the commanded effort
                elif wp.static(TAU[r]):
                    e = float(0.0)
                    if wp.static(IS_POS[r]):
                        e = tq[r] - q[r]
                    kpr = kpe[r]
                    kdr = kde[r]
                    if wp.static(ACCEL[r] != 0):  # acceleration drive: gains times the effective inertia 1/r
                        kpr = kpr / resp[r]
                        kdr = kdr / resp[r]
                    if wp.static(STABLE):
                        # PD on the end-of-step state of a semi-implicit Euler step, solved with the joint's response
                        # r: u = Kp (q* - q - dt qd) + Kd (qd* - qd) over 1 + r dt (Kd + dt Kp)
                        u[r] = (kpr * (e - dt * qd[r]) + kdr * (tqd[r] - qd[r])) / (
                            1.0 + resp[r] * dt * (kdr + dt * kpr)
                        )
                    else:
                        u[r] = kpr * e + kdr * (tqd[r] - qd[r])
                if wp.static(TAU[r]):
                    if wp.static(ACT[r] == ACT_DC_MOTOR):
                        f[r] = dc_motor_clamp(u[r], qd[r], sate[r], vlim[r], lim[r])
                    elif wp.static(ACT[r] == ACT_POSITION_LIMIT):
                        # The table at q (end values held outside): the first piece whose right end is >= q, each
                        # piece one multiply-add of constants (slope, intercept) and a select.
                        fl = wp.static(TAB[r][2])
                        for kk in range(wp.static(len(TAB[r][3]))):
                            fl = wp.where(
                                q[r] <= wp.static(TAB[r][3][kk][0]),
                                q[r] * wp.static(TAB[r][3][kk][1]) + wp.static(TAB[r][3][kk][2]),
                                fl,
                            )
                        fl = wp.where(q[r] <= wp.static(TAB[r][0]), wp.static(TAB[r][1]), fl)
                        fl = wp.min(fl, lim[r])
                        f[r] = wp.clamp(u[r], -fl, fl)
                    else:
                        f[r] = wp.clamp(u[r], -lim[r], lim[r])
            for r in range(wp.static(R)):
                if wp.static(WRITE_F[r]):
                    joint_f_out[di[r]] = f[r]
            if wp.static(EFFORT):
                for r in range(wp.static(R)):
                    if wp.static(TAU[r]):
                        computed_effort_out[env, r] = u[r]
                for r in range(wp.static(R)):
                    if wp.static(TAU[r]):
                        applied_effort_out[env, r] = f[r]
                for r in range(wp.static(R)):
                    if wp.static(TAU[r]):
                        if f[r] != u[r]:
                            saturation_count_out[env, r] = sat[r] + 1

    substep.__annotations__["hist_out"] = wp.array[vec_p]  # (the body does not name vec_p: no closure variable)
    # The kernel's name carries the layout (and the network's): Warp's module hash does not see the wp.static() values
    # that are resolved only at code generation (those under loops), so two layouts' kernels must differ by name.
    tag = hashlib.sha256(repr((L, row.key if NET else None)).encode()).hexdigest()[:16]
    if not NET:
        return wp.kernel(substep, name=f"wpctrl_substep_{tag}", enable_backward=False, module="unique")
    return net_kernel(substep, f"wpctrl_substep_actuator_net_{tag}")
