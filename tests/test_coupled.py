"""The coupled implicit PD drive (``explicit_pd="coupled"``) and the fused joint-space inertia kernel.

References: Newton's ``JointSpaceResponse`` and Featherstone's own mass matrix (for the fused ``H^-1``), the
closed-form float64 solution of the linear implicit PD system ``(I + D A) tau = b`` and the KKT conditions of its
box-constrained form (numpy), and the ``stable`` drive (which the coupled one must equal on a single-DOF chain).
"""

from __future__ import annotations

import newton
import numpy as np
import pytest
import warp as wp
from conftest import build_panda

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, PANDA_JOINTS

DT = 0.01
E = 3


def _random_states(model, rng, speed=1.0):
    lo, hi = model.joint_limit_lower.numpy(), model.joint_limit_upper.numpy()
    q = rng.uniform(lo, hi).astype(np.float32)
    qd = rng.normal(0.0, speed, q.shape).astype(np.float32)
    return q, qd


def _block(ctrl, state) -> np.ndarray:
    """The fused kernel's (rows x rows) block of H^-1 per env, float64 (private: the response part's fused kernel)."""
    n = len(ctrl.joint_names)
    resp = wp.zeros((ctrl.num_envs, n), dtype=wp.float32)
    blk = wp.zeros((ctrl.num_envs, n, n), dtype=wp.float32)
    ctrl._engine.response_part._fused.launch_response(state.joint_q, resp, blk)  # private: the fused kernel
    np.testing.assert_array_equal(resp.numpy(), np.diagonal(blk.numpy(), axis1=1, axis2=2))
    return blk.numpy().astype(np.float64)


def test_fused_response_matches_joint_space_response_and_featherstone():
    from newton.actuators import JointSpaceResponse

    model = build_panda(E, armature=[0.1, 0.05, 0.02, 0.01, 0.0, 0.0, 0.003, 0.0, 0.0])
    cfg = wpctrl.PDJointPosControllerConfig(
        PANDA_JOINTS, None, None, 1e3, 1e2, 100.0, normalize_action=False, drive_mode="acceleration"
    )
    ctrl = wpctrl.build_controller(cfg, model, actuation="explicit", explicit_pd="stable")
    part = ctrl._engine.response_part  # private: which path computes r
    assert part._fused is not None and part._jsr is None  # the fused path is the default
    jsr = JointSpaceResponse(model)
    fs = newton.solvers.SolverFeatherstone(model)
    s0, s1, control = model.state(), model.state(), model.control()
    rng = np.random.default_rng(7)
    for _ in range(2):
        q, qd = _random_states(model, rng)
        s0.joint_q.assign(q)
        s0.joint_qd.assign(qd)
        newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
        blk = _block(ctrl, s0)
        ctrl._engine.update_response(s0)  # private: refresh r now (what acceleration drives / stable PD read)
        np.testing.assert_array_equal(ctrl.response.numpy(), np.diagonal(blk, axis1=1, axis2=2).astype(np.float32))
        jsr.refresh(s0)
        inv = jsr.inverse_blocks.numpy().astype(np.float64)
        fs.step(s0, s1, control, None, 1e-5)  # Featherstone assembles H for s0
        # Featherstone's H is the rigid-body matrix: it adds the armature inside its Cholesky factorisation.
        Hf = fs.H.numpy()[: E * 81].reshape(E, 9, 9).astype(np.float64)
        Hf += np.eye(9)[None] * model.joint_armature.numpy().reshape(E, 1, 9)
        for e in range(E):
            ref_f = np.linalg.inv(Hf[e])
            for ref in (inv[e], ref_f):
                np.testing.assert_allclose(np.diag(blk[e]), np.diag(ref), rtol=1e-5)
                assert np.abs(blk[e] - ref).max() <= 1e-5 * np.abs(ref).max()


