"""Warp kernels of the impedance controllers: operational-space control (OSC) and joint impedance.

Private module (launched by :mod:`.engine_part`). Two kernels per controller, one thread per env each:

- ``set_action`` (once per control step, before the joint kernel): the processed action (NaN/Inf anywhere in the
  env's action: the env is left untouched, as the joint kernel does), the target (OSC: the target pose composed as the
  EE controllers do it, from the measured EE pose or the last target; joint impedance: joint targets, delta or
  absolute) and, with variable impedance, the gains from the action (damping ``2 ζ √Kp``).
- ``torque`` (before every solver substep, before the substep kernel): the commanded torque of every controlled joint
  from the measured state, written as the effort rows' command (``target_effort``): the substep kernel then delays,
  clamps to ``force_limit``, reads out and writes ``Control.joint_f`` as for any effort row.

The torque kernel is built on the end-effector kernels' chain FK and Jacobian (:mod:`wpctrl.kernels.ee_math`, root
frame, float32) and the fused inertia pass (:func:`wpctrl.kernels.inertia.chain_hg_func`: the articulation's H and
gravity torque from ``joint_q``, float64, world frame). ``M`` is the controlled rows' block of H (the other joints
held, as Newton's ``ControllerOperationalSpace`` takes it); solves are float64 Cholesky
(:mod:`wpctrl.kernels.cholesky`). OSC:

    e = [p* − p; log(q* q⁻¹)],  ẋ = J q̇,  a = Kp ∘ e − Kd ∘ ẋ
    F = Λ a  (Λ⁻¹ = J M⁻¹ Jᵀ; partial: its two 3×3 diagonal blocks; none: F = a),   τ = Jᵀ F
    null space: a₀ = Kp_n (q_n − q) − Kd_n q̇,  τ₀ = M a₀ (with decoupling) or a₀,
      τ += τ₀ − Jᵀ Λ J M⁻¹ τ₀ (full decoupling: dynamically consistent)  or  τ₀ − Jᵀ (J Jᵀ)⁻¹ J τ₀
    τ += g (gravity compensation)

Joint impedance: ``τ = [M] (Kp (q* − q) − Kd q̇) + g``. Option flags (decoupling, gravity, null space) are kernel
arguments, uniform over all threads: one compiled kernel per robot serves every option.

Task-space solves (``Λ⁻¹ x = b``, ``J Jᵀ x = b``) are scaled (``S = D A D``, each 3×3 block of translation and
rotation divided by its mean diagonal) and factored; where the smallest pivot ``p`` of ``S`` is below ``ε``
(``singularity_damping``), ``ε (1 − p/ε)²`` is added to the diagonal of ``S`` and it is factored again: zero away
from singularities, continuous, and bounded at a singularity (pivots are also floored as Newton's at 1.2e-7).
"""

from __future__ import annotations

import warp as wp

from ..kernels.cholesky import cholesky_funcs
from ..kernels.ee_math import (
    EEChain,
    _chain_fk,
    _compose,
    _jacobian,
    _log3,
    _pose_action,
    _read_pose,
    _write_pose,
    vecD,
)
from ..kernels.inertia import chain_hg_func
from ..kernels.pd import _action_finite, _bidx, _scale
from ..kernels.spatial import Articulation

wp.set_module_options({"enable_backward": False})

Vec6d = wp.types.vector(length=6, dtype=wp.float64)
Mat6d = wp.types.matrix(shape=(6, 6), dtype=wp.float64)

_factor6, _solve6, _, _ = cholesky_funcs(6, (0, 1, 2, 3, 4, 5))


@wp.func
def _task_solve(A: Mat6d, b: Vec6d, eps: wp.float64):
    """``A⁻¹ b`` for the SPD task matrix ``A`` (Jacobi-scaled, damped near a singularity: see the module docstring)."""
    # Each block (translation, rotation) scaled by its mean diagonal: unit-free, and a vanishing task direction (a
    # row of J near zero) shows as a small pivot.
    tiny = wp.float64(1.0e-300)
    sv = wp.float64(1.0) / wp.sqrt(wp.max((A[0, 0] + A[1, 1] + A[2, 2]) / wp.float64(3.0), tiny))
    sw = wp.float64(1.0) / wp.sqrt(wp.max((A[3, 3] + A[4, 4] + A[5, 5]) / wp.float64(3.0), tiny))
    d = Vec6d(sv, sv, sv, sw, sw, sw)
    S = Mat6d()
    for i in range(6):
        for j in range(6):
            S[i, j] = A[i, j] * d[i] * d[j]
    L, inv = _factor6(S)
    pmin = wp.float64(1.0)
    for i in range(6):
        pmin = wp.min(pmin, L[i, i] * L[i, i])
    if pmin < eps:
        r = wp.float64(1.0) - pmin / eps
        for i in range(6):
            S[i, i] = S[i, i] + eps * r * r
        L, inv = _factor6(S)
    x = _solve6(L, inv, wp.cw_mul(d, b))
    return wp.cw_mul(d, x)


