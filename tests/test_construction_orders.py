"""Setups that differ from the README's: the solver built before the controller (``solver=``) or attached later, envs
placed apart (and turned) under end-effector control, robots on a floating base under velocity controllers, a mobile
base that is not the first controller of its mode. Each against an independent reference: the same setup in its
plain form, Newton's forward kinematics, MuJoCo-Warp's own per-world arrays and rollouts, numpy; every joint index is
read from the model's own tables (``user_models.indices``), not from wpctrl's binding."""

from __future__ import annotations

import copy
import math
import warnings

import newton
import numpy as np
import pytest
import warp as wp
from user_models import BASE_JOINTS, MOBILE_ARM, indices, mobile_envs, panda_envs, put

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, PANDA_INITIAL_Q, panda, panda_control_modes

f32 = np.float32
MODES = panda_control_modes()


# -- the solver's construction order --------------------------------------------------------------------------------


def _rollout(ctrl, solver, model, steps=20):
    """Zero actions for ``steps`` control steps; the largest joint motion per joint [rad, m]."""
    s0, s1, c = model.state(), model.state(), model.control()
    ctrl.reset(s0, control=c)
    q0 = s0.joint_q.numpy().copy()
    zero = np.zeros((ctrl.num_envs, ctrl.action_dim), f32)
    for _ in range(steps):
        ctrl.set_action(zero, s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, c)
            solver.step(s0, s1, c, None, 1.0 / ctrl.sim_freq)
            s0, s1 = s1, s0
    return np.abs(s0.joint_q.numpy() - q0).reshape(ctrl.num_envs, -1).max(axis=0)


@pytest.mark.parametrize("order", ["solver=", "attach_solver", "solver after"])
def test_mujoco_learns_gravity_compensation_and_gains_in_every_construction_order(order):
    """ManiSkill's pd_joint_delta_pos (gravity off the robot) with non-default per-joint gains, per-env gains set
    later: with the solver built before the controller (given as ``solver=`` or to ``attach_solver``) as with the
    solver built after it, MuJoCo-Warp holds the arm still under gravity and its per-world actuators carry each env's
    gains. Gravity acts on the model (|g| = 9.81)."""
    E = 2
    builder = newton.ModelBuilder()
    builder.replicate(panda(actuator_mode=newton.JointTargetMode.POSITION), E)  # wpctrl's modes: no warning
    model = builder.finalize(device="cpu")
    assert np.linalg.norm(model.gravity.numpy()) > 9.0
    mode = copy.deepcopy(MODES["pd_joint_delta_pos"])
    kp = [900.0, 1100.0, 1000.0, 950.0, 1200.0, 1050.0, 1300.0]
    mode["arm"].stiffness = kp
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing to warn about: the target modes already match
        if order == "solver after":  # the README's order; later gain edits need the solver attached
            ctrl = wpctrl.build_controller(mode, model)
            solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
            ctrl.attach_solver(solver)
        else:
            solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
            if order == "solver=":
                ctrl = wpctrl.build_controller(mode, model, solver=solver)
            else:
                ctrl = wpctrl.build_controller(mode, model)
                ctrl.attach_solver(solver)
    gain = solver.mjw_model.actuator_gainprm.numpy()[:, :7, 0]  # (worlds, actuators): position actuators first
    np.testing.assert_array_equal(gain, np.tile(np.asarray(kp, f32), (E, 1)))
    drift = _rollout(ctrl, solver, model)
    assert drift[:7].max() < 1e-3, drift  # gravity is off the robot (measured with it on: 0.3 rad on joint 2)
    per_env = np.array([kp, [2.0 * k for k in kp]], f32)
    ctrl["arm"].set_drive_properties(stiffness=per_env)
    gain = solver.mjw_model.actuator_gainprm.numpy()[:, :7, 0]
    np.testing.assert_array_equal(gain, per_env)


