"""Fused joint-space inertia kernels: one thread per env builds its articulation's H from ``joint_q`` and factors it.

Private module. Per env, one thread:

1. forward kinematics of the articulation from ``State.joint_q`` (float32, Newton's conventions:
   ``X_wc = X_wp * joint_X_p * X_j(q) * inverse(joint_X_c)``), never from a possibly stale ``State.body_q``;
2. the joint-space inertia ``H = sum_b m_b Jv_b^T Jv_b + Jw_b^T I_b Jw_b`` over the articulation's bodies (the
   composite-rigid-body result, accumulated per body from its COM Jacobian), plus ``joint_armature`` on the diagonal
   (as Newton's ``eval_mass_matrix`` / ``JointSpaceResponse`` / Featherstone do), in float64;
3. its Cholesky factor ``H = L L^T`` (float64, pivots floored like Newton's ``JointSpaceResponse``), in registers;
4. for the controlled rows (articulation-local DOFs ``d_r``): ``y_r = L^-1 e_{d_r}``, so that
   ``(H^-1)_{d_r d_c} = y_r . y_c``. The response kernel writes ``r = (H^-1)_{d_r d_r}``; the coupled drive
   (:mod:`wpctrl.kernels.coupled_drive`) uses the whole block ``A = Y Y^T``.

Supported articulations (:func:`chain_layout` checks, else callers fall back to ``JointSpaceResponse``): fixed base
(the root joint's parent is the world), revolute / prismatic / fixed joints only, at most :data:`MAX_CHAIN_DOFS`
DOFs, the same layout in every world. Kernels are specialised per (joints, DOFs, rows) of the articulation: local
matrices have exact sizes, so they stay in registers on CUDA for a Panda-sized chain.
"""

from __future__ import annotations

from dataclasses import dataclass

import newton
import numpy as np
import warp as wp

from .dims import PER_ENV_BLOCK_DIM
from .inertia_unrolled import h_only, unrolled_chain_funcs
from .spatial import _FLOAT32_EPS, J_FIXED, J_PRISMATIC, J_REVOLUTE, _body_world_inertia  # noqa: F401

wp.set_module_options({"enable_backward": False})

MAX_CHAIN_DOFS = 24
"""Largest articulation DOF count of the fused kernels (the ancestor masks are int32 bitmasks; local matrices are
N x N float64, so the per-thread footprint grows as N^2: a 9-DOF Panda uses 81 doubles for H)."""


@dataclass
class ChainLayout:
    """Host tables of one articulation template (identical in every env), and per-env bases."""

    num_joints: int
    num_dofs: int
    jtype: np.ndarray  # (num_joints,) int32: J_FIXED / J_REVOLUTE / J_PRISMATIC
    parent: np.ndarray  # (num_joints,) int32: local index of the joint whose child is this joint's parent, -1: world
    dof: np.ndarray  # (num_joints,) int32: local DOF of the joint, -1 for a fixed joint
    anc: np.ndarray  # (num_joints,) int32: bitmask of the local DOFs that move this joint's child body
    row_dof: np.ndarray  # (rows,) int32: local DOF of each controlled row
    env_joint_base: np.ndarray  # (num_envs,) int32: global index of the articulation's first joint
    env_dof_base: np.ndarray  # (num_envs,) int32: global index of the articulation's first DOF

    def template(self) -> tuple:
        """The articulation's structure as compile-time constants of the unrolled kernels: (joint types, parents,
        DOFs, ancestor masks, controlled rows' DOFs), tuples of ints."""
        return tuple(tuple(int(x) for x in a) for a in (self.jtype, self.parent, self.dof, self.anc, self.row_dof))


