"""Mobile-base controllers (ManiSkill 3.0.1's ``pd_base_vel.py``) against its formulas re-derived in numpy float32.

A Fetch-style mobile manipulator is built here: a base on world-frame x / y prismatic joints and a yaw joint, a 3-link
arm and a two-finger gripper. Every env gets its own yaw, so the rotation is checked at nonzero, per-env angles.
"""

from __future__ import annotations

import math

import newton
import numpy as np
import pytest
import warp as wp

import wpctrl

f32 = np.float32
BASE = ["root_x_axis_joint", "root_y_axis_joint", "root_z_rotation_joint"]
ARM = ["arm_1", "arm_2", "arm_3"]
FINGERS = ["finger_l", "finger_r"]


def mobile_robot() -> newton.ModelBuilder:
    """x / y prismatic + yaw revolute base, a 3-joint arm, two prismatic fingers; one articulation."""
    b = newton.ModelBuilder()
    inertia = wp.mat33(0.05, 0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.05)
    joints = []

    def link(mass=2.0):
        return b.add_link(mass=mass, inertia=inertia)

    bx, by, base = link(), link(), link(20.0)
    joints.append(b.add_joint_prismatic(-1, bx, axis=(1, 0, 0), label=BASE[0]))
    joints.append(b.add_joint_prismatic(bx, by, axis=(0, 1, 0), label=BASE[1]))
    joints.append(b.add_joint_revolute(by, base, axis=(0, 0, 1), label=BASE[2]))
    parent = base
    for i, name in enumerate(ARM):
        child = link()
        xf = wp.transform((0.0, 0.0, 0.3 if i == 0 else 0.4), wp.quat_identity())
        axis = (0, 0, 1) if i == 0 else (0, 1, 0)
        joints.append(
            b.add_joint_revolute(
                parent, child, parent_xform=xf, axis=axis, limit_lower=-2.5, limit_upper=2.5, label=name
            )
        )
        parent = child
    for side, name in zip((1.0, -1.0), FINGERS):
        child = link(0.1)
        xf = wp.transform((0.0, 0.02 * side, 0.1), wp.quat_identity())
        joints.append(
            b.add_joint_prismatic(
                parent, child, parent_xform=xf, axis=(0, side, 0), limit_lower=0.0, limit_upper=0.04, label=name
            )
        )
    b.add_articulation(joints, label="mobile")
    return b


def build(num_envs: int, yaws: np.ndarray) -> tuple[newton.Model, newton.State]:
    builder = newton.ModelBuilder()
    builder.replicate(mobile_robot(), num_envs)
    model = builder.finalize(device="cpu")
    q = model.joint_q.numpy().reshape(num_envs, -1)
    q[:, 2] = yaws
    q[:, 0] = np.linspace(-1.0, 1.0, num_envs)  # the base's position does not enter the rotation
    model.joint_q.assign(q.reshape(-1))
    state = model.state()
    return model, state


def _scale(a, lo, hi):
    """ManiSkill's normalisation in float32: clip to [-1, 1], then 0.5(h+l) + 0.5(h-l)a."""
    a = np.clip(a.astype(f32), f32(-1), f32(1))
    return f32(0.5) * (f32(hi) + f32(lo)) + (f32(0.5) * (f32(hi) - f32(lo))) * a


def _rot(yaw, vx, vy):
    """ManiSkill's ``rot_mat @ [vx, vy]`` in float32, R = [[c, -s], [s, c]] of the measured yaw."""
    c, s = np.cos(f32(yaw)).astype(f32), np.sin(f32(yaw)).astype(f32)
    return c * vx + (-s) * vy, s * vx + c * vy


def _dof_targets(model, control, num_envs):
    return control.joint_target_qd.numpy().reshape(num_envs, -1)


YAWS = np.array([0.7, -2.1, 3.0, 1.2345], np.float32)


def test_base_vel_rotates_by_measured_yaw_per_env():
    """PDBaseVel: [vx, vy, w] -> [c vx - s vy, s vx + c vy, w]; clip and scale first, as PDJointVel."""
    model, state = build(len(YAWS), YAWS)
    lo, hi = np.array([-1.0, -0.5, -3.14], f32), np.array([1.0, 0.5, 3.14], f32)
    cfg = wpctrl.PDBaseVelControllerConfig(BASE, lo, hi, 1000.0, force_limit=500.0)
    ctrl = wpctrl.build_controller(cfg, model)
    control = model.control()
    ctrl.reset(state, control=control)
    rng = np.random.default_rng(0)
    for _ in range(3):
        a = rng.uniform(-1.3, 1.3, (len(YAWS), 3)).astype(f32)
        ctrl.set_action(a, state)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(state, control)
        v = _scale(a, lo, hi)
        np.testing.assert_array_equal(ctrl.processed_action.numpy(), v)
        ex, ey = _rot(YAWS, v[:, 0], v[:, 1])
        expected = np.stack([ex, ey, v[:, 2]], axis=1)
        np.testing.assert_allclose(ctrl.target_qvel.numpy(), expected, atol=2e-7, rtol=0)
        np.testing.assert_allclose(_dof_targets(model, control, len(YAWS))[:, :3], expected, atol=2e-7, rtol=0)
    # The base's drive is a velocity drive: stiffness 0, damping from the config.
    assert (model.joint_target_ke.numpy().reshape(len(YAWS), -1)[:, :3] == 0).all()
    np.testing.assert_array_equal(model.joint_target_kd.numpy().reshape(len(YAWS), -1)[:, :3], 1000.0)