def test_solver_given_before_sees_an_implicit_acceleration_drive_per_env():
    """An implicit acceleration drive writes Kp / r and Kd / r per env (r = (H^-1)_ii of each env's configuration);
    a solver given as ``solver=`` receives them: MuJoCo-Warp's per-world gains equal Newton's model arrays."""
    E = 2
    builder = newton.ModelBuilder()
    builder.replicate(panda(actuator_mode=newton.JointTargetMode.POSITION), E)
    model = builder.finalize(device="cpu")
    q = model.joint_q.numpy().reshape(E, -1)
    q[1, :7] += np.array([0.4, -0.3, 0.2, 0.3, -0.2, 0.5, 0.1])  # env 1 elsewhere: other inertias
    model.joint_q.assign(q.reshape(-1))
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    cfg = wpctrl.PDJointPosControllerConfig(list(PANDA_ARM_JOINTS), None, None, 100.0, 20.0, drive_mode="acceleration")
    ctrl = wpctrl.build_controller(cfg, model, solver=solver, balance_passive_force=False)
    _, dof = indices(model, PANDA_ARM_JOINTS)
    ke = model.joint_target_ke.numpy()[dof]
    assert np.abs(ke[0] - ke[1]).max() > 1.0  # different per env
    np.testing.assert_allclose(solver.mjw_model.actuator_gainprm.numpy()[:, :7, 0], ke, rtol=1e-6)
    r = ctrl.response.numpy()
    np.testing.assert_allclose(ke, 100.0 / r, rtol=1e-5)


# -- end-effector control of envs placed apart ----------------------------------------------------------------------


def _turned(num_envs: int):
    """Per-env placements: translated in x, y and z, and turned about z (env 0 at the origin, unturned)."""
    out = []
    for e in range(num_envs):
        q = wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), 0.8 * e)
        out.append(wp.transform(wp.vec3(1.5 * e, -2.0 * e, 0.25 * e), q))
    return out


def _placed(num_envs: int, how: str) -> newton.Model:
    if how == "spacing":
        return panda_envs(num_envs, spacing=(2.0, -1.0, 0.5))
    builder = newton.ModelBuilder()
    builder.replicate(panda(), num_envs, xforms=_turned(num_envs))
    return builder.finalize(device="cpu")


def _top_frames(model) -> np.ndarray:
    """(num_envs, 7) parent frame of each env's ``panda_joint1`` in the world (``joint_X_p``), world by world."""
    ids = [j for j, lb in enumerate(model.joint_label) if lb.rsplit("/", 1)[-1] == "panda_joint1"]
    world = model.joint_world.numpy()[ids]
    return model.joint_X_p.numpy()[np.asarray(ids)[np.argsort(world)]]


def _tcp_world(model, state, e):
    """The TCP site's world pose in env ``e`` from Newton's FK: (position, xyzw quaternion)."""
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    labels = list(model.shape_label)
    world = model.shape_world.numpy()
    site = next(i for i, lb in enumerate(labels) if lb.endswith("panda_hand_tcp") and world[i] == e)
    body = int(model.shape_body.numpy()[site])
    bq = state.body_q.numpy()[body]
    st = model.shape_transform.numpy()[site]
    x = wp.transform(wp.vec3(*bq[:3]), wp.quat(*bq[3:])) * wp.transform(wp.vec3(*st[:3]), wp.quat(*st[3:]))
    return np.array(x.p), np.array(x.q)