def chain_layout(model: newton.Model, joint_index: np.ndarray, dof_index: np.ndarray) -> tuple[ChainLayout | None, str]:
    """The fused-kernel layout of the articulation holding the controlled joints, or ``(None, reason)``.

    Args:
        model: The finalized model.
        joint_index: (num_envs, rows) Newton joint ids of the controlled joints.
        dof_index: (num_envs, rows) their DOF indices.
    """
    art = model.joint_articulation.numpy()[joint_index]
    if (art < 0).any():
        return None, "a controlled joint is not in an articulation"
    if (art != art[:, :1]).any():
        return None, "the controlled joints span several articulations of one env"
    art = art[:, 0]
    a_start = model.articulation_start.numpy()
    a_end = model.articulation_end.numpy() if model.articulation_end is not None else a_start[1:]
    j0 = a_start[art].astype(np.int64)
    j1 = a_end[art].astype(np.int64)
    nj = j1 - j0
    if (nj != nj[0]).any():
        return None, "the articulations differ across worlds"
    nj = int(nj[0])
    jt = model.joint_type.numpy()
    par = model.joint_parent.numpy()
    child = model.joint_child.numpy()
    qd_start = model.joint_qd_start.numpy()
    tmpl = np.arange(j0[0], j0[0] + nj)
    kinds = {int(newton.JointType.REVOLUTE): J_REVOLUTE, int(newton.JointType.PRISMATIC): J_PRISMATIC}
    kinds[int(newton.JointType.FIXED)] = J_FIXED
    jtype = np.zeros(nj, np.int32)
    parent = np.full(nj, -1, np.int32)
    dof = np.full(nj, -1, np.int32)
    anc = np.zeros(nj, np.int64)
    body_joint = {int(child[j]): k for k, j in enumerate(tmpl)}
    d = 0
    for k, j in enumerate(tmpl):
        t = int(jt[j])
        if t not in kinds:
            return None, f"joint type {newton.JointType(t).name} (only revolute / prismatic / fixed are fused)"
        jtype[k] = kinds[t]
        p = int(par[j])
        if p >= 0:
            if p not in body_joint:
                return None, "a joint's parent body is outside its articulation"
            parent[k] = body_joint[p]
            if parent[k] >= k:
                return None, "the articulation's joints are not ordered parents first"
            anc[k] = anc[parent[k]]
        if jtype[k] != J_FIXED:
            dof[k] = d
            anc[k] |= 1 << d
            d += 1
    if d > MAX_CHAIN_DOFS:
        return None, f"{d} DOFs in the articulation (the fused kernels take at most {MAX_CHAIN_DOFS})"
    if d == 0:
        return None, "the articulation has no DOF"
    dof_base = qd_start[j0].astype(np.int64)
    # Every env must have the same joint types and the same DOF count (checked on the type table, cheap).
    allj = j0[:, None] + np.arange(nj)[None, :]
    if (jt[allj] != jt[tmpl][None, :]).any() or (qd_start[j0 + nj] - dof_base != d).any():
        return None, "the articulations differ across worlds"
    local = dof_index.astype(np.int64) - dof_base[:, None]
    if (local != local[:1]).any() or (local < 0).any() or (local >= d).any():
        return None, "the controlled DOFs sit differently in their articulations across worlds"
    return (
        ChainLayout(
            num_joints=nj,
            num_dofs=d,
            jtype=jtype,
            parent=parent,
            dof=dof,
            anc=anc.astype(np.int32),
            row_dof=local[0].astype(np.int32),
            env_joint_base=j0.astype(np.int32),
            env_dof_base=dof_base.astype(np.int32),
        ),
        "",
    )


_funcs_cache: dict[tuple, tuple] = {}


def chain_funcs(nj: int, n: int, nr: int, template: tuple | None = None, full: bool = True):
    """``(chain_rows_factor, MatR, VecR)``: the fused inertia ``@wp.func`` for nj joints, n DOFs and nr rows.

    ``chain_rows_factor(...)`` returns ``A`` (nr x nr float64), the controlled block of ``H^-1`` [1/(kg m^2) or 1/kg].
    With ``template`` (:meth:`ChainLayout.template`) the articulation's structure is compiled in and every loop is
    unrolled (:mod:`wpctrl.kernels.inertia_unrolled`); ``full=False`` then fills only the diagonal of ``A``.
    """
    return _chain_funcs(nj, n, nr, template, full)[0]