def test_unrolled_fused_kernel_matches_the_runtime_loop_kernel():
    """The unrolled fused kernel (the default on CUDA: the articulation compiled in) against the runtime-loop one
    (the CPU default), forced on the CPU: the same H^-1 block to float32 rounding, on random Panda configurations;
    and the coupled drive built on it gives the same torques."""
    from wpctrl.kernels.inertia import FusedChain

    model = build_panda(E, armature=[0.1, 0.05, 0.02, 0.01, 0.0, 0.0, 0.003, 0.0, 0.0])
    ctrl = _coupled_ctrl(model, 50.0)
    eng = ctrl._engine  # private: the coupled part's fused kernel, swapped for the unrolled one below
    loop = eng.part("coupled_drive")._fused
    unrolled = FusedChain(loop.layout, model, unroll=True)
    assert not loop.unroll and loop.kernel_key()[3] is None and unrolled.kernel_key()[3] is not None
    s = model.state()
    rng = np.random.default_rng(11)
    for _ in range(3):
        q, _ = _random_states(model, rng)
        s.joint_q.assign(q)
        got = []
        for fc in (loop, unrolled):
            resp = wp.zeros((E, eng.num_rows), dtype=wp.float32)
            blk = wp.zeros((E, eng.num_rows, eng.num_rows), dtype=wp.float32)
            fc.launch_response(s.joint_q, resp, blk)
            got.append(blk.numpy().astype(np.float64))
        scale = np.abs(got[0]).max(axis=(1, 2), keepdims=True)
        assert (np.abs(got[1] - got[0]) <= 1e-6 * scale).all()
    # The coupled drive with the unrolled inertia: same torques as with the runtime loops.
    torques = []
    for fc in (loop, unrolled):
        part = eng.part("coupled_drive")
        part._fused, part._launch = fc, None
        s, c, _, _, target = _setup(ctrl, model, np.random.default_rng(5))
        ctrl.set_action(target, s)
        ctrl.before_simulation_step(s, c)
        torques.append(c.joint_f.numpy().astype(np.float64))
    np.testing.assert_allclose(torques[1], torques[0], rtol=1e-5, atol=1e-4)
    assert np.abs(torques[0]).max() > 1.0  # the drive pushes (a test of something)


def _tree(dfs: bool, num_envs: int = 2):
    """A fixed-base tree of 4 DOFs (a revolute trunk; two branches, one revolute then prismatic, one revolute), its
    joints written depth first (every subtree a contiguous run: H in composite form) or breadth first (the second
    branch between the first and its child: H body by body)."""
    b = newton.ModelBuilder()
    axes = [(0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0)]

    def link(i, mass):
        inertia = wp.mat33(*np.diag([0.02, 0.03, 0.01 + 0.01 * i]).reshape(-1).tolist())
        return b.add_link(mass=mass, com=wp.vec3(0.05 * i, 0.1, -0.02 * i), inertia=inertia)

    def rev(parent, child, i, pos):
        xf = wp.transform(pos, wp.quat_identity())
        return b.add_joint_revolute(parent, child, parent_xform=xf, axis=axes[i % 3], armature=0.01)

    def slide(parent, child):
        xf = wp.transform((0.0, 0.3, 0.1), wp.quat_identity())
        return b.add_joint_prismatic(parent, child, parent_xform=xf, axis=(0.0, 0.0, 1.0), armature=0.01)

    for _ in range(num_envs):
        trunk, left, right, tip = link(0, 3.0), link(1, 1.5), link(2, 1.2), link(3, 0.5)
        js = [rev(-1, trunk, 0, (0.0, 0.0, 0.3)), rev(trunk, left, 1, (0.2, 0.0, 0.4))]
        if dfs:
            js += [slide(left, tip), rev(trunk, right, 2, (-0.2, 0.1, 0.4))]
        else:
            js += [rev(trunk, right, 2, (-0.2, 0.1, 0.4)), slide(left, tip)]
        b.add_articulation(js)
    return b.finalize(device="cpu")


