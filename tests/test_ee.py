"""End-effector controllers against closed forms and real Newton: FK vs ``newton.eval_fk``, the Jacobian vs finite
differences of FK, converged IK on random reachable poses, per-env independence (64 envs), partial reset, CPU graph
capture (bitwise), the option switches, the Panda EE modes, a closed loop with MuJoCo-Warp, and config errors."""

from __future__ import annotations

import copy

import newton
import numpy as np
import pytest
import warp as wp
from conftest import PANDA_URDF, build_panda
from harness import ARM, gripper

import wpctrl
from wpctrl.robots import PANDA_INITIAL_Q, panda_control_modes

LIMITS = np.array(
    [[-2.8973, 2.8973], [-1.7628, 1.7628], [-2.8973, 2.8973], [-3.0718, -0.0698], [-2.8973, 2.8973],
     [-0.0175, 3.7525], [-2.8973, 2.8973]],
)  # fmt: skip
REST = np.asarray(PANDA_INITIAL_Q[:7], np.float64)


def pose_cfg(**kw):
    base = dict(pos_lower=-0.1, pos_upper=0.1, rot_lower=-0.1, rot_upper=0.1, stiffness=1e3, damping=1e2)
    base.update(force_limit=100, ee_link="panda_hand_tcp")
    base.update(kw)
    return wpctrl.PDEEPoseControllerConfig(list(ARM), **base)


def random_q(rng, n, spread=0.4):
    q = REST + rng.uniform(-spread, spread, (n, 7))
    return np.clip(q, LIMITS[:, 0] + 0.05, LIMITS[:, 1] - 0.05).astype(np.float32)


class Rig:
    def __init__(self, mode, num_envs, model=None):
        self.model = model if model is not None else build_panda(num_envs)
        self.ctrl = wpctrl.build_controller(mode, self.model)
        self.arm = self.ctrl["arm"] if isinstance(mode, dict) else self.ctrl
        self.state = self.model.state()
        self.control = self.model.control()
        self.coord = self.ctrl.coord_index
        self.arm_coord = self.coord[:, self.arm._rows]

    def put(self, arm_q, state=None):
        state = state or self.state
        q = state.joint_q.numpy()
        q[self.arm_coord] = arm_q
        state.joint_q.assign(q)

    def fk(self, arm_q):
        s = self.model.state()
        self.put(arm_q, s)
        pose, jac = self.arm.fk_jacobian(s)
        return pose.numpy(), jac.numpy()


def quat_xyzw(wxyz):
    return np.concatenate([wxyz[..., 1:], wxyz[..., :1]], axis=-1)


def qmat(wxyz):
    w, x, y, z = wxyz
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotvec(r):
    """Rotation vector of a rotation matrix (angles < pi)."""
    c = np.clip((np.trace(r) - 1) / 2, -1, 1)
    th = np.arccos(c)
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return v * (0.5 if th < 1e-8 else th / (2 * np.sin(th)))


def euler_xyz(r):
    return np.array([np.arctan2(-r[1, 2], r[2, 2]), np.arcsin(np.clip(r[0, 2], -1, 1)), np.arctan2(-r[0, 1], r[0, 0])])


