"""The impedance controllers where envs, worlds and controllers differ, checked env by env against independent
references: per-env task, joint and null-space gains, per-env joint states and per-world gravity against Newton's own
``ControllerOperationalSpace`` / ``ControllerJointImpedance``; two joint-impedance controllers of one mode on different
joints (the second one's rows and action columns, targets clipped to each joint's own limits) against a numpy form
built from Newton's mass matrix and gravity torque; and OSC's map from the action to the target pose, for every frame,
normalised or raw, delta or absolute, with and without ``use_target``, against a scipy re-derivation of ManiSkill's
``PDEEPoseController.compute_target_pose`` on Newton's forward kinematics."""

from __future__ import annotations

import itertools

import newton
import numpy as np
import pytest
import warp as wp
from harness import ARM, gripper
from scipy.spatial.transform import Rotation
from test_impedance import Robot, root_frames, step_torques

import wpctrl

E = 4
GRAVITY = np.array([[0.0, 0.0, -9.81], [0.0, 0.0, -3.71], [1.5, -2.0, -12.0], [-3.0, 0.5, -6.0]], np.float32)
"""One gravity per world [m/s²] (Newton's per-world ``Model.gravity``)."""


def _robot_with_world_gravity() -> Robot:
    rb = Robot("panda", E)
    rb.model.set_gravity(GRAVITY)
    return rb


def _newton_gravity_and_mass(model, state) -> tuple[np.ndarray, np.ndarray]:
    """Newton's per-world gravity torque (joint_dof_count,) and mass matrices (articulations, n, n), float64."""
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    n = model.max_dofs_per_articulation
    H = wp.zeros((model.articulation_count, n, n), dtype=float)
    g = wp.zeros(model.joint_dof_count, dtype=float)
    newton.eval_mass_matrix(model, state, H=H)
    newton.eval_inverse_dynamics_passive(model, state, gravity_force=g)
    return g.numpy().astype(np.float64), H.numpy().astype(np.float64)


def test_newtons_gravity_torque_differs_per_world():
    """The reference itself: Newton's gravity torque of one joint state differs between the worlds of different
    gravity (so a controller that reads world 0's gravity for every env cannot match it)."""
    rb = _robot_with_world_gravity()
    np.testing.assert_array_equal(rb.model.gravity.numpy()[:E], GRAVITY)
    g, _ = _newton_gravity_and_mass(rb.model, rb.model.state())
    per_env = g.reshape(E, -1)[:, :7]
    for e in range(1, E):
        assert np.abs(per_env[e] - per_env[0]).max() > 0.5, e


# -- per-env gains, per-env states, per-world gravity ------------------------------------------------------------------


def _newton_osc(rb: Robot, ctrl, state, decoupling: str, kp, kd, nkp, nkd) -> np.ndarray:
    """Newton's ControllerOperationalSpace with per-robot task gains ``kp``/``kd`` (E, 6) and per-DOF posture gains
    ``nkp``/``nkd`` (E, 7), the controller's root frame, target and posture, gravity and null space on: (E, 7)."""
    from newton.controllers import ControllerOperationalSpace

    arm = ctrl["arm"]
    sv = lambda a: wp.array([wp.spatial_vector(*row) for row in a], dtype=wp.spatial_vector)  # noqa: E731
    flat = lambda a: wp.array(np.asarray(a, np.float32).reshape(-1), dtype=float)  # noqa: E731
    n = ControllerOperationalSpace(
        rb.model,
        tool_sites=rb.site,
        joints=rb.arm,
        motion_stiffness=sv(kp),
        motion_damping=sv(kd),
        operational_frame_pose_world=wp.array(root_frames(rb, ctrl, state), dtype=wp.transform),
        use_inertia_decoupling=decoupling != "none",
        use_partial_inertia_decoupling=decoupling == "partial",
        use_gravity_compensation=True,
        use_null_space_control=True,
        null_space_stiffness=flat(nkp),
        null_space_damping=flat(nkd),
    )
    i, o = n.input(), n.output()
    i.joint_q.assign(state.joint_q)
    i.joint_qd.assign(state.joint_qd)
    tp = arm.target_pose.numpy()
    i.desired_tool_pose_operational.assign(np.concatenate([tp[:, :3], tp[:, 4:], tp[:, 3:4]], axis=1))
    i.joint_q_des_null.assign(arm.target_qpos.numpy().reshape(-1))
    i.joint_qd_des_null.zero_()
    n.step(inputs=i, outputs=o, dt=0.01)
    return o.joint_f.numpy().reshape(E, -1).astype(np.float64)