def chain_h_func(nj: int, n: int, nr: int, template: tuple | None = None):
    """``chain_h``: the ``@wp.func`` of H alone (same arguments as ``chain_rows_factor``): the articulation's
    joint-space inertia with the armature, float64, lower triangle filled [kg m^2 or kg]; unrolled with ``template``
    as :func:`chain_funcs`."""
    return _chain_funcs(nj, n, nr, template, True)[1]


def chain_hg_func(nj: int, n: int, nr: int, template: tuple | None = None):
    """``chain_hg``: ``chain_h``'s arguments and the gravity vector [m/s^2] in the world frame, last; returns H (as
    ``chain_h``) and the gravity force ``g(q) = dU/dq`` [N·m or N] of every DOF (float64, length n: the generalized
    force that holds the articulation static against gravity, ``eval_inverse_dynamics_passive``'s
    ``gravity_force``), accumulated in the same pass over the bodies; unrolled with ``template``."""
    return _chain_funcs(nj, n, nr, template, True)[2]


def _chain_funcs(nj: int, n: int, nr: int, template: tuple | None, full: bool):
    if template is not None:
        key = (nj, n, nr, template, bool(full))
        if key not in _funcs_cache:
            _funcs_cache[key] = unrolled_chain_funcs(nj, n, nr, template, bool(full))
        return _funcs_cache[key]
    key = (nj, n, nr)
    if key in _funcs_cache:
        return _funcs_cache[key]
    MatN = wp.types.matrix(shape=(n, n), dtype=wp.float64)
    VecN = wp.types.vector(length=n, dtype=wp.float64)
    MatN3 = wp.types.matrix(shape=(n, 3), dtype=wp.float64)
    MatJ3 = wp.types.matrix(shape=(nj, 3), dtype=float)
    MatJ4 = wp.types.matrix(shape=(nj, 4), dtype=float)
    MatRN = wp.types.matrix(shape=(nr, n), dtype=wp.float64)
    MatR = wp.types.matrix(shape=(nr, nr), dtype=wp.float64)
    VecR = wp.types.vector(length=nr, dtype=wp.float64)
    eps32 = wp.float64(_FLOAT32_EPS)

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
            # Loop bounds are read at run time (not unrolled): the fully unrolled triple loop over a 9-DOF chain takes
            # ~20 s to compile on the CPU backend for no measured gain.
            nj_rt = chain_type.shape[0]
            n_rt = num_dofs
            H = MatN()
            G = VecN()  # with GRAV: the gravity force dU/dq of every DOF [N·m or N]
            gv = wp.vec3d(wp.float64(gravity[0]), wp.float64(gravity[1]), wp.float64(gravity[2]))
            ax = MatN3()  # DOF axes in world
            pt = MatN3()  # DOF anchor points in world [m]
            isrev = MatN3()  # column 0: 1 for a revolute DOF
            bp = MatJ3()  # child-body world positions
            bq = MatJ4()  # child-body world rotations (x, y, z, w)
            for k in range(nj_rt):
                j = jb + k
                par = chain_parent[k]
                Xw = wp.transform_identity()
                if par >= 0:
                    Xw = wp.transform(
                        wp.vec3(bp[par, 0], bp[par, 1], bp[par, 2]),
                        wp.quat(bq[par, 0], bq[par, 1], bq[par, 2], bq[par, 3]),
                    )
                Xj = Xw * joint_X_p[j]
                t = chain_type[k]
                Xm = wp.transform_identity()
                if t != 0:
                    a = joint_axis[joint_qd_start[j]]
                    qv = joint_q[joint_q_start[j]]
                    d = chain_dof[k]
                    aw = wp.transform_vector(Xj, a)
                    ow = wp.transform_get_translation(Xj)
                    ax[d] = wp.vec3d(wp.float64(aw[0]), wp.float64(aw[1]), wp.float64(aw[2]))
                    pt[d] = wp.vec3d(wp.float64(ow[0]), wp.float64(ow[1]), wp.float64(ow[2]))
                    if t == 1:
                        Xm = wp.transform(wp.vec3(0.0), wp.quat_from_axis_angle(a, qv))
                        isrev[d, 0] = wp.float64(1.0)
                    else:
                        Xm = wp.transform(a * qv, wp.quat_identity())
                Xb = Xj * Xm * wp.transform_inverse(joint_X_c[j])
                p = wp.transform_get_translation(Xb)
                r = wp.transform_get_rotation(Xb)
                bp[k] = p
                bq[k] = wp.vec4(r[0], r[1], r[2], r[3])
                # This body's contribution to H over the DOFs that move it.
                m, c, Iw = _body_world_inertia(Xb, joint_child[j], body_mass, body_com, body_inertia)
                mask = chain_anc[k]
                jv = MatN3()  # COM velocity per unit rate of each DOF that moves this body [m/s]
                jw = MatN3()  # angular velocity per unit rate [rad/s]
                for i in range(n_rt):
                    if (mask >> i) & 1:
                        ai = ax[i]
                        if isrev[i, 0] > wp.float64(0.0):
                            jv[i] = wp.cross(ai, c - pt[i])
                            jw[i] = ai
                        else:
                            jv[i] = ai
                if wp.static(GRAV):  # dU/dq_i = -sum over the bodies moved by DOF i of m gravity . dc/dq_i
                    for i in range(n_rt):
                        if (mask >> i) & 1:
                            G[i] = G[i] - m * wp.dot(gv, jv[i])
                for i in range(n_rt):
                    if (mask >> i) & 1:
                        jvi = jv[i]
                        Ijwi = Iw * jw[i]
                        for jj in range(i + 1):
                            if (mask >> jj) & 1:
                                H[i, jj] = H[i, jj] + m * wp.dot(jvi, jv[jj]) + wp.dot(Ijwi, jw[jj])
            for i in range(n_rt):
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
        n_rt = num_dofs
        nr_rt = row_dof.shape[0]
        # Cholesky H = L L^T in place (lower triangle), pivots floored as in Newton's JointSpaceResponse.
        for jc in range(n_rt):
            s = H[jc, jc]
            for k in range(jc):
                s -= H[jc, k] * H[jc, k]
            s = wp.max(s, eps32 * wp.max(wp.abs(H[jc, jc]), wp.float64(1.0)))
            dg = wp.sqrt(s)
            H[jc, jc] = dg
            for i in range(jc + 1, n_rt):
                tt = H[i, jc]
                for k in range(jc):
                    tt -= H[i, k] * H[jc, k]
                H[i, jc] = tt / dg
        # y_r = L^-1 e_{d_r}: forward substitution from row d_r (entries above it are 0).
        Y = MatRN()
        for rr in range(nr_rt):
            dr = row_dof[rr]
            for i in range(dr, n_rt):
                tt = wp.float64(0.0)
                if i == dr:
                    tt = wp.float64(1.0)
                for k in range(dr, i):
                    tt -= H[i, k] * Y[rr, k]
                Y[rr, i] = tt / H[i, i]
        A = MatR()
        for rr in range(nr_rt):
            for cc in range(rr + 1):
                v = wp.float64(0.0)
                for k in range(n_rt):
                    v += Y[rr, k] * Y[cc, k]
                A[rr, cc] = v
                A[cc, rr] = v
        return A

    out = ((chain_rows_factor, MatR, VecR), chain_h, chain_hg)
    _funcs_cache[key] = out
    return out