def test_fk_matches_newton_eval_fk_and_the_urdf_offset():
    rng = np.random.default_rng(0)
    rig = Rig(pose_cfg(), 4)
    q = random_q(rng, 4)
    rig.put(q)
    newton.eval_fk(rig.model, rig.state.joint_q, rig.state.joint_qd, rig.state)
    pose, _ = rig.arm.fk_jacobian(rig.state)
    pose = pose.numpy()
    body_q = rig.state.body_q.numpy()
    labels = rig.model.body_label
    site = next(i for i, s in enumerate(rig.model.shape_label) if s.endswith("panda_hand_tcp"))
    st = rig.model.shape_transform.numpy()[site]
    for e in range(4):
        b = [i for i, lb in enumerate(labels) if lb.endswith("panda_link7")][e]
        x = wp.transform(wp.vec3(*body_q[b, :3]), wp.quat(*body_q[b, 3:])) * wp.transform(
            wp.vec3(*st[:3]), wp.quat(*st[3:])
        )
        np.testing.assert_allclose(pose[e, :3], np.array(x.p), atol=2e-6)
        ref = np.array([x.q[3], x.q[0], x.q[1], x.q[2]])
        assert min(np.abs(pose[e, 3:] - ref).max(), np.abs(pose[e, 3:] + ref).max()) < 2e-6
    # the same TCP through urdf_path on add_urdf's collapsed Panda
    robot = newton.ModelBuilder()
    robot.add_urdf(str(PANDA_URDF), collapse_fixed_joints=True, floating=False)
    b = newton.ModelBuilder()
    b.replicate(robot, 4)
    urdf = Rig(pose_cfg(urdf_path=str(PANDA_URDF)), 4, model=b.finalize(device="cpu"))
    np.testing.assert_allclose(urdf.fk(q)[0], pose, atol=2e-6)
    # Without a readable urdf_path (ManiSkill configs carry the packaged URDF's name), wpctrl's Panda facts
    # (robots.PANDA_FRAMES) give the merged TCP; root_link_name="panda_link0" is the base merged into the world.
    fallback = Rig(pose_cfg(urdf_path="panda_v2.urdf", root_link_name="panda_link0"), 4, model=urdf.model)
    np.testing.assert_allclose(fallback.fk(q)[0], pose, atol=2e-6)
    with pytest.raises(wpctrl.ConfigError, match="urdf_path: cannot read 'panda_v2.urdf'"):
        Rig(pose_cfg(ee_link="gripper_tcp", urdf_path="panda_v2.urdf"), 1, model=urdf.model)
    with pytest.raises(wpctrl.ConfigError, match="ee_link: 'gripper_tcp' is not a body or site"):
        Rig(pose_cfg(ee_link="gripper_tcp"), 1, model=urdf.model)


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(1)
    rig = Rig(pose_cfg(), 3)
    q = random_q(rng, 3)
    pose, jac = rig.fk(q)
    assert jac.shape == (3, 6, 7)
    h = 1e-2
    for c in range(7):
        dq = np.zeros_like(q)
        dq[:, c] = h
        p_plus, _ = rig.fk(q + dq)
        p_minus, _ = rig.fk(q - dq)
        for e in range(3):
            v = (p_plus[e, :3].astype(np.float64) - p_minus[e, :3]) / (2 * h)
            w = rotvec(qmat(p_plus[e, 3:]) @ qmat(p_minus[e, 3:]).T) / (2 * h)
            np.testing.assert_allclose(jac[e, :3, c], v, atol=5e-4, err_msg=f"v column {c}")
            np.testing.assert_allclose(jac[e, 3:, c], w, atol=5e-4, err_msg=f"w column {c}")


def test_converged_ik_reaches_random_reachable_poses():
    rng = np.random.default_rng(2)
    n = 16
    cfg = pose_cfg(
        pos_lower=None,
        pos_upper=None,
        rot_lower=None,
        rot_upper=None,
        use_delta=False,
        normalize_action=False,
        delta_solver_config=dict(type="levenberg_marquardt", alpha=1.0, solver_iterations=300, tolerance=1e-5),
    )
    rig = Rig(cfg, n)
    goal_q = random_q(rng, n, 0.5)
    goal, _ = rig.fk(goal_q)
    action = np.zeros((n, 6), np.float32)
    for e in range(n):
        action[e, :3] = goal[e, :3]
        action[e, 3:] = euler_xyz(qmat(goal[e, 3:].astype(np.float64)))
    start = np.clip(goal_q + rng.normal(0, 0.1, goal_q.shape), LIMITS[:, 0], LIMITS[:, 1]).astype(np.float32)
    rig.put(start)
    rig.ctrl.reset(rig.state)
    rig.ctrl.set_action(action, rig.state)
    assert rig.arm.ik_success.numpy().all()
    reached, _ = rig.fk(rig.arm.target_qpos.numpy())
    np.testing.assert_allclose(reached[:, :3], goal[:, :3], atol=3e-5)
    for e in range(n):
        r = qmat(reached[e, 3:].astype(np.float64)) @ qmat(goal[e, 3:].astype(np.float64)).T
        assert np.linalg.norm(rotvec(r)) < 3e-5
    # the stored target pose is the absolute action's pose
    tp = rig.arm.target_pose.numpy()
    np.testing.assert_allclose(tp[:, :3], goal[:, :3], atol=1e-6)