@pytest.mark.parametrize("decoupling", ["full", "partial", "none"])
def test_osc_per_env_gains_states_and_gravity_equal_newtons_controller(decoupling):
    """Four Pandas, each in a world of its own gravity, each with its own task stiffness and damping (drawn by
    ``randomize_task_impedance`` or written), its own null-space gains (``set_drive_properties``), its own joint
    state and posture and its own action: every env's OSC torque (gravity and null space on) equals Newton's
    ControllerOperationalSpace given the same per-robot gains, env by env."""
    rb = _robot_with_world_gravity()
    rng = np.random.default_rng(20)
    cfg = wpctrl.OperationalSpaceControllerConfig(
        list(ARM),
        ee_link=rb.ee_link,
        singularity_damping=0.0,
        inertial_dynamics_decoupling=decoupling != "none",
        partial_inertial_dynamics_decoupling=decoupling == "partial",
        nullspace_control="position",
    )
    ctrl = wpctrl.build_controller({"arm": cfg, "balance_passive_force": False}, rb.model, actuation="explicit")
    arm = ctrl["arm"]
    scale = 1.0 if decoupling != "none" else 5.0  # without decoupling the gains are forces: larger
    if decoupling == "full":
        kp = rng.uniform(20.0, 200.0, (E, 6)).astype(np.float32) * scale
        kd = rng.uniform(2.0, 25.0, (E, 6)).astype(np.float32) * scale
        arm.task_stiffness.assign(kp)
        arm.task_damping.assign(kd)
    else:
        arm.randomize_task_impedance(stiffness=(20.0 * scale, 200.0 * scale), damping=(2.0, 25.0), mode="abs", seed=5)
        kp, kd = arm.task_stiffness.numpy().copy(), arm.task_damping.numpy().copy()
    nkp = rng.uniform(2.0, 30.0, (E, 7)).astype(np.float32)
    nkd = rng.uniform(0.5, 6.0, (E, 7)).astype(np.float32)
    arm.set_drive_properties(stiffness=nkp, damping=nkd)
    for gains in (kp, kd, nkp, nkd):  # every env's gains differ from env 0's
        assert (np.abs(gains[1:] - gains[0]).max(axis=1) > 0.1 * np.abs(gains[0]).max()).all()
    np.testing.assert_array_equal(arm.stiffness.numpy(), nkp)
    state = rb.random_state(ctrl, rng)
    ctrl.reset(state)  # the posture: each env's reset pose
    state = rb.random_state(ctrl, rng, spread=0.15)
    action = rng.uniform(-1, 1, (E, 6)).astype(np.float32)
    ours = step_torques(ctrl, state, action)
    ref = _newton_osc(rb, ctrl, state, decoupling, kp, kd, nkp, nkd)
    for e in range(E):
        size = np.abs(ref[e]).max()
        assert size > 1.0, e
        np.testing.assert_allclose(ours[e], ref[e], rtol=0, atol=3e-5 * size, err_msg=f"env {e}")
    # the same controller with env 0's gains everywhere differs in every other env: the gains reach each env
    arm.task_stiffness.assign(np.tile(kp[0], (E, 1)))
    arm.task_damping.assign(np.tile(kd[0], (E, 1)))
    arm.set_drive_properties(stiffness=nkp[0], damping=nkd[0])
    same = step_torques(ctrl, state, action)
    for e in range(1, E):
        assert np.abs(same[e] - ours[e]).max() > 1e-3 * np.abs(ours[e]).max(), e


