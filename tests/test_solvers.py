"""Real Newton solver steps: a small 2-link arm with a mimic gripper tracks its targets.

MuJoCo-Warp (reduced coordinates, integrates joint_q) and XPBD (maximal coordinates: joint_q is recovered with
``newton.eval_ik`` after each step), each with wpctrl's implicit actuation (the solver's built-in drive) and explicit
actuation (wpctrl's clamped PD torques in ``Control.joint_f``), gravity on. Gains are chosen stable for the explicit
law at 100 Hz, the arm's force limit low enough to be reached. At every substep the solver is given the targets and
(explicit) the clamped PD law on that substep's measured state; the tracking error must shrink 10x within one second
of simulated time.
"""

from __future__ import annotations

import newton
import numpy as np
import pytest
import warp as wp

import wpctrl

ARM = ["shoulder", "elbow"]
FINGERS = ["finger_left", "finger_right"]


def small_arm(num_envs: int) -> newton.Model:
    robot = newton.ModelBuilder()
    cfg = newton.ModelBuilder.ShapeConfig(has_shape_collision=False, has_particle_collision=False, density=0.0)

    def link(mass, inertia, label):
        b = robot.add_link(mass=mass, inertia=wp.mat33(np.eye(3) * inertia), label=label)
        robot.add_shape_sphere(b, radius=0.02, cfg=cfg)
        return b

    l1 = link(1.0, 0.02, "arm/upper")
    l2 = link(0.5, 0.01, "arm/lower")
    f1 = link(0.1, 1e-3, "arm/left")
    f2 = link(0.1, 1e-3, "arm/right")
    up = wp.transform((0.0, 0.0, 0.3), wp.quat_identity())
    left = wp.transform((0.0, 0.05, 0.3), wp.quat_identity())
    right = wp.transform((0.0, -0.05, 0.3), wp.quat_identity())
    js = [
        robot.add_joint_revolute(-1, l1, axis=(0, 0, 1), limit_lower=-2.0, limit_upper=2.0, label="arm/shoulder"),
        robot.add_joint_revolute(
            l1, l2, parent_xform=up, axis=(0, 1, 0), limit_lower=-2.0, limit_upper=2.0, label="arm/elbow"
        ),
        robot.add_joint_prismatic(
            l2, f1, parent_xform=left, axis=(0, 1, 0), limit_lower=0.0, limit_upper=0.04, label="arm/finger_left"
        ),
        robot.add_joint_prismatic(
            l2, f2, parent_xform=right, axis=(0, -1, 0), limit_lower=0.0, limit_upper=0.04, label="arm/finger_right"
        ),
    ]
    robot.add_articulation(js, label="arm")
    builder = newton.ModelBuilder()  # gravity on: the steady-state sag stays well inside the bound
    builder.replicate(robot, num_envs)
    return builder.finalize(device="cpu")


def mode():
    return {
        "arm": wpctrl.PDJointPosControllerConfig(ARM, None, None, 20.0, 2.0, 10.0, normalize_action=False),
        "gripper": wpctrl.PDJointPosMimicControllerConfig(
            FINGERS, 0.0, 0.04, 20.0, 2.0, 50.0, mimic={"finger_right": {"joint": "finger_left"}}
        ),
    }


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
@pytest.mark.parametrize("solver_name", ["mujoco", "xpbd"])
def test_tracking_with_a_real_solver(solver_name, actuation):
    n = 2
    model = small_arm(n)
    ctrl = wpctrl.build_controller(mode(), model, control_freq=20, sim_freq=100, actuation=actuation)
    if solver_name == "mujoco":
        solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    else:
        solver = newton.solvers.SolverXPBD(model, iterations=4)
    s0, s1 = model.state(), model.state()
    control = model.control()
    newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    ctrl.reset(s0)
    # per-env targets: arm angles and gripper opening (normalised action, [-1, 1] -> [0, 0.04] m)
    action = np.array([[0.6, -0.5, 0.5], [-0.4, 0.7, -0.2]], np.float32)
    want = np.column_stack([action[:, :2], np.repeat(0.02 + 0.02 * action[:, 2:], 2, axis=1)])
    coord = ctrl.coord_index

    def error():
        return np.abs(s0.joint_q.numpy()[coord] - want).max(axis=1)

    e0 = error()
    dt = 1.0 / 100
    dof = ctrl.dof_index
    limit = np.array([10.0, 10.0, 50.0, 50.0], np.float32)
    saturated = 0
    for _ in range(20):  # one second
        ctrl.set_action(action, s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, control)
            # What the solver is given at every substep: the targets, and (explicit) the clamped PD law on this
            # substep's measured state, |f| <= the force limit (10 N·m on the arm, 50 N on the fingers).
            np.testing.assert_allclose(control.joint_target_q.numpy()[coord], want, atol=1e-7)
            if actuation == "explicit":
                q, qd = s0.joint_q.numpy()[coord], s0.joint_qd.numpy()[dof]
                law = np.float32(20.0) * (want - q) + np.float32(2.0) * (np.float32(0.0) - qd)
                f = control.joint_f.numpy()[dof]
                np.testing.assert_allclose(f, np.clip(law, -limit, limit), rtol=1e-5, atol=1e-5)
                assert (np.abs(f) <= limit).all()
                saturated += int((np.abs(law) > limit).sum())
            solver.step(s0, s1, control, None, dt)
            s0, s1 = s1, s0
            if solver_name == "xpbd":
                newton.eval_ik(model, s0, s0.joint_q, s0.joint_qd)
    e1 = error()
    assert np.isfinite(s0.joint_q.numpy()).all()
    assert (e1 < e0 / 10).all(), f"tracking error {e0} -> {e1}"
    if actuation == "explicit":
        assert saturated > 0  # the bound was reached on the way (a check of the clamp, not of a quiet state)
