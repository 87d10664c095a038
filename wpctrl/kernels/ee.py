"""Warp kernels of the end-effector controllers (PDEEPos / PDEEPose): FK, Jacobian, target pose, DLS / CLIK solve.

Private module. One thread per env walks the env's kinematic chain (root to EE body) from ``State.joint_q`` with the
model's ``joint_X_p`` / ``joint_X_c`` / ``joint_axis``, so a stale ``body_q`` never matters. Poses are stored as
``(num_envs, 7)`` float rows ``[x, y, z, qw, qx, qy, qz]`` in the robot-root frame (ManiSkill's layout); Warp's own
quaternions are ``(x, y, z, w)``. The Jacobian is geometric, in the root frame, about the EE point, rows ``[v; ω]``,
one column per controlled joint (at most ``MAX_DOF``). All solves run in registers:

- damped least squares (Levenberg–Marquardt): ``dq = Jᵀ (J Jᵀ + λ I₆)⁻¹ dx`` (equal to ManiSkill's
  ``(JᵀJ + λI)⁻¹ Jᵀ dx`` by the push-through identity; a 6×6 Cholesky whatever the chain length);
- pseudo-inverse: ``Jᵀ (J Jᵀ)⁻¹ dx`` for 6+ joints, ``(JᵀJ)⁻¹ Jᵀ dx`` below;
- iterative CLIK (``iterations > 1``), Pinocchio's algorithm as SAPIEN runs it for ManiSkill on CPU: error
  ``log6(oMdes⁻¹ · oMi)`` of the last moving joint's frame, local Jacobian, ``v = -Jᵀ (J Jᵀ + damp I)⁻¹ err``,
  ``q += dt v``; success when ``‖err‖ < tolerance``; a failed env keeps its measured positions as the target.
"""

from __future__ import annotations

import warp as wp

from .. import config_ee as _ce

wp.set_module_options({"enable_backward": False})

MAX_DOF = wp.constant(_ce.MAX_EE_DOF)
SOLVER_PINV = wp.constant(_ce.SOLVER_PINV)
FRAME_BODY_TRANS = wp.constant(_ce.FRAME_BODY_TRANS)
FRAME_BODY_ROT = wp.constant(_ce.FRAME_BODY_ROT)
JOINT_PRISMATIC = wp.constant(0)  # newton.JointType.PRISMATIC
JOINT_REVOLUTE = wp.constant(1)  # newton.JointType.REVOLUTE

vecD = wp.types.vector(length=_ce.MAX_EE_DOF, dtype=float)
mat3D = wp.types.matrix(shape=(3, _ce.MAX_EE_DOF), dtype=float)
mat6D = wp.types.matrix(shape=(6, _ce.MAX_EE_DOF), dtype=float)
matDD = wp.types.matrix(shape=(_ce.MAX_EE_DOF, _ce.MAX_EE_DOF), dtype=float)
vec6 = wp.types.vector(length=6, dtype=float)
mat66 = wp.types.matrix(shape=(6, 6), dtype=float)


# ---------------------------------------------------------------------------------------------------------------------
# Small helpers: poses, rotations.


@wp.func
def _read_pose(a: wp.array2d[float], env: int):
    return wp.transform(wp.vec3(a[env, 0], a[env, 1], a[env, 2]), wp.quat(a[env, 4], a[env, 5], a[env, 6], a[env, 3]))


@wp.func
def _std(q: wp.quat):
    """Standardised quaternion (w >= 0), as ManiSkill's."""
    if q[3] < 0.0:
        return wp.quat(-q[0], -q[1], -q[2], -q[3])
    return q


@wp.func
def _write_pose(a: wp.array2d[float], env: int, t: wp.transform):
    p = wp.transform_get_translation(t)
    q = _std(wp.transform_get_rotation(t))
    a[env, 0] = p[0]
    a[env, 1] = p[1]
    a[env, 2] = p[2]
    a[env, 3] = q[3]
    a[env, 4] = q[0]
    a[env, 5] = q[1]
    a[env, 6] = q[2]


@wp.func
def _quat_euler_xyz(e: wp.vec3):
    """pytorch3d's "XYZ" convention: R = Rx(e0) Ry(e1) Rz(e2)."""
    qx = wp.quat_from_axis_angle(wp.vec3(1.0, 0.0, 0.0), e[0])
    qy = wp.quat_from_axis_angle(wp.vec3(0.0, 1.0, 0.0), e[1])
    qz = wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), e[2])
    return _std(qx * qy * qz)


