"""``wpctrl.maniskill.load_robot`` with its options off their defaults: a keyframe other than the first (its qpos and
root pose from the agent class), no keyframe, a root pose of the user's, a floating root at a keyframe, fixed joints
collapsed (under end-effector control, in envs placed apart). References: the ManiSkill agent class's own keyframes,
Newton's forward kinematics of the default build, and the same robot built without collapsing."""

from __future__ import annotations

import copy

import newton
import numpy as np
import pytest

pytest.importorskip("mani_skill", reason="the maniskill extra (mani-skill) is not installed")  # a dev dependency
pytestmark = pytest.mark.filterwarnings("ignore")

from user_models import indices  # noqa: E402

import wpctrl  # noqa: E402
from wpctrl.maniskill import load_robot  # noqa: E402


def _agent(uid):
    from mani_skill.agents.registration import REGISTERED_AGENTS

    return REGISTERED_AGENTS[uid].agent_cls


def _body_poses(builder, num_envs=1):
    """{link name: (7,) world pose [x, y, z, qx, qy, qz, qw]} of a one-robot builder (Newton's FK of joint_q)."""
    b = newton.ModelBuilder()
    b.replicate(builder, num_envs)
    model = b.finalize(device="cpu")
    state = model.state()
    newton.eval_fk(model, model.joint_q, model.joint_qd, state)
    return model, {lb.rsplit("/", 1)[-1]: p for lb, p in zip(model.body_label, state.body_q.numpy().astype(float))}


def _compose(a, b):
    """Pose product a * b of [x, y, z, qx, qy, qz, qw] poses."""
    import warp as wp

    x = wp.transform(wp.vec3(*a[:3]), wp.quat(*a[3:])) * wp.transform(wp.vec3(*b[:3]), wp.quat(*b[3:]))
    return np.array([*x.p, *x.q])


def _same_pose(got, want, atol=1e-5):
    assert np.abs(got[:3] - want[:3]).max() < atol, (got, want)
    assert min(np.abs(got[3:] - want[3:]).max(), np.abs(got[3:] + want[3:]).max()) < atol, (got, want)


def _qpos(robot, builder):
    """The builder's initial position of each of ManiSkill's active joints, by name."""
    b = newton.ModelBuilder()
    b.replicate(builder, 1)
    model = b.finalize(device="cpu")
    coord, _ = indices(model, robot.joint_names)
    return dict(zip(robot.joint_names, model.joint_q.numpy()[coord[0]].astype(float)))


@pytest.mark.parametrize("uid, name", [("koch-v1.1", "elevated_turn"), ("allegro_hand_right", "palm_up")])
def test_a_named_keyframe_that_is_not_the_first(uid, name):
    """The builder starts at the named keyframe: its qpos (by joint name) and, for a fixed root, its root pose."""
    kf = _agent(uid).keyframes[name]
    assert name != next(iter(_agent(uid).keyframes))
    robot = load_robot(uid, keyframe=name)
    assert robot.keyframe == name
    q = _qpos(robot, robot.builder)
    want = dict(zip(robot.joint_names, np.asarray(kf.qpos, float).reshape(-1)))
    for j in robot.joint_names:
        assert q[j] == pytest.approx(want[j], abs=1e-6), j
    first = load_robot(uid)
    moved = any(abs(_qpos(first, first.builder)[j] - want[j]) > 1e-3 for j in robot.joint_names)
    if getattr(kf, "pose", None) is not None:
        _, poses = _body_poses(robot.builder)
        _, first_poses = _body_poses(first.builder)
        root = robot.builder.body_label[0].rsplit("/", 1)[-1]
        p, qwxyz = np.asarray(kf.pose.p, float).reshape(-1), np.asarray(kf.pose.q, float).reshape(-1)
        _same_pose(poses[root], np.array([*p, *qwxyz[1:], qwxyz[0]]))
        moved = moved or np.abs(poses[root] - first_poses[root]).max() > 1e-3
    assert moved  # the first keyframe is another pose (a test of the choice)


def test_no_keyframe_is_zero_qpos_at_the_identity():
    robot = load_robot("allegro_hand_right", keyframe=None)
    assert robot.keyframe is None
    assert all(v == 0.0 for v in _qpos(robot, robot.builder).values())
    _, poses = _body_poses(robot.builder)
    root = robot.builder.body_label[0].rsplit("/", 1)[-1]
    _same_pose(poses[root], np.array([0, 0, 0, 0, 0, 0, 1.0]))


def test_root_pose_moves_every_link_of_a_fixed_robot():
    """A root pose of the user's ([x, y, z, qw, qx, qy, qz], turned about z): every link's world pose is that pose
    times the link's pose in the default build (whose root is at the identity), the joints unchanged."""
    pose = [-0.615, 0.2, 0.1, np.cos(0.3), 0.0, 0.0, np.sin(0.3)]
    moved = load_robot("panda", root_pose=pose)
    plain = load_robot("panda")
    _, pm = _body_poses(moved.builder)
    _, pp = _body_poses(plain.builder)
    x = np.array([*pose[:3], *pose[4:], pose[3]])
    assert set(pm) == set(pp)
    for link in pp:
        _same_pose(pm[link], _compose(x, pp[link]))
    assert _qpos(moved, moved.builder) == pytest.approx(_qpos(plain, plain.builder))


