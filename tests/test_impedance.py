"""The impedance controllers (operational space, joint impedance) against independent references: Newton's own
``ControllerOperationalSpace`` / ``ControllerJointImpedance`` with the same gains on the same states (the Panda and
ManiSkill's Fetch arm, every option on and off), a numpy closed form built from Newton's FK, mass matrix and gravity
torque, the gravity torque of the fused inertia pass (runtime loops and unrolled) against Newton's inverse dynamics;
then the options (variable impedance, targets, null-space posture, singular configurations), the row machinery
(force limit, delay, effort readout, NaN hold, randomisation, resets, graph capture) and the config errors."""

from __future__ import annotations

import copy
import itertools

import newton
import numpy as np
import pytest
import warp as wp
from conftest import PANDA_URDF, build_panda
from harness import ARM

import wpctrl
from wpctrl.robots import panda_control_modes

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


# -- modes, options ------------------------------------------------------------------------------------------------


def test_panda_impedance_modes():
    """The Panda's torque-level modes: OSC (delta and absolute pose) and joint impedance, each with the mimic gripper;
    gains per unit inertia, critically damped; their action layouts."""
    from wpctrl.robots.impedance_modes import JOINT_STIFFNESS, OSC_NULLSPACE_STIFFNESS, OSC_STIFFNESS

    modes = panda_control_modes()
    delta, absolute, joint = (
        modes[m]["arm"] for m in ("osc_ee_delta_pose", "osc_ee_pose", "joint_impedance_delta_pos")
    )
    assert delta == wpctrl.OperationalSpaceControllerConfig(
        list(ARM), -0.1, 0.1, -0.1, 0.1, OSC_STIFFNESS, force_limit=100, ee_link="panda_hand_tcp",
        nullspace_control="position", nullspace_stiffness=OSC_NULLSPACE_STIFFNESS,
    )  # fmt: skip
    assert not absolute.use_delta and not absolute.normalize_action and absolute.pos_lower is None
    assert joint == wpctrl.JointImpedanceControllerConfig(
        list(ARM), -0.1, 0.1, JOINT_STIFFNESS, use_delta=True, force_limit=100, inertial_compensation=True
    )
    for name in ("osc_ee_delta_pose", "osc_ee_pose", "joint_impedance_delta_pos"):
        assert modes[name]["gripper"] == modes["pd_joint_delta_pos"]["gripper"]
    model = build_panda(1)
    dims = {m: wpctrl.build_controller(modes[m], model).action_dim for m in ("osc_ee_delta_pose", "osc_ee_pose")}
    assert dims == {"osc_ee_delta_pose": 7, "osc_ee_pose": 7}
    ctrl = wpctrl.build_controller(modes["osc_ee_delta_pose"], model)
    arm = ctrl["arm"]
    kd = arm.task_damping.numpy()
    np.testing.assert_allclose(kd, 2.0 * np.sqrt(OSC_STIFFNESS), rtol=1e-6)  # critically damped
    np.testing.assert_allclose(arm.damping.numpy(), 2.0 * np.sqrt(OSC_NULLSPACE_STIFFNESS), rtol=1e-6)
    assert type(arm).__name__ == "OperationalSpaceController" and arm.target_effort.shape == (1, 7)