@pytest.mark.parametrize("iterations", [1, 40])
def test_per_env_independence_and_nan_hold(iterations):
    rng = np.random.default_rng(3)
    n = 64
    mode = {
        "arm": pose_cfg(
            use_target=True, delta_solver_config=dict(type="levenberg_marquardt", solver_iterations=iterations)
        ),
        "gripper": gripper(),
    }
    q = random_q(rng, n)
    acts = rng.uniform(-1.3, 1.3, (2, n, 7)).astype(np.float32)
    perm = rng.permutation(n)

    def run(q, acts, nan_env=None):
        rig = Rig(copy.deepcopy(mode), n)
        rig.put(q)
        rig.ctrl.reset(rig.state)
        outs = []
        for i, a in enumerate(acts):
            a = a.copy()
            if nan_env is not None and i == 1:
                a[nan_env, 4] = np.nan
            rig.ctrl.set_action(a, rig.state)
            outs.append(
                [rig.arm.target_qpos.numpy().copy(), rig.arm.target_pose.numpy().copy(), rig.ctrl.target_qpos.numpy()]
            )
        return outs, rig

    base, _ = run(q, acts)
    permuted, _ = run(q[perm], acts[:, perm])
    for a, b in zip(base, permuted):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x[perm], y)
    held, rig = run(q, acts, nan_env=5)
    others = np.arange(n) != 5
    for x, y in zip(held[1], base[1]):
        np.testing.assert_array_equal(x[others], y[others])
    for x, y in zip(held[1], held[0]):  # env 5 kept its targets (arm, target pose, gripper)
        np.testing.assert_array_equal(x[5], y[5])
    assert rig.ctrl.bad_action_count.numpy().tolist() == [int(e == 5) for e in range(n)]


@pytest.mark.parametrize("mode_name", ["pd_ee_delta_pos", "pd_ee_target_delta_pose"])
def test_a_nan_in_any_column_holds_the_whole_env(mode_name):
    """The hold rule is per env over the whole flat action: a NaN/Inf in the gripper's column holds the EE rows (and
    the EE's processed action and target pose) as well, and one in an EE column holds the gripper; the other envs
    move; each held env is counted once."""
    rng = np.random.default_rng(9)
    n = 4
    rig = Rig(copy.deepcopy(panda_control_modes()[mode_name]), n)
    rig.put(random_q(rng, n))
    rig.ctrl.reset(rig.state)
    D = rig.ctrl.action_dim
    rig.ctrl.set_action(rng.uniform(-1, 1, (n, D)).astype(np.float32), rig.state)
    names = ("target_qpos", "processed_action", "target_pose")
    before = {k: getattr(rig.arm, k).numpy().copy() for k in names}
    gripper_before = rig.ctrl["gripper"].target_qpos.numpy().copy()
    a = rng.uniform(-1, 1, (n, D)).astype(np.float32)
    a[1, D - 1] = np.nan  # the gripper's column
    a[2, 0] = np.inf  # the EE's first column
    rig.ctrl.set_action(a, rig.state)
    held = [1, 2]
    for k in names:
        got = getattr(rig.arm, k).numpy()
        np.testing.assert_array_equal(got[held], before[k][held], err_msg=k)
        if k != "target_pose" or rig.arm.config.use_target:  # (without use_target no target pose is composed)
            assert (got[[0, 3]] != before[k][[0, 3]]).any(axis=1).all(), k  # the others took their new actions
    np.testing.assert_array_equal(rig.ctrl["gripper"].target_qpos.numpy()[held], gripper_before[held])
    assert rig.ctrl.bad_action_count.numpy().tolist() == [0, 1, 1, 0]


def test_partial_reset():
    rng = np.random.default_rng(4)
    n = 4
    rig = Rig({"arm": pose_cfg(use_target=True), "gripper": gripper()}, n)
    rig.put(random_q(rng, n))
    rig.ctrl.reset(rig.state)
    for _ in range(2):
        rig.ctrl.set_action(rng.uniform(-1, 1, (n, 7)).astype(np.float32), rig.state)
    before = {k: getattr(rig.arm, k).numpy().copy() for k in ("target_pose", "ee_pose", "target_qpos", "start_qpos")}
    q_new = random_q(rng, n)
    rig.put(q_new)
    rig.ctrl.reset(rig.state, env_ids=[1, 3])
    fk, _ = rig.fk(q_new)
    for k in before:
        got = getattr(rig.arm, k).numpy()
        np.testing.assert_array_equal(got[[0, 2]], before[k][[0, 2]], err_msg=k)
    np.testing.assert_allclose(rig.arm.target_pose.numpy()[[1, 3]], fk[[1, 3]], atol=1e-7)
    np.testing.assert_allclose(rig.arm.ee_pose.numpy()[[1, 3]], fk[[1, 3]], atol=1e-7)
    np.testing.assert_array_equal(rig.arm.target_qpos.numpy()[[1, 3]], q_new[[1, 3]])
    np.testing.assert_array_equal(rig.arm.start_qpos.numpy()[[1, 3]], q_new[[1, 3]])
    # without use_target the target pose is left as it was (ManiSkill)
    rig2 = Rig({"arm": pose_cfg(), "gripper": gripper()}, n)
    rig2.ctrl.set_action(np.full((n, 7), 0.5, np.float32), rig2.state)
    stale = rig2.arm.target_pose.numpy().copy()
    rig2.put(q_new)
    rig2.ctrl.reset(rig2.state, env_ids=[0])
    np.testing.assert_array_equal(rig2.arm.target_pose.numpy(), stale)