def test_floating_root_at_a_keyframe():
    """A floating robot (G1, ``fix_root_link=False``) at its ``right_knee_up`` keyframe: the free root at the
    keyframe's pose, the joints at its qpos."""
    cls = _agent("unitree_g1_simplified_legs")
    assert cls.fix_root_link is False
    kf = cls.keyframes["right_knee_up"]
    robot = load_robot("unitree_g1_simplified_legs", keyframe="right_knee_up")
    q = _qpos(robot, robot.builder)
    for j, v in zip(robot.joint_names, np.asarray(kf.qpos, float).reshape(-1)):
        assert q[j] == pytest.approx(v, abs=1e-6), j
    model, poses = _body_poses(robot.builder)
    root = model.body_label[int(model.joint_child.numpy()[0])].rsplit("/", 1)[-1]
    assert int(model.joint_type.numpy()[0]) == int(newton.JointType.FREE)
    p, qwxyz = np.asarray(kf.pose.p, float).reshape(-1), np.asarray(kf.pose.q, float).reshape(-1)
    _same_pose(poses[root], np.array([*p, *qwxyz[1:], qwxyz[0]]))


@pytest.mark.parametrize("mode_name", ["pd_ee_delta_pose", "pd_ee_pose"])
def test_collapsed_fixed_joints_under_ee_control_in_placed_envs(mode_name):
    """ManiSkill's Panda with its fixed joints collapsed (panda_link0 merged into the world, the TCP into link 7),
    at a root pose of the user's, replicated apart: its EE controller reports and commands the poses the
    uncollapsed robot does (the root link kept as a body), env by env."""
    E = 3
    pose = [0.4, -0.3, 0.05, np.cos(0.25), 0.0, 0.0, np.sin(0.25)]
    out = []
    for collapse in (True, False):
        robot = load_robot("panda", root_pose=pose, collapse_fixed_joints=collapse)
        b = newton.ModelBuilder()
        b.replicate(robot.builder, E, spacing=(1.5, 1.0, 0.0))
        model = b.finalize(device="cpu")
        mode = copy.deepcopy(robot.control_modes[mode_name])
        ctrl = wpctrl.build_controller(mode, model)
        arm_coord, _ = indices(model, mode["arm"].joint_names)
        s = model.state()
        q = s.joint_q.numpy()
        rng = np.random.default_rng(0)
        q[arm_coord] += rng.uniform(-0.3, 0.3, arm_coord.shape)
        s.joint_q.assign(q)
        ctrl.reset(s)
        pose0 = ctrl["arm"].ee_pose.numpy().copy()
        a = np.zeros((E, ctrl.action_dim), np.float32)
        if mode_name == "pd_ee_pose":
            a[:, :3] = pose0[:, :3] + [0.02, -0.03, 0.01]
            a[:, 3:6] = [np.pi, 0.05, -0.1]
        else:
            a[:, :6] = np.linspace(-0.7, 0.7, 6)
        ctrl.set_action(a, s)
        out.append((pose0, ctrl["arm"].target_pose.numpy().copy(), ctrl["arm"].target_qpos.numpy().copy()))
    for got, want in zip(out[0], out[1]):
        np.testing.assert_allclose(got, want, atol=5e-5)


def test_collapsing_merges_the_fixed_links():
    """``collapse_fixed_joints=True`` merges the links hung on fixed joints into their parents (ManiSkill's Panda:
    panda_link0 into the world, link8, the hand and the TCP into link7, the finger pads into the fingers); the
    moving joints stay, and the merged robot keeps the mass of every link but the base's."""
    full = load_robot("panda").builder
    merged = load_robot("panda", collapse_fixed_joints=True).builder
    names = {lb.rsplit("/", 1)[-1] for lb in merged.body_label}
    assert {"panda_link0", "panda_hand", "panda_hand_tcp", "panda_link8"}.isdisjoint(names)
    assert {f"panda_link{i}" for i in range(1, 8)} <= names
    assert merged.body_count < full.body_count
    moving = lambda b: sorted(  # noqa: E731
        lb.rsplit("/", 1)[-1] for lb, t in zip(b.joint_label, b.joint_type) if t != newton.JointType.FIXED
    )
    assert moving(merged) == moving(full)
    base = [m for lb, m in zip(full.body_label, full.body_mass) if lb.endswith("/panda_link0")]
    assert sum(merged.body_mass) == pytest.approx(sum(full.body_mass) - sum(base), rel=1e-6)  # link0 went to the world