@wp.func
def _euler_xyz(q: wp.quat):
    """Inverse of :func:`_quat_euler_xyz`: ``(atan2(-R12, R22), asin(R02), atan2(-R01, R00))``."""
    r = wp.quat_to_matrix(q)
    return wp.vec3(
        wp.atan2(-r[1, 2], r[2, 2]),
        wp.asin(wp.clamp(r[0, 2], -1.0, 1.0)),
        wp.atan2(-r[0, 1], r[0, 0]),
    )


@wp.func
def _log3(q: wp.quat):
    """Rotation vector θu of a unit quaternion (θ in [0, π])."""
    qs = _std(q)
    v = wp.vec3(qs[0], qs[1], qs[2])
    s = wp.length(v)
    if s < 1.0e-7:
        return 2.0 * v
    theta = 2.0 * wp.atan2(s, qs[3])
    return v * (theta / s)


@wp.func
def _log6(t: wp.transform):
    """Pinocchio's log6 of an SE(3) element: the twist [v; ω] with exp6([v; ω]) = t."""
    w = _log3(wp.transform_get_rotation(t))
    p = wp.transform_get_translation(t)
    theta = wp.length(w)
    t2 = theta * theta
    alpha = float(0.0)
    beta = float(0.0)
    if theta < 1.0e-3:
        alpha = 1.0 - t2 / 12.0 - t2 * t2 / 720.0
        beta = 1.0 / 12.0 + t2 / 720.0
    else:
        st = wp.sin(theta)
        ct = wp.cos(theta)
        alpha = theta * st / (2.0 * (1.0 - ct))
        beta = 1.0 / t2 - st / (2.0 * theta * (1.0 - ct))
    lin = alpha * p - 0.5 * wp.cross(w, p) + (beta * wp.dot(w, p)) * w
    return vec6(lin[0], lin[1], lin[2], w[0], w[1], w[2])


# ---------------------------------------------------------------------------------------------------------------------
# Chain FK and Jacobian.


@wp.func
def _chain_fk(
    env: int,
    chain_joint: wp.array2d[wp.int32],
    chain_col: wp.array[wp.int32],
    joint_type: wp.array[wp.int32],
    joint_X_p: wp.array[wp.transform],
    joint_X_c: wp.array[wp.transform],
    joint_axis: wp.array[wp.vec3],
    joint_q_start: wp.array[wp.int32],
    joint_qd_start: wp.array[wp.int32],
    env_root: wp.array[wp.transform],
    ee_offset: wp.transform,
    joint_q: wp.array[float],
    qv: vecD,
):
    """FK of one env's chain in the root frame. Controlled joints (column c >= 0) take ``qv[c]``, other 1-DOF joints
    their ``joint_q``. Returns the EE pose, the frame of the last moving joint (Pinocchio's joint frame), the
    columns' axes, origins (root frame) and kinds (1 revolute, 0 prismatic)."""
    t = env_root[env]
    t_joint = t
    axes = mat3D()
    origins = mat3D()
    kinds = vecD()
    for i in range(chain_joint.shape[1]):
        j = chain_joint[env, i]
        x = t * joint_X_p[j]
        jt = joint_type[j]
        if jt == JOINT_REVOLUTE or jt == JOINT_PRISMATIC:
            c = chain_col[i]
            a = joint_axis[joint_qd_start[j]]
            q = float(0.0)
            if c >= 0:
                for cc in range(MAX_DOF):  # constant indices (registers on the GPU), not qv[c]
                    if cc == c:
                        q = qv[cc]
            else:
                q = joint_q[joint_q_start[j]]
            if jt == JOINT_REVOLUTE:
                x = x * wp.transform(wp.vec3(), wp.quat_from_axis_angle(a, q))
            else:
                x = x * wp.transform(a * q, wp.quat_identity())
            t_joint = x
            if c >= 0:
                aw = wp.transform_vector(x, a)
                o = wp.transform_get_translation(x)
                for cc in range(MAX_DOF):
                    if cc == c:
                        for k in range(3):
                            axes[k, cc] = aw[k]
                            origins[k, cc] = o[k]
                        if jt == JOINT_REVOLUTE:
                            kinds[cc] = 1.0
        t = x * wp.transform_inverse(joint_X_c[j])
    return t * ee_offset, t_joint, axes, origins, kinds


