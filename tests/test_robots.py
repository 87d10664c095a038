"""wpctrl.robots: the in-code Panda against Newton's own import of the URDF, and ManiSkill's Panda control modes."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import newton
import numpy as np
import pytest
import warp as wp
from conftest import PANDA_URDF

from wpctrl.config import (
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointPosVelControllerConfig,
    PDJointVelControllerConfig,
    check_mode_dict,
    config_rows,
)
from wpctrl.robots import (
    PANDA_ARM_JOINTS,
    PANDA_BODIES,
    PANDA_CONTROL_MODES,
    PANDA_GRIPPER_JOINTS,
    PANDA_INITIAL_Q,
    PANDA_REST_QPOS,
    panda,
    panda_control_modes,
)

TOL = 1e-6


def _last(label: str) -> str:
    return label.rsplit("/", 1)[-1]


def _urdf_builder(**kwargs) -> newton.ModelBuilder:
    b = newton.ModelBuilder()
    b.add_urdf(str(PANDA_URDF), collapse_fixed_joints=True, floating=False, **kwargs)
    return b


@pytest.fixture(scope="module")
def models():
    """(ours, Newton's collapsed URDF import), both finalized on the CPU."""
    ref = _urdf_builder().finalize(device="cpu")
    ours = panda(mimic_fingers=True).finalize(device="cpu")
    return ours, ref


def _fk(model: newton.Model, q: np.ndarray) -> np.ndarray:
    state = model.state()
    jq = wp.array(np.asarray(q, dtype=np.float32), dtype=wp.float32, device="cpu")
    newton.eval_fk(model, jq, wp.zeros_like(model.joint_qd), state)
    return state.body_q.numpy().astype(np.float64)


def _same_pose(a: np.ndarray, b: np.ndarray) -> float:
    """Largest difference between two (n, 7) arrays of transforms, quaternion sign ignored."""
    dp = np.abs(a[:, :3] - b[:, :3]).max()
    sign = np.where(np.sum(a[:, 3:] * b[:, 3:], axis=1, keepdims=True) < 0.0, -1.0, 1.0)
    dq = np.abs(a[:, 3:] - sign * b[:, 3:]).max()
    return float(max(dp, dq))


# ----------------------------------------------------------------------------------------------------------------------
# Model structure against Newton's URDF import


def test_joints_match_urdf_import(models):
    ours, ref = models
    names = [_last(s) for s in ours.joint_label]
    assert names == PANDA_ARM_JOINTS + PANDA_GRIPPER_JOINTS
    assert names == [_last(s) for s in ref.joint_label]
    assert ours.joint_label[0] == "panda/panda_joint1"
    assert ours.joint_count == ref.joint_count == 9
    assert ours.joint_dof_count == ours.joint_coord_count == 9
    types = ours.joint_type.numpy().tolist()
    assert types == [int(newton.JointType.REVOLUTE)] * 7 + [int(newton.JointType.PRISMATIC)] * 2
    assert types == ref.joint_type.numpy().tolist()
    for field in (
        "joint_parent",
        "joint_child",
        "joint_q_start",
        "joint_qd_start",
        "joint_dof_dim",
        "articulation_start",
    ):
        np.testing.assert_array_equal(getattr(ours, field).numpy(), getattr(ref, field).numpy(), err_msg=field)
    assert ours.joint_parent.numpy()[0] == -1  # panda_link0 is welded to the world, as the collapse does
    # Joint frames in the parent body frame, axes in the joint frame: the same convention on both sides.
    for field in ("joint_X_p", "joint_X_c"):
        np.testing.assert_allclose(getattr(ours, field).numpy(), getattr(ref, field).numpy(), atol=TOL, err_msg=field)
    for field in ("joint_axis", "joint_limit_lower", "joint_limit_upper", "joint_effort_limit", "joint_velocity_limit"):
        np.testing.assert_allclose(getattr(ours, field).numpy(), getattr(ref, field).numpy(), atol=TOL, err_msg=field)
    np.testing.assert_allclose(ours.joint_limit_lower.numpy()[3], -3.0718, atol=TOL)
    np.testing.assert_allclose(ours.joint_velocity_limit.numpy(), [2.175] * 4 + [2.61] * 3 + [0.2] * 2, atol=TOL)
    # The limit springs keep the builder defaults, like add_urdf.
    for field in ("joint_limit_ke", "joint_limit_kd"):
        np.testing.assert_allclose(getattr(ours, field).numpy(), getattr(ref, field).numpy(), err_msg=field)
    # URDF <mimic> on finger 2 == mimic_fingers=True.
    np.testing.assert_array_equal(ours.joint_mimic_joint.numpy(), ref.joint_mimic_joint.numpy())
    np.testing.assert_allclose(ours.joint_mimic_coeffs.numpy(), ref.joint_mimic_coeffs.numpy())
    assert ours.articulation_count == 1 and ours.articulation_label == ["panda"]


def test_bodies_match_urdf_import(models):
    ours, ref = models
    assert [_last(s) for s in ours.body_label] == PANDA_BODIES == [_last(s) for s in ref.body_label]
    assert ours.body_label[6] == "panda/panda_link7"
    np.testing.assert_allclose(ours.body_mass.numpy(), ref.body_mass.numpy(), atol=TOL)
    np.testing.assert_allclose(ours.body_com.numpy(), ref.body_com.numpy(), atol=TOL)
    np.testing.assert_allclose(ours.body_inertia.numpy(), ref.body_inertia.numpy(), atol=TOL)
    np.testing.assert_allclose(ours.body_inv_mass.numpy(), ref.body_inv_mass.numpy(), rtol=1e-6)
    # link7 carries the hand: 0.735522 + 0.73 kg.
    assert ours.body_mass.numpy()[6] == pytest.approx(1.465522, abs=TOL)


def test_forward_kinematics_match_urdf_import(models):
    ours, ref = models
    lower, upper = ref.joint_limit_lower.numpy(), ref.joint_limit_upper.numpy()
    rng = np.random.default_rng(7)
    configs = [np.zeros(9), np.asarray(PANDA_REST_QPOS)] + [rng.uniform(lower, upper) for _ in range(4)]
    for q in configs:
        assert _same_pose(_fk(ours, q), _fk(ref, q)) < 1e-5, q


def test_initial_body_q_is_fk_of_initial_q(models):
    ours, _ = models
    np.testing.assert_allclose(ours.joint_q.numpy(), PANDA_INITIAL_Q, atol=TOL)
    assert _same_pose(ours.body_q.numpy().astype(np.float64), _fk(ours, np.asarray(PANDA_INITIAL_Q))) < 1e-5


def test_exact_inertia_merge_is_the_rigid_composite():
    """inertia_merge="exact" gives link7 + hand as one rigid body about its COM (computed here from the URDF XML)."""
    root = ET.parse(PANDA_URDF).getroot()

    def inertial(link):
        el = root.find(f"link[@name='{link}']/inertial")
        i = {k: float(v) for k, v in el.find("inertia").attrib.items()}
        tensor = np.array(
            [[i["ixx"], i["ixy"], i["ixz"]], [i["ixy"], i["iyy"], i["iyz"]], [i["ixz"], i["iyz"], i["izz"]]]
        )
        com = np.array([float(v) for v in el.find("origin").get("xyz").split()])
        return float(el.find("mass").get("value")), com, tensor

    def origin(joint):
        el = root.find(f"joint[@name='{joint}']/origin")
        return np.array([float(v) for v in el.get("xyz").split()]), [float(v) for v in el.get("rpy").split()]

    p8, rpy8 = origin("panda_joint8")
    ph, rpyh = origin("panda_hand_joint")
    assert rpy8 == [0.0, 0.0, 0.0] and ph.tolist() == [0.0, 0.0, 0.0] and rpyh[:2] == [0.0, 0.0]
    yaw = rpyh[2]
    rot = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    m7, c7, i7 = inertial("panda_link7")
    mh, ch, ih = inertial("panda_hand")
    ch = p8 + rot @ ch
    mass = m7 + mh
    com = (m7 * c7 + mh * ch) / mass

    def steiner(m, d):
        return m * (d @ d * np.eye(3) - np.outer(d, d))

    tensor = i7 + steiner(m7, c7 - com) + rot @ ih @ rot.T + steiner(mh, ch - com)

    exact = panda(inertia_merge="exact", visual_shapes=False)
    newton_like = panda(visual_shapes=False)
    assert exact.body_mass[6] == pytest.approx(mass, abs=TOL)
    np.testing.assert_allclose(np.array(exact.body_com[6]), com, atol=TOL)
    np.testing.assert_allclose(np.array(exact.body_inertia[6]).reshape(3, 3), tensor, atol=TOL)
    # Only link7's tensor differs between the modes.
    for i in range(9):
        assert exact.body_mass[i] == newton_like.body_mass[i]
        np.testing.assert_allclose(np.array(exact.body_com[i]), np.array(newton_like.body_com[i]), atol=1e-9)
        if i != 6:
            np.testing.assert_array_equal(np.array(exact.body_inertia[i]), np.array(newton_like.body_inertia[i]))


# ----------------------------------------------------------------------------------------------------------------------
# Builder options (no finalize needed)


def test_initial_q_and_drive_defaults():
    b = panda()
    np.testing.assert_allclose(b.joint_q, PANDA_INITIAL_Q)
    np.testing.assert_allclose(b.joint_target_q, PANDA_INITIAL_Q)
    assert PANDA_INITIAL_Q[:7] == PANDA_REST_QPOS[:7] and PANDA_INITIAL_Q[7:] == (0.035, 0.035)
    assert PANDA_REST_QPOS == pytest.approx(
        (0.0, math.pi / 8, 0.0, -5 * math.pi / 8, 0.0, 3 * math.pi / 4, math.pi / 4, 0.04, 0.04)
    )
    for field in ("joint_target_ke", "joint_target_kd", "joint_damping", "joint_stiffness", "joint_friction"):
        assert list(getattr(b, field)) == [0.0] * 9, field
    assert list(b.joint_armature) == [0.0] * 9
    assert list(b.joint_target_qd) == [0.0] * 9
    assert list(b.joint_target_mode) == [int(newton.JointTargetMode.POSITION_VELOCITY)] * 9
    assert list(b.joint_mimic_joint) == [-1] * 9

    q = [0.1, 0.2, -0.3, -1.0, 0.5, 1.0, -0.4, 0.0, 0.04]
    b = panda(initial_q=q, armature=0.1, actuator_mode=newton.JointTargetMode.NONE, label_prefix="r0")
    np.testing.assert_allclose(b.joint_q, q)
    np.testing.assert_allclose(b.joint_target_q, q)
    np.testing.assert_allclose(b.joint_armature, [0.1] * 9)
    assert list(b.joint_target_mode) == [int(newton.JointTargetMode.NONE)] * 9
    assert b.joint_label[7] == "r0/panda_finger_joint1" and b.body_label[0] == "r0/panda_link1"
    np.testing.assert_allclose(panda(armature=list(range(9))).joint_armature, list(range(9)))
    assert panda(label_prefix="").joint_label[0] == "panda_joint1"


def test_initial_q_lands_in_replicated_model():
    robot = panda(initial_q=PANDA_REST_QPOS, visual_shapes=False)
    scene = newton.ModelBuilder()
    scene.replicate(robot, 2)
    model = scene.finalize(device="cpu")
    np.testing.assert_allclose(model.joint_q.numpy(), list(PANDA_REST_QPOS) * 2, atol=TOL)
    np.testing.assert_allclose(model.joint_target_q.numpy(), list(PANDA_REST_QPOS) * 2, atol=TOL)
    assert model.joint_count == 18 and model.world_count == 2


def test_invalid_arguments():
    with pytest.raises(ValueError, match="panda_joint4"):
        panda(initial_q=[0.0] * 9)  # joint4 upper limit is -0.0698
    with pytest.raises(ValueError, match="initial_q"):
        panda(initial_q=[0.0] * 8)
    with pytest.raises(ValueError, match="armature"):
        panda(armature=[0.1, 0.2])
    with pytest.raises(ValueError, match="inertia_merge"):
        panda(inertia_merge="physx")


def test_visual_shapes_are_massless_and_never_collide():
    with_shapes, without = panda(), panda(visual_shapes=False)
    site = int(newton.ShapeFlags.SITE)
    assert [f & site for f in without.shape_flags] == [site]  # only the panda_hand_tcp site
    assert len(with_shapes.shape_type) > 1
    collide = int(newton.ShapeFlags.COLLIDE_SHAPES) | int(newton.ShapeFlags.COLLIDE_PARTICLES)
    assert all(flags & collide == 0 for flags in with_shapes.shape_flags)
    assert all(flags & int(newton.ShapeFlags.VISIBLE) for flags in with_shapes.shape_flags if not flags & site)
    assert with_shapes.body_mass == without.body_mass
    for a, b in zip(with_shapes.body_com, without.body_com, strict=True):
        assert tuple(a) == tuple(b)
    for a, b in zip(with_shapes.body_inertia, without.body_inertia, strict=True):
        np.testing.assert_array_equal(np.array(a), np.array(b))
    assert -1 in with_shapes.shape_body  # the base outline is static


# ----------------------------------------------------------------------------------------------------------------------
# ManiSkill's Panda control modes

MODES = [
    "pd_joint_delta_pos",
    "pd_joint_pos",
    "pd_joint_target_delta_pos",
    "pd_joint_vel",
    "pd_joint_pos_vel",
    "pd_joint_delta_pos_vel",
]
EE_MODES = ["pd_ee_delta_pos", "pd_ee_delta_pose", "pd_ee_pose", "pd_ee_target_delta_pos", "pd_ee_target_delta_pose"]
IMPEDANCE_MODES = ["osc_ee_delta_pose", "osc_ee_pose", "joint_impedance_delta_pos"]


def test_control_modes_numbers():
    modes = panda_control_modes()
    # the EE modes' numbers: tests/test_ee.py; the impedance modes': tests/test_impedance.py
    assert list(modes) == MODES + EE_MODES + IMPEDANCE_MODES
    for mode, children in modes.items():
        assert list(children) == ["arm", "gripper"], mode
        g = children["gripper"]
        assert type(g) is PDJointPosMimicControllerConfig
        assert g == PDJointPosMimicControllerConfig(
            ["panda_finger_joint1", "panda_finger_joint2"],
            -0.01,
            0.04,
            1e3,
            1e2,
            100,
            mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}},
        ), mode
        assert g.normalize_action and not g.use_delta and g.friction == 0.0 and g.drive_mode == "force"
        check_mode_dict(children)

    arm = {mode: children["arm"] for mode, children in modes.items()}
    joints = [f"panda_joint{i}" for i in range(1, 8)]
    assert PANDA_ARM_JOINTS == joints and PANDA_GRIPPER_JOINTS == ["panda_finger_joint1", "panda_finger_joint2"]
    expected = {
        "pd_joint_delta_pos": PDJointPosControllerConfig(joints, -0.1, 0.1, 1e3, 1e2, 100, use_delta=True),
        "pd_joint_pos": PDJointPosControllerConfig(joints, None, None, 1e3, 1e2, 100, normalize_action=False),
        "pd_joint_target_delta_pos": PDJointPosControllerConfig(
            joints, -0.1, 0.1, 1e3, 1e2, 100, use_delta=True, use_target=True
        ),
        "pd_joint_vel": PDJointVelControllerConfig(joints, -1.0, 1.0, 1e2, 100),
        "pd_joint_pos_vel": PDJointPosVelControllerConfig(joints, None, None, 1e3, 1e2, 100, normalize_action=False),
        "pd_joint_delta_pos_vel": PDJointPosVelControllerConfig(joints, -0.1, 0.1, 1e3, 1e2, 100, use_delta=True),
    }
    for mode in MODES:
        assert type(arm[mode]) is type(expected[mode]), mode
        assert arm[mode] == expected[mode], mode
    assert arm["pd_joint_vel"].normalize_action
    assert arm["pd_joint_pos_vel"].vel_lower == -1.0 and arm["pd_joint_pos_vel"].vel_upper == 1.0
    assert arm["pd_joint_delta_pos"].use_target is False

    # Action widths through the rows ManiSkill's bounds produce (arm limits from the URDF numbers).
    qlim = np.array(
        [[-2.8973, 2.8973], [-1.7628, 1.7628], [-2.8973, 2.8973], [-3.0718, -0.0698], [-2.8973, 2.8973],
         [-0.0175, 3.7525], [-2.8973, 2.8973]],
        dtype=np.float32,
    )  # fmt: skip
    glim = np.array([[0.0, 0.04], [0.0, 0.04]], dtype=np.float32)
    dims = {m: config_rows(arm[m], qlim).action_dim + config_rows(modes[m]["gripper"], glim).action_dim for m in MODES}
    assert dims == {m: 15 if m.endswith("pos_vel") else 8 for m in MODES}


def test_control_modes_are_fresh_copies():
    a, b = panda_control_modes(), panda_control_modes()
    assert a == b == PANDA_CONTROL_MODES
    seen = set()
    for d in (a, b, PANDA_CONTROL_MODES):
        for children in d.values():
            for cfg in children.values():
                assert id(cfg) not in seen  # no config object shared between modes or calls
                seen.add(id(cfg))
                assert id(cfg.joint_names) not in seen
                seen.add(id(cfg.joint_names))
    a["pd_joint_pos"]["arm"].stiffness = 5.0
    a["pd_joint_delta_pos"]["gripper"].mimic["panda_finger_joint2"]["multiplier"] = -1.0
    a["pd_joint_vel"]["arm"].joint_names.append("oops")
    assert panda_control_modes() == b
    assert PANDA_CONTROL_MODES == b
    assert a["pd_joint_pos_vel"]["gripper"].mimic == {"panda_finger_joint2": {"joint": "panda_finger_joint1"}}
    assert PANDA_ARM_JOINTS == [f"panda_joint{i}" for i in range(1, 8)]