def test_cpu_graph_capture_is_bitwise():
    rng = np.random.default_rng(5)
    n = 8
    mode = {
        "arm": pose_cfg(
            use_target=True,
            interpolate=True,
            delta_solver_config=dict(type="levenberg_marquardt", solver_iterations=20),
        ),
        "gripper": gripper(),
    }
    q = random_q(rng, n)
    acts = rng.uniform(-1.2, 1.2, (4, n, 7)).astype(np.float32)
    acts[2, 3, 0] = np.nan
    out = []
    for captured in (False, True):
        rig = Rig(copy.deepcopy(mode), n)
        rig.put(q)
        rig.ctrl.reset(rig.state)
        act = wp.zeros((n, 7), dtype=wp.float32)
        mask = wp.array(np.arange(n) % 3 == 0, dtype=wp.bool)

        def control_step(rig=rig, act=act):
            rig.ctrl.set_action(act, rig.state)
            for _ in range(rig.ctrl.num_substeps):
                rig.ctrl.before_simulation_step(rig.state, rig.control)

        graph = None
        if captured:
            with wp.ScopedCapture(device="cpu") as cap:
                control_step()
            graph = cap.graph
        res = []
        for i in range(4):
            act.assign(acts[i])
            if graph is not None:
                wp.capture_launch(graph)
            else:
                control_step()
            if i == 1:
                rig.ctrl.reset(rig.state, env_ids=mask)
            res.append(
                (
                    rig.ctrl.target_qpos.numpy().copy(),
                    rig.arm.target_pose.numpy().copy(),
                    rig.control.joint_target_q.numpy().copy(),
                )
            )
        out.append(res)
    for a, b in zip(*out):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


def test_rotation_sign_and_pos_controller():
    rig = Rig(pose_cfg(), 1)
    rig.ctrl.set_action(np.array([[0, 0, 0, 0.3, 0, 0]], np.float32), rig.state)
    np.testing.assert_allclose(rig.ctrl.processed_action.numpy()[0, 3:], [-0.03, 0, 0], atol=1e-8)  # ManiSkill's sign
    rig = Rig(pose_cfg(delta_solver_config=dict(type="pseudo_inverse", rotation_sign="corrected")), 1)
    rig.ctrl.set_action(np.array([[0, 0, 0, 3.0, 4.0, 0]], np.float32), rig.state)
    np.testing.assert_allclose(rig.ctrl.processed_action.numpy()[0, 3:], [0.06, 0.08, 0], atol=1e-7)  # norm-clipped
    # pseudo-inverse, one step: J dq reproduces the processed action exactly (7 joints, full row rank)
    q = rig.state.joint_q.numpy()[rig.arm_coord]
    _, jac = rig.fk(q)
    dq = rig.ctrl.target_qpos.numpy() - q
    np.testing.assert_allclose(jac[0] @ dq[0], [0, 0, 0, 0.06, 0.08, 0], atol=2e-5)

    # Position-only, body frame, CLIK: the target keeps the orientation and moves along the EE's own axes.
    cfg = wpctrl.PDEEPosControllerConfig(
        list(ARM), -0.1, 0.1, 1e3, 1e2, ee_link="panda_hand_tcp", frame="body_translation",
        delta_solver_config=dict(solver_iterations=100),
    )  # fmt: skip
    rig = Rig(cfg, 1)
    assert rig.ctrl.action_dim == 3
    rig.ctrl.set_action(np.array([[0.0, 0.0, 0.5]], np.float32), rig.state)
    ee = rig.arm.ee_pose.numpy()[0]
    tp = rig.arm.target_pose.numpy()[0]
    np.testing.assert_allclose(tp[:3], ee[:3] + qmat(ee[3:]) @ [0, 0, 0.05], atol=1e-6)
    np.testing.assert_allclose(tp[3:], ee[3:], atol=1e-7)
    assert rig.arm.ik_success.numpy()[0] == 1
    reached, _ = rig.fk(rig.ctrl.target_qpos.numpy())
    np.testing.assert_allclose(reached[0, :3], tp[:3], atol=2e-4)