def test_variable_impedance_gains_come_from_the_action():
    """ "variable": 6 stiffness then 6 damping-ratio columns, normalised onto their limits; the torque is the fixed-gain
    controller's with those gains. Joint impedance "variable_kp": the stiffness columns set ``ctrl.stiffness``."""
    rb = robot("panda")
    rng = np.random.default_rng(4)
    cfg = osc_config(
        rb, damping=None, impedance_mode="variable", stiffness_limits=(10.0, 310.0), damping_ratio_limits=(0.5, 1.5)
    )
    ctrl = build(rb, cfg, actuation="explicit")
    assert ctrl.action_dim == 18
    state = rb.random_state(ctrl, rng)
    action = rng.uniform(-1.2, 1.2, (rb.num_envs, 18)).astype(np.float32)
    ours = step_torques(ctrl, state, action)
    a = np.clip(action, -1, 1)
    kp = 160.0 + 150.0 * a[:, 6:12]
    ratio = 1.0 + 0.5 * a[:, 12:]
    arm = ctrl["arm"]
    np.testing.assert_allclose(arm.processed_action.numpy()[:, 6:12], kp, rtol=1e-6)
    np.testing.assert_allclose(arm.processed_action.numpy()[:, 12:], ratio, rtol=1e-6)
    np.testing.assert_allclose(arm.task_stiffness.numpy(), kp, rtol=1e-6)
    np.testing.assert_allclose(arm.task_damping.numpy(), 2 * ratio * np.sqrt(kp), rtol=1e-5)
    fixed = build(rb, osc_config(rb), actuation="explicit")
    fixed["arm"].task_stiffness.assign(kp.astype(np.float32))
    fixed["arm"].task_damping.assign((2 * ratio * np.sqrt(kp)).astype(np.float32))
    np.testing.assert_allclose(step_torques(fixed, state, action[:, :6]), ours, rtol=1e-5, atol=1e-4)
    # joint impedance, variable_kp: n stiffness columns after the joint targets, the damping from the fixed ratio
    ji = build(rb, wpctrl.JointImpedanceControllerConfig(list(ARM), -0.1, 0.1, 50.0, impedance_mode="variable_kp",
                                                         damping_ratio=0.7, use_delta=True))  # fmt: skip
    act = rng.uniform(-1, 1, (rb.num_envs, 14)).astype(np.float32)
    ji.set_action(act, state)
    kp = 500.0 + 500.0 * act[:, 7:]
    np.testing.assert_allclose(ji["arm"].stiffness.numpy(), kp, rtol=1e-6)
    np.testing.assert_allclose(ji["arm"].damping.numpy(), 1.4 * np.sqrt(kp), rtol=1e-5)


@pytest.mark.parametrize(
    "kw", [dict(), dict(use_delta=True), dict(use_delta=True, use_target=True), dict(normalize_action=False)]
)
def test_joint_impedance_targets(kw):
    """Absolute, delta from the measured positions, delta on the last target, unnormalised; ``clip_targets``
    clamps to the joint limits; ``target_qpos`` and the state round-trip."""
    rb = robot("panda")
    rng = np.random.default_rng(5)
    cfg = wpctrl.JointImpedanceControllerConfig(list(ARM), -0.5, 0.5, 10.0, **kw)
    ctrl = build(rb, cfg, clip_targets="joint_limits")
    state = rb.random_state(ctrl, rng)
    ctrl.reset(state)
    q = state.joint_q.numpy()[ctrl._engine.binding.coord_index[:, :7]]
    ctrl.set_action(rng.uniform(-1, 1, (rb.num_envs, 7)).astype(np.float32), state)  # a first target, off q
    prev = ctrl["arm"].target_qpos.numpy().copy()
    assert not np.allclose(prev, q)
    act = rng.uniform(-1.5, 1.5, (rb.num_envs, 7)).astype(np.float32)
    ctrl.set_action(act, state)
    x = act if not cfg.normalize_action else 0.5 * np.clip(act, -1, 1)
    want = x if not cfg.use_delta else (prev if cfg.use_target else q) + x
    lo, hi = ctrl._engine.binding.qlimits[:7].T
    np.testing.assert_allclose(ctrl["arm"].target_qpos.numpy(), np.clip(want, lo, hi), atol=1e-6)
    state_dict = ctrl.get_state()
    if cfg.use_target:
        np.testing.assert_array_equal(state_dict["arm"]["target_qpos"].numpy(), ctrl["arm"].target_qpos.numpy())
        ctrl.set_state({"arm": {"target_qpos": np.zeros((rb.num_envs, 7), np.float32)}})
        assert (ctrl["arm"].target_qpos.numpy() == 0).all()
    else:
        assert state_dict == {}


def test_nan_action_holds_the_env_and_reset_takes_the_measured_pose():
    """A NaN anywhere in an env's action leaves its target pose and gains alone (counted); a partial reset makes the
    measured TCP pose the target of the reset env only, and zeroes its torque."""
    rb = robot("panda")
    rng = np.random.default_rng(6)
    ctrl = build(rb, osc_config(rb, impedance_mode="variable_kp", damping=None), actuation="explicit")
    state = rb.random_state(ctrl, rng)
    ctrl.reset(state)
    arm = ctrl["arm"]
    before = arm.target_pose.numpy().copy(), arm.task_stiffness.numpy().copy()
    action = rng.uniform(-1, 1, (rb.num_envs, 12)).astype(np.float32)
    action[1, 9] = np.nan
    ctrl.set_action(action, state)
    after = arm.target_pose.numpy(), arm.task_stiffness.numpy()
    assert ctrl.bad_action_count.numpy().tolist() == [0, 1, 0]
    for b, a in zip(before, after):
        np.testing.assert_array_equal(a[1], b[1])
        assert not np.allclose(a[0], b[0])
    control = rb.model.control()
    ctrl.before_simulation_step(state, control)
    moved = rb.random_state(ctrl, rng)
    ctrl.reset(moved, env_ids=[2], control=control)
    measured = arm.fk_jacobian(moved)[0].numpy()
    np.testing.assert_allclose(arm.target_pose.numpy()[2], measured[2], atol=1e-6)
    assert not np.allclose(arm.target_pose.numpy()[0], measured[0], atol=1e-3)
    dof = ctrl._engine.binding.dof_index[:, :7]
    f = control.joint_f.numpy()[dof]
    assert (f[2] == 0).all() and (np.abs(f[0]) > 0).any()


