"""The impedance controllers (operational space, joint impedance) against independent references: Newton's own
``ControllerOperationalSpace`` / ``ControllerJointImpedance`` with the same gains on the same states (the Panda and
ManiSkill's Fetch arm, every option on and off), a numpy closed form built from Newton's FK, mass matrix and gravity
torque, the gravity torque of the fused inertia pass (runtime loops and unrolled) against Newton's inverse dynamics;
then the options (variable impedance, targets, null-space posture, singular configurations), the row machinery
(force limit, delay, effort readout, NaN hold, randomisation, resets, graph capture) and the config errors."""

from __future__ import annotations

import itertools

import newton
import numpy as np
import pytest
import warp as wp
from conftest import build_panda
from harness import ARM

import wpctrl

FETCH_ARM = ["shoulder_pan_joint", "shoulder_lift_joint", "upperarm_roll_joint", "elbow_flex_joint",
             "forearm_roll_joint", "wrist_flex_joint", "wrist_roll_joint"]  # fmt: skip
KP = np.array([100.0, 120.0, 140.0, 50.0, 60.0, 70.0])
KD = np.array([20.0, 21.0, 22.0, 10.0, 11.0, 12.0])
NKP = np.linspace(5.0, 11.0, 7)
NKD = np.linspace(1.0, 3.0, 7)


def _xyzw(pose7: np.ndarray) -> np.ndarray:
    """``[x, y, z, qw, qx, qy, qz]`` rows as Warp transforms ``[x, y, z, qx, qy, qz, qw]``."""
    return np.concatenate([pose7[:, :3], pose7[:, 4:], pose7[:, 3:4]], axis=1)


class Robot:
    """A model of ``num_envs`` robots, the arm's joints, its EE link and a Newton site on it (Newton's tool)."""

    def __init__(self, name: str, num_envs: int):
        self.name = name
        self.num_envs = num_envs
        if name == "panda":
            self.model = build_panda(num_envs)
            self.arm, self.ee_link, self.site, self.urdf = list(ARM), "panda_hand_tcp", "panda_hand_tcp", None
        else:
            from wpctrl.maniskill import load_robot

            robot = load_robot("fetch")
            arm = robot.control_modes["pd_ee_delta_pose"]["arm"]
            b = robot.builder
            body = [i for i, lbl in enumerate(b.body_label) if lbl.rsplit("/", 1)[-1] == arm.ee_link][0]
            b.add_site(body, label="osc_tool")
            top = newton.ModelBuilder()
            top.replicate(b, num_envs)
            self.model = top.finalize(device="cpu")
            self.arm, self.ee_link, self.site, self.urdf = list(FETCH_ARM), arm.ee_link, "osc_tool", arm.urdf_path

    def random_state(self, ctrl, rng, spread=0.3, speed=0.5):
        """A state near the initial pose: the controller's joints moved by U(±spread) and moving; the other DOFs at
        rest (OSC damps the EE twist of the controlled joints, Newton's the whole body's: they differ where a base
        or torso moves)."""
        s = self.model.state()
        b = ctrl._engine.binding
        q = s.joint_q.numpy()
        q[b.coord_index] += rng.uniform(-spread, spread, b.coord_index.shape).astype(np.float32)
        s.joint_q.assign(q)
        qd = np.zeros(s.joint_qd.shape[0], np.float32)
        qd[b.dof_index] = rng.uniform(-speed, speed, b.dof_index.shape)
        s.joint_qd.assign(qd)
        return s


_ROBOTS: dict[str, Robot] = {}


def robot(name: str) -> Robot:
    if name not in _ROBOTS:
        if name == "fetch":
            pytest.importorskip("mani_skill", reason="the maniskill extra (mani-skill) is not installed")
        _ROBOTS[name] = Robot(name, 3)
    return _ROBOTS[name]


def osc_config(rb: Robot, **kw) -> wpctrl.OperationalSpaceControllerConfig:
    base = dict(ee_link=rb.ee_link, urdf_path=rb.urdf, stiffness=KP, damping=KD, singularity_damping=0.0)
    base.update(kw)
    return wpctrl.OperationalSpaceControllerConfig(list(rb.arm), **base)


def build(rb: Robot, config, **kw):
    return wpctrl.build_controller({"arm": config, "balance_passive_force": False}, rb.model, **kw)