def test_root_link_name_frame():
    rng = np.random.default_rng(6)
    rig = Rig(pose_cfg(), 2)
    cfg = pose_cfg(root_link_name="panda_link2")
    cfg.joint_names = list(ARM[2:])  # the joints below the root link
    linked = Rig(cfg, 2, model=rig.model)
    q = random_q(rng, 2)
    world, _ = rig.fk(q)
    rig.put(q)
    newton.eval_fk(rig.model, rig.state.joint_q, rig.state.joint_qd, rig.state)
    local, jac = linked.arm.fk_jacobian(rig.state)
    local, jac = local.numpy(), jac.numpy()
    assert jac.shape == (2, 6, 5)
    b2 = [i for i, lb in enumerate(rig.model.body_label) if lb.endswith("panda_link2")]
    for e in range(2):
        x = rig.state.body_q.numpy()[b2[e]]
        r = qmat(np.array([x[6], x[3], x[4], x[5]]))
        np.testing.assert_allclose(r.T @ (world[e, :3] - x[:3]), local[e, :3], atol=2e-6)
        np.testing.assert_allclose(r.T @ qmat(world[e, 3:]), qmat(local[e, 3:]), atol=2e-6)


def test_panda_ee_modes():
    modes = panda_control_modes()
    ee = [m for m in modes if m.startswith("pd_ee")]
    assert ee == [
        "pd_ee_delta_pos",
        "pd_ee_delta_pose",
        "pd_ee_pose",
        "pd_ee_target_delta_pos",
        "pd_ee_target_delta_pose",
    ]
    common = dict(stiffness=1e3, damping=1e2, force_limit=100, ee_link="panda_hand_tcp")
    assert modes["pd_ee_delta_pos"]["arm"] == wpctrl.PDEEPosControllerConfig(list(ARM), -0.1, 0.1, **common)
    assert modes["pd_ee_delta_pose"]["arm"] == wpctrl.PDEEPoseControllerConfig(
        list(ARM), -0.1, 0.1, rot_lower=-0.1, rot_upper=0.1, **common
    )
    assert modes["pd_ee_pose"]["arm"] == wpctrl.PDEEPoseControllerConfig(
        list(ARM), None, None, use_delta=False, normalize_action=False, **common
    )
    assert modes["pd_ee_target_delta_pose"]["arm"].use_target and modes["pd_ee_target_delta_pos"]["arm"].use_target
    model = build_panda(1)
    dims = {m: wpctrl.build_controller(modes[m], model).action_dim for m in ee}
    assert dims == {"pd_ee_delta_pos": 4, "pd_ee_delta_pose": 7, "pd_ee_pose": 7, "pd_ee_target_delta_pos": 4,
                    "pd_ee_target_delta_pose": 7}  # fmt: skip
    ctrl = wpctrl.build_controller(modes["pd_ee_pose"], model)
    assert np.isinf(ctrl["arm"].single_action_space.low).all()
    assert ctrl["arm"]._original_single_action_space is None
    # ManiSkill's field order and defaults
    fields = list(wpctrl.PDEEPoseControllerConfig.__dataclass_fields__)
    assert fields == [
        "joint_names", "pos_lower", "pos_upper", "stiffness", "damping", "force_limit", "friction", "ee_link",
        "urdf_path", "frame", "root_link_name", "use_delta", "use_target", "interpolate", "normalize_action",
        "delta_solver_config", "drive_mode", "rot_lower", "rot_upper",
    ]  # fmt: skip
    d = wpctrl.PDEEPosControllerConfig(list(ARM), -0.1, 0.1, 1, 1)
    assert d.frame == "root_translation" and d.use_delta and not d.use_target and d.normalize_action
    assert d.delta_solver_config == {"type": "levenberg_marquardt", "alpha": 1.0}
    assert wpctrl.PDEEPoseControllerConfig(list(ARM), 0, 0).frame == "root_translation:root_aligned_body_rotation"