def test_base_forward_vel_in_a_fetch_mode_dict():
    """Fetch's pd_joint_delta_pos: arm delta + mimic gripper + PDBaseForwardVel ([v, w], bounds broadcast to 2)."""
    model, state = build(len(YAWS), YAWS)
    mode = {
        "arm": wpctrl.PDJointPosControllerConfig(ARM, -0.1, 0.1, 1e3, 1e2, 100, use_delta=True),
        "gripper": wpctrl.PDJointPosMimicControllerConfig(
            FINGERS, -0.01, 0.05, 1e3, 1e2, 100, mimic={"finger_r": {"joint": "finger_l"}}
        ),
        "base": wpctrl.PDBaseForwardVelControllerConfig(BASE, [-1.0, -3.14], [1.0, 3.14], 1000, force_limit=500),
    }
    ctrl = wpctrl.build_controller(mode, model)
    assert ctrl.action_space.shape == (len(YAWS), 3 + 1 + 2)
    assert ctrl.action_mapping == {"arm": (0, 3), "gripper": (3, 4), "base": (4, 6)}
    assert ctrl["base"].single_action_space.shape == (2,)
    control = model.control()
    ctrl.reset(state, control=control)
    rng = np.random.default_rng(1)
    q0 = state.joint_q.numpy().reshape(len(YAWS), -1)
    for _ in range(3):
        a = rng.uniform(-1.3, 1.3, (len(YAWS), 6)).astype(f32)
        ctrl.set_action(a, state)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(state, control)
        v = _scale(a[:, 4:6], np.array([-1, -3.14], f32), np.array([1, 3.14], f32))
        np.testing.assert_array_equal(ctrl["base"].processed_action.numpy(), v)
        ex, ey = _rot(YAWS, v[:, 0], np.zeros_like(v[:, 0]))
        expected = np.stack([ex, ey, v[:, 1]], axis=1)
        np.testing.assert_allclose(ctrl["base"].target_qvel.numpy(), expected, atol=2e-7, rtol=0)
        np.testing.assert_allclose(_dof_targets(model, control, len(YAWS))[:, :3], expected, atol=2e-7, rtol=0)
        # The arm's deltas are unaffected by the base: measured q + scaled action.
        arm_t = q0[:, 3:6] + _scale(a[:, :3], -0.1, 0.1)
        np.testing.assert_allclose(ctrl["arm"].target_qpos.numpy(), arm_t, atol=1e-7)
        np.testing.assert_allclose(control.joint_target_q.numpy().reshape(len(YAWS), -1)[:, 3:6], arm_t, atol=1e-7)


def test_base_yaw_is_read_at_set_action():
    """The rotation uses the yaw measured at set_action, not a later one (targets are set once per control step)."""
    model, state = build(2, np.array([0.0, 0.0], f32))
    cfg = wpctrl.PDBaseForwardVelControllerConfig(BASE, -1.0, 1.0, 1000.0)
    ctrl = wpctrl.build_controller(cfg, model, actuation="explicit")
    control = model.control()
    ctrl.reset(state, control=control)
    a = np.array([[1.0, 0.0], [0.5, 0.0]], f32)
    ctrl.set_action(a, state)
    q = state.joint_q.numpy().reshape(2, -1)
    q[:, 2] = math.pi / 2
    state.joint_q.assign(q.reshape(-1))
    ctrl.before_simulation_step(state, control)
    np.testing.assert_allclose(ctrl.target_qvel.numpy(), [[1.0, 0.0, 0.0], [0.5, 0.0, 0.0]], atol=1e-7)
    # Explicit actuation: joint_f = Kd (qd* - qd) on the base's velocity rows (stiffness 0).
    f = control.joint_f.numpy().reshape(2, -1)[:, :3]
    np.testing.assert_allclose(f, 1000.0 * np.array([[1.0, 0.0, 0.0], [0.5, 0.0, 0.0]]), atol=1e-3)


def test_base_graph_capture_replays_eager():
    """A captured set_action with base rows equals the eager one bitwise (CPU graph capture)."""
    model, state = build(len(YAWS), YAWS)
    cfg = wpctrl.PDBaseVelControllerConfig(BASE, -1.0, 1.0, 1000.0)
    ctrl = wpctrl.build_controller(cfg, model)
    control = model.control()
    ctrl.reset(state, control=control)
    a = wp.array(np.random.default_rng(2).uniform(-1, 1, (len(YAWS), 3)).astype(f32), device="cpu")
    ctrl.set_action(a, state)
    eager = ctrl.target_qvel.numpy().copy()
    with wp.ScopedCapture(device="cpu") as cap:
        ctrl.set_action(a, state)
    ctrl.target_qvel.zero_()
    wp.capture_launch(cap.graph)
    np.testing.assert_array_equal(ctrl.target_qvel.numpy(), eager)


@pytest.mark.parametrize(
    ("cls", "names", "lower", "match"),
    [
        (wpctrl.PDBaseVelControllerConfig, BASE[:2], -1.0, "at least 3 joints"),
        (wpctrl.PDBaseForwardVelControllerConfig, BASE + ARM[:1], -1.0, "exactly 3 joints"),
        # ManiSkill's PDBaseVel takes PDJointVel's per-joint bounds: Fetch's 2-entry bounds do not broadcast to 3.
        (wpctrl.PDBaseVelControllerConfig, BASE, [-1.0, -3.14], r"lower: expected a scalar or 3 values"),
        (wpctrl.PDBaseForwardVelControllerConfig, BASE, [-1.0, -1.0, -1.0], r"lower: expected a scalar or 2 values"),
    ],
)
def test_base_config_errors(cls, names, lower, match):
    model, _ = build(1, np.zeros(1, f32))
    upper = [-x for x in lower] if isinstance(lower, list) else 1.0
    with pytest.raises(wpctrl.ConfigError, match=match):
        wpctrl.build_controller(cls(names, lower, upper, 100.0), model)
