"""The coupled implicit PD drive (``explicit_pd="coupled"``): PhysX's articulation drive as a box-constrained solve.

Private module. One thread per env, one launch per substep, run right after the substep kernel (which writes the drive
targets into the ``Control``; this kernel reads them back from there, so it sees exactly what the solver is given).

Per env, with ``A`` the controlled block of the articulation's inverse joint-space inertia ``H^-1`` (computed in the
same thread from ``joint_q``: :mod:`wpctrl.kernels.inertia`), the drive torques ``tau`` [N·m or N] of the controlled
rows satisfy the PD law evaluated on the end-of-substep state of a semi-implicit Euler step,
``qd+ = qd + dt A tau``, ``q+ = q + dt qd+``, each clamped to its force limit ``l``:

    tau = clamp(b - D A tau, -l, l),   b = Kp (q* - q - dt qd) + Kd (qd* - qd),   D = diag(dt Kd + dt^2 Kp)

(the velocity-bias term, Coriolis and gravity, is left out: see the README). Without active limits this is the linear
system ``(I + D A) tau = b``. With them it is the KKT system of the convex box QP
``min 1/2 tau^T (D^-1 + A) tau - (D^-1 b)^T tau  s.t. |tau| <= l`` (``D^-1 + A`` is SPD). Rows with
``Kp = Kd = 0`` get ``tau = 0`` and stay out of the QP (their DOFs still move through ``A``).

Method: primal-dual active set (a semismooth Newton method on the clamp equation), float64, in registers. Each
iteration solves ``(D_F^-1 + A_FF) tau_F = D_F^-1 b_F - A_FC tau_C`` for the free rows F by Cholesky, with the
clamped rows C at their bounds, then moves every free row that violates its bound onto it and releases every clamped
row whose unclamped PD value ``b_i - d_i (A tau)_i`` lies back inside; it stops when the active set repeats, which is
then an exact KKT point. Iteration 1 is the unconstrained solution, so without active limits the result is exact
after one iteration; at most ``rows + 2`` iterations are run, then projected Gauss–Seidel sweeps polish the (rare)
unconverged case. Acceleration drives divide Kp, Kd by ``A_ii`` (the joint's response), as the stable drive does.
"""

from __future__ import annotations

import warp as wp

from ..config import rows as _cfg
from .inertia import chain_funcs
from .pd import _bidx

wp.set_module_options({"enable_backward": False})

PGS_SWEEPS = 16
"""Projected Gauss–Seidel sweeps run only when the active-set iteration did not settle within ``rows + 2``."""

_ROW_POS = _cfg.ROW_POS
_FLAG_VEL_TARGET = _cfg.FLAG_VEL_TARGET

_cache: dict[tuple, wp.Kernel] = {}


def coupled_matrix_type(nr: int):
    """The (nr, nr) float64 matrix type of A (one element of the coupled kernel's ``a_cache``)."""
    return wp.types.matrix(shape=(nr, nr), dtype=wp.float64)


