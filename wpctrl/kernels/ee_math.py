"""Warp functions of the end-effector kernels: pose rows, rotations, log6, chain FK, Jacobian, solves, target pose.

Private module (see :mod:`wpctrl.kernels.ee`). Every per-thread vector and matrix is indexed with constants (loops
with constant bounds, select chains instead of ``a[c]`` with a loaded ``c``), so on the GPU they live in registers.
"""

from __future__ import annotations

import newton
import warp as wp

from ..config import ee as ee_config
from .cholesky import spd_solve
from .pd import _scale

wp.set_module_options({"enable_backward": False})

MAX_DOF = wp.constant(ee_config.MAX_EE_DOF)
SOLVER_PINV = wp.constant(ee_config.SOLVER_PINV)
FRAME_BODY_TRANS = wp.constant(ee_config.FRAME_BODY_TRANS)
FRAME_BODY_ROT = wp.constant(ee_config.FRAME_BODY_ROT)
JOINT_PRISMATIC = wp.constant(int(newton.JointType.PRISMATIC))
JOINT_REVOLUTE = wp.constant(int(newton.JointType.REVOLUTE))

vecD = wp.types.vector(length=ee_config.MAX_EE_DOF, dtype=float)
mat3D = wp.types.matrix(shape=(3, ee_config.MAX_EE_DOF), dtype=float)
mat6D = wp.types.matrix(shape=(6, ee_config.MAX_EE_DOF), dtype=float)
matDD = wp.types.matrix(shape=(ee_config.MAX_EE_DOF, ee_config.MAX_EE_DOF), dtype=float)
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


@wp.func
def _pose_action(
    action_in: wp.array2d[float],
    env: int,
    col0: int,
    pose: int,
    normalize: int,
    act_lo: wp.vec3,
    act_hi: wp.vec3,
    rot_scale: wp.vec3,
):
    """ManiSkill's processed EE action from columns ``col0..``: the position scaled onto [lo, hi] (clipped to [-1, 1]
    first when normalised), then for a pose the rotation clipped by its norm and multiplied by ``rot_scale``."""
    act = vecD()
    for k in range(3):
        act[k] = _scale(action_in[env, col0 + k], act_lo[k], act_hi[k], normalize)
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
    return act


# ---------------------------------------------------------------------------------------------------------------------
# Chain FK and Jacobian.


@wp.func
def _measured_q(
    env: int, row_q_off: wp.array[wp.int32], env_q_base: wp.array[wp.int32], num_dof: int, joint_q: wp.array[float]
):
    """The env's measured positions [rad or m] of the controlled joints (columns 0..num_dof-1; the rest zero)."""
    q = vecD()
    for c in range(MAX_DOF):
        if c < num_dof:
            q[c] = joint_q[env_q_base[env] + row_q_off[c]]
    return q


@wp.struct
class EEChain:
    """An end-effector chain as the EE and OSC kernels read it (one kernel argument instead of ten): per env, the
    chain's Newton joints from the root to the EE body, the Jacobian column of each (-1: a joint the controller does
    not move), each env's root frame and the EE body's offset, and Newton's joint arrays the forward kinematics
    reads. Filled by the end-effector part (:class:`wpctrl.engine.parts.ee.EEPart`)."""

    chain_joint: wp.array2d[wp.int32]  # (num_envs, chain joints) Newton joint ids, root first
    chain_col: wp.array[wp.int32]  # (chain joints,) the joint's column in the Jacobian, -1 when not controlled
    joint_type: wp.array[wp.int32]  # Newton's model arrays
    joint_X_p: wp.array[wp.transform]
    joint_X_c: wp.array[wp.transform]
    joint_axis: wp.array[wp.vec3]
    joint_q_start: wp.array[wp.int32]
    joint_qd_start: wp.array[wp.int32]
    env_root: wp.array[wp.transform]  # (num_envs,) the root frame in world
    ee_offset: wp.transform  # the EE frame in its body's frame


@wp.func
def _chain_fk(
    env: int,
    chain: EEChain,
    joint_q: wp.array[float],
    qv: vecD,
):
    """FK of one env's chain in the root frame. Controlled joints (column c >= 0) take ``qv[c]``, other 1-DOF joints
    their ``joint_q``. Returns the EE pose, the frame of the last moving joint (Pinocchio's joint frame), the
    columns' axes, origins (root frame) and kinds (1 revolute, 0 prismatic)."""
    t = chain.env_root[env]
    t_joint = t
    axes = mat3D()
    origins = mat3D()
    kinds = vecD()
    for i in range(chain.chain_joint.shape[1]):
        j = chain.chain_joint[env, i]
        x = t * chain.joint_X_p[j]
        jt = chain.joint_type[j]
        if jt == JOINT_REVOLUTE or jt == JOINT_PRISMATIC:
            c = chain.chain_col[i]
            a = chain.joint_axis[chain.joint_qd_start[j]]
            q = float(0.0)
            if c >= 0:
                for cc in range(MAX_DOF):  # constant indices (registers on the GPU), not qv[c]
                    if cc == c:
                        q = qv[cc]
            else:
                q = joint_q[chain.joint_q_start[j]]
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
        t = x * wp.transform_inverse(chain.joint_X_c[j])
    return t * chain.ee_offset, t_joint, axes, origins, kinds


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


_chol_solve6 = spd_solve(6)
"""x with a x = b for a symmetric positive definite 6 x 6 a."""
_chol_solveD = spd_solve(ee_config.MAX_EE_DOF)
"""x with a x = b for a symmetric positive definite MAX_DOF x MAX_DOF a."""


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
