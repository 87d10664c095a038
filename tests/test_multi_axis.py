"""Robots beyond fixed-base 1-DOF chains: MJCF multi-hinge bodies (one Newton D6 joint per body, each hinge bound by
its MJCF name) and floating bases (the free joint's coordinates, DOFs, gains and targets never touched)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import newton
import newton.examples
import numpy as np
import pytest
import warp as wp

import wpctrl
from wpctrl.binding import bind_joints

f32 = np.float32
HUMANOID = newton.examples.get_asset("nv_humanoid.xml")
HINGES = [j.get("name") for j in ET.parse(HUMANOID).getroot().iter("joint") if j.get("name") not in (None, "root")]


def humanoid(num_envs: int) -> newton.Model:
    robot = newton.ModelBuilder()
    robot.add_mjcf(HUMANOID)
    builder = newton.ModelBuilder()
    builder.replicate(robot, num_envs)
    return builder.finalize(device="cpu")


def _hinge_index(model: newton.Model) -> tuple[np.ndarray, np.ndarray]:
    """Coordinate and DOF index of every MJCF hinge in world 0, found independently of wpctrl: the D6 joints' axes
    in order, matched to the hinges by their joint axis direction and the body they move."""
    labels = list(model.joint_label)
    q_start, qd_start = model.joint_q_start.numpy(), model.joint_qd_start.numpy()
    coords, dofs = [], []
    for name in HINGES:
        for j, label in enumerate(labels[: len(labels) // model.world_count]):
            short = label.rsplit("/", 1)[-1]
            # merged labels join the hinge names: find the hinge as a run of whole name parts
            n = int(qd_start[j + 1] - qd_start[j])
            joined = [short] if n == 1 else None
            if joined is None:
                # split by the XML's own hinge names (the file's order)
                names = [h for h in HINGES if h in short]
                names.sort(key=short.index)
                joined = names if "_".join(names) == short else []
            if name in joined:
                k = joined.index(name)
                coords.append(q_start[j] + k)
                dofs.append(qd_start[j] + k)
                break
        else:
            raise AssertionError(f"{name} not found")
    return np.array(coords), np.array(dofs)


def test_all_21_hinges_bind_by_mjcf_name():
    model = humanoid(2)
    assert len(HINGES) == 21
    d6 = (model.joint_type.numpy() == int(newton.JointType.D6)).sum()
    assert d6 == 2 * 7  # abdomen, 2 hips, 2 ankles, 2 shoulders per world: merged hinges
    binding = bind_joints(model, HINGES)
    coords, dofs = _hinge_index(model)
    np.testing.assert_array_equal(binding.coord_index[0], coords)
    np.testing.assert_array_equal(binding.dof_index[0], dofs)
    per_world_q = model.joint_coord_count // 2
    np.testing.assert_array_equal(binding.coord_index[1], coords + per_world_q)
    # each hinge's limits are its own axis's
    lo = model.joint_limit_lower.numpy()[dofs]
    np.testing.assert_array_equal(binding.qlimits[:, 0], lo)


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
def test_humanoid_delta_targets_are_each_axis_coordinate_plus_action(actuation):
    model = humanoid(2)
    rng = np.random.default_rng(3)
    q = model.joint_q.numpy()
    coords, dofs = _hinge_index(model)
    per_world_q = model.joint_coord_count // 2
    per_world_qd = model.joint_dof_count // 2
    for w in range(2):
        q[coords + w * per_world_q] = rng.uniform(-0.3, 0.3, 21)
    model.joint_q.assign(q)
    state = model.state()
    kp = rng.uniform(50, 200, 21).astype(f32)
    cfg = wpctrl.PDJointPosControllerConfig(HINGES, -0.2, 0.2, kp, 5.0, 100.0, use_delta=True)
    ctrl = wpctrl.build_controller(cfg, model, actuation=actuation, balance_passive_force=False)
    control = model.control()
    jt0, f0, ke0 = control.joint_target_q.numpy().copy(), control.joint_f.numpy().copy(), model.joint_target_ke.numpy()
    ctrl.reset(state, control=control)
    a = rng.uniform(-1.2, 1.2, (2, 21)).astype(f32)
    ctrl.set_action(a, state)
    ctrl.before_simulation_step(state, control)
    qm = np.stack([q[coords + w * per_world_q] for w in range(2)])
    expected = qm + (f32(0.5) * (f32(0.2) - f32(-0.2))) * np.clip(a, -1, 1)
    np.testing.assert_allclose(ctrl.target_qpos.numpy(), expected, atol=1e-7)
    jt = control.joint_target_q.numpy()
    ke = model.joint_target_ke.numpy()
    f = control.joint_f.numpy()
    for w in range(2):
        np.testing.assert_allclose(jt[coords + w * per_world_q], expected[w], atol=1e-7)
        if actuation == "implicit":
            np.testing.assert_array_equal(ke[dofs + w * per_world_qd], kp)
        else:
            np.testing.assert_allclose(f[dofs + w * per_world_qd], np.clip(kp * (expected[w] - qm[w]), -100, 100), 1e-5)
    # the free root (7 coordinates, 6 DOFs at the start of each world) is untouched
    for w in range(2):
        root_q, root_qd = slice(w * per_world_q, w * per_world_q + 7), slice(w * per_world_qd, w * per_world_qd + 6)
        np.testing.assert_array_equal(jt[root_q], jt0[root_q])
        np.testing.assert_array_equal(f[root_qd], f0[root_qd])
        np.testing.assert_array_equal(ke[root_qd], ke0[root_qd])


def test_ball_and_free_joints_are_refused_with_their_type():
    model = humanoid(1)
    with pytest.raises(wpctrl.ConfigError, match=r"'humanoid/worldbody/torso/root' is a FREE joint"):
        wpctrl.build_controller(wpctrl.PDJointPosControllerConfig(["root"], -1, 1, 1, 1), model)
    with pytest.raises(wpctrl.ConfigError, match=r"is a D6 joint.*name one of its axes"):
        wpctrl.build_controller(wpctrl.PDJointPosControllerConfig(["abdomen_z_abdomen_y"], -1, 1, 1, 1), model)
    with pytest.raises(wpctrl.ConfigError, match=r"'abdomen_q' is not in world 0"):
        wpctrl.build_controller(wpctrl.PDJointPosControllerConfig(["abdomen_q"], -1, 1, 1, 1), model)


QUADRUPED = newton.examples.get_asset("quadruped.urdf")
LEGS = [f"{leg}_{j}" for leg in ("LF", "RF", "LH", "RH") for j in ("HAA", "HFE", "KFE")]


def quadruped(num_envs: int) -> newton.Model:
    robot = newton.ModelBuilder()
    robot.add_urdf(QUADRUPED, floating=True)
    builder = newton.ModelBuilder()
    builder.replicate(robot, num_envs)
    return builder.finalize(device="cpu")


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
def test_floating_base_joint_controllers_leave_the_free_joint_alone(actuation):
    """12 leg joints of a floating quadruped: targets, gains and torques land on the legs only, through partial
    resets and graph replay; the free joint's 7 coordinates and 6 DOFs keep what they held."""
    E = 3
    model = quadruped(E)
    nq, nqd = model.joint_coord_count // E, model.joint_dof_count // E
    root_q = np.concatenate([np.arange(w * nq, w * nq + 7) for w in range(E)])
    root_qd = np.concatenate([np.arange(w * nqd, w * nqd + 6) for w in range(E)])
    legs_q = np.concatenate([np.arange(w * nq + 7, (w + 1) * nq) for w in range(E)])
    rng = np.random.default_rng(5)
    q = model.joint_q.numpy()
    q[legs_q] = rng.uniform(-0.4, 0.4, legs_q.size)
    model.joint_q.assign(q)
    state = model.state()
    control = model.control()
    jt0, jtd0, f0 = (a.numpy().copy() for a in (control.joint_target_q, control.joint_target_qd, control.joint_f))
    ke0, kd0, mode0 = (
        a.numpy().copy() for a in (model.joint_target_ke, model.joint_target_kd, model.joint_target_mode)
    )
    cfg = wpctrl.PDJointPosControllerConfig(LEGS, -0.1, 0.1, 80.0, 2.0, 40.0, use_delta=True, use_target=True)
    ctrl = wpctrl.build_controller(cfg, model, actuation=actuation, balance_passive_force=False)
    ctrl.reset(state, control=control)
    a = wp.array(rng.uniform(-1, 1, (E, 12)).astype(f32), device="cpu")
    ctrl.set_action(a, state)  # eager: every env's virtual target moves one step
    with wp.ScopedCapture(device="cpu") as cap:  # (recorded, not run)
        ctrl.set_action(a, state)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(state, control)
    ctrl.reset(state, np.array([False, True, False]), control=control)  # env 1 back to its measured pose
    wp.capture_launch(cap.graph)
    wp.capture_launch(cap.graph)  # two replays: the virtual target moves twice more in envs 0 and 2
    qm = q[legs_q].reshape(E, 12)
    step = (f32(0.5) * (f32(0.1) - f32(-0.1))) * a.numpy()
    expected = qm + 2 * step  # env 1: reset to its measured pose, then two replays
    expected[[0, 2]] += step[[0, 2]]  # envs 0 and 2: the eager step and two replays
    np.testing.assert_allclose(ctrl.target_qpos.numpy(), expected, atol=1e-6)
    np.testing.assert_allclose(control.joint_target_q.numpy()[legs_q].reshape(E, 12), expected, atol=1e-6)
    np.testing.assert_array_equal(control.joint_target_q.numpy()[root_q], jt0[root_q])
    np.testing.assert_array_equal(control.joint_target_qd.numpy()[root_qd], jtd0[root_qd])
    np.testing.assert_array_equal(control.joint_f.numpy()[root_qd], f0[root_qd])
    for arr, before in ((model.joint_target_ke, ke0), (model.joint_target_kd, kd0), (model.joint_target_mode, mode0)):
        np.testing.assert_array_equal(arr.numpy()[root_qd], before[root_qd])
    if actuation == "explicit":
        legs_qd = np.setdiff1d(np.arange(model.joint_dof_count), root_qd)
        np.testing.assert_allclose(
            control.joint_f.numpy()[legs_qd].reshape(E, 12), np.clip(80.0 * (expected - qm), -40, 40), rtol=1e-5
        )