@wp.struct
class ImpedanceAction:
    """How an impedance controller's ``set_action`` reads its action (one kernel argument instead of sixteen, fixed
    for the controller's life): the action's options, the target columns' raw bounds, the gain limits of the
    variable modes and the joint targets' clipping. Filled by :mod:`wpctrl.impedance.engine_part`."""

    mode: int  # 0 fixed, 1 variable_kp, 2 variable
    use_delta: int
    use_target: int
    normalize: int
    frame_bits: int  # OSC: the frames of the translation and rotation (as the EE kernels')
    clip_targets: int  # joint impedance: clamp the targets to the joints' limits
    target_lo: wp.array[float]  # (T,) raw bounds of the target columns
    target_hi: wp.array[float]
    rot_scale: wp.vec3
    damping_ratio: wp.array[float]  # (T,) the fixed ratio of "variable_kp"
    kp_lo: float  # the variable modes' stiffness and damping-ratio limits
    kp_hi: float
    ratio_lo: float
    ratio_hi: float
    row_qlo: wp.array[float]  # (rows,) the joints' limits (clip_targets)
    row_qhi: wp.array[float]


_set_action_cache: dict[tuple, wp.Kernel] = {}
_torque_cache: dict[tuple, wp.Kernel] = {}


def set_action_kernel(osc: bool, n: int) -> wp.Kernel:
    """The ``set_action`` kernel of an OSC (``osc``) or joint-impedance controller of ``n`` joints (cached)."""
    key = (bool(osc), int(n))
    if key in _set_action_cache:
        return _set_action_cache[key]
    OSC, N = bool(osc), int(n)
    T = 6 if OSC else N  # the task axes (the gains' count)
    VecT = wp.types.vector(length=T, dtype=float)

    @wp.kernel(enable_backward=False, module="unique")
    def impedance_set_action(
        chain: EEChain,  # the EE chain (wpctrl.kernels.ee_math.EEChain)
        # Rows and columns:
        row_q_off: wp.array[wp.int32],  # (n,) the rows' coordinate offsets from the env's first
        env_q_base: wp.array[wp.int32],
        row0: int,
        col0: int,
        gain_col0: int,  # first column of the gain action (variable modes)
        gain_off: int,  # first column of the gains in kp_out / kd_out
        p: ImpedanceAction,  # how the action maps to targets and gains
        # In:
        action_in: wp.array2d[float],
        joint_q_in: wp.array[float],
        # Out:
        processed_action_out: wp.array2d[float],
        target_pose_out: wp.array2d[float],  # OSC, in/out with use_target
        ee_pose_out: wp.array2d[float],  # OSC
        target_qpos_out: wp.array2d[float],  # joint impedance, in/out with use_target
        kp_out: wp.array2d[float],  # variable modes: (num_envs, >= gain_off + T)
        kd_out: wp.array2d[float],
    ):
        env = wp.tid()
        if not _action_finite(action_in, env):
            return
        mode, use_delta, use_target, normalize = p.mode, p.use_delta, p.use_target, p.normalize
        target_lo, target_hi = p.target_lo, p.target_hi
        kp_lo, kp_hi, ratio_lo, ratio_hi = p.kp_lo, p.kp_hi, p.ratio_lo, p.ratio_hi
        qb = env_q_base[env]
        if wp.static(OSC):
            q0 = vecD()
            for c in range(wp.static(N)):
                q0[c] = joint_q_in[qb + row_q_off[c]]
            lo = wp.vec3(target_lo[0], target_lo[1], target_lo[2])
            hi = wp.vec3(target_hi[0], target_hi[1], target_hi[2])
            act = _pose_action(action_in, env, col0, 1, normalize, lo, hi, p.rot_scale)
            for k in range(6):
                processed_action_out[env, col0 + k] = act[k]
            t_ee, t_joint, axes, origins, kinds = _chain_fk(env, chain, joint_q_in, q0)
            _write_pose(ee_pose_out, env, t_ee)
            prev = t_ee
            if use_target != 0:
                prev = _read_pose(target_pose_out, env)
            _write_pose(target_pose_out, env, _compose(prev, act, 1, use_delta, p.frame_bits))
        else:
            for c in range(wp.static(N)):
                x = _scale(action_in[env, col0 + c], target_lo[c], target_hi[c], normalize)
                processed_action_out[env, col0 + c] = x
                t = x
                if use_delta != 0:
                    if use_target != 0:
                        t = target_qpos_out[env, row0 + c] + x
                    else:
                        t = joint_q_in[qb + row_q_off[c]] + x
                if p.clip_targets != 0:
                    t = wp.clamp(t, p.row_qlo[row0 + c], p.row_qhi[row0 + c])
                target_qpos_out[env, row0 + c] = t
        if mode != 0:
            kp = VecT()
            ratio = VecT()
            for k in range(wp.static(T)):
                kp[k] = wp.clamp(_scale(action_in[env, gain_col0 + k], kp_lo, kp_hi, normalize), kp_lo, kp_hi)
                processed_action_out[env, gain_col0 + k] = kp[k]
                ratio[k] = p.damping_ratio[k]
            if mode == 2:
                for k in range(wp.static(T)):
                    c = gain_col0 + wp.static(T) + k
                    ratio[k] = wp.clamp(_scale(action_in[env, c], ratio_lo, ratio_hi, normalize), ratio_lo, ratio_hi)
                    processed_action_out[env, c] = ratio[k]
            for k in range(wp.static(T)):
                kp_out[env, gain_off + k] = kp[k]
                kd_out[env, gain_off + k] = 2.0 * ratio[k] * wp.sqrt(kp[k])

    _set_action_cache[key] = impedance_set_action
    return impedance_set_action