def test_force_limit_effort_readout_and_delay():
    """The torque is an effort row's command: clamped to the per-env force limit, read out before / after the
    clamp (``computed_effort`` / ``applied_effort``, saturations counted), and delayed by ``delay`` substeps."""
    rb = robot("panda")
    rng = np.random.default_rng(7)
    cfg = osc_config(rb, force_limit=5.0)
    ctrl = build(rb, cfg, actuation="explicit", track_effort=True, delay=2, sim_freq=100, control_freq=20)
    state = rb.random_state(ctrl, rng)
    ctrl.reset(state)
    control = rb.model.control()
    action = np.ones((rb.num_envs, 6), np.float32)
    ctrl.set_action(action, state)
    arm = ctrl["arm"]
    dof = ctrl._engine.binding.dof_index[:, :7]
    commanded, applied = [], []
    for _ in range(4):
        ctrl.before_simulation_step(state, control)
        commanded.append(arm.target_effort.numpy().copy())
        applied.append(control.joint_f.numpy()[dof].copy())
        state.joint_qd.assign(state.joint_qd.numpy() * 0.5)  # a new state each substep: new torques
    assert (np.abs(applied[0]) == 0).all() and (np.abs(applied[1]) == 0).all()  # the reset's zero, twice
    np.testing.assert_allclose(applied[2], np.clip(commanded[0], -5, 5), rtol=1e-6)
    np.testing.assert_allclose(applied[3], np.clip(commanded[1], -5, 5), rtol=1e-6)
    assert not np.allclose(commanded[0], commanded[1])
    np.testing.assert_allclose(arm.computed_effort.numpy(), commanded[1], rtol=1e-6)
    np.testing.assert_allclose(arm.applied_effort.numpy(), applied[3], rtol=1e-6)
    assert (arm.saturation_count.numpy() > 0).any() and (np.abs(commanded[1]) > 5).any()
    # a per-env force limit (set like any row's)
    ctrl2 = build(rb, osc_config(rb), actuation="explicit")
    ctrl2["arm"].set_drive_properties(force_limit=np.array([[1.0] * 7, [2.0] * 7, [1e9] * 7]))
    t = step_torques(ctrl2, state, action)
    assert np.abs(t[0]).max() <= 1.0 and np.abs(t[1]).max() <= 2.0 and np.abs(t[2]).max() > 2.0


def test_randomised_joint_gains_reach_the_torque():
    """Joint impedance: ``randomize_drive_properties(stiffness=...)`` draws per-env joint stiffness on the device; the
    torque is Kp (q* − q) − Kd q̇ with the drawn Kp."""
    rb = robot("panda")
    rng = np.random.default_rng(8)
    cfg = wpctrl.JointImpedanceControllerConfig(list(ARM), -0.2, 0.2, 100.0, 0.0, gravity_compensation=False,
                                                use_delta=True)  # fmt: skip
    ctrl = build(rb, cfg, actuation="explicit")
    ctrl["arm"].randomize_drive_properties(stiffness=(0.5, 2.0), seed=3)
    kp = ctrl["arm"].stiffness.numpy()
    assert kp.min() >= 50.0 and kp.max() <= 200.0 and kp.std() > 5.0
    state = rb.random_state(ctrl, rng)
    t = step_torques(ctrl, state, rng.uniform(-1, 1, (rb.num_envs, 7)).astype(np.float32))
    q = state.joint_q.numpy()[ctrl._engine.binding.coord_index[:, :7]]
    np.testing.assert_allclose(t, kp * (ctrl["arm"].target_qpos.numpy() - q), rtol=1e-5, atol=1e-5)