@wp.func
def _jacobian(p: wp.vec3, axes: mat3D, origins: mat3D, kinds: vecD, n: int):
    """Geometric Jacobian about point ``p`` (root frame), rows [v; ω]."""
    jac = mat6D()
    for c in range(MAX_DOF):  # constant bound: unrolled; columns >= n have zero axes and stay zero
        a = wp.vec3(axes[0, c], axes[1, c], axes[2, c])
        if kinds[c] > 0.5:
            o = wp.vec3(origins[0, c], origins[1, c], origins[2, c])
            v = wp.cross(a, p - o)
            for k in range(3):
                jac[k, c] = v[k]
                jac[k + 3, c] = a[k]
        else:
            for k in range(3):
                jac[k, c] = a[k]
    return jac


@wp.func
def _chol_solve6(a: mat66, b: vec6):
    """Solve a x = b for a symmetric positive definite 6×6 a (Cholesky; constant loop bounds, unrolled)."""
    lo = mat66()
    for i in range(6):
        for j in range(6):
            if j <= i:
                s = a[i, j]
                for k in range(6):
                    if k < j:
                        s -= lo[i, k] * lo[j, k]
                if i == j:
                    lo[i, i] = wp.sqrt(wp.max(s, 1.0e-30))
                else:
                    lo[i, j] = s / lo[j, j]
    y = vec6()
    for i in range(6):
        s = b[i]
        for k in range(6):
            if k < i:
                s -= lo[i, k] * y[k]
        y[i] = s / lo[i, i]
    x = vec6()
    for ii in range(6):
        i = 5 - ii
        s = y[i]
        for k in range(6):
            if k > i:
                s -= lo[k, i] * x[k]
        x[i] = s / lo[i, i]
    return x


@wp.func
def _chol_solveD(a: matDD, b: vecD):
    """Solve a x = b for a symmetric positive definite MAX_DOF × MAX_DOF a (Cholesky; constant loop bounds)."""
    lo = matDD()
    for i in range(MAX_DOF):
        for j in range(MAX_DOF):
            if j <= i:
                s = a[i, j]
                for k in range(MAX_DOF):
                    if k < j:
                        s -= lo[i, k] * lo[j, k]
                if i == j:
                    lo[i, i] = wp.sqrt(wp.max(s, 1.0e-30))
                else:
                    lo[i, j] = s / lo[j, j]
    y = vecD()
    for i in range(MAX_DOF):
        s = b[i]
        for k in range(MAX_DOF):
            if k < i:
                s -= lo[i, k] * y[k]
        y[i] = s / lo[i, i]
    x = vecD()
    for ii in range(MAX_DOF):
        i = MAX_DOF - 1 - ii
        s = y[i]
        for k in range(MAX_DOF):
            if k > i:
                s -= lo[k, i] * x[k]
        x[i] = s / lo[i, i]
    return x


@wp.func
def _dls(jac: mat6D, dx: vec6, n: int, lam: float, pinv: int):
    """Joint step of one damped least-squares (or pseudo-inverse) solve of ``J dq = dx``."""
    dq = vecD()
    if pinv != 0 and n < 6:
        a = matDD()
        rhs = vecD()
        for i in range(MAX_DOF):
            for j in range(MAX_DOF):
                s = float(0.0)
                for k in range(6):
                    s += jac[k, i] * jac[k, j]
                a[i, j] = s
            if i >= n:
                a[i, i] = 1.0  # unused columns: identity, so their dq is 0
            s2 = float(0.0)
            for k in range(6):
                s2 += jac[k, i] * dx[k]
            rhs[i] = s2
        return _chol_solveD(a, rhs)
    a6 = mat66()
    for i in range(6):
        for j in range(i + 1):
            s = float(0.0)
            for c in range(MAX_DOF):  # zero columns beyond n add nothing
                s += jac[i, c] * jac[j, c]
            a6[i, j] = s
            a6[j, i] = s
        if pinv == 0:
            a6[i, i] = a6[i, i] + lam
    y = _chol_solve6(a6, dx)
    for c in range(MAX_DOF):
        s = float(0.0)
        for k in range(6):
            s += jac[k, c] * y[k]
        dq[c] = s
    return dq