@pytest.mark.parametrize("inertia", [False, True])
def test_joint_impedance_per_env_gains_and_gravity_equal_newtons_controller(inertia):
    """Joint impedance with per-env stiffness and damping (``set_drive_properties``), per-env states and targets and
    per-world gravity equals Newton's ControllerJointImpedance with the same per-DOF gains (Coriolis off), env by
    env."""
    from newton.controllers import ControllerJointImpedance

    rb = _robot_with_world_gravity()
    rng = np.random.default_rng(21)
    cfg = wpctrl.JointImpedanceControllerConfig(
        list(ARM), -0.3, 0.3, 10.0, use_delta=True, inertial_compensation=inertia
    )
    ctrl = wpctrl.build_controller({"arm": cfg, "balance_passive_force": False}, rb.model, actuation="explicit")
    kp = rng.uniform(20.0, 300.0, (E, 7)).astype(np.float32)
    kd = rng.uniform(2.0, 30.0, (E, 7)).astype(np.float32)
    ctrl["arm"].set_drive_properties(stiffness=kp, damping=kd)
    state = rb.random_state(ctrl, rng)
    ours = step_torques(ctrl, state, rng.uniform(-1, 1, (E, 7)).astype(np.float32))
    ji = ControllerJointImpedance(
        rb.model,
        joints=list(ARM),
        stiffness=wp.array(kp.reshape(-1), dtype=float),
        damping=wp.array(kd.reshape(-1), dtype=float),
        use_gravity_compensation=True,
        use_coriolis_compensation=False,
        use_inertia_decoupling=inertia,
    )
    i, o = ji.input(), ji.output()
    i.joint_q.assign(state.joint_q)
    i.joint_qd.assign(state.joint_qd)
    i.joint_q_des.assign(ctrl["arm"].target_qpos.numpy().reshape(-1))
    i.joint_qd_des.zero_()
    ji.step(inputs=i, outputs=o, dt=0.01)
    ref = o.joint_f.numpy().reshape(E, 7).astype(np.float64)
    for e in range(E):
        size = np.abs(ref[e]).max()
        assert size > 1.0, e
        np.testing.assert_allclose(ours[e], ref[e], rtol=0, atol=2e-5 * size, err_msg=f"env {e}")


# -- two joint-impedance controllers of one mode ----------------------------------------------------------------------

SHOULDER, WRIST = list(ARM[:3]), list(ARM[3:])