def test_floating_base_stable_pd_includes_the_free_root_and_coupled_names_the_alternative():
    """Stable explicit PD takes r = (H^-1)_ii from the whole articulation, the free root's 6 DOFs included: compare
    with the diagonal of the inverse of Newton's mass matrix (``newton.eval_mass_matrix``, inverted in numpy)."""
    model = quadruped(1)
    cfg = wpctrl.PDJointPosControllerConfig(LEGS, -0.1, 0.1, 80.0, 2.0, use_delta=True)
    ctrl = wpctrl.build_controller(cfg, model, actuation="explicit", explicit_pd="stable", balance_passive_force=False)
    state = model.state()
    q = state.joint_q.numpy()
    q[7:] = np.random.default_rng(6).uniform(-0.5, 0.5, 12)
    state.joint_q.assign(q)
    ctrl.reset(state)
    ctrl.set_action(np.zeros((12,), f32), state)
    H = _mass_matrix(model, state)
    r_ref = np.diag(np.linalg.inv(H))[6:]  # the legs' DOFs follow the root's 6
    np.testing.assert_allclose(ctrl.response.numpy()[0], r_ref, rtol=1e-4)
    # a fixed-base inverse (root DOFs dropped) differs: the free root matters
    assert not np.allclose(np.diag(np.linalg.inv(H[6:, 6:])), r_ref, rtol=1e-3)
    with pytest.raises(wpctrl.ConfigError, match=r"'coupled'.*use explicit_pd='stable'"):
        wpctrl.build_controller(cfg, model, actuation="explicit", explicit_pd="coupled", balance_passive_force=False)


def _mass_matrix(model, state) -> np.ndarray:
    """Newton's joint-space mass matrix of world 0's articulation (float64 numpy)."""
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    return newton.eval_mass_matrix(model, state).numpy()[0].astype(np.float64)