@pytest.mark.parametrize("how", ["spacing", "turned"])
@pytest.mark.parametrize("mode_name", ["pd_ee_pose", "pd_ee_delta_pose", "pd_ee_target_delta_pos"])
def test_ee_control_of_envs_placed_apart_equals_the_envs_at_the_origin(how, mode_name):
    """Envs replicated ``spacing`` apart (or placed and turned by ``xforms``) under a Panda EE mode: every env's
    measured EE pose, target pose and IK joint targets equal those of the same env at the origin (poses are in each
    robot's own base frame), and the measured pose is Newton's FK of the TCP mapped into that env's base frame."""
    E = 3
    mode = copy.deepcopy(MODES[mode_name])
    placed_model, origin_model = _placed(E, how), panda_envs(E)
    rng = np.random.default_rng(0)
    q = (np.asarray(PANDA_INITIAL_Q[:7], f32) + rng.uniform(-0.3, 0.3, (E, 7))).astype(f32)
    out = []
    for model in (placed_model, origin_model):
        ctrl = wpctrl.build_controller(mode, model)
        arm = ctrl["arm"]
        s = model.state()
        put(s, model, PANDA_ARM_JOINTS, q)
        ctrl.reset(s)
        pose0 = arm.ee_pose.numpy().copy()
        if mode_name == "pd_ee_pose":  # absolute: a target near each env's own pose (xyz + euler XYZ), per env
            a = np.zeros((E, 7), f32)
            a[:, :3] = pose0[:, :3] + np.array([[0.03, -0.02, 0.04], [-0.02, 0.05, 0.0], [0.0, 0.01, -0.03]], f32)
            a[:, 3:6] = np.array([[math.pi, 0.1, 0.0], [math.pi - 0.1, 0.0, 0.2], [3.0, -0.1, -0.1]], f32)
        else:
            a = np.tile(np.linspace(-0.8, 0.8, ctrl.action_dim, dtype=f32), (E, 1)) * [[1.0], [-0.5], [0.7]]
        for _ in range(2):
            ctrl.set_action(a.astype(f32), s)
        out.append((pose0, arm.target_pose.numpy().copy(), arm.target_qpos.numpy().copy(), s))
    (p_pose, p_target, p_q, p_state), (o_pose, o_target, o_q, _) = out
    np.testing.assert_allclose(p_pose, o_pose, atol=2e-5)
    np.testing.assert_allclose(p_target, o_target, atol=2e-5)
    np.testing.assert_allclose(p_q, o_q, atol=1e-4)
    assert np.abs(p_q - q).max() > 1e-3  # the IK moved the targets (a comparison of something)
    # Newton's FK: the pose the controller reports is the TCP in the origin model's world (its base frame), and the
    # placed model's TCP is that pose moved by env e's placement (joint 1's parent frame, placed vs at the origin)
    origin_state = origin_model.state()
    put(origin_state, origin_model, PANDA_ARM_JOINTS, q)
    x_p = [_top_frames(m) for m in (placed_model, origin_model)]
    for e in range(E):
        pos, quat = _tcp_world(origin_model, origin_state, e)
        np.testing.assert_allclose(p_pose[e, :3], pos, atol=2e-5)
        w = np.array([quat[3], quat[0], quat[1], quat[2]])  # [qw, qx, qy, qz] as the controller reports
        assert min(np.abs(p_pose[e, 3:] - w).max(), np.abs(p_pose[e, 3:] + w).max()) < 2e-5
        placed = [wp.transform(wp.vec3(*x[e, :3]), wp.quat(*x[e, 3:])) for x in x_p]
        base = placed[0] * wp.transform_inverse(placed[1])
        ppos, pquat = _tcp_world(placed_model, p_state, e)
        want = base * wp.transform(wp.vec3(*pos), wp.quat(*quat))
        np.testing.assert_allclose(ppos, np.array(want.p), atol=2e-5)
    if how == "spacing":
        assert np.abs(x_p[0][0, :3] - x_p[1][0, :3]).max() > 0.1  # replicate centres the grid: env 0 moved too


