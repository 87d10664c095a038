"""The coupled implicit PD drive (``explicit_pd="coupled"``): PhysX's articulation drive as a box-constrained solve.

Private module. One thread per env, one launch per substep, run right after the substep kernel (which writes the drive
targets into the ``Control``; this kernel reads them back from there, so it sees exactly what the solver is given).

Per env, with ``H`` the articulation's joint-space inertia (computed in the same thread from ``joint_q``:
:mod:`wpctrl.kernels.inertia`), ``S`` the selection of the controlled rows' DOFs and ``A = S H^-1 S^T``, the drive
torques ``tau`` [N·m or N] of the controlled rows satisfy the PD law evaluated on the end-of-substep state of a
semi-implicit Euler step, ``qd+ = qd + dt A tau``, ``q+ = q + dt qd+``, each clamped to its force limit ``l``:

    tau = clamp(b - D A tau, -l, l),   b = Kp (q* - q - dt qd) + Kd (qd* - qd),   D = diag(dt Kd + dt^2 Kp)

(the velocity-bias term, Coriolis and gravity, is left out: see docs/actuation.md). Without active limits this is the
linear system ``(I + D A) tau = b``. With them it is the KKT system of the convex box QP
``min 1/2 tau^T (D^-1 + A) tau - (D^-1 b)^T tau  s.t. |tau| <= l`` (``D^-1 + A`` is SPD). Rows with
``Kp = Kd = 0`` get ``tau = 0`` and stay out of the QP (their DOFs still move through ``H``).

Method: primal-dual active set (a semismooth Newton method on the clamp equation), float64, in registers, solved in
the articulation's own coordinates so that ``H^-1`` is never formed: with the free rows F, the rows C clamped at
their bounds and ``v = H^-1 S^T tau``, the free rows' law ``tau_F = b_F - D_F S_F v`` is the SPD system

    (H + S_F^T D_F S_F) v = S_F^T b_F + S_C^T tau_C,   then   tau_F = b_F - D_F S_F v,

one Cholesky factorisation of an n x n matrix per iteration (n the articulation's DOFs). Every free row that violates
its bound then moves onto it, and every clamped row whose unclamped PD value ``b_i - d_i (S v)_i`` lies back inside
is released; it stops when the active set repeats, which is then an exact KKT point. Iteration 1 is the
unconstrained solution, so without active limits the result is exact after one iteration; a later iteration recovers
``H`` from the last factor (``H = L L^T - S_F^T D_F S_F``). At most ``rows + 2`` iterations are run, then projected
Gauss–Seidel sweeps on the block ``A`` polish the (rare) unconverged case. Acceleration drives divide Kp, Kd by
``A_ii`` (the joint's response), as the stable drive does; only they make the kernel compute the response.
"""

import warp as wp

from .cholesky import cholesky_funcs
from .inertia import chain_h_func
from .pd import _bidx

wp.set_module_options({"enable_backward": False})

PGS_SWEEPS = 16
"""Projected Gauss–Seidel sweeps run only when the active-set iteration did not settle within ``rows + 2``
iterations (the kernel's ``max_iterations``)."""

_cache: dict[tuple, wp.Kernel] = {}


def coupled_matrix_type(n: int):
    """The (n, n) float64 matrix type of H (one element of the coupled kernel's ``h_cache``), n the articulation's
    DOFs."""
    return wp.types.matrix(shape=(n, n), dtype=wp.float64)


