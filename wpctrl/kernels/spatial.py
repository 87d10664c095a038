"""Warp functions, constants and the argument bundle shared by the articulation-inertia kernels (:mod:`.inertia`,
:mod:`.inertia_unrolled`, :mod:`.coupled_drive`, :mod:`wpctrl.impedance.warp_kernels`)."""

from __future__ import annotations

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

J_FIXED = 0
J_REVOLUTE = 1
J_PRISMATIC = 2

_FLOAT32_EPS = float(np.finfo(np.float32).eps)


@wp.struct
class Articulation:
    """One articulation per env, as the fused inertia functions read it (one kernel argument instead of eighteen):
    the chain's template (joint types, parents, DOFs, ancestor masks, the controlled rows' DOFs), each env's first
    joint and DOF, and Newton's model arrays the forward kinematics and the inertia read. Filled by
    :meth:`wpctrl.kernels.inertia.FusedChain.articulation`."""

    chain_type: wp.array[wp.int32]  # (joints,) J_FIXED / J_REVOLUTE / J_PRISMATIC
    chain_parent: wp.array[wp.int32]  # (joints,) the parent joint's index in the chain, -1 at the root
    chain_dof: wp.array[wp.int32]  # (joints,) the joint's DOF in the articulation, -1 for a fixed joint
    chain_anc: wp.array[wp.int32]  # (joints,) bit mask of the DOFs that move the joint's child body
    row_dof: wp.array[wp.int32]  # (rows,) each controlled row's DOF in the articulation
    env_joint_base: wp.array[wp.int32]  # (num_envs,) the env's first joint of the articulation
    env_dof_base: wp.array[wp.int32]  # (num_envs,) its first DOF
    joint_q_start: wp.array[wp.int32]  # Newton's model arrays
    joint_qd_start: wp.array[wp.int32]
    joint_X_p: wp.array[wp.transform]
    joint_X_c: wp.array[wp.transform]
    joint_axis: wp.array[wp.vec3]
    joint_child: wp.array[wp.int32]
    joint_armature: wp.array[float]
    body_mass: wp.array[float]
    body_com: wp.array[wp.vec3]
    body_inertia: wp.array[wp.mat33]
    num_dofs: int  # the articulation's DOFs


@wp.func
def _body_world_inertia(Xb: wp.transform, b: int, art: Articulation):
    """Body ``b`` at world pose ``Xb``: its mass [kg], world COM [m] and world inertia about its COM [kg m^2], float64
    (the inertia rotated in float32, as Newton stores it)."""
    m = wp.float64(art.body_mass[b])
    R = wp.quat_to_matrix(wp.transform_get_rotation(Xb))
    cw = R * art.body_com[b] + wp.transform_get_translation(Xb)  # the COM in world (R is needed below too)
    c = wp.vec3d(wp.float64(cw[0]), wp.float64(cw[1]), wp.float64(cw[2]))
    RI = R * art.body_inertia[b]
    # R I R^T, symmetric: its upper triangle, mirrored
    i00 = wp.float64(wp.dot(RI[0], R[0]))
    i01 = wp.float64(wp.dot(RI[0], R[1]))
    i02 = wp.float64(wp.dot(RI[0], R[2]))
    i11 = wp.float64(wp.dot(RI[1], R[1]))
    i12 = wp.float64(wp.dot(RI[1], R[2]))
    i22 = wp.float64(wp.dot(RI[2], R[2]))
    Iw = wp.mat33d(i00, i01, i02, i01, i11, i12, i02, i12, i22)
    return m, c, Iw