# -- floating bases under velocity controllers ----------------------------------------------------------------------


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
def test_floating_base_velocity_targets_land_on_each_envs_dofs(actuation):
    """Pandas on a free joint (16 coordinates, 15 DOFs per env: coordinate and DOF indices differ, and more so in
    every later env), spaced apart: a velocity arm and a position-velocity gripper. Env e's velocity targets land
    at env e's arm DOFs, its position targets at its coordinates, explicit torques at its DOFs from its measured
    velocities; the free joints' entries are never written."""
    E = 3
    model = panda_envs(E, spacing=(1.0, 1.0, 0.0), floating=True)
    assert model.joint_coord_count == 16 * E and model.joint_dof_count == 15 * E
    mode = {
        "arm": wpctrl.PDJointVelControllerConfig(list(PANDA_ARM_JOINTS), -1.0, 1.0, 50.0, 1e9),
        "gripper": wpctrl.PDJointPosVelControllerConfig(
            list(PANDA_GRIPPER_JOINTS), -0.01, 0.04, 1e3, 1e2, 1e9, vel_lower=-0.2, vel_upper=0.2
        ),  # fmt: skip
    }
    ctrl = wpctrl.build_controller(mode, model, 20, 100, actuation=actuation, balance_passive_force=False)
    arm_q, arm_dof = indices(model, PANDA_ARM_JOINTS)
    g_q, g_dof = indices(model, PANDA_GRIPPER_JOINTS)
    rng = np.random.default_rng(1)
    s = model.state()
    s.joint_qd.assign(rng.uniform(-2.0, 2.0, model.joint_dof_count).astype(f32))  # base DOFs move too
    c = model.control()
    ctrl.reset(s, control=c)
    before = {k: getattr(c, k).numpy().copy() for k in ("joint_target_q", "joint_target_qd", "joint_f")}
    a = rng.uniform(-1.0, 1.0, (E, 11)).astype(f32)
    ctrl.set_action(a, s)
    ctrl.before_simulation_step(s, c)
    v = a[:, :7]  # [-1, 1] onto [-1, 1]
    g_pos = f32(0.5) * (f32(0.04) + f32(-0.01)) + f32(0.5) * (f32(0.04) - f32(-0.01)) * a[:, 7:9]
    g_vel = f32(0.5) * (f32(0.2) + f32(-0.2)) + f32(0.5) * (f32(0.2) - f32(-0.2)) * a[:, 9:11]
    tq, tqd, jf = (getattr(c, k).numpy() for k in ("joint_target_q", "joint_target_qd", "joint_f"))
    np.testing.assert_allclose(tqd[arm_dof], v, atol=1e-7)
    np.testing.assert_allclose(tq[g_q], g_pos, atol=1e-7)
    np.testing.assert_allclose(tqd[g_dof], g_vel, atol=1e-7)
    written_q = np.zeros(model.joint_coord_count, bool)
    written_q[g_q] = True
    written_qd = np.zeros(model.joint_dof_count, bool)
    written_qd[arm_dof] = written_qd[g_dof] = True
    np.testing.assert_array_equal(tq[~written_q], before["joint_target_q"][~written_q])
    np.testing.assert_array_equal(tqd[~written_qd], before["joint_target_qd"][~written_qd])
    qd = s.joint_qd.numpy()
    if actuation == "explicit":
        np.testing.assert_allclose(jf[arm_dof], f32(50.0) * (v - qd[arm_dof]), rtol=1e-6, atol=1e-5)
        qm = s.joint_q.numpy()[g_q]
        want = f32(1e3) * (g_pos - qm) + f32(1e2) * (g_vel - qd[g_dof])
        np.testing.assert_allclose(jf[g_dof], want, rtol=1e-6, atol=1e-4)
        np.testing.assert_array_equal(jf[~written_qd], 0.0)
    else:
        np.testing.assert_array_equal(jf, before["joint_f"])
    # the drive properties went to the same DOFs: velocity drive (ke 0, kd 50) on the arm
    np.testing.assert_array_equal(model.joint_target_kd.numpy()[arm_dof], 0.0 if actuation == "explicit" else 50.0)