def root_frames(rb: Robot, ctrl, state) -> np.ndarray:
    """(num_envs, 7) Warp transforms: each env's root frame in the world (where Newton's operational frame goes), from
    Newton's FK of the site and the controller's EE pose in the root frame."""
    newton.eval_fk(rb.model, state.joint_q, state.joint_qd, state)
    pose, _ = ctrl["arm"].fk_jacobian(state)
    site = [i for i, lbl in enumerate(rb.model.shape_label) if lbl.rsplit("/", 1)[-1] == rb.site]
    body = rb.model.shape_body.numpy()[site]
    st = rb.model.shape_transform.numpy()[site]
    bq = state.body_q.numpy()[body]
    out = []
    for e in range(rb.num_envs):
        world = wp.transform(*bq[e]) * wp.transform(*st[e])
        root = wp.transform(*_xyzw(pose.numpy()[e : e + 1])[0])
        out.append(np.array(world * wp.transform_inverse(root), np.float32))
    return np.stack(out)


def newton_osc(rb: Robot, ctrl, state, decoupling: str, gravity: bool, nullspace: bool) -> np.ndarray:
    """Newton's ControllerOperationalSpace with the controller's gains, frame, target and posture: (num_envs, n)."""
    from newton.controllers import ControllerOperationalSpace

    E, arm = rb.num_envs, ctrl["arm"]
    sv = lambda a: wp.array([wp.spatial_vector(*a)] * E, dtype=wp.spatial_vector)  # noqa: E731
    tiled = lambda a: wp.array(np.tile(a, E).astype(np.float32), dtype=float)  # noqa: E731
    frames = root_frames(rb, ctrl, state)
    n = ControllerOperationalSpace(
        rb.model,
        tool_sites=rb.site,
        joints=rb.arm,
        motion_stiffness=sv(KP),
        motion_damping=sv(KD),
        operational_frame_pose_world=wp.array(frames, dtype=wp.transform),
        use_inertia_decoupling=decoupling != "none",
        use_partial_inertia_decoupling=decoupling == "partial",
        use_gravity_compensation=gravity,
        use_null_space_control=nullspace,
        null_space_stiffness=tiled(NKP) if nullspace else None,
        null_space_damping=tiled(NKD) if nullspace else None,
    )
    i, o = n.input(), n.output()
    i.joint_q.assign(state.joint_q)
    i.joint_qd.assign(state.joint_qd)
    i.desired_tool_pose_operational.assign(_xyzw(arm.target_pose.numpy()))
    if nullspace:
        i.joint_q_des_null.assign(arm.target_qpos.numpy().reshape(-1))
        i.joint_qd_des_null.zero_()
    n.step(inputs=i, outputs=o, dt=0.01)
    return o.joint_f.numpy().reshape(E, -1).astype(np.float64)


def step_torques(ctrl, state, action) -> np.ndarray:
    """The arm's commanded torque after set_action and one substep: (num_envs, n)."""
    control = ctrl._engine.model.control()
    ctrl.set_action(action, state)
    ctrl.before_simulation_step(state, control)
    dof = ctrl._engine.binding.dof_index[:, ctrl["arm"]._rows]
    return control.joint_f.numpy()[dof].astype(np.float64)


OSC_OPTIONS = list(itertools.product(["none", "full", "partial"], [False, True], [False, True]))


@pytest.mark.parametrize("name", ["panda", "fetch"])
def test_osc_equals_newtons_controller_for_every_option(name):
    """Same gains, frame, target, posture and state: the torques of every option combination equal Newton's
    ControllerOperationalSpace (float32) to float32 rounding of the largest torque."""
    rb = robot(name)
    rng = np.random.default_rng(0)
    for decoupling, gravity, nullspace in OSC_OPTIONS:
        cfg = osc_config(
            rb,
            inertial_dynamics_decoupling=decoupling != "none",
            partial_inertial_dynamics_decoupling=decoupling == "partial",
            gravity_compensation=gravity,
            nullspace_control="position" if nullspace else "none",
            nullspace_stiffness=NKP,
            nullspace_damping=NKD,
        )
        ctrl = build(rb, cfg, actuation="explicit")
        state = rb.random_state(ctrl, rng)
        ctrl.reset(state)  # the posture: the reset pose
        state = rb.random_state(ctrl, rng, spread=0.1)
        action = rng.uniform(-1, 1, (rb.num_envs, 6)).astype(np.float32)
        ours = step_torques(ctrl, state, action)
        ref = newton_osc(rb, ctrl, state, decoupling, gravity, nullspace)
        scale = np.abs(ref).max()
        assert scale > 1.0, (decoupling, gravity, nullspace)
        err = np.abs(ours - ref).max() / scale
        assert err < 2e-5, (name, decoupling, gravity, nullspace, err)


