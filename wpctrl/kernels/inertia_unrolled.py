"""The fused inertia function compiled for one articulation: every loop unrolled (the CUDA default of
:class:`wpctrl.kernels.inertia.FusedChain`).

Private module. Same signature and result as the runtime-loop function of :func:`wpctrl.kernels.inertia.chain_funcs`
(forward kinematics from ``joint_q``, H over the bodies plus armature, float64 Cholesky (:mod:`.cholesky`), the
controlled block of ``H^-1``), with the articulation's structure (joint types, parents, DOFs, ancestor masks,
controlled rows) as compile-time constants. On CUDA its local matrices are then indexed by constants only and stay in
registers.
"""

from __future__ import annotations

import warp as wp

from .cholesky import cholesky_funcs
from .spatial import J_FIXED, J_REVOLUTE, _body_world_inertia

wp.set_module_options({"enable_backward": False})


def subtrees_contiguous(template: tuple, n: int) -> bool:
    """Whether every DOF's subtree is a contiguous run of the articulation's joints, starting at the DOF's own joint
    (joints in parents-first depth-first order, as builders write articulations). Then H is built in composite form
    (the composite rigid-body algorithm's ``I^c`` of a subtree as the difference of two running sums over the
    bodies); otherwise body by body over the DOF pairs that move each body."""
    JT, PAR, DOF, ANC, ROWD = template
    nj = len(JT)
    for i in range(n):
        sub = [k for k in range(nj) if (ANC[k] >> i) & 1]
        k0 = [k for k in range(nj) if DOF[k] == i]
        if not k0 or sub != list(range(k0[0], k0[0] + len(sub))):
            return False
    return True


def h_only(chain_hg_no_gravity):
    """``chain_h``: H alone (``chain_hg``'s arguments without the gravity vector), from a ``chain_hg`` compiled
    without the gravity pass."""

    @wp.func
    def chain_h(
        num_dofs: int,
        jb: int,
        db: int,
        chain_type: wp.array[wp.int32],
        chain_parent: wp.array[wp.int32],
        chain_dof: wp.array[wp.int32],
        chain_anc: wp.array[wp.int32],
        row_dof: wp.array[wp.int32],
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
        joint_q: wp.array[float],
    ):
        H, G = chain_hg_no_gravity(
            num_dofs, jb, db, chain_type, chain_parent, chain_dof, chain_anc, row_dof, joint_q_start, joint_qd_start,
            joint_X_p, joint_X_c, joint_axis, joint_child, joint_armature, body_mass, body_com, body_inertia, joint_q,
            wp.vec3(0.0),
        )  # fmt: skip
        return H

    return chain_h