_response_cache: dict[tuple, wp.Kernel] = {}


def response_kernel(nj: int, n: int, nr: int, template: tuple | None = None) -> wp.Kernel:
    """The fused response kernel for nj joints, n DOFs, nr controlled rows (cached); unrolled with ``template``."""
    key = (nj, n, nr, template)
    if key in _response_cache:
        return _response_cache[key]
    chain_rows_factor, _, _ = chain_funcs(nj, n, nr, template)

    @wp.kernel(enable_backward=False, module="unique")
    def _fused_response_kernel(
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
        # In:
        joint_q_in: wp.array[float],
        # Out:
        response_out: wp.array2d[float],
        block_out: wp.array3d[float],  # optional: the (rows x rows) block of H^-1
    ):
        """Per env: r = (H^-1)_ii [1/(kg m^2) or 1/kg] of every controlled row (and optionally the whole block)."""
        env = wp.tid()
        A = chain_rows_factor(
            num_dofs, env_joint_base[env], env_dof_base[env], chain_type, chain_parent, chain_dof, chain_anc, row_dof,
            joint_q_start, joint_qd_start, joint_X_p, joint_X_c, joint_axis, joint_child, joint_armature,
            body_mass, body_com, body_inertia, joint_q_in,
        )  # fmt: skip
        nr_rt = row_dof.shape[0]
        for rr in range(nr_rt):
            response_out[env, rr] = float(A[rr, rr])
        if block_out:
            for rr in range(nr_rt):
                for cc in range(nr_rt):
                    block_out[env, rr, cc] = float(A[rr, cc])

    _response_cache[key] = _fused_response_kernel
    return _fused_response_kernel