def test_closed_loop_tracking_with_mujoco():
    model = build_panda(2)
    model.set_gravity((0.0, 0.0, 0.0))
    mode = panda_control_modes()["pd_ee_target_delta_pos"]
    ctrl = wpctrl.build_controller(mode, model)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    s0, s1, control = model.state(), model.state(), model.control()
    newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    ctrl.reset(s0, control=control)
    start = ctrl["arm"].ee_pose.numpy().copy()
    action = np.array([[-0.5, 0.0, 0.0, 1.0], [0.0, -1.0, 0.5, 1.0]], np.float32)  # -0.05 m/step in x, or -y +z
    for _ in range(4):
        ctrl.set_action(action, s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, control)
            solver.step(s0, s1, control, None, 0.01)
            s0, s1 = s1, s0
    for _ in range(20):  # hold the accumulated target
        ctrl.set_action(np.array([[0, 0, 0, 1.0]] * 2, np.float32), s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, control)
            solver.step(s0, s1, control, None, 0.01)
            s0, s1 = s1, s0
    ctrl.set_action(np.array([[0, 0, 0, 1.0]] * 2, np.float32), s0)
    reached = ctrl["arm"].ee_pose.numpy()
    want = start[:, :3] + np.array([[-0.2, 0, 0], [0, -0.4, 0.2]])
    np.testing.assert_allclose(ctrl["arm"].target_pose.numpy()[:, :3], want, atol=1e-5)
    assert np.abs(reached[:, :3] - want).max() < 2e-3, reached[:, :3] - want


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(frame="root_translation"), r"PDEEPoseControllerConfig\.frame: expected one of"),
        (dict(delta_solver_config=dict(type="newton")), r"delta_solver_config\['type'\]: expected one of"),
        (dict(delta_solver_config=dict(solver_iterations=0)), r"solver_iterations'\]: expected an int in \[1, 10000\]"),
        (dict(delta_solver_config=dict(alpha=float("nan"))), r"\['alpha'\]: expected a finite number, got nan"),
        (dict(delta_solver_config=dict(step=1)), r"unknown keys \['step'\]"),
        (dict(pos_lower=0.2), r"pos_lower/pos_upper: lower must be <= upper, got lower=0.2 > upper=0.1 for axis 'x'"),
        (dict(rot_lower=None), r"rot_lower: expected a number or 3 numbers, got None"),
        (dict(pos_lower=[0, 1]), r"pos_lower: expected a scalar or 3 values \(x, y, z\), got shape \(2,\)"),
        (dict(ee_link="panda_hand_tc"), r"ee_link: 'panda_hand_tc' is not a body or site.*close matches"),
        (dict(ee_link=None), r"ee_link: expected the name of the controlled link, got None"),
        (dict(root_link_name="panda_link9"), r"root_link_name: expected one body named 'panda_link9'"),
        (dict(stiffness=-1.0), r"PDEEPoseControllerConfig\.stiffness: expected values >= 0"),
        (dict(drive_mode="torque"), r"PDEEPoseControllerConfig\.drive_mode: expected one of"),
        (dict(use_target=1), r"use_target: expected a bool, got 1"),
    ],
)
def test_config_errors(kw, match):
    model = build_panda(1)
    with pytest.raises(wpctrl.ConfigError, match=match):
        wpctrl.build_controller({"arm": pose_cfg(**kw), "gripper": gripper()}, model)


def test_chain_errors():
    model = build_panda(1)
    cfg = pose_cfg()
    cfg.joint_names = [*ARM[:6], "panda_finger_joint1"]
    with pytest.raises(wpctrl.ConfigError, match=r"'panda/panda_finger_joint1' is not on the kinematic chain"):
        wpctrl.build_controller(cfg, model)
    cfg = pose_cfg(ee_link="panda_hand_tcp", urdf_path="/nonexistent.urdf")
    cfg.ee_link = "gripper_tcp"  # neither in the model nor a known Panda frame
    with pytest.raises(wpctrl.ConfigError, match="urdf_path: cannot read"):
        wpctrl.build_controller(cfg, model)