def unrolled_chain_funcs(nj: int, n: int, nr: int, template: tuple, full: bool):
    """The fused inertia function with the articulation's structure as compile-time constants (same signature and result
    as :func:`~wpctrl.kernels.inertia.chain_funcs`' runtime-loop version; the chain tables passed to it are not read),
    the function of H alone it is built on (``chain_h``, same arguments: H with the armature, lower triangle), and
    ``chain_hg`` (the same arguments and the gravity vector [m/s^2] in the world frame, last: H and the gravity force
    ``g(q) = dU/dq`` [N·m or N] of every DOF, the generalized force that holds the articulation against gravity,
    accumulated in the same pass over the bodies).

    Every loop is unrolled and every local matrix is indexed by constants, so on CUDA the matrices live in registers
    instead of per-thread local memory. H is built in composite form where :func:`subtrees_contiguous` allows it
    (per DOF one product of a running composite inertia with its unit motion where its subtree starts and one where
    it ends, then one 6-vector dot per entry of H), else accumulated body by body over the DOF pairs that move each
    body (its ancestor mask, known at compile time)."""
    JT, PAR, DOF, ANC, ROWD = template
    MatN = wp.types.matrix(shape=(n, n), dtype=wp.float64)
    VecN = wp.types.vector(length=n, dtype=wp.float64)
    MatN3 = wp.types.matrix(shape=(n, 3), dtype=wp.float64)
    MatJ3 = wp.types.matrix(shape=(nj, 3), dtype=float)
    MatJ4 = wp.types.matrix(shape=(nj, 4), dtype=float)
    MatR = wp.types.matrix(shape=(nr, nr), dtype=wp.float64)
    VecR = wp.types.vector(length=nr, dtype=wp.float64)
    REV = [0] * n  # 1: the DOF is revolute
    for k in range(nj):
        if DOF[k] >= 0:
            REV[DOF[k]] = int(JT[k] == J_REVOLUTE)
    MOV = [tuple(i for i in range(n) if (ANC[k] >> i) & 1) for k in range(nj)]  # the DOFs that move body k
    # DOF pairs (i >= j) moving body k, with whether both are revolute (an angular term).
    PAIRS = [tuple((a, b, REV[a] and REV[b]) for a in MOV[k] for b in MOV[k] if b <= a) for k in range(nj)]
    FULL = bool(full)
    _, _, inverse_block, inverse_diag = cholesky_funcs(n, ROWD)
    # The composite form of H: every DOF's subtree a contiguous run of bodies K_i .. LAST[i] (K_i: its own joint).
    KDOF = [0] * n
    for k in range(nj):
        if DOF[k] >= 0:
            KDOF[DOF[k]] = k
    COMPOSITE = subtrees_contiguous(template, n)
    LAST = [max(k for k in range(nj) if (ANC[k] >> i) & 1) for i in range(n)] if COMPOSITE else [0] * n
    ENDS = [tuple(i for i in range(n) if LAST[i] == k) for k in range(nj)]  # DOFs whose subtree ends at body k
    ANCD = [MOV[KDOF[i]] for i in range(n)]  # DOF i and the DOFs above it (j <= i): the row of H it fills

    def make_chain_hg(GRAV: bool):
        """``chain_hg``: H and, with ``GRAV``, the gravity force of every DOF from the same pass (0 without)."""

        @wp.func
        def chain_hg(
            num_dofs: int,
            jb: int,
            db: int,
            chain_type: wp.array[wp.int32],
            chain_parent: wp.array[wp.int32],
            chain_dof: wp.array[wp.int32],
            chain_anc: wp.array[wp.int32],
            row_dof: wp.array[wp.int32],
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
            joint_q: wp.array[float],
            gravity: wp.vec3,
        ):
            H = MatN()
            G = VecN()  # with GRAV: the gravity force dU/dq of every DOF [N·m or N]
            gv = wp.vec3d(wp.float64(gravity[0]), wp.float64(gravity[1]), wp.float64(gravity[2]))
            ax = MatN3()  # DOF axes in world (composite form: the unit motion's angular part, 0 for a prismatic DOF)
            vo = MatN3()  # composite form: the unit motion's linear part, the velocity of O [m/s per unit rate]
            pt = MatN3()  # DOF anchor points in world [m]
            bp = MatJ3()  # child-body world positions
            bq = MatJ4()  # child-body world rotations (x, y, z, w)
            o = wp.vec3d()  # composite form: O, the root joint's anchor in world,
            pm = wp.float64(0.0)  # and the running composite of the bodies so far, about O: mass [kg],
            ph = wp.vec3d()  # first moment [kg m],
            pj = wp.mat33d()  # and rotational inertia [kg m^2]
            for k in range(wp.static(nj)):
                j = jb + k
                Xw = wp.transform_identity()
                if wp.static(PAR[k] >= 0):
                    pk = wp.static(max(PAR[k], 0))
                    Xw = wp.transform(
                        wp.vec3(bp[pk, 0], bp[pk, 1], bp[pk, 2]), wp.quat(bq[pk, 0], bq[pk, 1], bq[pk, 2], bq[pk, 3])
                    )
                Xj = Xw * joint_X_p[j]
                Xjm = Xj  # Xj * X_joint(q), the identity and zero parts of X_joint left out
                if wp.static(JT[k] != J_FIXED):
                    a = joint_axis[joint_qd_start[j]]
                    qv = joint_q[joint_q_start[j]]
                    d = wp.static(max(DOF[k], 0))
                    aw = wp.transform_vector(Xj, a)
                    ow = wp.transform_get_translation(Xj)
                    ax[d] = wp.vec3d(wp.float64(aw[0]), wp.float64(aw[1]), wp.float64(aw[2]))
                    pt[d] = wp.vec3d(wp.float64(ow[0]), wp.float64(ow[1]), wp.float64(ow[2]))
                    if wp.static(JT[k] == J_REVOLUTE):
                        Xjm = wp.transform(ow, wp.transform_get_rotation(Xj) * wp.quat_from_axis_angle(a, qv))
                    else:
                        Xjm = wp.transform(ow + aw * qv, wp.transform_get_rotation(Xj))
                # Xb = Xjm * inverse(X_c): rotation q_jm q_c^-1, origin p_jm - R_b t_c (one rotation fewer)
                Xc = joint_X_c[j]
                qb = wp.transform_get_rotation(Xjm) * wp.quat_inverse(wp.transform_get_rotation(Xc))
                Xb = wp.transform(
                    wp.transform_get_translation(Xjm) - wp.quat_rotate(qb, wp.transform_get_translation(Xc)), qb
                )
                p = wp.transform_get_translation(Xb)
                r = wp.transform_get_rotation(Xb)
                bp[k] = p
                bq[k] = wp.vec4(r[0], r[1], r[2], r[3])
                if wp.static(COMPOSITE):
                    if wp.static(k == 0):
                        ow0 = wp.transform_get_translation(Xj)
                        o = wp.vec3d(wp.float64(ow0[0]), wp.float64(ow0[1]), wp.float64(ow0[2]))
                    # A DOF's subtree starts here: its unit motion, and minus the composite so far applied to it.
                    if wp.static(DOF[k] >= 0):
                        i = wp.static(max(DOF[k], 0))
                        if wp.static(REV[max(DOF[k], 0)]):
                            vo[i] = wp.cross(ax[i], o - pt[i])
                        else:
                            vo[i] = ax[i]
                            ax[i] = wp.vec3d()
                        lm = pj * ax[i] + wp.cross(ph, vo[i])
                        pl = pm * vo[i] + wp.cross(ax[i], ph)
                        for jj in range(wp.static(len(ANCD[max(DOF[k], 0)]))):
                            jd = wp.static(ANCD[max(DOF[k], 0)][jj])
                            H[i, jd] = H[i, jd] - (wp.dot(ax[jd], lm) + wp.dot(vo[jd], pl))
                        if wp.static(GRAV):  # pl: the composite's momentum per unit rate of DOF i (sum of m dc/dq_i)
                            G[i] = G[i] + wp.dot(gv, pl)
                    # This body joins the composite.
                    if wp.static(len(MOV[k]) > 0):
                        m, c, Iw = _body_world_inertia(Xb, joint_child[j], body_mass, body_com, body_inertia)
                        rr = c - o
                        pm = pm + m
                        ph = ph + m * rr
                        pj = pj + Iw + m * (wp.dot(rr, rr) * wp.identity(n=3, dtype=wp.float64) - wp.outer(rr, rr))
                    # Subtrees ending here: the composite now minus the one at their start is their own (CRBA's I^c).
                    for ee in range(wp.static(len(ENDS[k]))):
                        i = wp.static(ENDS[k][ee])
                        lm = pj * ax[i] + wp.cross(ph, vo[i])
                        pl = pm * vo[i] + wp.cross(ax[i], ph)
                        for jj in range(wp.static(len(ANCD[ENDS[k][ee]]))):
                            jd = wp.static(ANCD[ENDS[k][ee]][jj])
                            H[i, jd] = H[i, jd] + wp.dot(ax[jd], lm) + wp.dot(vo[jd], pl)
                        if wp.static(GRAV):  # dU/dq_i = -gravity . (sum over the subtree of m dc/dq_i)
                            G[i] = G[i] - wp.dot(gv, pl)
                else:
                    # This body's contribution to H over the DOF pairs that move it.
                    if wp.static(len(MOV[k]) > 0):
                        m, c, Iw = _body_world_inertia(Xb, joint_child[j], body_mass, body_com, body_inertia)
                        jv = MatN3()  # COM velocity per unit rate of each DOF that moves this body [m/s]
                        Ijw = MatN3()  # I_world times the angular velocity per unit rate (revolute DOFs)
                        for ii in range(wp.static(len(MOV[k]))):
                            i = wp.static(MOV[k][ii])
                            if wp.static(REV[MOV[k][ii]]):
                                jv[i] = wp.cross(ax[i], c - pt[i])
                                Ijw[i] = Iw * ax[i]
                            else:
                                jv[i] = ax[i]
                        if wp.static(GRAV):
                            for ii in range(wp.static(len(MOV[k]))):
                                i = wp.static(MOV[k][ii])
                                G[i] = G[i] - m * wp.dot(gv, jv[i])
                        for pp in range(wp.static(len(PAIRS[k]))):
                            i = wp.static(PAIRS[k][pp][0])
                            i2 = wp.static(PAIRS[k][pp][1])
                            h = H[i, i2] + m * wp.dot(jv[i], jv[i2])
                            if wp.static(PAIRS[k][pp][2]):
                                h = h + wp.dot(Ijw[i], ax[i2])
                            H[i, i2] = h
            for i in range(wp.static(n)):
                H[i, i] = H[i, i] + wp.float64(joint_armature[db + i])
            return H, G

        return chain_hg

    chain_hg = make_chain_hg(True)
    chain_h = h_only(make_chain_hg(False))

    @wp.func
    def chain_rows_factor(
        num_dofs: int,
        jb: int,
        db: int,
        chain_type: wp.array[wp.int32],
        chain_parent: wp.array[wp.int32],
        chain_dof: wp.array[wp.int32],
        chain_anc: wp.array[wp.int32],
        row_dof: wp.array[wp.int32],
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
        joint_q: wp.array[float],
    ):
        H = chain_h(
            num_dofs, jb, db, chain_type, chain_parent, chain_dof, chain_anc, row_dof, joint_q_start, joint_qd_start,
            joint_X_p, joint_X_c, joint_axis, joint_child, joint_armature, body_mass, body_com, body_inertia, joint_q,
        )  # fmt: skip
        if wp.static(FULL):
            return inverse_block(H)
        return inverse_diag(H)

    return (chain_rows_factor, MatR, VecR), chain_h, chain_hg