def torque_kernel(osc: bool, n: int, row_dof: tuple | None, chain_key: tuple | None) -> wp.Kernel:
    """The torque kernel of an OSC (``osc``) or joint-impedance controller of ``n`` joints (cached).

    Args:
        row_dof: The rows' DOFs in their articulation (compile-time), with ``chain_key``; None without.
        chain_key: :meth:`wpctrl.kernels.inertia.FusedChain.kernel_key` of the articulation, or None: no mass
            matrix or gravity torque (the articulation does not fit the fused pass; the options that need them are
            refused on the host).
    """
    key = (bool(osc), int(n), row_dof, chain_key)
    if key in _torque_cache:
        return _torque_cache[key]
    OSC, N = bool(osc), int(n)
    HAS_H = chain_key is not None
    ROWD = tuple(row_dof) if HAS_H else tuple(range(N))
    chain_hg = chain_hg_func(*chain_key) if HAS_H else None
    VecN = wp.types.vector(length=N, dtype=wp.float64)
    MatN = wp.types.matrix(shape=(N, N), dtype=wp.float64)
    Mat6N = wp.types.matrix(shape=(6, N), dtype=wp.float64)
    factor_n, solve_n, _, _ = cholesky_funcs(N, tuple(range(N)))

    @wp.kernel(enable_backward=False, module="unique")
    def impedance_torque(
        chain: EEChain,  # the EE chain (wpctrl.kernels.ee_math.EEChain)
        art: Articulation,  # the articulation for the fused inertia pass (an empty one without it)
        gravity_in: wp.array[wp.vec3],  # Model.gravity, per world
        env_world: wp.array[wp.int32],  # (num_envs,) index into gravity_in
        # Rows:
        row_q_off: wp.array[wp.int32],  # (n,)
        row_qd_off: wp.array[wp.int32],  # (n,)
        env_q_base: wp.array[wp.int32],
        env_qd_base: wp.array[wp.int32],
        row0: int,
        # Options (uniform over the threads):
        decoupling: int,  # 0 none, 1 full, 2 partial (joint impedance: 1 = inertial compensation)
        gravity_on: int,
        nullspace_on: int,
        singularity_damping: float,
        # Gains:
        task_kp: wp.array2d[float],  # OSC: (num_envs, 6)
        task_kd: wp.array2d[float],
        kp: wp.array2d[float],  # (1 | num_envs, rows): joint gains (joint impedance) or posture gains (OSC)
        kd: wp.array2d[float],
        posture: wp.array[float],  # optional (n,): a fixed null-space posture; else target_qpos_in's rows
        # In:
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        target_pose_in: wp.array2d[float],  # OSC
        target_qpos_in: wp.array2d[float],  # joint targets, or the posture of each env
        # Out:
        target_effort_out: wp.array2d[float],  # the rows' commanded torque [N·m or N]
    ):
        env = wp.tid()
        qb = env_q_base[env]
        db = env_qd_base[env]
        q = VecN()
        qd = VecN()
        for c in range(wp.static(N)):
            q[c] = wp.float64(joint_q_in[qb + row_q_off[c]])
            qd[c] = wp.float64(joint_qd_in[db + row_qd_off[c]])
        M = MatN()
        g = VecN()
        if wp.static(HAS_H):
            if decoupling != 0 or gravity_on != 0:
                gv = wp.vec3(0.0)
                if gravity_on != 0:
                    gv = gravity_in[env_world[env]]
                H, G = chain_hg(art, env, joint_q_in, gv)
                for r in range(wp.static(N)):
                    g[r] = G[wp.static(ROWD[r])]
                    for c in range(wp.static(N)):
                        M[r, c] = H[wp.static(max(ROWD[r], ROWD[c])), wp.static(min(ROWD[r], ROWD[c]))]
        eps = wp.float64(singularity_damping)
        tau = VecN()
        if wp.static(OSC):
            q32 = vecD()
            for c in range(wp.static(N)):
                q32[c] = float(q[c])
            t_ee, t_joint, axes, origins, kinds = _chain_fk(env, chain, joint_q_in, q32)
            jac = _jacobian(wp.transform_get_translation(t_ee), axes, origins, kinds, wp.static(N))
            J = Mat6N()
            for k in range(6):
                for c in range(wp.static(N)):
                    J[k, c] = wp.float64(jac[k, c])
            tgt = _read_pose(target_pose_in, env)
            dp = wp.transform_get_translation(tgt) - wp.transform_get_translation(t_ee)
            dr = _log3(wp.transform_get_rotation(tgt) * wp.quat_inverse(wp.transform_get_rotation(t_ee)))
            xd = J * qd
            e = Vec6d(
                wp.float64(dp[0]), wp.float64(dp[1]), wp.float64(dp[2]),
                wp.float64(dr[0]), wp.float64(dr[1]), wp.float64(dr[2]),
            )  # fmt: skip
            a = Vec6d()
            for k in range(6):
                a[k] = wp.float64(task_kp[env, k]) * e[k] - wp.float64(task_kd[env, k]) * xd[k]
            f = a
            lam_inv = Mat6d()  # J M^-1 J^T
            if decoupling != 0:
                L, inv = factor_n(M)
                W = Mat6N()  # row k: L^-1 J_k^T
                for k in range(6):
                    for i in range(wp.static(N)):
                        t = J[k, i]
                        for m in range(wp.static(i)):
                            t -= L[i, m] * W[k, m]
                        W[k, i] = t * inv[i]
                for k in range(6):
                    for m in range(wp.static(k + 1)):
                        v = wp.float64(0.0)
                        if decoupling == 1 or wp.static((k < 3) == (m < 3)):
                            for i in range(wp.static(N)):
                                v += W[k, i] * W[m, i]
                        lam_inv[k, m] = v
                        lam_inv[m, k] = v
                f = _task_solve(lam_inv, a, eps)
            tau = wp.transpose(J) * f
            if nullspace_on != 0:
                a0 = VecN()
                kb = _bidx(kp.shape[0], env)
                for c in range(wp.static(N)):
                    qn = float(0.0)  # a mutable local in a Warp kernel
                    if posture:
                        qn = posture[c]
                    else:
                        qn = target_qpos_in[env, row0 + c]
                    a0[c] = (
                        wp.float64(kp[kb, row0 + c]) * (wp.float64(qn) - q[c]) - wp.float64(kd[kb, row0 + c]) * qd[c]
                    )
                t0 = a0
                if decoupling != 0:
                    t0 = M * a0
                y = Vec6d()
                if decoupling == 1:  # dynamically consistent: J^T Λ J M^-1 τ₀ = J^T Λ J a₀
                    y = _task_solve(lam_inv, J * a0, eps)
                else:  # kinematic: J^T (J J^T)^-1 J τ₀
                    y = _task_solve(J * wp.transpose(J), J * t0, eps)
                tau = tau + t0 - wp.transpose(J) * y
        else:
            kb = _bidx(kp.shape[0], env)
            a = VecN()
            for c in range(wp.static(N)):
                a[c] = (
                    wp.float64(kp[kb, row0 + c]) * (wp.float64(target_qpos_in[env, row0 + c]) - q[c])
                    - wp.float64(kd[kb, row0 + c]) * qd[c]
                )
            tau = a
            if decoupling != 0:
                tau = M * a
        if gravity_on != 0:
            tau = tau + g
        for c in range(wp.static(N)):
            target_effort_out[env, row0 + c] = float(tau[c])

    _torque_cache[key] = impedance_torque
    return impedance_torque
