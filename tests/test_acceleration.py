"""PhysX's acceleration drive and stable explicit PD, both built on each joint's response r = (H^-1)_ii.

- r from wpctrl matches the inverse of the mass matrix that Newton's Featherstone solver assembles itself, and Newton's
  JointSpaceResponse at the state of the call that refreshes it (set_action, or each substep with
  ``inertia_update="substep"``); the implicit drive's per-env gains Kp/r, Kd/r reach MuJoCo-Warp's actuators after
  every refresh.
- Acceleration drives make two Pandas whose link masses differ 3x follow the same trajectory (implicit in MuJoCo-Warp
  and explicit) to 5e-5 rad, while force drives visibly differ.
- Stable explicit PD holds ManiSkill's Panda gains (1000/100) at 100 Hz where the naive explicit law diverges, with
  a tracking error within 1.5x of MuJoCo's implicit drive; its torques with r per substep follow the closed form and
  replay bitwise from a captured graph.
"""

from __future__ import annotations

import newton
import numpy as np
import pytest
import warp as wp
from conftest import build_panda

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, PANDA_INITIAL_Q, panda


def _arm_config(kp=1e3, kd=1e2, drive_mode="force"):
    return wpctrl.PDJointPosControllerConfig(
        PANDA_ARM_JOINTS + PANDA_GRIPPER_JOINTS, None, None, kp, kd, 1e4, normalize_action=False, drive_mode=drive_mode
    )


def test_response_matches_featherstone_mass_matrix():
    model = build_panda(1)
    ctrl = wpctrl.build_controller(_arm_config(drive_mode="acceleration"), model, actuation="explicit")
    solver = newton.solvers.SolverFeatherstone(model)
    s0, s1, control = model.state(), model.state(), model.control()
    rng = np.random.default_rng(0)
    lo, hi = model.joint_limit_lower.numpy(), model.joint_limit_upper.numpy()
    for _ in range(4):
        q = rng.uniform(lo, hi).astype(np.float32)
        s0.joint_q.assign(q)
        newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
        ctrl.set_action(q[None, :], s0)  # refreshes r for this configuration
        solver.step(s0, s1, control, None, 1e-4)  # Featherstone assembles H for s0
        H = solver.H.numpy()[:81].reshape(9, 9).astype(np.float64)
        np.testing.assert_allclose(H, H.T, rtol=1e-4, atol=1e-6)  # it is the full symmetric block
        want = np.diag(np.linalg.inv(H))
        np.testing.assert_allclose(ctrl.response.numpy()[0], want, rtol=1e-4)


def _two_pandas(mass_scale: float) -> newton.Model:
    """Two Pandas in two worlds; world 1's links are ``mass_scale`` times heavier (mass and inertia). Gravity off."""
    builder = newton.ModelBuilder()
    builder.replicate(panda(), 2)
    for b in range(builder.body_count):
        if builder.body_world[b] == 1:
            builder.body_mass[b] *= mass_scale
            builder.body_inertia[b] = builder.body_inertia[b] * mass_scale
    model = builder.finalize(device="cpu")
    model.set_gravity((0.0, 0.0, 0.0))
    return model


def _step_response(drive_mode, actuation, explicit_pd=None, seconds=0.5):
    """Both envs get the same 0.2 rad target step on every arm joint; returns q(t) of shape (steps, 2, 9)."""
    model = _two_pandas(3.0)
    kp, kd = (400.0, 40.0) if drive_mode == "acceleration" else (400.0, 40.0)
    ctrl = wpctrl.build_controller(
        _arm_config(kp, kd, drive_mode), model, 100, 100, actuation=actuation, explicit_pd=explicit_pd
    )
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    ctrl.attach_solver(solver)
    s0, s1, control = model.state(), model.state(), model.control()
    ctrl.reset(s0)
    target = np.tile(np.asarray(PANDA_INITIAL_Q, np.float32), (2, 1))
    target[:, :7] += 0.2
    qs = []
    for _ in range(int(seconds * 100)):
        ctrl.set_action(target, s0)
        ctrl.before_simulation_step(s0, control)
        solver.step(s0, s1, control, None, 0.01)
        s0, s1 = s1, s0
        qs.append(s0.joint_q.numpy()[ctrl._engine.binding.coord_index])
    return np.array(qs)