def test_second_joint_impedance_controller_clips_to_its_own_joints_limits():
    """A mode of two joint-impedance controllers on different joints (the shoulder: absolute raw targets, gravity;
    the wrist, second: raw increments on its last target, inertial compensation and gravity) and the gripper, with
    ``clip_targets="joint_limits"``, per-env gains and per-world gravity: over two actions, each env's targets are
    its own action (on its own last target) clipped to each joint's own limits (Newton's ``joint_limit_lower`` /
    ``upper``), and each env's torques are ``[M] (Kp (q* − q) − Kd q̇) + g`` from Newton's mass matrix (the
    controller's block) and per-world gravity torque."""
    rb = _robot_with_world_gravity()
    model = rb.model
    rng = np.random.default_rng(22)
    mode = {
        "shoulder": wpctrl.JointImpedanceControllerConfig(SHOULDER, None, None, 10.0, normalize_action=False),
        "wrist": wpctrl.JointImpedanceControllerConfig(
            WRIST, -2.5, 2.5, 10.0, use_delta=True, use_target=True, normalize_action=False, inertial_compensation=True
        ),
        "gripper": gripper(),
        "balance_passive_force": False,
    }
    ctrl = wpctrl.build_controller(
        mode, model, actuation="explicit", explicit_pd="stable", clip_targets="joint_limits"
    )  # the gripper: a stable PD
    assert ctrl.action_dim == 3 + 4 + 1
    gains = {}
    for name, n, (lo, hi) in (("shoulder", 3, (50.0, 400.0)), ("wrist", 4, (20.0, 200.0))):
        kp = rng.uniform(lo, hi, (E, n)).astype(np.float32)
        kd = rng.uniform(0.05, 0.2, (E, n)).astype(np.float32) * kp
        ctrl[name].set_drive_properties(stiffness=kp, damping=kd)
        gains[name] = kp.astype(np.float64), kd.astype(np.float64)
    coord, dof = ctrl.coord_index[:, :7], ctrl.dof_index[:, :7]
    qlo = model.joint_limit_lower.numpy()[dof].astype(np.float64)  # (E, 7): each joint's own limits
    qhi = model.joint_limit_upper.numpy()[dof].astype(np.float64)
    state = rb.random_state(ctrl, rng)
    ctrl.reset(state)
    prev = state.joint_q.numpy()[coord].astype(np.float64)  # a reset's targets: the measured positions
    assert model.articulation_count == E
    control = model.control()
    clipped = np.zeros((E, 7), bool)
    for _ in range(2):
        state = rb.random_state(ctrl, rng, spread=0.5, speed=1.0)
        action = np.zeros((E, 8), np.float32)
        action[:, :3] = rng.uniform(-3.5, 3.5, (E, 3))
        action[:, 3:7] = rng.uniform(-2.5, 2.5, (E, 4))
        action[:, 7] = rng.uniform(-1, 1, E)
        ctrl.set_action(action, state)
        ctrl.before_simulation_step(state, control)
        want = np.concatenate([action[:, :3], prev[:, 3:] + action[:, 3:7]], axis=1)
        target = np.clip(want, qlo, qhi)
        clipped |= target != want
        q = state.joint_q.numpy()[coord].astype(np.float64)
        qd = state.joint_qd.numpy()[dof].astype(np.float64)
        g, H = _newton_gravity_and_mass(model, state)
        ours = np.concatenate([ctrl["shoulder"].target_qpos.numpy(), ctrl["wrist"].target_qpos.numpy()], axis=1)
        torque = control.joint_f.numpy()[dof].astype(np.float64)
        for e in range(E):
            np.testing.assert_allclose(ours[e], target[e], rtol=0, atol=2e-6, err_msg=f"targets, env {e}")
            local = dof[e] - dof[e, 0]  # env e is articulation e; its DOFs within it
            M = H[e][np.ix_(local, local)]
            (skp, skd), (wkp, wkd) = gains["shoulder"], gains["wrist"]
            a_s = skp[e] * (target[e, :3] - q[e, :3]) - skd[e] * qd[e, :3]
            a_w = wkp[e] * (target[e, 3:] - q[e, 3:]) - wkd[e] * qd[e, 3:]
            tau = np.concatenate([a_s, M[3:, 3:] @ a_w]) + g[dof[e]]
            np.testing.assert_allclose(torque[e], tau, rtol=0, atol=1e-4 * np.abs(tau).max(), err_msg=f"env {e}")
        prev = target
    # both controllers' targets were clipped somewhere, and some were left alone
    assert clipped[:, :3].any() and clipped[:, 3:].any() and not clipped.all()


# -- OSC: the action's target pose in every frame and option -----------------------------------------------------------

FRAMES = [
    "root_translation:root_aligned_body_rotation",
    "body_translation:root_aligned_body_rotation",
    "root_translation:body_aligned_body_rotation",
    "body_translation:body_aligned_body_rotation",
]
POS_LO, POS_HI = np.array([-0.05, -0.1, -0.02]), np.array([0.1, 0.05, 0.08])
ROT_LO, ROT_HI = np.array([-0.2, -0.5, -0.1]), np.array([0.4, 0.3, 0.5])


def _tcp_in_world(rb: Robot, state) -> tuple[np.ndarray, Rotation]:
    """Each env's TCP (the site on the hand) by Newton's forward kinematics: positions (E, 3), rotations (E,)."""
    m = rb.model
    newton.eval_fk(m, state.joint_q, state.joint_qd, state)
    site = [i for i, lbl in enumerate(m.shape_label) if lbl.rsplit("/", 1)[-1] == rb.site]
    assert len(site) == E
    bq = state.body_q.numpy()[m.shape_body.numpy()[site]].astype(np.float64)
    st = m.shape_transform.numpy()[site].astype(np.float64)
    rb_, rs = Rotation.from_quat(bq[:, 3:]), Rotation.from_quat(st[:, 3:])
    return bq[:, :3] + rb_.apply(st[:, :3]), rb_ * rs


def _processed(a: np.ndarray, normalize: bool) -> tuple[np.ndarray, np.ndarray]:
    """The processed position and rotation (Euler XYZ) of one env's raw action (float64)."""
    a = a.astype(np.float64)
    if not normalize:
        return a[:3], a[3:]
    pos = 0.5 * (POS_HI + POS_LO) + 0.5 * (POS_HI - POS_LO) * np.clip(a[:3], -1.0, 1.0)
    rot = a[3:].copy()
    norm = np.linalg.norm(rot)
    if norm > 1.0:
        rot /= norm
    return pos, rot * 0.5 * (ROT_HI - ROT_LO)


