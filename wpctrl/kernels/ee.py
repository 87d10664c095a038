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

from .ee_math import (
    MAX_DOF,
    _chain_fk,
    _compose,
    _dls,
    _euler_xyz,
    _jacobian,
    _log6,
    _measured_q,
    _pose_action,
    _read_pose,
    _std,
    _store_target,
    _write_pose,
    mat6D,
    vec6,
)
from .pd import _action_finite

wp.set_module_options({"enable_backward": False})


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
        if not _action_finite(action_in, env):
            return
        q0 = _measured_q(env, row_q_off, env_q_base, num_dof, joint_q_in)

        # Processed action (ManiSkill's _preprocess_action).
        act = _pose_action(action_in, env, col0, pose, normalize, act_lo, act_hi, rot_scale)
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
    q0 = _measured_q(env, row_q_off, env_q_base, num_dof, joint_q_in)
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
    q0 = _measured_q(env, row_q_off, env_q_base, num_dof, joint_q_in)
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