@pytest.mark.parametrize("dfs", [True, False])
def test_unrolled_inertia_composite_and_body_by_body_match_the_runtime_loops(dfs):
    """H^-1 of a branched chain with a prismatic joint, unrolled (composite form for depth-first joints, body by body
    otherwise) against the runtime-loop kernel and Newton's JointSpaceResponse."""
    from newton.actuators import JointSpaceResponse

    from wpctrl.kernels.inertia import FusedChain, chain_layout
    from wpctrl.kernels.inertia_unrolled import subtrees_contiguous

    model = _tree(dfs)
    dof = np.arange(8, dtype=np.int32).reshape(2, 4)
    joints = model.joint_qd_start.numpy()
    jidx = np.array([[np.searchsorted(joints, d, side="right") - 1 for d in row] for row in dof], np.int32)
    layout, why = chain_layout(model, jidx, dof)
    assert layout is not None, why
    assert subtrees_contiguous(layout.template(), layout.num_dofs) == dfs
    jsr = JointSpaceResponse(model)
    s = model.state()
    rng = np.random.default_rng(4)
    for _ in range(3):
        s.joint_q.assign(rng.uniform(-1.5, 1.5, 8).astype(np.float32))
        newton.eval_fk(model, s.joint_q, s.joint_qd, s)
        got = []
        for unroll in (False, True):
            resp = wp.zeros((2, 4), dtype=wp.float32)
            blk = wp.zeros((2, 4, 4), dtype=wp.float32)
            FusedChain(layout, model, unroll=unroll).launch_response(s.joint_q, resp, blk)
            got.append(blk.numpy().astype(np.float64))
        scale = np.abs(got[0]).max()
        assert np.abs(got[1] - got[0]).max() <= 1e-6 * scale
        jsr.refresh(s)
        ref = jsr.inverse_blocks.numpy().astype(np.float64).reshape(2, 4, 4)
        assert np.abs(got[1] - ref).max() <= 1e-5 * scale


def _coupled_ctrl(model, force_limit, drive_mode="force", gripper_passive=False, kp=1e3, kd=1e2, **kw):
    arm = wpctrl.PDJointPosControllerConfig(
        PANDA_ARM_JOINTS, None, None, kp, kd, force_limit, normalize_action=False, drive_mode=drive_mode
    )
    if gripper_passive:
        grip = wpctrl.PassiveControllerConfig(PANDA_GRIPPER_JOINTS, damping=0.0)
    else:
        grip = wpctrl.PDJointPosControllerConfig(
            PANDA_GRIPPER_JOINTS, None, None, kp, kd, force_limit, normalize_action=False, drive_mode=drive_mode
        )
    return wpctrl.build_controller(
        {"arm": arm, "gripper": grip}, model, 100, 100, actuation="explicit", explicit_pd="coupled", **kw
    )


def _setup(ctrl, model, rng, spread=0.3):
    s, c = model.state(), model.control()
    ctrl.reset(s)
    q, qd = _random_states(model, rng)
    s.joint_q.assign(q)
    s.joint_qd.assign(qd)
    b = ctrl  # the controlled joints' coord_index / dof_index
    target = (q[b.coord_index] + rng.normal(0.0, spread, b.coord_index.shape)).astype(np.float32)
    return s, c, q[b.coord_index].astype(np.float64), qd[b.dof_index].astype(np.float64), target


def _system(A, kp, kd, q, qd, tq, accel=False):
    """b and d = dt Kd + dt^2 Kp of one env (float64); acceleration drives scale the gains by 1 / A_ii."""
    kp = np.broadcast_to(kp, q.shape).astype(np.float64)
    kd = np.broadcast_to(kd, q.shape).astype(np.float64)
    if accel:
        kp, kd = kp / np.diag(A), kd / np.diag(A)
    b = kp * (tq - q - DT * qd) + kd * (0.0 - qd)
    d = DT * kd + DT * DT * kp
    return b, d


