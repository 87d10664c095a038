"""PhysX's articulation drive as its TGS solver applies it: one Gauss–Seidel pass over the drive rows per solver step.

Private module. ManiSkill's PhysX (TGS, 15 position iterations per 10 ms step) does not solve an articulation's joint
drives to convergence. Each position iteration is a sub-step of ``h = dt / 15``: it visits the drive rows once, root
to tip, and gives each an impulse from the implicit PD law over ``h`` with that row's own response
``A_ii = (H^-1)_ii``, seeing the velocity the rows before it have just changed; the accumulated impulse of a row over
the whole step stays within ``force_limit * dt``. On a Panda's coupled shoulder joints this stops a fast move short of
what the rigid-body dynamics give (``panda_joint1`` 25 % in the first saturated step of a ``pd_ee_delta_pos``
episode); the model below reproduces PhysX's result of a 10 ms step within 0.01 mrad.

Per env and solver step (``h`` the solver step, one launch before it), rows ``r`` in articulation order, with
``A = S H^-1 S^T`` of the step's start (:func:`wpctrl.kernels.inertia.FusedChain.launch_response`):

    v_r   = qd_r + h * sum_{c < r} A_rc tau_c                  (the rows already visited in this pass)
    tau_r = (Kp (q*_r - q_r) + Kd qd*_r - (Kp h + Kd) v_r) / (1 + (Kp h + Kd) h A_rr)
    tau_r = clamp(tau_r, (-L T - J_r) / h, (L T - J_r) / h),   J_r += h tau_r

``J`` is the row's impulse so far in the physics step of length ``T`` (zeroed at its start), ``L`` its force limit.
``tau`` goes to ``Control.joint_f``; the solver's own drive of these DOFs must be off. Contacts are the solver's: the
drive reads the velocity its last step left, as PhysX's next iteration does.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.kernel
def tgs_sweep_kernel(
    # Rows (num_envs, rows), in articulation order:
    coord_index: wp.array2d[wp.int32],
    dof_index: wp.array2d[wp.int32],
    kp: wp.array2d[float],
    kd: wp.array2d[float],
    force_limit: wp.array2d[float],
    block: wp.array3d[float],  # A = S H^-1 S^T of the physics step's start [1/(kg m^2) or 1/kg]
    h: float,  # the solver step [s]
    window: float,  # the physics step [s]: the force limit bounds the impulse over it
    velocity_target: int,  # 1: the rows track Control.joint_target_qd, 0: a zero target velocity
    # In:
    joint_q: wp.array[float],
    joint_qd: wp.array[float],
    joint_target_q: wp.array[float],
    joint_target_qd: wp.array[float],
    # In / out:
    impulse: wp.array2d[float],  # [N·m·s or N·s] each row's impulse so far in the physics step
    # Out:
    joint_f: wp.array[float],
):
    """Per env: one Gauss–Seidel pass over the drive rows (module docstring); writes each row's torque."""
    env = wp.tid()
    rows = dof_index.shape[1]
    for r in range(rows):
        d = dof_index[env, r]
        v = joint_qd[d]
        for c in range(r):
            v += h * block[env, r, c] * joint_f[dof_index[env, c]]
        p = kp[env, r]
        damp = kd[env, r]
        target_v = float(0.0)
        if velocity_target != 0:
            target_v = joint_target_qd[d]
        ci = coord_index[env, r]
        c_eff = p * h + damp
        tau = (p * (joint_target_q[ci] - joint_q[ci]) + damp * target_v - c_eff * v) / (
            1.0 + c_eff * h * block[env, r, r]
        )
        room = force_limit[env, r] * window
        tau = wp.clamp(tau, (-room - impulse[env, r]) / h, (room - impulse[env, r]) / h)
        impulse[env, r] = impulse[env, r] + tau * h
        joint_f[d] = tau