def test_cpu_graph_capture_replays_bitwise():
    """set_action and K substeps of an OSC mode captured in a CPU graph: replaying it gives the eager torques and
    targets bitwise."""
    rb = robot("panda")
    mode = panda_control_modes()["osc_ee_delta_pose"]
    runs = []
    for graph in (False, True):
        ctrl = wpctrl.build_controller(mode, rb.model)
        state = rb.random_state(ctrl, np.random.default_rng(9))
        control = rb.model.control()
        ctrl.reset(state, control=control)
        action = wp.array(np.random.default_rng(10).uniform(-1, 1, (rb.num_envs, 7)).astype(np.float32))

        def step(ctrl=ctrl, state=state, control=control, action=action):
            ctrl.set_action(action, state)
            for _ in range(ctrl.num_substeps):
                ctrl.before_simulation_step(state, control)

        if graph:
            with wp.ScopedCapture(device="cpu") as cap:
                step()
            ctrl.reset(state, control=control)
            wp.capture_launch(cap.graph)
        else:
            step()
        runs.append((control.joint_f.numpy().copy(), ctrl["arm"].target_pose.numpy().copy()))
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)
    assert np.abs(runs[0][0]).max() > 1.0


def test_singular_configuration_is_finite_and_damped():
    """Towards the Panda straight up (the rest pose scaled by d → 0: J loses rank, the TCP cannot move vertically):
    the task torque stays finite with or without damping; undamped (only Newton's pivot floor) it peaks several
    times over its regular size near the singularity, damped (the default ε = 1e-3) it stays within 20 % of its size
    at d = 0.01; at regular states the default damping changes nothing (bitwise)."""
    from wpctrl.robots import PANDA_INITIAL_Q

    rb = robot("panda")
    rest = np.asarray(PANDA_INITIAL_Q[:7])
    action = np.random.default_rng(11).uniform(-1, 1, (rb.num_envs, 6)).astype(np.float32)
    peaks = {}
    for sd in (0.0, 1e-3):
        ctrl = build(rb, osc_config(rb, singularity_damping=sd, gravity_compensation=False), actuation="explicit")
        coord = ctrl._engine.binding.coord_index[:, :7]
        peak = {}
        for d in (0.0, 1e-5, 1e-4, 3e-4, 1e-3, 1e-2):
            state = rb.model.state()
            q = state.joint_q.numpy()
            q[coord] = d * rest
            state.joint_q.assign(q)
            ctrl.reset(state)
            t = step_torques(ctrl, state, action)
            assert np.isfinite(t).all(), (sd, d)
            peak[d] = np.abs(t).max()
        regular = rb.random_state(ctrl, np.random.default_rng(12))
        peaks[sd] = peak, step_torques(ctrl, regular, action)
    (undamped, reg0), (damped, reg1) = peaks[0.0], peaks[1e-3]
    assert max(damped.values()) <= 1.2 * damped[1e-2], damped
    assert max(undamped.values()) > 2.0 * max(damped.values()), (undamped, damped)
    np.testing.assert_array_equal(reg1, reg0)


@pytest.mark.parametrize(
    "cls, kw, match",
    [
        ("osc", dict(stiffness=[1.0, 2.0]), r"Config\.stiffness: expected a scalar or 6 values"),
        ("osc", dict(stiffness=-1.0), r"OperationalSpaceControllerConfig\.stiffness: expected values >= 0"),
        ("osc", dict(damping=[1.0] * 7), r"\.damping: expected a scalar or 6 values \(one per task axis"),
        ("osc", dict(nullspace_stiffness=[1.0] * 6, nullspace_control="position"),
         r"\.nullspace_stiffness: expected a scalar or 7 values \(one per joint\)"),
        ("osc", dict(impedance_mode="variable_kd"), r"\.impedance_mode: expected one of"),
        ("osc", dict(impedance_mode="variable", damping=5.0), r"\.damping: with impedance_mode='variable'"),
        ("osc", dict(stiffness_limits=(10.0, 1.0)), r"\.stiffness_limits: expected finite 0 <= low <= high"),
        ("osc", dict(partial_inertial_dynamics_decoupling=True, inertial_dynamics_decoupling=False),
         r"partial_inertial_dynamics_decoupling: needs inertial_dynamics_decoupling=True"),
        ("osc", dict(singularity_damping=2.0), r"\.singularity_damping: expected a number in \[0, 1\)"),
        ("joint", dict(stiffness=[1.0] * 3), r"JointImpedanceControllerConfig\.stiffness: expected a scalar or 7"),
        ("joint", dict(damping=-2.0), r"JointImpedanceControllerConfig\.damping: expected values >= 0"),
    ],
)  # fmt: skip
def test_config_errors_name_the_field(cls, kw, match):
    rb = robot("panda")
    if cls == "osc":
        cfg = osc_config(rb, **kw)
    else:
        cfg = wpctrl.JointImpedanceControllerConfig(list(ARM), -0.1, 0.1, **{"stiffness": 10.0, **kw})
    with pytest.raises(wpctrl.ConfigError, match=match):
        build(rb, cfg)