def test_floating_base_under_stable_explicit_pd_uses_the_whole_articulations_inertia():
    """Stable explicit PD on a floating Panda: r = (H^-1)_ii of each env's full articulation (base DOFs included),
    Newton's JointSpaceResponse of the same state, and the torque the stable law gives with it."""
    from newton.actuators import JointSpaceResponse

    E = 2
    model = panda_envs(E, spacing=(1.0, 0.0, 0.0), floating=True)
    cfg = wpctrl.PDJointVelControllerConfig(list(PANDA_ARM_JOINTS), -1.0, 1.0, 80.0, 1e9)
    ctrl = wpctrl.build_controller(
        cfg, model, 100, 100, actuation="explicit", explicit_pd="stable", balance_passive_force=False
    )
    rng = np.random.default_rng(2)
    s = model.state()
    put(s, model, PANDA_ARM_JOINTS, (np.asarray(PANDA_INITIAL_Q[:7], f32) + rng.uniform(-0.3, 0.3, (E, 7))))
    s.joint_qd.assign(rng.uniform(-1.0, 1.0, model.joint_dof_count).astype(f32))
    c = model.control()
    ctrl.reset(s, control=c)
    a = rng.uniform(-1.0, 1.0, (E, 7)).astype(f32)
    ctrl.set_action(a, s)
    ctrl.before_simulation_step(s, c)
    jsr = JointSpaceResponse(model)
    jsr.refresh(s)
    inv = jsr.inverse_blocks.numpy()
    _, dof = indices(model, PANDA_ARM_JOINTS)
    art_dof0 = np.array([15 * e for e in range(E)])
    r = np.stack([np.diag(inv[e])[dof[e] - art_dof0[e]] for e in range(E)])
    np.testing.assert_allclose(ctrl.response.numpy(), r, rtol=1e-4)
    qd = s.joint_qd.numpy()[dof]
    dt = f32(0.01)
    want = (f32(80.0) * (a - qd)) / (f32(1.0) + r * dt * f32(80.0))
    np.testing.assert_allclose(c.joint_f.numpy()[dof], want, rtol=1e-4, atol=1e-4)


# -- a mobile base that is not the mode's first controller ----------------------------------------------------------


@pytest.mark.parametrize("forward", [False, True])
def test_mobile_base_after_an_arm_rotates_by_its_own_yaw(forward):
    """{"arm": ..., "base": PDBaseVel / PDBaseForwardVel}: the base's rows come after the arm's, yet its planar
    velocity is rotated by each env's measured yaw (not by an arm joint's angle)."""
    yaws = np.array([0.4, -1.9, 2.8], f32)
    arm_q = np.array([[1.0, -0.5, 0.3], [-1.2, 0.8, 2.0], [0.1, 1.5, -2.2]], f32)  # unlike the yaws
    model = mobile_envs(3, yaws, arm_q, spacing=(3.0, 0.0, 0.0))
    if forward:
        base = wpctrl.PDBaseForwardVelControllerConfig(BASE_JOINTS, [-1.0, -2.0], [1.0, 2.0], 100.0)
    else:
        base = wpctrl.PDBaseVelControllerConfig(BASE_JOINTS, [-1.0, -0.5, -2.0], [1.0, 0.5, 2.0], 100.0)
    mode = {"arm": wpctrl.PDJointPosControllerConfig(MOBILE_ARM, -0.1, 0.1, 100.0, 10.0, use_delta=True), "base": base}
    ctrl = wpctrl.build_controller(mode, model)
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    rng = np.random.default_rng(3)
    a = rng.uniform(-1.0, 1.0, (3, ctrl.action_dim)).astype(f32)
    ctrl.set_action(a, s)
    ctrl.before_simulation_step(s, c)
    b = a[:, 3:]
    if forward:  # [v, w] in [-1, 1]^2 onto [-1, 1] x [-2, 2]
        vx, vy, w = b[:, 0], np.zeros(3, f32), f32(2.0) * b[:, 1]
    else:
        vx, vy, w = b[:, 0], f32(0.5) * b[:, 1], f32(2.0) * b[:, 2]
    cy, sy = np.cos(yaws), np.sin(yaws)
    want = np.stack([cy * vx - sy * vy, sy * vx + cy * vy, w], axis=1)
    _, dof = indices(model, BASE_JOINTS)
    np.testing.assert_allclose(c.joint_target_qd.numpy()[dof], want, atol=2e-6)
    np.testing.assert_allclose(ctrl["base"].target_qvel.numpy(), want, atol=2e-6)