def test_demo_runs_an_ee_mode(tmp_path):
    import json

    from wpctrl.demo import main

    out = tmp_path / "demo"
    rc = main(["--control-mode", "pd_ee_delta_pose", "--envs", "2", "--seconds", "1.5", "--out", str(out),
               "--no-progress"])  # fmt: skip
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert (out / "tracking.png").stat().st_size > 10_000
    assert s["units"]["ee"] == "m" and "TCP" in s["tracking"]
    # The TCP follows a ~0.1-0.3 m sweep with the PD lag of a few cm; a wrong sign or frame diverges by decimetres.
    assert 0 < s["tracking_rms"]["ee"] < 0.05 and s["all_finite"]


def test_bench_torch_baseline_is_the_same_step():
    """bench/step/ee_step.py's torch port of ManiSkill's GPU EE path computes the same step as wpctrl (so the benchmark
    compares equal work): drive targets of the gripper equal, the arm's task-space step within float32 noise."""
    import sys

    from conftest import ROOT

    torch = pytest.importorskip("torch")
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from bench.step.ee_step import TorchEEPose

    n = 8
    model = build_panda(n)
    ctrl = wpctrl.build_controller(panda_control_modes()["pd_ee_delta_pose"], model)
    state, control, control_t = model.state(), model.control(), model.control()
    rig_q = random_q(np.random.default_rng(7), n)
    q = state.joint_q.numpy()
    q[ctrl.coord_index[:, :7]] = rig_q
    state.joint_q.assign(q)
    ref = TorchEEPose(ctrl, state, control_t, torch.device("cpu"))
    action = torch.rand((n, 7), generator=torch.Generator().manual_seed(0)) * 2.4 - 1.2
    ctrl.reset(state)
    ctrl.set_action(action, state)
    ctrl.before_simulation_step(state, control)
    ref.set_action(action)
    q0 = torch.as_tensor(rig_q)
    ee, jac = ref.fk_jacobian(q0)
    np.testing.assert_allclose(ee[:, :3, 3].numpy(), ctrl["arm"].ee_pose.numpy()[:, :3], atol=2e-6)
    np.testing.assert_allclose(jac.numpy(), ctrl["arm"].fk_jacobian(state)[1].numpy(), atol=2e-6)
    step_wp = jac @ (wp.to_torch(ctrl["arm"].target_qpos) - q0)[:, :, None]
    step_t = jac @ (ref.target_qpos - q0)[:, :, None]
    np.testing.assert_allclose(step_wp.numpy(), step_t.numpy(), atol=2e-5)
    coord = ctrl.coord_index
    np.testing.assert_array_equal(
        control.joint_target_q.numpy()[coord[:, 7:]], control_t.joint_target_q.numpy()[coord[:, 7:]]
    )


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
def test_interpolated_drive_targets_and_torques(actuation):
    n = 3
    model = build_panda(n)
    mode = {"arm": pose_cfg(interpolate=True), "gripper": gripper()}
    ctrl = wpctrl.build_controller(mode, model, actuation=actuation)
    state, control = model.state(), model.control()
    coord, dof = ctrl.coord_index, ctrl.dof_index
    q = state.joint_q.numpy()
    q[coord[:, :7]] = random_q(np.random.default_rng(8), n)
    state.joint_q.assign(q)
    ctrl.reset(state)
    ctrl.set_action(np.random.default_rng(9).uniform(-1, 1, (n, 7)).astype(np.float32), state)
    start, target = ctrl.start_qpos.numpy(), ctrl.target_qpos.numpy()
    assert np.abs(target[:, :7] - start[:, :7]).max() > 1e-3
    K = ctrl.num_substeps
    for i in range(1, K + 1):
        ctrl.before_simulation_step(state, control)
        drive = control.joint_target_q.numpy()[coord]
        want = start[:, :7] + ((target[:, :7] - start[:, :7]) / np.float32(K)) * np.float32(i)
        np.testing.assert_allclose(drive[:, :7], want, atol=1e-6)
        np.testing.assert_array_equal(drive[:, 7:], target[:, 7:])  # the gripper does not interpolate
        tau = control.joint_f.numpy()[dof]
        if actuation == "explicit":  # PD torques on the interpolated targets (qd = 0), clamped at 100 N·m
            np.testing.assert_allclose(tau, np.clip(1e3 * (drive - state.joint_q.numpy()[coord]), -100, 100), atol=1e-3)
        else:
            assert not tau.any()