class FusedChain:
    """Device tables of a :class:`ChainLayout` and the model arrays the fused kernels read.

    ``unroll`` (default: on CUDA devices) compiles the articulation's structure into the kernels with every loop
    unrolled (:mod:`wpctrl.kernels.inertia_unrolled`): on a GPU the local matrices then stay in registers (H200,
    4k Pandas: see bench/README.md). On the CPU backend the unrolled kernel takes far longer to compile for little
    gain, so the runtime-loop kernel is the default there."""

    def __init__(self, layout: ChainLayout, model: newton.Model, unroll: bool | None = None):
        dev = model.device
        self.layout = layout
        self.model = model
        self.unroll = bool(dev.is_cuda) if unroll is None else bool(unroll)

        def up(a):
            return wp.array(np.ascontiguousarray(a, dtype=np.int32), dtype=wp.int32, device=dev)

        self.chain_type = up(layout.jtype)
        self.chain_parent = up(layout.parent)
        self.chain_dof = up(layout.dof)
        self.chain_anc = up(layout.anc)
        self.row_dof = up(layout.row_dof)
        self.env_joint_base = up(layout.env_joint_base)
        self.env_dof_base = up(layout.env_dof_base)
        self.num_rows = int(layout.row_dof.shape[0])

    def chain_args(self) -> dict:
        """The chain, env and model parameters shared by the fused kernels (in their signature order)."""
        m = self.model
        return {
            "chain_type": self.chain_type,
            "chain_parent": self.chain_parent,
            "chain_dof": self.chain_dof,
            "chain_anc": self.chain_anc,
            "row_dof": self.row_dof,
            "env_joint_base": self.env_joint_base,
            "env_dof_base": self.env_dof_base,
            "joint_q_start": m.joint_q_start,
            "joint_qd_start": m.joint_qd_start,
            "joint_X_p": m.joint_X_p,
            "joint_X_c": m.joint_X_c,
            "joint_axis": m.joint_axis,
            "joint_child": m.joint_child,
            "joint_armature": m.joint_armature,
            "body_mass": m.body_mass,
            "body_com": m.body_com,
            "body_inertia": m.body_inertia,
            "num_dofs": self.layout.num_dofs,
        }

    def kernel_key(self) -> tuple:
        """``(joints, DOFs, rows, template or None)``: what the fused kernels are compiled for."""
        return (
            self.layout.num_joints,
            self.layout.num_dofs,
            self.num_rows,
            self.layout.template() if self.unroll else None,
        )

    def launch_response(self, joint_q: wp.array, response_out: wp.array, block_out: wp.array | None = None) -> None:
        """One launch over all envs: ``response_out[env, r] = (H^-1)_rr`` (and the block, if given)."""
        k = response_kernel(*self.kernel_key())
        args = self.chain_args()
        args.update({"joint_q_in": joint_q, "response_out": response_out, "block_out": block_out})
        wp.launch(
            k,
            dim=self.layout.env_joint_base.shape[0],
            inputs=list(args.values()),
            device=self.model.device,
            block_dim=PER_ENV_BLOCK_DIM,
        )