def test_build_errors():
    """The coupled drive would overwrite the impedance torques (refused); a floating base (outside the fused inertia
    pass) refuses the options that need the mass matrix or the gravity torque, and builds without them."""
    rb = robot("panda")
    mode = panda_control_modes()["osc_ee_delta_pose"]
    with pytest.raises(wpctrl.ConfigError, match=r"explicit_pd: 'coupled' solves every row's drive torque"):
        wpctrl.build_controller(mode, rb.model, actuation="explicit", explicit_pd="coupled")
    robot_b = newton.ModelBuilder()
    robot_b.add_urdf(str(PANDA_URDF), collapse_fixed_joints=True, floating=True)
    b = newton.ModelBuilder()
    b.replicate(robot_b, 2)
    floating = b.finalize(device="cpu")
    cfg = wpctrl.OperationalSpaceControllerConfig(list(ARM), ee_link="panda_hand_tcp", urdf_path=str(PANDA_URDF))
    with pytest.raises(wpctrl.ConfigError, match=r"joint_names: inertial decoupling needs the mass matrix"):
        wpctrl.build_controller({"arm": cfg, "balance_passive_force": False}, floating)
    cfg.inertial_dynamics_decoupling = False
    with pytest.raises(wpctrl.ConfigError, match=r"joint_names: gravity compensation needs the mass matrix"):
        wpctrl.build_controller({"arm": cfg, "balance_passive_force": False}, floating)
    cfg.gravity_compensation = False
    ctrl = wpctrl.build_controller({"arm": cfg, "balance_passive_force": False}, floating, actuation="explicit")
    assert np.isfinite(step_torques(ctrl, floating.state(), np.zeros((2, 6), np.float32))).all()


def test_balance_passive_force_leaves_gravity_to_the_solver():
    """With ``balance_passive_force`` on (ManiSkill's default), the solver takes gravity off the robot's links, so the
    controllers add no gravity torque (zero gains: zero torque); off, the torque is g(q)."""
    rb = robot("panda")
    cfg = wpctrl.JointImpedanceControllerConfig(list(ARM), -0.1, 0.1, 0.0, 0.0, use_delta=True)
    state = rb.random_state(build(rb, cfg), np.random.default_rng(13))
    zero = np.zeros((rb.num_envs, 7), np.float32)
    on = step_torques(wpctrl.build_controller({"arm": cfg}, rb.model, actuation="explicit"), state, zero)
    off = step_torques(build(rb, cfg, actuation="explicit"), state, zero)
    assert (on == 0).all() and np.abs(off).max() > 5.0


def test_fixed_nullspace_target_is_the_posture():
    """``nullspace_target`` fixes the posture (else each env's reset pose): the OSC torque equals the one of a
    controller whose reset-pose posture is set to the same joint positions."""
    rb = robot("panda")
    rng = np.random.default_rng(14)
    posture = rng.uniform(-0.2, 0.2, 7) + np.asarray(rb.model.joint_q.numpy()[:7])
    fixed = build(rb, osc_config(rb, nullspace_control="position", nullspace_target=posture), actuation="explicit")
    free = build(rb, osc_config(rb, nullspace_control="position"), actuation="explicit")
    state = rb.random_state(fixed, rng)
    fixed.reset(state)
    free.reset(state)
    free["arm"].target_qpos.assign(np.tile(posture, (rb.num_envs, 1)).astype(np.float32))
    action = rng.uniform(-1, 1, (rb.num_envs, 6)).astype(np.float32)
    a, b = step_torques(fixed, state, action), step_torques(free, state, action)
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-5)
    free["arm"].target_qpos.assign(np.tile(posture + 0.3, (rb.num_envs, 1)).astype(np.float32))
    assert np.abs(step_torques(free, state, action) - a).max() > 0.1