def test_coupled_without_active_limits_is_the_linear_implicit_solution():
    model = build_panda(E)
    ctrl = _coupled_ctrl(model, 1e9, drive_mode="acceleration")
    # Per-env gains (num_envs, rows).
    kp = np.array([[1e3] * 9, [400.0] * 9, [2e3] * 9], np.float32)
    kd = np.array([[1e2] * 9, [40.0] * 9, [50.0] * 9], np.float32)
    ctrl.set_drive_properties(stiffness=kp, damping=kd)
    s, c, q, qd, target = _setup(ctrl, model, np.random.default_rng(1))
    ctrl.set_action(target, s)
    ctrl.before_simulation_step(s, c)
    tau = c.joint_f.numpy()[ctrl.dof_index].astype(np.float64)
    np.testing.assert_array_equal(c.joint_target_q.numpy()[ctrl.coord_index], target)
    A = _block(ctrl, s)
    for e in range(E):
        b, d = _system(A[e], kp[e], kd[e], q[e], qd[e], target[e], accel=True)
        want = np.linalg.solve(np.eye(9) + np.diag(d) @ A[e], b)
        np.testing.assert_allclose(tau[e], want, rtol=1e-5, atol=1e-5 * np.abs(want).max())
    assert (ctrl.coupled_iterations.numpy() == 1).all()  # exact after the first active-set iteration


def test_coupled_with_limits_satisfies_box_and_kkt():
    model = build_panda(E)
    lim = 30.0
    ctrl = _coupled_ctrl(model, lim, gripper_passive=True, track_effort=True)
    s, c, q, qd, target = _setup(ctrl, model, np.random.default_rng(2), spread=0.5)
    ctrl.set_action(target[:, :7], s)
    ctrl.before_simulation_step(s, c)
    tau = c.joint_f.numpy()[ctrl.dof_index].astype(np.float64)
    A = _block(ctrl, s)
    kp = np.r_[np.full(7, 1e3), 0.0, 0.0]
    kd = np.r_[np.full(7, 1e2), 0.0, 0.0]
    tq = np.concatenate([target[:, :7], np.zeros((E, 2))], axis=1)
    saturated = 0
    for e in range(E):
        np.testing.assert_array_equal(tau[e, 7:], 0.0)  # passive rows (Kp = Kd = 0) apply nothing
        b, d = _system(A[e], kp, kd, q[e], qd[e], tq[e])
        w = b - d * (A[e] @ tau[e])  # the PD force each row asks for at the predicted end-of-substep state
        tol = 1e-4 * lim
        for i in range(7):
            assert abs(tau[e, i]) <= lim * (1 + 1e-6)
            if tau[e, i] >= lim * (1 - 1e-6):
                assert w[i] >= lim - tol  # clamped at +l: the law asks for at least +l
                saturated += 1
            elif tau[e, i] <= -lim * (1 - 1e-6):
                assert w[i] <= -lim + tol
                saturated += 1
            else:
                assert abs(tau[e, i] - w[i]) <= tol  # free: the law holds exactly
    assert 3 <= saturated < 7 * E  # the case exercises both active and free rows
    # Effort readout: the solved torque, the law at the predicted state, one saturation count per clamped row.
    np.testing.assert_array_equal(ctrl.applied_effort.numpy(), tau.astype(np.float32))
    assert int(ctrl.saturation_count.numpy().sum()) == saturated
    assert ctrl.coupled_iterations.numpy().max() <= 9 + 2  # settled by the active-set iteration