@pytest.mark.parametrize("actuation, explicit_pd", [("implicit", None), ("explicit", "naive"), ("explicit", "stable")])
def test_acceleration_drive_is_mass_independent(actuation, explicit_pd):
    q = _step_response("acceleration", actuation, explicit_pd)
    assert np.isfinite(q).all()
    q0 = np.asarray(PANDA_INITIAL_Q, np.float32)[:7]
    motion = q[:, :, :7] - q0  # (steps, env, joint)
    assert np.abs(motion[-1]).min() > 0.15  # both arms moved toward the 0.2 rad step
    # the same trajectory: measured 1.1e-5 (implicit), 1.4e-5 (naive), 2.1e-5 rad (stable) over the 0.5 s; a force
    # drive differs by 0.07 rad (test_force_drive_depends_on_mass)
    assert np.abs(motion[:, 0] - motion[:, 1]).max() < 5e-5


def test_force_drive_depends_on_mass():
    q = _step_response("force", "implicit")
    q0 = np.asarray(PANDA_INITIAL_Q, np.float32)[:7]
    motion = q[:, :, :7] - q0
    assert np.abs(motion[:, 0] - motion[:, 1]).max() > 0.1 * 0.2  # the heavy arm visibly lags


def _stability_run(actuation, explicit_pd=None, seconds=10.0):
    """Panda, gains 1000/100 on every joint, 100 Hz, target steps of +-0.1 rad every 50 ms. Returns (finite, rms)."""
    model = build_panda(1)
    model.set_gravity((0.0, 0.0, 0.0))
    cfg = wpctrl.PDJointPosControllerConfig(
        PANDA_ARM_JOINTS + PANDA_GRIPPER_JOINTS, None, None, 1e3, 1e2, 1e3, normalize_action=False
    )
    ctrl = wpctrl.build_controller(cfg, model, 20, 100, actuation=actuation, explicit_pd=explicit_pd)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    ctrl.attach_solver(solver)
    s0, s1, control = model.state(), model.state(), model.control()
    ctrl.reset(s0)
    q0 = np.asarray(PANDA_INITIAL_Q, np.float32)
    sign = np.array([1, -1, 1, -1, 1, -1, 1, 0, 0], np.float32)
    err = []
    for i in range(int(seconds * 20)):
        target = (q0 + 0.1 * sign * (1 if i % 2 else -1)).astype(np.float32)
        ctrl.set_action(target[None, :], s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, control)
            solver.step(s0, s1, control, None, 0.01)
            s0, s1 = s1, s0
            q = s0.joint_q.numpy()[:9]
            if not np.isfinite(q).all() or np.abs(q).max() > 1e3:
                return False, np.inf
            err.append(q[:7] - target[:7])
    return True, float(np.sqrt(np.mean(np.square(err))))


def test_stable_explicit_pd_holds_maniskill_gains():
    naive_ok, _ = _stability_run("explicit", "naive")
    stable_ok, stable_rms = _stability_run("explicit", "stable")
    implicit_ok, implicit_rms = _stability_run("implicit")
    assert not naive_ok, "the naive explicit law was expected to diverge at 1000/100 and 100 Hz"
    assert stable_ok and implicit_ok
    assert stable_rms <= 1.5 * implicit_rms, (stable_rms, implicit_rms)