@pytest.mark.parametrize("name", ["panda", "fetch"])
def test_joint_impedance_equals_newtons_controller(name):
    """Joint impedance (inertial compensation and gravity on / off) equals Newton's ControllerJointImpedance
    (Coriolis compensation off) with the same per-joint gains, targets and state."""
    from newton.controllers import ControllerJointImpedance

    rb = robot(name)
    rng = np.random.default_rng(1)
    n = len(rb.arm)
    kp, kd = np.linspace(50.0, 200.0, n), np.linspace(5.0, 20.0, n)
    for inertia, gravity in itertools.product([False, True], [False, True]):
        cfg = wpctrl.JointImpedanceControllerConfig(
            list(rb.arm), -0.2, 0.2, kp, kd, use_delta=True, inertial_compensation=inertia, gravity_compensation=gravity
        )
        ctrl = build(rb, cfg, actuation="explicit")
        state = rb.random_state(ctrl, rng)
        ours = step_torques(ctrl, state, rng.uniform(-1, 1, (rb.num_envs, n)).astype(np.float32))
        ji = ControllerJointImpedance(
            rb.model,
            joints=rb.arm,
            stiffness=wp.array(np.tile(kp, rb.num_envs).astype(np.float32), dtype=float),
            damping=wp.array(np.tile(kd, rb.num_envs).astype(np.float32), dtype=float),
            use_gravity_compensation=gravity,
            use_coriolis_compensation=False,
            use_inertia_decoupling=inertia,
        )
        i, o = ji.input(), ji.output()
        i.joint_q.assign(state.joint_q)
        i.joint_qd.assign(state.joint_qd)
        i.joint_q_des.assign(ctrl["arm"].target_qpos.numpy().reshape(-1))
        i.joint_qd_des.zero_()
        ji.step(inputs=i, outputs=o, dt=0.01)
        ref = o.joint_f.numpy().reshape(rb.num_envs, n)
        scale = np.abs(ref).max()
        assert scale > 1.0
        assert np.abs(ours - ref).max() / scale < 2e-5, (name, inertia, gravity)


def _fd_jacobian(rb: Robot, ctrl, state, env: int, h=1e-3) -> np.ndarray:
    """The site's geometric Jacobian (6, n) in the world frame by central differences of Newton's FK (float64 math on
    Newton's float32 poses)."""
    coord = ctrl._engine.binding.coord_index[env, ctrl["arm"]._rows]
    site = [i for i, lbl in enumerate(rb.model.shape_label) if lbl.rsplit("/", 1)[-1] == rb.site][env]
    body = int(rb.model.shape_body.numpy()[site])
    st = wp.transform(*rb.model.shape_transform.numpy()[site])
    s = rb.model.state()

    def pose(q):
        s.joint_q.assign(q.astype(np.float32))
        newton.eval_fk(rb.model, s.joint_q, s.joint_qd, s)
        t = wp.transform(*s.body_q.numpy()[body]) * st
        return np.array(t.p, np.float64), np.array(wp.quat_to_matrix(t.q), np.float64).reshape(3, 3)

    q0 = state.joint_q.numpy().astype(np.float64)
    J = np.zeros((6, len(coord)))
    for c, k in enumerate(coord):
        qp, qm = q0.copy(), q0.copy()
        qp[k] += h
        qm[k] -= h
        (pp, rp), (pm, rm) = pose(qp), pose(qm)
        J[:3, c] = (pp - pm) / (2 * h)
        w = (rp - rm) @ pose(q0)[1].T / (2 * h)  # dR/dq R^T = [ω]x
        J[3:, c] = [w[2, 1], w[0, 2], w[1, 0]]
    return J