def coupled_kernel(nj: int, n: int, nr: int, template: tuple | None, rows: tuple, fast_math: bool = False) -> wp.Kernel:
    """The coupled drive kernel for an articulation of nj joints and n DOFs and nr controlled rows (cached); the
    inertia part unrolled with ``template`` (:meth:`wpctrl.kernels.inertia.ChainLayout.template`). ``rows``: per
    row, as compile-time constants, (articulation DOF, acceleration drive 0/1, position row 0/1, velocity target
    0/1, coordinate offset, DOF offset), the offsets from the env's first coordinate / DOF in Newton's arrays. Its
    ``h_cache`` argument (an array of ``coupled_matrix_type(n)``) keeps H over a control step. ``fast_math``
    compiles it with the GPU's approximate single-precision intrinsics (the forward kinematics' sines and cosines,
    the pivots' first estimate; float64 is unaffected): the CUDA default."""
    rows = tuple(tuple(int(x) for x in r) for r in rows)
    key = (nj, n, nr, template, rows, bool(fast_math))
    if key in _cache:
        return _cache[key]
    chain_h = chain_h_func(nj, n, nr, template)
    N, NR = n, nr  # compile-time bounds: every loop unrolls, H / L and the vectors stay in registers on CUDA
    ROWD, ACC, POS, VT, QOFF, DOFF = (tuple(r[c] for r in rows) for c in range(6))
    ANY_ACC = any(ACC)
    MatN = coupled_matrix_type(n)
    VecN = wp.types.vector(length=n, dtype=wp.float64)
    VecR = wp.types.vector(length=nr, dtype=wp.float64)
    VecRi = wp.types.vector(length=nr, dtype=wp.int32)

    factor, solve, inverse_block, inverse_diag = cholesky_funcs(n, ROWD)

    @wp.func
    def recover(L: MatN, dprev: VecR):
        """H from the factor L of ``H + S^T diag(dprev) S``: ``L L^T`` (lower triangle) in place, rows last to first
        and each row's columns last to first, so every entry is overwritten after its last use; then the rows'
        ``dprev`` off the diagonal."""
        for ii in range(wp.static(N)):
            i = wp.static(N - 1 - ii)
            for jj in range(wp.static(i + 1)):
                j = wp.static(i - jj)
                t = wp.float64(0.0)
                for k in range(wp.static(j + 1)):
                    t += L[i, k] * L[j, k]
                L[i, j] = t
        for r in range(wp.static(NR)):
            L[wp.static(ROWD[r]), wp.static(ROWD[r])] = L[wp.static(ROWD[r]), wp.static(ROWD[r])] - dprev[r]
        return L

    @wp.kernel(enable_backward=False, module="unique", module_options={"fast_math": bool(fast_math)})
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
        # Envs:
        env_q_base: wp.array[wp.int32],
        env_qd_base: wp.array[wp.int32],
        # Gains (1 | num_envs, rows):
        kp: wp.array2d[float],
        kd: wp.array2d[float],
        force_limit: wp.array2d[float],
        dt: float,
        pgs_sweeps: int,
        max_iterations: int,  # active-set iterations before the sweeps take over (rows + 2)
        # In:
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        joint_target_q_in: wp.array[float],
        joint_target_qd_in: wp.array[float],
        # Out:
        joint_f_out: wp.array[float],
        response_out: wp.array2d[float],  # with acceleration rows: (H^-1)_ii of each row [1/(kg m^2) or 1/kg]
        h_cache: wp.array[MatN],  # optional, in/out: H per env, kept over a control step (inertia_update="control")
        step_in: wp.array[wp.int32],  # with h_cache: the substep counter (the substep kernel's, ManiSkill's _step)
        num_substeps: int,  # with h_cache: K; H is recomputed at the first substep of each control step
        iterations_out: wp.array[wp.int32],  # optional: active-set iterations (rows + 3 + sweeps: not settled)
        computed_effort_out: wp.array2d[float],  # optional [N·m or N]: the PD law at the predicted state, unclamped
        applied_effort_out: wp.array2d[float],  # optional [N·m or N]: the solved torque
        saturation_count_out: wp.array2d[wp.int32],  # optional, in/out: substeps with the row at its limit
    ):
        """Per env: coupled implicit PD torques [N·m or N] of every controlled row, clamped inside the solve."""
        env = wp.tid()
        fresh = int(1)
        if h_cache:  # H of the control step's first substep, reused by the others
            fresh = int((step_in[env] - 1) % num_substeps == 0)
        H = MatN()
        if fresh != 0:
            H = chain_h(
                num_dofs, env_joint_base[env], env_dof_base[env], chain_type, chain_parent, chain_dof, chain_anc,
                row_dof, joint_q_start, joint_qd_start, joint_X_p, joint_X_c, joint_axis, joint_child, joint_armature,
                body_mass, body_com, body_inertia, joint_q_in,
            )  # fmt: skip
            if h_cache:
                h_cache[env] = H
        else:
            H = h_cache[env]
        resp = VecR()
        if wp.static(ANY_ACC):
            Ad = inverse_diag(H)
            for r in range(wp.static(NR)):
                resp[r] = Ad[r, r]
                response_out[env, r] = float(resp[r])
        h = wp.float64(dt)
        b = VecR()  # unclamped PD force at the start-of-step prediction [N·m or N]
        d = VecR()  # dt Kd + dt^2 Kp
        lim = VecR()
        state = VecRi()  # 0 free, +1 / -1 at the upper / lower bound, 2 passive (Kp = Kd = 0: tau = 0)
        kbp = _bidx(kp.shape[0], env)
        kbd = _bidx(kd.shape[0], env)
        kbl = _bidx(force_limit.shape[0], env)
        qb = env_q_base[env]
        db = env_qd_base[env]
        for r in range(wp.static(NR)):
            qd = wp.float64(joint_qd_in[db + wp.static(DOFF[r])])
            kpe = wp.float64(0.0)
            e = wp.float64(0.0)
            if wp.static(POS[r] != 0):
                kpe = wp.float64(kp[kbp, r])
                qi = qb + wp.static(QOFF[r])
                e = wp.float64(joint_target_q_in[qi]) - wp.float64(joint_q_in[qi])
            tqd = wp.float64(0.0)
            if wp.static(VT[r] != 0):
                tqd = wp.float64(joint_target_qd_in[db + wp.static(DOFF[r])])
            kde = wp.float64(kd[kbd, r])
            if wp.static(ACC[r] != 0):  # acceleration drive: gains times the effective inertia 1 / A_ii
                kpe = kpe / resp[r]
                kde = kde / resp[r]
            b[r] = kpe * (e - h * qd) + kde * (tqd - qd)
            d[r] = h * kde + h * h * kpe
            lim[r] = wp.float64(force_limit[kbl, r])
            if not d[r] > wp.float64(0.0):
                state[r] = 2

        # Primal-dual active set in the articulation's coordinates (see the module docstring).
        tau = VecR()
        av = VecR()  # (S v)_r = (A tau)_r of the last solve
        dprev = VecR()  # D_F of the last factorisation (to recover H from its factor)
        settled = int(0)
        it = int(0)
        while it < max_iterations and settled == 0:
            if it > 0:
                H = recover(H, dprev)
            it += 1
            x = VecN()
            for r in range(wp.static(NR)):
                dd = wp.static(ROWD[r])
                dprev[r] = wp.float64(0.0)
                if state[r] == 0:
                    dprev[r] = d[r]
                    H[dd, dd] = H[dd, dd] + d[r]
                    x[dd] = b[r]
                elif state[r] == 1:
                    x[dd] = lim[r]
                elif state[r] == -1:
                    x[dd] = -lim[r]
            H, inv = factor(H)
            v = solve(H, inv, x)
            changed = int(0)
            for r in range(wp.static(NR)):
                vr = v[wp.static(ROWD[r])]
                av[r] = vr
                s = state[r]
                w = b[r] - d[r] * vr  # the PD force this row asks for at the predicted state
                if s == 0:
                    tau[r] = w
                    if w > lim[r]:
                        state[r] = 1
                        changed = 1
                    elif w < -lim[r]:
                        state[r] = -1
                        changed = 1
                elif s == 1 or s == -1:
                    tau[r] = wp.float64(s) * lim[r]
                    if (s == 1 and w < lim[r]) or (s == -1 and w > -lim[r]):  # back inside: released
                        state[r] = 0
                        changed = 1
                else:
                    tau[r] = wp.float64(0.0)
            if changed == 0:
                settled = 1
        if settled == 0:
            # Not settled (cycling between active sets): projected Gauss–Seidel on the clamp equation, with A.
            A = inverse_block(recover(H, dprev))
            for r in range(wp.static(NR)):
                if state[r] == 2:
                    tau[r] = wp.float64(0.0)
                else:
                    tau[r] = wp.clamp(tau[r], -lim[r], lim[r])
            for _sweep in range(pgs_sweeps):
                for r in range(wp.static(NR)):
                    if state[r] != 2:
                        at = wp.float64(0.0)
                        for c in range(wp.static(NR)):
                            at += A[r, c] * tau[c]
                        res = tau[r] - b[r] + d[r] * at  # residual of tau = b - D A tau
                        tau[r] = wp.clamp(tau[r] - res / (wp.float64(1.0) + d[r] * A[r, r]), -lim[r], lim[r])
            for r in range(wp.static(NR)):
                at = wp.float64(0.0)
                for c in range(wp.static(NR)):
                    at += A[r, c] * tau[c]
                av[r] = at
            it += pgs_sweeps + 1
        for r in range(wp.static(NR)):
            joint_f_out[db + wp.static(DOFF[r])] = float(tau[r])
        if computed_effort_out:
            for r in range(wp.static(NR)):
                w = wp.float64(0.0)
                if state[r] != 2:
                    w = b[r] - d[r] * av[r]
                computed_effort_out[env, r] = float(w)
                applied_effort_out[env, r] = float(tau[r])
                if wp.abs(w) > lim[r]:
                    saturation_count_out[env, r] = saturation_count_out[env, r] + 1
        if iterations_out:
            iterations_out[env] = it

    _cache[key] = _coupled_drive_kernel
    return _coupled_drive_kernel