def _newton_response(model, joint_q: np.ndarray) -> np.ndarray:
    """(worlds, 9) diag of H^-1 of each Panda at ``joint_q`` (a full joint_q array), from Newton's own
    JointSpaceResponse (FK, mass matrix and block inverse of its own)."""
    from newton.actuators import JointSpaceResponse

    state = model.state()
    state.joint_q.assign(joint_q.astype(np.float32))
    jsr = JointSpaceResponse(model)
    jsr.refresh(state)
    inv = jsr.inverse_blocks.numpy().astype(np.float64)
    return np.diagonal(inv, axis1=1, axis2=2)[:, :9]


def _random_q(model, rng) -> np.ndarray:
    lo, hi = model.joint_limit_lower.numpy(), model.joint_limit_upper.numpy()
    return rng.uniform(lo, hi).astype(np.float32)


@pytest.mark.parametrize("inertia_update", ["control", "substep"])
def test_response_is_refreshed_where_inertia_update_says(inertia_update):
    """ "control": r (and the implicit acceleration gains Kp/r, Kd/r in the model) are those of the state given to
    set_action for the whole control step; "substep": those of the state given to each before_simulation_step.
    Reference: Newton's JointSpaceResponse on the same joint positions."""
    model = build_panda(2)
    kp, kd = 400.0, 40.0
    ctrl = wpctrl.build_controller(_arm_config(kp, kd, "acceleration"), model, 20, 100, inertia_update=inertia_update)
    s, control = model.state(), model.control()
    ctrl.reset(s)
    dof = ctrl._engine.binding.dof_index
    rng = np.random.default_rng(0)
    target = np.tile(np.asarray(PANDA_INITIAL_Q, np.float32), (2, 1))

    def check(want, where):
        np.testing.assert_allclose(ctrl.response.numpy(), want, rtol=1e-4, err_msg=where)
        np.testing.assert_allclose(model.joint_target_ke.numpy()[dof], kp / want, rtol=1e-4, err_msg=where)
        np.testing.assert_allclose(model.joint_target_kd.numpy()[dof], kd / want, rtol=1e-4, err_msg=where)

    for step in range(2):
        q_set = _random_q(model, rng)
        s.joint_q.assign(q_set)
        ctrl.set_action(target, s)
        r_set = _newton_response(model, q_set)
        if inertia_update == "control":  # "substep" leaves set_action alone: r is refreshed before each substep
            check(r_set, f"step {step}: set_action")
        for k in range(ctrl.num_substeps):
            q_k = _random_q(model, rng)
            s.joint_q.assign(q_k)
            ctrl.before_simulation_step(s, control)
            r_k = _newton_response(model, q_k)
            assert np.abs(r_k / r_set - 1).max() > 0.05  # the states differ enough to tell the two apart
            check(r_k if inertia_update == "substep" else r_set, f"step {step}: substep {k}")


@pytest.mark.parametrize("inertia_update", ["control", "substep"])
def test_implicit_acceleration_gains_reach_mujoco_after_every_update(inertia_update):
    """Each refresh of r writes Kp/r, Kd/r into the model and notifies the solver: MuJoCo-Warp's per-world actuator
    gains (position actuator: gainprm[0] = Kp', biasprm[1:3] = (-Kp', -Kd')) follow at once. Two Pandas whose masses
    differ 3x, so that the per-world gains differ."""
    model = _two_pandas(3.0)
    kp, kd = 400.0, 40.0
    ctrl = wpctrl.build_controller(_arm_config(kp, kd, "acceleration"), model, 20, 100, inertia_update=inertia_update)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    ctrl.attach_solver(solver)
    s, control = model.state(), model.control()
    ctrl.reset(s)
    rng = np.random.default_rng(1)
    target = np.tile(np.asarray(PANDA_INITIAL_Q, np.float32), (2, 1))

    def check(where):
        r = ctrl.response.numpy().astype(np.float64)
        gain = solver.mjw_model.actuator_gainprm.numpy()[:, :9, 0]
        bias = solver.mjw_model.actuator_biasprm.numpy()[:, :9, :3]
        np.testing.assert_allclose(gain, kp / r, rtol=1e-5, err_msg=where)
        np.testing.assert_allclose(bias[:, :, 1], -kp / r, rtol=1e-5, err_msg=where)
        np.testing.assert_allclose(bias[:, :, 2], -kd / r, rtol=1e-5, err_msg=where)
        assert np.abs(gain[1] / gain[0] - 3.0).max() < 0.05  # 3x the mass, 3x the gains

    def pose():  # the same random pose in both worlds: world 1's gains are then exactly 3x world 0's
        q = _random_q(model, rng)
        return np.tile(q[:9], 2)

    before = solver.mjw_model.actuator_gainprm.numpy()[:, :9, 0].copy()
    for step in range(2):
        s.joint_q.assign(pose())
        ctrl.set_action(target, s)
        if inertia_update == "control":
            check(f"step {step}: set_action")
        for k in range(2):
            s.joint_q.assign(pose())
            ctrl.before_simulation_step(s, control)
            check(f"step {step}: substep {k}")
    assert np.abs(solver.mjw_model.actuator_gainprm.numpy()[:, :9, 0] / before - 1).max() > 0.05  # they moved