@pytest.mark.parametrize("drive_mode", ["force", "acceleration"])
def test_coupled_matches_the_box_qp_on_random_states(drive_mode):
    """Random states, targets and per-env force limits (from none active to most rows clamped): the torques are the
    box QP's solution (reference_np.coupled_torques: scipy's BVLS), with A from Newton's JointSpaceResponse. Clamped
    rows must also be released: a second substep at a state that needs less force frees rows clamped in the first."""
    from newton.actuators import JointSpaceResponse
    from reference_np import coupled_torques

    model = build_panda(E)
    ctrl = _coupled_ctrl(model, 1.0, drive_mode=drive_mode, track_effort=True)
    b_ = ctrl  # the controlled joints' coord_index / dof_index
    jsr = JointSpaceResponse(model)
    rng = np.random.default_rng(12)
    s, c = model.state(), model.control()
    ctrl.reset(s)
    kp, kd = np.full(9, 1e3), np.full(9, 1e2)
    clamped_then_freed = 0
    saturated = free = 0
    for trial in range(6):
        lim = rng.choice([5.0, 30.0, 200.0, 1e4], (E, 9)).astype(np.float32)
        ctrl.set_drive_properties(force_limit=lim)
        q, qd = _random_states(model, rng)
        s.joint_q.assign(q)
        s.joint_qd.assign(qd)
        target = (q[b_.coord_index] + rng.normal(0.0, 0.5, b_.coord_index.shape)).astype(np.float32)
        ctrl.set_action(target, s)
        prev = None
        for sub in range(2):
            if sub == 1:  # nearly at the target: the law asks for less, rows clamped before must be released
                q2 = q.copy()
                q2[b_.coord_index] = target + rng.normal(0.0, 1e-3, target.shape).astype(np.float32)
                s.joint_q.assign(q2)
                s.joint_qd.assign(np.zeros_like(qd))
            ctrl.before_simulation_step(s, c)
            jsr.refresh(s)
            inv = jsr.inverse_blocks.numpy().astype(np.float64)
            qn = s.joint_q.numpy()[b_.coord_index].astype(np.float64)
            qdn = s.joint_qd.numpy()[b_.dof_index].astype(np.float64)
            tau = c.joint_f.numpy()[b_.dof_index].astype(np.float64)
            for e in range(E):
                A = inv[e][:9, :9]
                b, d = _system(A, kp, kd, qn[e], qdn[e], target[e], accel=drive_mode == "acceleration")
                want = coupled_torques(A, b, d, lim[e])
                scale = max(np.abs(want).max(), 1.0)
                np.testing.assert_allclose(tau[e], want, rtol=0, atol=2e-5 * scale, err_msg=f"trial {trial}.{sub}")
                at_limit = np.abs(want) >= lim[e] * (1 - 1e-6)
                saturated += int(at_limit.sum())
                free += int((~at_limit).sum())
                if prev is not None:
                    clamped_then_freed += int((prev[e] & ~at_limit).sum())
            prev = np.abs(tau) >= lim * (1 - 1e-6)
    assert saturated > 20 and free > 20 and clamped_then_freed > 5, (saturated, free, clamped_then_freed)


def _pgs(A, b, d, lim, tau, sweeps):
    """numpy's projected Gauss-Seidel on ``tau = clamp(b - D A tau)`` from ``tau`` clamped (rows with d = 0 at 0)."""
    act = d > 0
    tau = np.where(act, np.clip(tau, -lim, lim), 0.0)
    for _ in range(sweeps):
        for r in np.nonzero(act)[0]:
            res = tau[r] - b[r] + d[r] * (A[r] @ tau)
            tau[r] = np.clip(tau[r] - res / (1.0 + d[r] * A[r, r]), -lim[r], lim[r])
    return tau


def test_coupled_fallback_sweeps_match_numpy_when_the_active_set_does_not_settle():
    """The rare path: with the active-set iterations capped at 1 (rows + 2 by default), every env whose first solve
    leaves a row past its limit falls back to projected Gauss-Seidel on A (rebuilt from H in the kernel). The result
    equals the same sweeps in numpy from the same start, with A from Newton's JointSpaceResponse, and the iteration
    count says so (1 + sweeps + 1)."""
    from newton.actuators import JointSpaceResponse

    from wpctrl.kernels.coupled_drive import PGS_SWEEPS

    model = build_panda(E)
    lim = 30.0
    ctrl = _coupled_ctrl(model, lim)
    ctrl._engine.part("coupled_drive").max_iterations = 1  # private: the active-set cap, lowered to force the sweeps
    s, c, q, qd, target = _setup(ctrl, model, np.random.default_rng(2), spread=0.5)
    ctrl.set_action(target, s)
    ctrl.before_simulation_step(s, c)
    tau = c.joint_f.numpy()[ctrl.dof_index].astype(np.float64)
    its = ctrl.coupled_iterations.numpy()
    jsr = JointSpaceResponse(model)
    jsr.refresh(s)
    inv = jsr.inverse_blocks.numpy().astype(np.float64)
    fell_back = 0
    for e in range(E):
        A = inv[e][:9, :9]
        b, d = _system(A, 1e3, 1e2, q[e], qd[e], target[e])
        first = np.linalg.solve(np.eye(9) + np.diag(d) @ A, b)  # the first (unconstrained) active-set solve
        if (np.abs(first) > lim).any():
            fell_back += 1
            assert its[e] == 1 + PGS_SWEEPS + 1
            want = _pgs(A, b, d, np.full(9, lim), first, PGS_SWEEPS)
        else:
            assert its[e] == 1
            want = first
        np.testing.assert_allclose(tau[e], want, rtol=0, atol=1e-4 * max(np.abs(want).max(), 1.0))
    assert fell_back >= 2  # the case exercises the fallback