def test_osc_numpy_closed_form():
    """τ = Jᵀ Λ (Kp e − Kd J q̇) + N M a₀ + g with Λ = (J M⁻¹ Jᵀ)⁻¹ and the dynamically consistent null-space
    projector, in float64 numpy from Newton's FK (finite differences), mass matrix and gravity torque."""
    rb = robot("panda")
    rng = np.random.default_rng(2)
    cfg = osc_config(rb, nullspace_control="position", nullspace_stiffness=NKP, nullspace_damping=NKD)
    ctrl = build(rb, cfg, actuation="explicit")
    state = rb.random_state(ctrl, rng)
    ctrl.reset(state)
    state = rb.random_state(ctrl, rng, spread=0.1)
    ours = step_torques(ctrl, state, rng.uniform(-1, 1, (rb.num_envs, 6)).astype(np.float32))
    arm = ctrl["arm"]
    m = rb.model
    newton.eval_fk(m, state.joint_q, state.joint_qd, state)
    H = wp.zeros((m.articulation_count, m.max_dofs_per_articulation, m.max_dofs_per_articulation), dtype=float)
    g = wp.zeros(m.joint_dof_count, dtype=float)
    newton.eval_mass_matrix(m, state, H=H)
    newton.eval_inverse_dynamics_passive(m, state, gravity_force=g)
    H, g = H.numpy().astype(np.float64), g.numpy().astype(np.float64)
    dof = ctrl._engine.binding.dof_index[:, arm._rows]
    q = state.joint_q.numpy()[ctrl._engine.binding.coord_index[:, arm._rows]].astype(np.float64)
    qd = state.joint_qd.numpy()[dof].astype(np.float64)
    target, posture = arm.target_pose.numpy().astype(np.float64), arm.target_qpos.numpy().astype(np.float64)
    for e in range(rb.num_envs):
        J = _fd_jacobian(rb, ctrl, state, e)
        M = H[e][:7, :7]
        site = wp.transform(*root_frames(rb, ctrl, state)[e]) * wp.transform(*_xyzw(arm.ee_pose.numpy()[e : e + 1])[0])
        newton.eval_fk(m, state.joint_q, state.joint_qd, state)
        p = np.array(arm.fk_jacobian(state)[0].numpy()[e, :3], np.float64)
        qe = wp.transform(*_xyzw(target[e : e + 1])[0]).q * wp.quat_inverse(site.q)
        qe = np.array(qe, np.float64) * (1 if qe[3] >= 0 else -1)
        ang = 2 * np.arctan2(np.linalg.norm(qe[:3]), qe[3])
        err = np.concatenate([target[e, :3] - p, qe[:3] / np.linalg.norm(qe[:3]) * ang])
        Minv = np.linalg.inv(M)
        Lam = np.linalg.inv(J @ Minv @ J.T)
        a0 = NKP * (posture[e] - q[e]) - NKD * qd[e]
        N = np.eye(7) - J.T @ (Lam @ J @ Minv)
        tau = J.T @ Lam @ (KP * err - KD * (J @ qd[e])) + N @ (M @ a0) + g[dof[e]]
        np.testing.assert_allclose(ours[e], tau, rtol=0, atol=2e-3 * np.abs(tau).max())


@pytest.mark.parametrize("unroll", [False, True])
def test_fused_gravity_torque_matches_newtons_inverse_dynamics(unroll):
    """The gravity torque of the fused inertia pass (runtime loops: the CPU default; unrolled composite form: the CUDA
    default, forced here) equals Newton's eval_inverse_dynamics_passive on random Panda states, through a joint
    impedance controller with zero gains: τ = g(q)."""
    from wpctrl.kernels.inertia import FusedChain

    rb = robot("panda")
    cfg = wpctrl.JointImpedanceControllerConfig(list(ARM), -0.1, 0.1, 0.0, 0.0, use_delta=True)
    ctrl = build(rb, cfg, actuation="explicit")
    unit = ctrl._engine.part("impedance").units[0]
    unit.fused, unit._torque = FusedChain(unit.fused.layout, rb.model, unroll=unroll), None
    rng = np.random.default_rng(3)
    m = rb.model
    for _ in range(2):
        state = rb.random_state(ctrl, rng, spread=1.0)
        ours = step_torques(ctrl, state, np.zeros((rb.num_envs, 7), np.float32))
        newton.eval_fk(m, state.joint_q, state.joint_qd, state)
        g = wp.zeros(m.joint_dof_count, dtype=float)
        newton.eval_inverse_dynamics_passive(m, state, gravity_force=g)
        ref = g.numpy()[ctrl._engine.binding.dof_index[:, ctrl["arm"]._rows]]
        assert np.abs(ref).max() > 5.0
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-5 * np.abs(ref).max())