def test_floating_base_poses_are_relative_to_the_base():
    robot = newton.ModelBuilder()
    robot.add_urdf(str(PANDA_URDF), collapse_fixed_joints=True, floating=True)
    b = newton.ModelBuilder()
    b.replicate(robot, 2)
    model = b.finalize(device="cpu")
    rig = Rig(pose_cfg(urdf_path=str(PANDA_URDF)), 2, model=model)
    q = random_q(np.random.default_rng(10), 2)
    state = model.state()
    jq = state.joint_q.numpy()
    jq[rig.arm_coord] = q
    jq[0:7] = [0.3, -0.2, 0.5, 0.0, 0.0, 0.3826834, 0.9238795]  # env 0's base: moved and yawed 45 degrees
    state.joint_q.assign(jq)
    local = rig.arm.fk_jacobian(state)[0].numpy()
    fixed = Rig(pose_cfg(), 2)  # wpctrl's fixed-base Panda (TCP site)
    np.testing.assert_allclose(local, fixed.fk(q)[0], atol=2e-6)


def test_clip_targets_clamps_ee_joint_targets():
    n = 4
    mode = {"arm": pose_cfg(delta_solver_config=dict(alpha=40.0)), "gripper": gripper()}  # overshooting steps
    out = {}
    for clip in ("none", "joint_limits"):
        model = build_panda(n)
        ctrl = wpctrl.build_controller(copy.deepcopy(mode), model, clip_targets=clip)
        state = model.state()
        ctrl.reset(state)
        ctrl.set_action(np.random.default_rng(11).uniform(-1, 1, (n, 7)).astype(np.float32), state)
        out[clip] = ctrl["arm"].target_qpos.numpy()
    lo, hi = LIMITS[:, 0].astype(np.float32), LIMITS[:, 1].astype(np.float32)
    assert ((out["none"] < lo) | (out["none"] > hi)).any()
    np.testing.assert_array_equal(out["joint_limits"], np.clip(out["none"], lo, hi))


def test_unreachable_target_holds_the_measured_position():
    n = 2
    cfg = pose_cfg(
        pos_lower=None, pos_upper=None, rot_lower=None, rot_upper=None, use_delta=False, normalize_action=False,
        delta_solver_config=dict(solver_iterations=100, tolerance=1e-4),
    )  # fmt: skip
    rig = Rig(cfg, n)
    q = random_q(np.random.default_rng(12), n)
    rig.put(q)
    rig.ctrl.reset(rig.state)
    action = np.array([[2.0, 0.0, 0.5, np.pi, 0.0, 0.0], [0.5, 0.0, 0.3, np.pi, 0.0, 0.0]], np.float32)  # 2 m: out
    rig.ctrl.set_action(action, rig.state)
    assert rig.arm.ik_success.numpy().tolist() == [0, 1]
    np.testing.assert_array_equal(rig.arm.target_qpos.numpy()[0], q[0])
    np.testing.assert_allclose(rig.arm.target_pose.numpy()[0, :3], [2.0, 0.0, 0.5], atol=1e-6)  # kept, unreached
    reached, _ = rig.fk(rig.arm.target_qpos.numpy())
    np.testing.assert_allclose(reached[1, :3], [0.5, 0.0, 0.3], atol=2e-4)


def test_pseudo_inverse_on_a_short_chain_is_least_squares():
    """4 joints below panda_link3 (fewer than 6): dq = (JᵀJ)⁻¹Jᵀ dx, the least-squares step."""
    cfg = pose_cfg(root_link_name="panda_link3", delta_solver_config=dict(type="pseudo_inverse"))
    cfg.joint_names = list(ARM[3:])
    rig = Rig(cfg, 2)
    q = random_q(np.random.default_rng(13), 2)
    from wpctrl.binding import bind_joints

    full = rig.state.joint_q.numpy()
    full[bind_joints(rig.model, ARM).coord_index] = q
    rig.state.joint_q.assign(full)
    action = np.array([[0.5, -0.3, 0.2, 0.4, 0.1, -0.6], [-1.0, 0.2, 0.9, 0.0, 0.7, 0.3]], np.float32)
    rig.ctrl.set_action(action, rig.state)
    _, jac = rig.arm.fk_jacobian(rig.state)
    jac = jac.numpy().astype(np.float64)
    dx = rig.ctrl.processed_action.numpy().astype(np.float64)
    dq = rig.arm.target_qpos.numpy() - q[:, 3:]
    for e in range(2):
        ref = np.linalg.lstsq(jac[e], dx[e], rcond=None)[0]
        np.testing.assert_allclose(dq[e], ref, atol=2e-4)