def coupled_kernel(nj: int, n: int, nr: int, template: tuple | None = None) -> wp.Kernel:
    """The coupled drive kernel for an articulation of nj joints and n DOFs, nr controlled rows (cached); the
    inertia part unrolled with ``template`` (:meth:`wpctrl.kernels.inertia.ChainLayout.template`). Its ``a_cache``
    argument (an array of ``coupled_matrix_type(nr)``) keeps A over a control step."""
    key = (nj, n, nr, template)
    if key in _cache:
        return _cache[key]
    chain_rows_factor, MatR, VecR = chain_funcs(nj, n, nr, template)
    NR = nr  # the row loops have a compile-time bound: unrolled, so A, M and the vectors stay in registers
    row_pos = wp.constant(_ROW_POS)
    flag_vel = wp.constant(_FLAG_VEL_TARGET)

    @wp.func
    def solve_masked(A: MatR, dinv: VecR, rhs: VecR, free: VecR):
        """Solve ``(diag(dinv) + A)_FF x_F = rhs_F`` with ``x_i = rhs_i`` on the rows where ``free`` is 0."""
        M = MatR()
        for i in range(NR):
            if free[i] > wp.float64(0.0):
                for j in range(NR):
                    if free[j] > wp.float64(0.0):
                        M[i, j] = A[i, j]
                M[i, i] = M[i, i] + dinv[i]
            else:
                M[i, i] = wp.float64(1.0)
        # Cholesky in place (SPD: D^-1 + A restricted to F, identity elsewhere).
        for jc in range(NR):
            s = M[jc, jc]
            for k in range(jc):
                s -= M[jc, k] * M[jc, k]
            s = wp.max(s, wp.float64(1.0e-300))
            dg = wp.sqrt(s)
            M[jc, jc] = dg
            for i in range(jc + 1, NR):
                t = M[i, jc]
                for k in range(jc):
                    t -= M[i, k] * M[jc, k]
                M[i, jc] = t / dg
        x = VecR()
        for i in range(NR):
            t = rhs[i]
            for k in range(i):
                t -= M[i, k] * x[k]
            x[i] = t / M[i, i]
        for ii in range(NR):
            i = NR - 1 - ii
            t = x[i]
            for k in range(i + 1, NR):
                t -= M[k, i] * x[k]
            x[i] = t / M[i, i]
        return x

    @wp.kernel(enable_backward=False, module="unique")
    def _coupled_drive_kernel(
        # Chain (articulation template):
        chain_type: wp.array[wp.int32],
        chain_parent: wp.array[wp.int32],
        chain_dof: wp.array[wp.int32],
        chain_anc: wp.array[wp.int32],
        row_dof: wp.array[wp.int32],
        # Envs:
        env_joint_base: wp.array[wp.int32],
        env_dof_base: wp.array[wp.int32],
        # Model:
        joint_q_start: wp.array[wp.int32],
        joint_qd_start: wp.array[wp.int32],
        joint_X_p: wp.array[wp.transform],
        joint_X_c: wp.array[wp.transform],
        joint_axis: wp.array[wp.vec3],
        joint_child: wp.array[wp.int32],
        joint_armature: wp.array[float],
        body_mass: wp.array[float],
        body_com: wp.array[wp.vec3],
        body_inertia: wp.array[wp.mat33],
        num_dofs: int,
        # Rows:
        row_kind: wp.array[wp.int32],
        row_flags: wp.array[wp.int32],
        row_q_off: wp.array[wp.int32],
        row_qd_off: wp.array[wp.int32],
        row_accel: wp.array[wp.int32],
        # Envs:
        env_q_base: wp.array[wp.int32],
        env_qd_base: wp.array[wp.int32],
        # Gains (1 | num_envs, rows):
        kp: wp.array2d[float],
        kd: wp.array2d[float],
        force_limit: wp.array2d[float],
        dt: float,
        pgs_sweeps: int,
        # In:
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        joint_target_q_in: wp.array[float],
        joint_target_qd_in: wp.array[float],
        # Out:
        joint_f_out: wp.array[float],
        response_out: wp.array2d[float],  # optional: (H^-1)_ii of each row [1/(kg m^2) or 1/kg]
        a_cache: wp.array[MatR],  # optional, in/out: A per env, kept over a control step (inertia_update="control")
        step_in: wp.array[wp.int32],  # with a_cache: the substep counter (the substep kernel's, ManiSkill's _step)
        num_substeps: int,  # with a_cache: K; A is recomputed at the first substep of each control step
        iterations_out: wp.array[wp.int32],  # optional: active-set iterations (rows + 3 + sweeps: not settled)
        computed_effort_out: wp.array2d[float],  # optional [N·m or N]: the PD law at the predicted state, unclamped
        applied_effort_out: wp.array2d[float],  # optional [N·m or N]: the solved torque
        saturation_count_out: wp.array2d[wp.int32],  # optional, in/out: substeps with the row at its limit
    ):
        """Per env: coupled implicit PD torques [N·m or N] of every controlled row, clamped inside the solve."""
        env = wp.tid()
        fresh = int(1)
        if a_cache:  # A of the control step's first substep, reused by the others
            fresh = int((step_in[env] - 1) % num_substeps == 0)
        A = MatR()
        if fresh != 0:
            A = chain_rows_factor(
                num_dofs, env_joint_base[env], env_dof_base[env], chain_type, chain_parent, chain_dof, chain_anc,
                row_dof, joint_q_start, joint_qd_start, joint_X_p, joint_X_c, joint_axis, joint_child, joint_armature,
                body_mass, body_com, body_inertia, joint_q_in,
            )  # fmt: skip
            if a_cache:
                a_cache[env] = A
        else:
            A = a_cache[env]
        h = wp.float64(dt)
        b = VecR()  # unclamped PD force at the start-of-step prediction [N·m or N]
        d = VecR()  # dt Kd + dt^2 Kp
        dinv = VecR()
        lim = VecR()
        active = VecR()  # 1: in the QP (Kp or Kd > 0), 0: passive (tau = 0)
        for r in range(NR):
            kind = row_kind[r]
            qi = env_q_base[env] + row_q_off[r]
            di = env_qd_base[env] + row_qd_off[r]
            qd = wp.float64(joint_qd_in[di])
            kpe = wp.float64(0.0)
            e = wp.float64(0.0)
            if kind == row_pos:
                kpe = wp.float64(kp[_bidx(kp.shape[0], env), r])
                e = wp.float64(joint_target_q_in[qi]) - wp.float64(joint_q_in[qi])
            tqd = wp.float64(0.0)
            if kind != row_pos or (row_flags[r] & flag_vel) != 0:
                tqd = wp.float64(joint_target_qd_in[di])
            kde = wp.float64(kd[_bidx(kd.shape[0], env), r])
            if row_accel[r] != 0:  # acceleration drive: gains times the effective inertia 1 / A_ii
                kpe = kpe / A[r, r]
                kde = kde / A[r, r]
            b[r] = kpe * (e - h * qd) + kde * (tqd - qd)
            d[r] = h * kde + h * h * kpe
            lim[r] = wp.float64(force_limit[_bidx(force_limit.shape[0], env), r])
            if d[r] > wp.float64(0.0):
                active[r] = wp.float64(1.0)
                dinv[r] = wp.float64(1.0) / d[r]
            if response_out:
                response_out[env, r] = float(A[r, r])

        # Primal-dual active set. state: 0 free, +1 / -1 at the upper / lower bound, 2 passive.
        state = VecR()
        for r in range(NR):
            if active[r] == wp.float64(0.0):
                state[r] = wp.float64(2.0)
        tau = VecR()
        settled = int(0)
        it = int(0)
        while it < NR + 2 and settled == 0:
            it += 1
            free = VecR()
            fixed = VecR()
            for r in range(NR):
                if state[r] == wp.float64(0.0):
                    free[r] = wp.float64(1.0)
                elif state[r] == wp.float64(1.0):
                    fixed[r] = lim[r]
                elif state[r] == wp.float64(-1.0):
                    fixed[r] = -lim[r]
            rhs = VecR()
            for r in range(NR):
                if free[r] > wp.float64(0.0):
                    t = b[r] * dinv[r]
                    for c in range(NR):
                        t -= A[r, c] * fixed[c]
                    rhs[r] = t
                else:
                    rhs[r] = fixed[r]
            tau = solve_masked(A, dinv, rhs, free)
            changed = int(0)
            for r in range(NR):
                s = state[r]
                if s == wp.float64(0.0):
                    if tau[r] > lim[r]:
                        state[r] = wp.float64(1.0)
                        changed = 1
                    elif tau[r] < -lim[r]:
                        state[r] = wp.float64(-1.0)
                        changed = 1
                elif s == wp.float64(1.0) or s == wp.float64(-1.0):
                    at = wp.float64(0.0)
                    for c in range(NR):
                        at += A[r, c] * tau[c]
                    w = b[r] - d[r] * at  # the PD force this row asks for at the predicted state
                    if (s > wp.float64(0.0) and w < lim[r]) or (s < wp.float64(0.0) and w > -lim[r]):
                        state[r] = wp.float64(0.0)
                        changed = 1
            if changed == 0:
                settled = 1
        if settled == 0:
            # Not settled (cycling between active sets): projected Gauss–Seidel on the clamp equation.
            for r in range(NR):
                tau[r] = wp.clamp(tau[r], -lim[r], lim[r]) * active[r]
            for _sweep in range(pgs_sweeps):
                for r in range(NR):
                    if active[r] > wp.float64(0.0):
                        at = wp.float64(0.0)
                        for c in range(NR):
                            at += A[r, c] * tau[c]
                        res = tau[r] - b[r] + d[r] * at  # residual of tau = b - D A tau
                        tau[r] = wp.clamp(tau[r] - res / (wp.float64(1.0) + d[r] * A[r, r]), -lim[r], lim[r])
            it += pgs_sweeps + 1
        for r in range(NR):
            di = env_qd_base[env] + row_qd_off[r]
            joint_f_out[di] = float(tau[r] * active[r])
            if computed_effort_out:
                at = wp.float64(0.0)
                for c in range(NR):
                    at += A[r, c] * tau[c]
                w = (b[r] - d[r] * at) * active[r]
                computed_effort_out[env, r] = float(w)
                applied_effort_out[env, r] = float(tau[r] * active[r])
                if wp.abs(w) > lim[r]:
                    saturation_count_out[env, r] = saturation_count_out[env, r] + 1
        if iterations_out:
            iterations_out[env] = it

    _cache[key] = _coupled_drive_kernel
    return _coupled_drive_kernel