@wp.func
def _compose(prev: wp.transform, act: vecD, pose: int, use_delta: int, frame_bits: int):
    """ManiSkill's ``compute_target_pose`` from the processed action (root frame)."""
    p_prev = wp.transform_get_translation(prev)
    q_prev = wp.transform_get_rotation(prev)
    dp = wp.vec3(act[0], act[1], act[2])
    if use_delta == 0:
        q = q_prev
        if pose != 0:
            q = _quat_euler_xyz(wp.vec3(act[3], act[4], act[5]))
        return wp.transform(dp, q)
    q = q_prev
    if pose != 0:
        dq = _quat_euler_xyz(wp.vec3(act[3], act[4], act[5]))
        if frame_bits & FRAME_BODY_ROT:
            q = _std(q_prev * dq)
        else:
            q = _std(dq * q_prev)
    p = p_prev + dp
    if frame_bits & FRAME_BODY_TRANS:
        p = p_prev + wp.quat_rotate(q_prev, dp)
    return wp.transform(p, q)


@wp.func
def _store_target(
    target_qpos_out: wp.array2d[float],
    env: int,
    r: int,
    t: float,
    qlo: wp.array[float],
    qhi: wp.array[float],
    clip: int,
):
    """Store a joint target; with ``clip_targets`` clamped to the joint's limits, as the joint rows are."""
    if clip != 0:
        t = wp.clamp(t, qlo[r], qhi[r])
    target_qpos_out[env, r] = t


# ---------------------------------------------------------------------------------------------------------------------
# Kernels.