def test_coupled_effort_readout_is_zeroed_by_reset():
    """The coupled drive writes the effort readout itself; a reset still zeroes the reset envs' rows of it (computed,
    applied, saturation count) and leaves the others."""
    model = build_panda(E)
    ctrl = _coupled_ctrl(model, 5.0, track_effort=True)
    s, c, _, _, target = _setup(ctrl, model, np.random.default_rng(6), spread=0.5)
    ctrl.set_action(target, s)
    for _ in range(2):
        ctrl.before_simulation_step(s, c)
    before = [a.numpy().copy() for a in (ctrl.computed_effort, ctrl.applied_effort, ctrl.saturation_count)]
    assert all(np.abs(b).min(axis=1).max() > 0 for b in before[:2]) and before[2].sum() > 0
    ctrl.reset(s, env_ids=[1])
    for name, b in zip(("computed", "applied", "saturation"), before):
        got = getattr(ctrl, {"computed": "computed_effort", "applied": "applied_effort"}.get(name, "saturation_count"))
        got = got.numpy()
        np.testing.assert_array_equal(got[1], 0, err_msg=name)
        np.testing.assert_array_equal(got[[0, 2]], b[[0, 2]], err_msg=name)


def _one_dof_model():
    b = newton.ModelBuilder()
    link = b.add_link(mass=2.0, com=wp.vec3(0.0, 0.1, 0.0), inertia=wp.mat33(0.02, 0, 0, 0, 0.03, 0, 0, 0, 0.04))
    j = b.add_joint_revolute(-1, link, axis=(0.0, 0.0, 1.0), armature=0.01, label="hinge")
    b.add_articulation([j])
    return b.finalize(device="cpu")


@pytest.mark.parametrize("limit", [1e6, 20.0])
def test_coupled_reduces_to_stable_on_one_dof(limit):
    model = _one_dof_model()
    cfg = wpctrl.PDJointPosControllerConfig(["hinge"], None, None, 1e3, 1e2, limit, normalize_action=False)
    out = {}
    for pd in ("stable", "coupled"):
        ctrl = wpctrl.build_controller(
            cfg, model, 100, 100, actuation="explicit", explicit_pd=pd, inertia_update="substep"
        )
        s, c = model.state(), model.control()
        ctrl.reset(s)
        s.joint_q.assign(np.array([0.3], np.float32))
        s.joint_qd.assign(np.array([-2.0], np.float32))
        ctrl.set_action(np.array([[1.0]], np.float32), s)
        ctrl.before_simulation_step(s, c)
        out[pd] = float(c.joint_f.numpy()[0])
    np.testing.assert_allclose(out["coupled"], out["stable"], rtol=1e-5)
    if limit < 1e3:
        assert out["coupled"] == pytest.approx(limit)


def test_coupled_graph_capture_replays_bitwise():
    model = build_panda(2)
    ctrl = _coupled_ctrl(model, 50.0)
    s, c, _, _, target = _setup(ctrl, model, np.random.default_rng(3))
    act = wp.array(target, dtype=wp.float32)
    q0, qd0 = wp.clone(s.joint_q), wp.clone(s.joint_qd)

    def step():
        ctrl.set_action(act, s)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s, c)  # the state stays fixed: only the controller's launches replay

    step()
    eager = c.joint_f.numpy().copy()
    assert np.abs(eager).max() > 0
    c.joint_f.zero_()
    s.joint_q.assign(q0)
    s.joint_qd.assign(qd0)
    with wp.ScopedCapture(device="cpu") as cap:
        step()
    c.joint_f.zero_()
    wp.capture_launch(cap.graph)
    np.testing.assert_array_equal(c.joint_f.numpy(), eager)