def _target(p_prev, r_prev: Rotation, pos, rot, use_delta: bool, frame: str) -> tuple[np.ndarray, Rotation]:
    """ManiSkill's ``PDEEPoseController.compute_target_pose`` of one env (scipy)."""
    d = Rotation.from_euler("XYZ", rot)  # ManiSkill's euler_angles_to_matrix(rot, "XYZ")
    if not use_delta:
        return pos, d
    r = r_prev * d if "body_aligned_body_rotation" in frame else d * r_prev
    p = p_prev + (r_prev.apply(pos) if frame.startswith("body_translation") else pos)
    return p, r


def _pose_rows(pose7: np.ndarray) -> tuple[np.ndarray, Rotation]:
    """``[x, y, z, qw, qx, qy, qz]`` rows as positions and rotations."""
    p = pose7.astype(np.float64)
    return p[:, :3], Rotation.from_quat(np.concatenate([p[:, 4:], p[:, 3:4]], axis=1))


@pytest.mark.parametrize("frame", FRAMES)
def test_osc_target_pose_from_the_action_in_every_frame_and_option(frame):
    """Normalised or raw, delta or absolute, on the measured pose or on the last target: over a reset and two actions
    (the joints moved in between, each env its own state and action, rotations inside and beyond the unit norm), the
    processed action and the target pose of every env equal a scipy re-derivation of ManiSkill's PDEEPoseController
    (position scaled onto [pos_lower, pos_upper]; rotation clipped by its norm and scaled by the half range, the
    documented convention; Euler XYZ; ``frame``'s translation and rotation) on Newton's forward kinematics of the
    TCP (the measured pose ``ee_pose`` checked too)."""
    rb = Robot("panda", E)
    rng = np.random.default_rng(23 + FRAMES.index(frame))
    spread = np.array([0.4, 0.9, 1.3, 2.0])[:, None]  # env 0's rotation inside the unit ball, env 3's beyond it
    for normalize, use_delta, use_target in itertools.product([True, False], [True, False], [False, True]):
        opts = (frame, normalize, use_delta, use_target)
        cfg = wpctrl.OperationalSpaceControllerConfig(
            list(ARM), POS_LO, POS_HI, ROT_LO, ROT_HI, ee_link=rb.ee_link, frame=frame, use_delta=use_delta,
            use_target=use_target, normalize_action=normalize,
        )  # fmt: skip
        ctrl = wpctrl.build_controller({"arm": cfg}, rb.model)
        arm = ctrl["arm"]
        state = rb.random_state(ctrl, rng)
        ctrl.reset(state)
        prev = _tcp_in_world(rb, state)  # the reset's target: the measured pose
        for step in range(2):
            state = rb.random_state(ctrl, rng, spread=0.4)
            if normalize:
                action = rng.uniform(-1.0, 1.0, (E, 6)) * spread
            elif use_delta:
                action = rng.uniform(-1.0, 1.0, (E, 6)) * np.array([0.15, 0.15, 0.15, 0.6, 0.6, 0.6])
            else:
                action = np.concatenate([rng.uniform(-0.6, 0.6, (E, 3)), rng.uniform(-np.pi, np.pi, (E, 3))], axis=1)
            action = action.astype(np.float32)
            ctrl.set_action(action, state)
            measured = _tcp_in_world(rb, state)
            ee_p, ee_r = _pose_rows(arm.ee_pose.numpy())
            tp, tr = _pose_rows(arm.target_pose.numpy())
            processed = arm.processed_action.numpy()
            base = prev if use_target else measured
            want_p, want_r = np.zeros((E, 3)), []
            for e in range(E):
                where = (*opts, step, e)
                np.testing.assert_allclose(ee_p[e], measured[0][e], atol=2e-6, err_msg=str(where))
                assert (ee_r[e] * measured[1][e].inv()).magnitude() < 2e-6, where
                pos, rot = _processed(action[e], normalize)
                np.testing.assert_allclose(processed[e], np.concatenate([pos, rot]), rtol=1e-6, atol=1e-7,
                                           err_msg=str(where))  # fmt: skip
                p, r = _target(base[0][e], base[1][e], pos, rot, use_delta, frame)
                np.testing.assert_allclose(tp[e], p, atol=3e-6, err_msg=str(where))
                assert (tr[e] * r.inv()).magnitude() < 5e-6, (where, tr[e].as_quat(), r.as_quat())
                want_p[e] = p
                want_r.append(r)
            prev = want_p, Rotation.concatenate(want_r)