def _make_set_action_kernel(clik: bool):
    """The EE ``set_action`` kernel, specialised at code generation: one DLS step (``clik=False``, ManiSkill's
    GPU semantics) or the iterative CLIK (``clik=True``, its CPU semantics). Each variant carries only its own
    path, which keeps the one-step kernel's per-thread state small on the GPU."""

    @wp.kernel(module="unique", enable_backward=False)
    def kernel(
        # Chain:
        chain_joint: wp.array2d[wp.int32],
        chain_col: wp.array[wp.int32],
        joint_type: wp.array[wp.int32],
        joint_X_p: wp.array[wp.transform],
        joint_X_c: wp.array[wp.transform],
        joint_axis: wp.array[wp.vec3],
        joint_q_start: wp.array[wp.int32],
        joint_qd_start: wp.array[wp.int32],
        env_root: wp.array[wp.transform],
        ee_offset: wp.transform,
        # Rows of the EE joints (columns of the Jacobian) and action columns:
        row_q_off: wp.array[wp.int32],
        env_q_base: wp.array[wp.int32],
        row_qlo: wp.array[float],  # the mode's rows (index row0 + c): joint limits [rad or m] for clip_targets
        row_qhi: wp.array[float],
        clip_targets: int,
        row0: int,
        num_dof: int,
        col0: int,
        # Parameters:
        pose: int,
        use_delta: int,
        use_target: int,
        normalize: int,
        frame_bits: int,
        solver: int,
        alpha: float,
        lm_lambda: float,
        iterations: int,
        tolerance: float,
        clik_dt: float,
        clik_damping: float,
        act_lo: wp.vec3,
        act_hi: wp.vec3,
        rot_scale: wp.vec3,
        # In:
        action_in: wp.array2d[float],
        joint_q_in: wp.array[float],
        # Out:
        processed_action_out: wp.array2d[float],
        target_qpos_out: wp.array2d[float],
        target_pose_out: wp.array2d[float],  # in/out with use_target
        ee_pose_out: wp.array2d[float],
        ik_success_out: wp.array[wp.int32],
    ):
        """One control step of one env: processed action, target pose, IK; writes the EE rows' ``target_qpos`` [rad/m].

        An env whose action holds NaN/Inf (any column of the whole mode) is left untouched, as the joint kernel does.
        """
        env = wp.tid()
        for c in range(action_in.shape[1]):
            if not wp.isfinite(action_in[env, c]):
                return
        q_base = env_q_base[env]
        q0 = vecD()
        for c in range(MAX_DOF):
            if c < num_dof:
                q0[c] = joint_q_in[q_base + row_q_off[c]]

        # Processed action (ManiSkill's _preprocess_action).
        act = vecD()
        for k in range(3):
            a = action_in[env, col0 + k]
            if normalize != 0:
                a = 0.5 * (act_hi[k] + act_lo[k]) + (0.5 * (act_hi[k] - act_lo[k])) * wp.clamp(a, -1.0, 1.0)
            act[k] = a
        if pose != 0:
            r = wp.vec3(action_in[env, col0 + 3], action_in[env, col0 + 4], action_in[env, col0 + 5])
            if normalize != 0:
                nrm = wp.sqrt(r[2] * r[2] + (r[1] * r[1] + r[0] * r[0]))
                if nrm > 1.0:
                    r = r * (1.0 / nrm)
                r = wp.cw_mul(r, rot_scale)
            act[3] = r[0]
            act[4] = r[1]
            act[5] = r[2]
        for k in range(6):
            if k < 3 + 3 * pose:
                processed_action_out[env, col0 + k] = act[k]

        t_ee, t_joint, axes, origins, kinds = _chain_fk(
            env,
            chain_joint,
            chain_col,
            joint_type,
            joint_X_p,
            joint_X_c,
            joint_axis,
            joint_q_start,
            joint_qd_start,
            env_root,
            ee_offset,
            joint_q_in,
            q0,
        )
        _write_pose(ee_pose_out, env, t_ee)

        compose = iterations > 1 or use_target != 0 or use_delta == 0
        target = t_ee
        if compose:
            prev = t_ee
            if use_target != 0:
                prev = _read_pose(target_pose_out, env)
            target = _compose(prev, act, pose, use_delta, frame_bits)
            _write_pose(target_pose_out, env, target)

        if not wp.static(clik):
            # ManiSkill's GPU path: one damped least-squares step at the measured q.
            dx = vec6()
            if not compose:
                for k in range(6):
                    dx[k] = act[k]  # zero rotation for a position-only controller
            else:
                dp = wp.transform_get_translation(target) - wp.transform_get_translation(t_ee)
                dr = _euler_xyz(
                    _std(wp.transform_get_rotation(target) * wp.quat_inverse(wp.transform_get_rotation(t_ee)))
                )
                dx = vec6(dp[0], dp[1], dp[2], dr[0], dr[1], dr[2])
            jac = _jacobian(wp.transform_get_translation(t_ee), axes, origins, kinds, num_dof)
            dq = _dls(jac, dx, num_dof, lm_lambda, solver)
            for c in range(MAX_DOF):
                if c < num_dof:
                    _store_target(target_qpos_out, env, row0 + c, q0[c] + alpha * dq[c], row_qlo, row_qhi, clip_targets)
            ik_success_out[env] = 1

        if wp.static(clik):
            # ManiSkill's CPU path: Pinocchio CLIK on the last moving joint's frame, seeded with the measured q.
            l2j = wp.transform_inverse(t_joint) * t_ee  # EE frame in the joint frame (constant)
            des = target * wp.transform_inverse(l2j)
            des_inv = wp.transform_inverse(des)
            q = q0
            success = int(0)
            for it in range(iterations + 1):
                te, tj, ax, og, kd = _chain_fk(
                    env,
                    chain_joint,
                    chain_col,
                    joint_type,
                    joint_X_p,
                    joint_X_c,
                    joint_axis,
                    joint_q_start,
                    joint_qd_start,
                    env_root,
                    ee_offset,
                    joint_q_in,
                    q,
                )
                err = _log6(des_inv * tj)
                if wp.length(err) < tolerance:
                    success = 1
                    break
                if it >= iterations:
                    break
                # Local (joint-frame) Jacobian: velocity of the joint origin, rotated into the joint frame.
                pj = wp.transform_get_translation(tj)
                jw = _jacobian(pj, ax, og, kd, num_dof)
                rq = wp.transform_get_rotation(tj)
                jl = mat6D()
                for c in range(MAX_DOF):  # zero columns beyond num_dof stay zero
                    v = wp.quat_rotate_inv(rq, wp.vec3(jw[0, c], jw[1, c], jw[2, c]))
                    w = wp.quat_rotate_inv(rq, wp.vec3(jw[3, c], jw[4, c], jw[5, c]))
                    for k in range(3):
                        jl[k, c] = v[k]
                        jl[k + 3, c] = w[k]
                step = _dls(jl, err, num_dof, clik_damping, 0)
                for c in range(MAX_DOF):
                    q[c] = q[c] - clik_dt * step[c]
            ik_success_out[env] = success
            for c in range(MAX_DOF):
                if c < num_dof:
                    t = q0[c]
                    if success != 0:
                        t = q[c]
                    _store_target(target_qpos_out, env, row0 + c, t, row_qlo, row_qhi, clip_targets)

    return kernel


