"""PhysX's acceleration drive and stable explicit PD, both built on each joint's response r = (H^-1)_ii.

- r from wpctrl matches the inverse of the mass matrix that Newton's Featherstone solver assembles itself.
- Acceleration drives make two Pandas whose link masses differ 3x follow the same trajectory (implicit in MuJoCo-Warp
  and explicit), while force drives visibly differ.
- Stable explicit PD holds ManiSkill's Panda gains (1000/100) at 100 Hz where the naive explicit law diverges, with
  a tracking error within 1.5x of MuJoCo's implicit drive.
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


def _step_response(drive_mode, actuation, explicit_pd="naive", seconds=0.5):
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


@pytest.mark.parametrize(
    "actuation, explicit_pd", [("implicit", "naive"), ("explicit", "naive"), ("explicit", "stable")]
)
def test_acceleration_drive_is_mass_independent(actuation, explicit_pd):
    q = _step_response("acceleration", actuation, explicit_pd)
    assert np.isfinite(q).all()
    q0 = np.asarray(PANDA_INITIAL_Q, np.float32)[:7]
    motion = q[:, :, :7] - q0  # (steps, env, joint)
    assert np.abs(motion[-1]).min() > 0.15  # both arms moved toward the 0.2 rad step
    # same trajectory within 2% of the step
    assert np.abs(motion[:, 0] - motion[:, 1]).max() < 0.02 * 0.2


def test_force_drive_depends_on_mass():
    q = _step_response("force", "implicit")
    q0 = np.asarray(PANDA_INITIAL_Q, np.float32)[:7]
    motion = q[:, :, :7] - q0
    assert np.abs(motion[:, 0] - motion[:, 1]).max() > 0.1 * 0.2  # the heavy arm visibly lags


def _stability_run(actuation, explicit_pd="naive", seconds=10.0):
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


def test_substep_inertia_update_and_graph_capture():
    model = build_panda(2)
    ctrl = wpctrl.build_controller(
        _arm_config(drive_mode="acceleration"), model, actuation="explicit", explicit_pd="stable",
        inertia_update="substep",
    )  # fmt: skip
    s0, control = model.state(), model.control()
    ctrl.reset(s0)
    act = wp.array(np.tile(np.asarray(PANDA_INITIAL_Q, np.float32), (2, 1)), dtype=wp.float32)

    def step():
        ctrl.set_action(act, s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, control)

    step()
    eager = control.joint_f.numpy().copy()
    control.joint_f.zero_()
    with wp.ScopedCapture(device="cpu") as cap:
        step()
    control.joint_f.zero_()
    wp.capture_launch(cap.graph)
    np.testing.assert_array_equal(control.joint_f.numpy(), eager)
    assert (ctrl.response.numpy() > 0).all()