def step_torques_of(ctrl, state, action) -> np.ndarray:
    """The mode's first seven rows' commanded torque after set_action and one substep: (num_envs, 7)."""
    control = ctrl.model.control()
    ctrl.set_action(action, state)
    ctrl.before_simulation_step(state, control)
    return control.joint_f.numpy()[ctrl.dof_index[:, :7]].astype(np.float64)


def test_second_joint_impedance_controller_takes_its_own_variable_gains():
    """The second of two joint-impedance controllers with ``impedance_mode="variable"``: its stiffness and
    damping-ratio columns (after its targets, behind the first controller's) set its own joints' per-env gains
    (``Kp`` onto ``stiffness_limits``, ``Kd = 2 ζ √Kp``), the first controller keeps its per-env gains, and each
    env's torques are ``Kp (q* − q) − Kd q̇`` with those gains (numpy)."""
    rb = Robot("panda", E)
    rng = np.random.default_rng(24)
    mode = {
        "shoulder": wpctrl.JointImpedanceControllerConfig(SHOULDER, -0.5, 0.5, 10.0, gravity_compensation=False),
        "wrist": wpctrl.JointImpedanceControllerConfig(
            WRIST,
            -0.2,
            0.2,
            10.0,
            use_delta=True,
            impedance_mode="variable",
            stiffness_limits=(10.0, 310.0),
            damping_ratio_limits=(0.5, 1.5),
            gravity_compensation=False,
        ),
        "balance_passive_force": False,
    }
    ctrl = wpctrl.build_controller(mode, rb.model, actuation="explicit")
    assert ctrl.action_dim == 3 + 4 * 3
    skp = rng.uniform(50.0, 400.0, (E, 3)).astype(np.float32)
    skd = rng.uniform(2.0, 20.0, (E, 3)).astype(np.float32)
    ctrl["shoulder"].set_drive_properties(stiffness=skp, damping=skd)
    state = rb.random_state(ctrl, rng)
    action = rng.uniform(-1.2, 1.2, (E, 15)).astype(np.float32)
    torque = step_torques_of(ctrl, state, action)
    a = np.clip(action.astype(np.float64), -1.0, 1.0)
    wkp = 160.0 + 150.0 * a[:, 7:11]
    wkd = 2.0 * (1.0 + 0.5 * a[:, 11:15]) * np.sqrt(wkp)
    q = state.joint_q.numpy()[ctrl.coord_index[:, :7]].astype(np.float64)
    qd = state.joint_qd.numpy()[ctrl.dof_index[:, :7]].astype(np.float64)
    target = np.concatenate([0.5 * a[:, :3], q[:, 3:] + 0.2 * a[:, 3:7]], axis=1)
    kp, kd = np.concatenate([skp, wkp], axis=1), np.concatenate([skd, wkd], axis=1)
    for e in range(E):
        np.testing.assert_array_equal(ctrl["shoulder"].stiffness.numpy()[e], skp[e], err_msg=f"env {e}")
        np.testing.assert_array_equal(ctrl["shoulder"].damping.numpy()[e], skd[e], err_msg=f"env {e}")
        np.testing.assert_allclose(ctrl["wrist"].stiffness.numpy()[e], wkp[e], rtol=1e-6, err_msg=f"env {e}")
        np.testing.assert_allclose(ctrl["wrist"].damping.numpy()[e], wkd[e], rtol=1e-5, err_msg=f"env {e}")
        tau = kp[e] * (target[e] - q[e]) - kd[e] * qd[e]
        np.testing.assert_allclose(torque[e], tau, rtol=0, atol=1e-5 * np.abs(tau).max(), err_msg=f"env {e}")