_ee_set_action_kernel = _make_set_action_kernel(False)
_ee_clik_kernel = _make_set_action_kernel(True)


@wp.kernel
def _ee_reset_kernel(
    # Chain:
    chain_joint: wp.array2d[wp.int32],
    chain_col: wp.array[wp.int32],
    joint_type: wp.array[wp.int32],
    joint_X_p: wp.array[wp.transform],
    joint_X_c: wp.array[wp.transform],
    joint_axis: wp.array[wp.vec3],
    joint_q_start: wp.array[wp.int32],
    joint_qd_start: wp.array[wp.int32],
    env_root: wp.array[wp.transform],
    ee_offset: wp.transform,
    row_q_off: wp.array[wp.int32],
    env_q_base: wp.array[wp.int32],
    num_dof: int,
    use_target: int,
    # In:
    env_ids_in: wp.array[wp.int32],  # optional: thread i resets env env_ids_in[i]
    env_mask_in: wp.array[wp.bool],  # optional: reset only where True
    joint_q_in: wp.array[float],
    # Out:
    target_pose_out: wp.array2d[float],
    ee_pose_out: wp.array2d[float],
):
    """Reset: the measured EE pose; with ``use_target`` it also becomes the target pose (ManiSkill's reset)."""
    env = wp.tid()
    if env_ids_in:
        env = env_ids_in[env]
        if env < 0 or env >= ee_pose_out.shape[0]:
            return
    if env_mask_in:
        if not env_mask_in[env]:
            return
    q0 = vecD()
    for c in range(MAX_DOF):
        if c < num_dof:
            q0[c] = joint_q_in[env_q_base[env] + row_q_off[c]]
    t_ee, t_joint, axes, origins, kinds = _chain_fk(
        env,
        chain_joint,
        chain_col,
        joint_type,
        joint_X_p,
        joint_X_c,
        joint_axis,
        joint_q_start,
        joint_qd_start,
        env_root,
        ee_offset,
        joint_q_in,
        q0,
    )
    _write_pose(ee_pose_out, env, t_ee)
    if use_target != 0:
        _write_pose(target_pose_out, env, t_ee)


@wp.kernel
def _ee_fk_jacobian_kernel(
    # Chain:
    chain_joint: wp.array2d[wp.int32],
    chain_col: wp.array[wp.int32],
    joint_type: wp.array[wp.int32],
    joint_X_p: wp.array[wp.transform],
    joint_X_c: wp.array[wp.transform],
    joint_axis: wp.array[wp.vec3],
    joint_q_start: wp.array[wp.int32],
    joint_qd_start: wp.array[wp.int32],
    env_root: wp.array[wp.transform],
    ee_offset: wp.transform,
    row_q_off: wp.array[wp.int32],
    env_q_base: wp.array[wp.int32],
    num_dof: int,
    # In:
    joint_q_in: wp.array[float],
    # Out:
    ee_pose_out: wp.array2d[float],
    jacobian_out: wp.array3d[float],
):
    """The EE pose (root frame) and its geometric Jacobian (6, num_dof) per env, from ``joint_q``."""
    env = wp.tid()
    q0 = vecD()
    for c in range(MAX_DOF):
        if c < num_dof:
            q0[c] = joint_q_in[env_q_base[env] + row_q_off[c]]
    t_ee, t_joint, axes, origins, kinds = _chain_fk(
        env,
        chain_joint,
        chain_col,
        joint_type,
        joint_X_p,
        joint_X_c,
        joint_axis,
        joint_q_start,
        joint_qd_start,
        env_root,
        ee_offset,
        joint_q_in,
        q0,
    )
    _write_pose(ee_pose_out, env, t_ee)
    jac = _jacobian(wp.transform_get_translation(t_ee), axes, origins, kinds, num_dof)
    for k in range(6):
        for c in range(MAX_DOF):
            if c < num_dof:
                jacobian_out[env, k, c] = jac[k, c]


@wp.kernel
def _copy_pose_kernel(
    # In:
    src_in: wp.array2d[float],
    # Out:
    dst_out: wp.array2d[float],
):
    """Copy (num_envs, 7) pose rows."""
    i, j = wp.tid()
    dst_out[i, j] = src_in[i, j]