@pytest.mark.parametrize("how", ["spacing", "turned"])
def test_envs_placed_apart_and_turned_get_the_torques_of_envs_at_the_origin(how):
    """Pandas replicated apart or placed and turned about z (gravity along the world's z, so the same in every base
    frame): the OSC torques (decoupling, gravity, null space) of each env equal those of the same joint state at the
    origin; every pose is in the env's own base frame."""
    from wpctrl.robots import panda

    E = 3
    builder = newton.ModelBuilder()
    if how == "spacing":
        builder.replicate(panda(), E, spacing=(2.0, -1.0, 0.5))
    else:
        xf = [wp.transform(wp.vec3(1.5 * e, -2.0 * e, 0.25 * e), wp.quat_from_axis_angle(wp.vec3(0, 0, 1), 0.8 * e))
              for e in range(E)]  # fmt: skip
        builder.replicate(panda(), E, xforms=xf)
    placed = builder.finalize(device="cpu")
    origin = build_panda(E)
    rng = np.random.default_rng(15)
    mode = panda_control_modes()["osc_ee_delta_pose"]
    mode["balance_passive_force"] = False
    action = rng.uniform(-1, 1, (E, 7)).astype(np.float32)
    dq = rng.uniform(-0.3, 0.3, (E, 7)).astype(np.float32)
    dqd = rng.uniform(-0.5, 0.5, (E, 7)).astype(np.float32)
    out = []
    for model in (placed, origin):
        ctrl = wpctrl.build_controller(copy.deepcopy(mode), model, actuation="explicit")
        state = model.state()
        b = ctrl._engine.binding
        q, qd = state.joint_q.numpy(), state.joint_qd.numpy()
        q[b.coord_index[:, :7]] += dq
        qd[b.dof_index[:, :7]] = dqd
        state.joint_q.assign(q)
        state.joint_qd.assign(qd)
        ctrl.reset(state)
        out.append((step_torques(ctrl, state, action)[:, :7], ctrl["arm"].target_pose.numpy()))
    np.testing.assert_allclose(out[0][0], out[1][0], rtol=0, atol=1e-4 * np.abs(out[1][0]).max())
    np.testing.assert_allclose(out[0][1], out[1][1], atol=2e-6)


def test_randomised_task_gains():
    """``randomize_task_impedance``: per env and axis inside the range ("abs") or the config's value times it
    ("scale", (1, 1): bit-identical), only the selected envs, new values on every call and on every replay of a
    captured graph, and the torque follows the drawn gains."""
    rb = robot("panda")
    ctrl = build(rb, osc_config(rb), actuation="explicit")
    arm = ctrl["arm"]
    arm.randomize_task_impedance(stiffness=(50.0, 150.0), damping=(5.0, 10.0), mode="abs", seed=1)
    kp, kd = arm.task_stiffness.numpy().copy(), arm.task_damping.numpy().copy()
    assert kp.min() >= 50 and kp.max() <= 150 and kd.min() >= 5 and kd.max() <= 10 and kp.std() > 5
    arm.randomize_task_impedance(stiffness=(1.0, 1.0), mode="scale", env_ids=[1])
    np.testing.assert_array_equal(arm.task_stiffness.numpy()[1], KP.astype(np.float32))
    np.testing.assert_array_equal(arm.task_stiffness.numpy()[[0, 2]], kp[[0, 2]])
    np.testing.assert_array_equal(arm.task_damping.numpy(), kd)
    with wp.ScopedCapture(device="cpu") as cap:
        arm.randomize_task_impedance(stiffness=(0.5, 2.0), seed=2)
    draws = []
    for _ in range(2):
        wp.capture_launch(cap.graph)
        draws.append(arm.task_stiffness.numpy().copy())
    assert not np.allclose(draws[0], draws[1]) and (draws[1] >= 0.5 * KP - 1e-3).all()
    state = rb.random_state(ctrl, np.random.default_rng(16))
    action = np.zeros((rb.num_envs, 6), np.float32)
    drawn = step_torques(ctrl, state, action)
    fixed = build(rb, osc_config(rb), actuation="explicit")
    fixed["arm"].task_stiffness.assign(arm.task_stiffness.numpy())
    fixed["arm"].task_damping.assign(arm.task_damping.numpy())
    np.testing.assert_allclose(step_torques(fixed, state, action), drawn, rtol=1e-6, atol=1e-5)
    with pytest.raises(ValueError, match=r"randomize_task_impedance\.stiffness: expected finite 0 <= lo <= hi"):
        arm.randomize_task_impedance(stiffness=(2.0, 1.0))