def test_substep_inertia_update_and_graph_capture():
    """Stable explicit PD with acceleration drives and r refreshed before every substep: each substep's torque
    against the closed form on Newton's JointSpaceResponse at that substep's state, then a captured control step
    (whose graph copies the substep states in itself) replays the same torques bitwise."""
    E = 2
    model = build_panda(E)
    kp, kd, dt = 400.0, 40.0, 0.01
    ctrl = wpctrl.build_controller(
        _arm_config(kp, kd, "acceleration"), model, 20, 100, actuation="explicit", explicit_pd="stable",
        inertia_update="substep",
    )  # fmt: skip
    K = ctrl.num_substeps
    s0, control = model.state(), model.control()
    ctrl.reset(s0)
    b = ctrl._engine.binding
    rng = np.random.default_rng(3)
    qs = [_random_q(model, rng) for _ in range(K)]
    qds = [rng.normal(0.0, 0.5, model.joint_dof_count).astype(np.float32) for _ in range(K)]
    q_src = [wp.array(q, dtype=wp.float32) for q in qs]
    qd_src = [wp.array(qd, dtype=wp.float32) for qd in qds]
    forces = [wp.zeros_like(control.joint_f) for _ in range(K)]
    target = (qs[0][b.coord_index] + rng.normal(0.0, 0.3, b.coord_index.shape)).astype(np.float32)
    act = wp.array(target, dtype=wp.float32)

    def step():
        ctrl.set_action(act, s0)
        for k in range(K):
            wp.copy(s0.joint_q, q_src[k])
            wp.copy(s0.joint_qd, qd_src[k])
            ctrl.before_simulation_step(s0, control)
            wp.copy(forces[k], control.joint_f)

    step()
    eager = [f.numpy().copy() for f in forces]
    for k in range(K):
        r = _newton_response(model, qs[k])
        q = qs[k][b.coord_index].astype(np.float64)
        qd = qds[k][b.dof_index].astype(np.float64)
        kpr, kdr = kp / r, kd / r
        u = (kpr * (target - q - dt * qd) + kdr * (0.0 - qd)) / (1.0 + r * dt * (kdr + dt * kpr))
        want = np.clip(u, -1e4, 1e4)
        np.testing.assert_allclose(eager[k][b.dof_index], want, rtol=1e-4, atol=1e-4, err_msg=f"substep {k}")
    assert min(np.abs(f[b.dof_index]).max() for f in eager) > 1.0  # the drive pushes in every substep
    for f in forces:
        f.zero_()
    control.joint_f.zero_()
    with wp.ScopedCapture(device="cpu") as cap:
        step()
    for f in forces:
        f.zero_()
    control.joint_f.zero_()
    wp.capture_launch(cap.graph)
    for k in range(K):
        np.testing.assert_array_equal(forces[k].numpy(), eager[k], err_msg=f"substep {k}")