def test_coupled_rejects_a_floating_base():
    b = newton.ModelBuilder()
    body = b.add_link(mass=1.0, inertia=wp.mat33(np.eye(3, dtype=np.float32) * 0.1))
    j0 = b.add_joint_free(body)
    link = b.add_link(mass=1.0, inertia=wp.mat33(np.eye(3, dtype=np.float32) * 0.1))
    j1 = b.add_joint_revolute(body, link, axis=(0.0, 0.0, 1.0), label="hinge")
    b.add_articulation([j0, j1])
    model = b.finalize(device="cpu")
    cfg = wpctrl.PDJointPosControllerConfig(["hinge"], None, None, 1e3, 1e2, 100.0, normalize_action=False)
    with pytest.raises(wpctrl.ConfigError, match="coupled"):
        wpctrl.build_controller(cfg, model, actuation="explicit", explicit_pd="coupled")
    # stable PD falls back to Newton's JointSpaceResponse there
    ctrl = wpctrl.build_controller(cfg, model, actuation="explicit", explicit_pd="stable")
    part = ctrl._engine.response_part  # private: which path computes r
    assert part._fused is None and part._jsr is not None


@pytest.mark.parametrize("inertia_update", [None, "substep", "control"])
def test_coupled_inertia_update_control_reuses_the_first_substeps_block(inertia_update):
    """inertia_update="control": A is computed at a control step's first substep and reused for the other K - 1 (the
    PD law still reads each substep's q, qd); the coupled drive's default recomputes it every substep."""
    model = build_panda(E)
    arm = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 1e3, 1e2, 1e9, normalize_action=False)
    grip = wpctrl.PDJointPosControllerConfig(PANDA_GRIPPER_JOINTS, None, None, 1e3, 1e2, 1e9, normalize_action=False)
    ctrl = wpctrl.build_controller(
        {"arm": arm, "gripper": grip}, model, 20, 100, actuation="explicit", explicit_pd="coupled",
        inertia_update=inertia_update, balance_passive_force=False,
    )  # fmt: skip
    assert ctrl.num_substeps == 5
    rng = np.random.default_rng(7)
    s, c, q, qd, target = _setup(ctrl, model, rng)
    b = ctrl  # the controlled joints' coord_index / dof_index
    cached = inertia_update == "control"

    def torques_match(A):
        tau = c.joint_f.numpy()[b.dof_index].astype(np.float64)
        qq = s.joint_q.numpy()[b.coord_index].astype(np.float64)
        qqd = s.joint_qd.numpy()[b.dof_index].astype(np.float64)
        for e in range(E):
            bb, d = _system(A[e], 1e3, 1e2, qq[e], qqd[e], target[e])
            want = np.linalg.solve(np.eye(9) + np.diag(d) @ A[e], bb)
            np.testing.assert_allclose(tau[e], want, rtol=1e-5, atol=1e-5 * np.abs(want).max())

    for _control_step in range(2):
        ctrl.set_action(target, s)
        ctrl.before_simulation_step(s, c)  # the first substep: A of this configuration in every mode
        A_first = _block(ctrl, s)
        torques_match(A_first)
        for _substep in range(ctrl.num_substeps - 1):
            q2, qd2 = _random_states(model, rng)  # the solver moved the arm far (a configuration A depends on)
            s.joint_q.assign(q2)
            s.joint_qd.assign(qd2)
            A_now = _block(ctrl, s)
            assert np.abs(A_now - A_first).max() > 1e-2 * np.abs(A_first).max()  # A really changed
            ctrl.before_simulation_step(s, c)
            torques_match(A_first if cached else A_now)
        q3, qd3 = _random_states(model, rng)  # the next control step starts elsewhere: A is fresh again
        s.joint_q.assign(q3)
        s.joint_qd.assign(qd3)
