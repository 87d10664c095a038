"""Actuator models beyond ManiSkill, against independent references: Newton 1.8's own clamping components run on
the same PD torques and joint states, the closed forms, and (for actuator networks) the same network in torch."""

from __future__ import annotations

import math

import newton
import numpy as np
import pytest
import warp as wp
from conftest import build_panda

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS

f32 = np.float32
E = 4
DT = 0.01


def _arm(actuator, kp=400.0, kd=20.0, force_limit=60.0, **kw):
    return wpctrl.PDJointPosControllerConfig(
        PANDA_ARM_JOINTS, None, None, kp, kd, force_limit, normalize_action=False, actuator=actuator, **kw
    )


def _random_state(model, rng, qd_scale=4.0):
    s = model.state()
    q = s.joint_q.numpy()
    q += rng.uniform(-0.3, 0.3, q.shape).astype(f32)
    s.joint_q.assign(q)
    s.joint_qd.assign(rng.uniform(-qd_scale, qd_scale, s.joint_qd.shape).astype(f32))
    return s


def _one_substep(cfg, model, rng, track_effort=True, **kw):
    """Build, reset, random state and absolute targets, one substep: (ctrl, state, control, q, qd, target, pd)."""
    ctrl = wpctrl.build_controller(cfg, model, 100, 100, actuation="explicit", track_effort=track_effort, **kw)
    s = _random_state(model, rng)
    c = model.control()
    ctrl.reset(model.state(), control=c)
    b = ctrl._engine.binding
    q = s.joint_q.numpy()[b.coord_index]
    qd = s.joint_qd.numpy()[b.dof_index]
    target = (q + rng.normal(0.0, 0.4, q.shape)).astype(f32)
    ctrl.set_action(target, s)
    ctrl.before_simulation_step(s, c)
    return ctrl, s, c, q, qd, target


def _newton_clamp(component, u, q, qd, n):
    """Run a Newton clamping component (its own kernel) on efforts ``u`` at states ``q``, ``qd``, all flat."""
    idx = wp.array(np.arange(n, dtype=np.uint32), dtype=wp.uint32)
    src = wp.array(u.astype(f32).reshape(-1))
    dst = wp.zeros_like(src)
    component.modify_forces(
        src, dst, wp.array(q.astype(f32).reshape(-1)), wp.array(qd.astype(f32).reshape(-1)), idx, idx
    )
    return dst.numpy().reshape(u.shape)


def test_dc_motor_equals_newtons_clamping_dc_motor_and_the_closed_form():
    from newton.actuators import ClampingDCMotor

    model = build_panda(E)
    rng = np.random.default_rng(0)
    sat = np.array([80.0, 60.0, 70.0, 50.0, 40.0, 30.0, 20.0], f32)
    vmax = np.array([2.0, 2.5, 3.0, 1.5, 4.0, 5.0, 6.0], f32)
    ctrl, s, c, q, qd, target = _one_substep(_arm(wpctrl.DCMotor(sat, vmax)), model, rng)
    pd = f32(400.0) * (target - q) + f32(20.0) * (f32(0.0) - qd)
    tau = c.joint_f.numpy()[ctrl._engine.binding.dof_index]
    # Newton's component on the same PD torques and velocities (max_motor_effort = the config's force_limit)
    n = E * 7
    comp = ClampingDCMotor(wp.array(np.tile(sat, E)), wp.array(np.tile(vmax, E)), wp.array(np.full(n, 60.0, f32)))
    ref = _newton_clamp(comp, pd, q, qd, n)
    np.testing.assert_allclose(tau, ref, rtol=1e-5, atol=1e-4)
    # the closed form (float64): velocity clipped to the corner velocities, then the envelope
    corner = vmax * (1.0 + 60.0 / sat)
    v = np.clip(qd.astype(np.float64), -corner, corner)
    hi = np.minimum(sat * (1.0 - v / vmax), 60.0)
    lo = np.maximum(sat * (-1.0 - v / vmax), -60.0)
    np.testing.assert_allclose(tau, np.clip(pd, lo, hi), rtol=1e-5, atol=1e-4)
    assert (np.abs(tau - np.clip(pd, -60, 60)) > 1.0).any()  # the envelope binds somewhere (a test of something)
    # the effort readout: the PD law, the clamped torque, and one saturated substep where they differ
    np.testing.assert_allclose(ctrl.computed_effort.numpy(), pd, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(ctrl.applied_effort.numpy(), tau, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(ctrl.saturation_count.numpy(), (tau != ctrl.computed_effort.numpy()).astype(int))


def test_position_based_limit_equals_newtons_clamping_position_based():
    from newton.actuators import ClampingPositionBased

    model = build_panda(E)
    rng = np.random.default_rng(1)
    positions = [-2.0, -0.5, 0.0, 0.4, 1.5]
    efforts = [5.0, 30.0, 40.0, 12.0, 25.0]
    cfg = _arm(wpctrl.PositionBasedEffortLimit(positions, efforts), force_limit=1e9)
    ctrl, s, c, q, qd, target = _one_substep(cfg, model, rng)
    pd = f32(400.0) * (target - q) + f32(20.0) * (f32(0.0) - qd)
    tau = c.joint_f.numpy()[ctrl._engine.binding.dof_index]
    comp = ClampingPositionBased(lookup_positions=tuple(positions), lookup_efforts=tuple(efforts))
    comp.finalize(wp.get_device("cpu"), E * 7)
    ref = _newton_clamp(comp, pd, q, qd, E * 7)
    np.testing.assert_allclose(tau, ref, rtol=1e-5, atol=1e-4)
    lim = np.interp(q.astype(np.float64), positions, efforts)  # numpy holds the end values outside, as Newton
    np.testing.assert_allclose(tau, np.clip(pd, -lim, lim), rtol=1e-5, atol=1e-4)
    assert (np.abs(pd) > lim).any()
    # and the config's force_limit clamps too
    ctrl2, _, c2, q2, _, t2 = _one_substep(
        _arm(wpctrl.PositionBasedEffortLimit(positions, efforts), force_limit=10.0), model, np.random.default_rng(1)
    )
    tau2 = c2.joint_f.numpy()[ctrl2._engine.binding.dof_index]
    assert np.abs(tau2).max() <= 10.0 + 1e-6


def test_position_table_steps_knots_and_ends_equal_newtons_component():
    """The compiled-in table at its knots, on both sides of a step (a repeated position), outside both ends, and a
    one-entry table: Newton's ClampingPositionBased on the same positions, and numpy's left-continuous reading."""
    from newton.actuators import ClampingPositionBased

    model = build_panda(1)
    cases = [
        ([-1.0, 0.0, 0.0, 0.5, 2.0], [10.0, 20.0, 4.0, 8.0, 30.0]),  # a step at 0 (left value 20, then 4)
        ([0.3], [7.0]),  # one entry: a constant limit
    ]
    for positions, efforts in cases:
        ctrl = wpctrl.build_controller(
            _arm(wpctrl.PositionBasedEffortLimit(positions, efforts), force_limit=1e9),
            model,
            100,
            100,
            actuation="explicit",
        )
        b = ctrl._engine.binding
        s = model.state()
        c = model.control()
        ctrl.reset(s, control=c)
        # 7 arm joints: the knots, just around the step and outside both ends
        qs = np.array([-1.5, -1.0, -1e-3, 0.0, 1e-3, 0.5, 2.5], f32)
        q = s.joint_q.numpy()
        q[b.coord_index[0]] = qs
        s.joint_q.assign(q)
        ctrl.set_action(qs + f32(10.0), s)  # a large PD torque on every joint: the table binds everywhere
        ctrl.before_simulation_step(s, c)
        tau = c.joint_f.numpy()[b.dof_index[0]]
        comp = ClampingPositionBased(lookup_positions=tuple(positions), lookup_efforts=tuple(efforts))
        comp.finalize(wp.get_device("cpu"), 7)
        pd = f32(400.0) * f32(10.0) * np.ones(7, f32)
        np.testing.assert_allclose(tau, _newton_clamp(comp, pd, qs, np.zeros(7, f32), 7), rtol=1e-6)
        x, y = np.asarray(positions, np.float64), np.asarray(efforts, np.float64)
        ref = np.array([y[0] if v <= x[0] else y[-1] if v >= x[-1] else np.interp(v, x, y) for v in qs])
        if len(x) > 1:  # numpy's interp takes the right value at a repeated position; the table the left one
            ref[3] = 20.0
        np.testing.assert_allclose(tau, ref, rtol=1e-6)


def test_zero_range_randomisation_is_bit_identical_and_draws_differ_per_env():
    model = build_panda(E)
    ctrl = wpctrl.build_controller(_arm(wpctrl.DCMotor(80.0, 3.0)), model, 20, 100, actuation="explicit")
    s0, v0 = ctrl.saturation_effort.numpy().copy(), ctrl.velocity_limit.numpy().copy()
    np.testing.assert_array_equal(s0, 80.0)
    ctrl.randomize_drive_properties(saturation_effort=(1.0, 1.0), velocity_limit=(1.0, 1.0))
    np.testing.assert_array_equal(ctrl.saturation_effort.numpy(), s0)
    np.testing.assert_array_equal(ctrl.velocity_limit.numpy(), v0)
    ctrl.randomize_drive_properties(saturation_effort=(0.5, 1.5), seed=3)
    a = ctrl.saturation_effort.numpy()
    assert ((a >= 40.0) & (a <= 120.0)).all() and len(np.unique(a)) == a.size
    np.testing.assert_array_equal(ctrl.velocity_limit.numpy(), v0)  # not drawn
    # abs mode, one env by id; the other envs keep their values
    before = ctrl.velocity_limit.numpy().copy()
    ctrl.randomize_drive_properties(env_ids=[2], velocity_limit=(7.0, 7.0), mode="abs")
    after = ctrl.velocity_limit.numpy()
    np.testing.assert_array_equal(after[2], 7.0)
    np.testing.assert_array_equal(np.delete(after, 2, 0), np.delete(before, 2, 0))
    ctrl.set_drive_properties(saturation_effort=[10.0] * 7, env_ids=[0])
    np.testing.assert_array_equal(ctrl.saturation_effort.numpy()[0], 10.0)


def test_per_env_dc_parameters_reach_the_torque():
    """Per-env stall efforts set on the controller change that env's envelope (and only that one's)."""
    model = build_panda(2)
    rng = np.random.default_rng(4)
    cfg = _arm(wpctrl.DCMotor(200.0, 1e3), kp=2000.0, force_limit=500.0)
    ctrl = wpctrl.build_controller(cfg, model, 100, 100, actuation="explicit")
    ctrl.set_drive_properties(saturation_effort=np.array([[200.0] * 7, [5.0] * 7], f32))
    s = model.state()
    c = model.control()
    ctrl.reset(s, control=c)
    q = s.joint_q.numpy()[ctrl._engine.binding.coord_index]
    ctrl.set_action((q + 0.5).astype(f32), s)
    ctrl.before_simulation_step(s, c)
    tau = c.joint_f.numpy()[ctrl._engine.binding.dof_index]
    np.testing.assert_allclose(tau[0], np.minimum(2000.0 * 0.5, 200.0), rtol=1e-5)
    np.testing.assert_allclose(tau[1], 5.0, rtol=1e-5)
    del rng


def test_actuator_models_are_refused_with_implicit_actuation_and_bad_parameters():
    model = build_panda(1)
    with pytest.raises(wpctrl.ConfigError, match=r"actuator: DCMotor needs actuation='explicit'"):
        wpctrl.build_controller(_arm(wpctrl.DCMotor(80.0, 3.0)), model)
    with pytest.raises(wpctrl.ConfigError, match=r"explicit_pd='coupled' solves the force limits"):
        wpctrl.build_controller(_arm(wpctrl.DCMotor(80.0, 3.0)), model, actuation="explicit", explicit_pd="coupled")
    bad = [
        (wpctrl.DCMotor(-1.0, 3.0), r"saturation_effort: expected values >= 0"),
        (wpctrl.DCMotor(10.0, 0.0), r"velocity_limit: expected values > 0"),
        (wpctrl.DCMotor(10.0, [1.0, 2.0]), r"actuator.velocity_limit: expected a scalar or 7 values"),
        (wpctrl.PositionBasedEffortLimit([0.0, -1.0], [1.0, 2.0]), r"expected non-decreasing positions"),
        (wpctrl.PositionBasedEffortLimit([0.0], [1.0, 2.0]), r"same non-zero length"),
        (wpctrl.PositionBasedEffortLimit([0.0, 1.0], [1.0, -2.0]), r"efforts >= 0"),
        ("dc", r"expected wpctrl.DCMotor, wpctrl.PositionBasedEffortLimit, wpctrl.ActuatorNet or None, got str"),
    ]
    for act, match in bad:
        with pytest.raises(wpctrl.ConfigError, match=match):
            wpctrl.build_controller(_arm(act), model, actuation="explicit")


def test_default_step_is_unchanged_by_the_actuator_fields():
    """No actuator model: the substep kernel's layout carries no actuator entries (the default step compiles as
    before), and the torques are ManiSkill's clamp."""
    model = build_panda(E)
    rng = np.random.default_rng(5)
    ctrl, s, c, q, qd, target = _one_substep(_arm(None), model, rng, track_effort=False)
    assert ctrl._engine.layout.act_model == () and ctrl._engine.part("actuator_models") is None
    pd = f32(400.0) * (target - q) + f32(20.0) * (f32(0.0) - qd)
    np.testing.assert_allclose(c.joint_f.numpy()[ctrl._engine.binding.dof_index], np.clip(pd, -60, 60), rtol=1e-6)


# --- direct effort control --------------------------------------------------------------------------------------


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
def test_joint_effort_controller_writes_the_scaled_action(actuation):
    model = build_panda(E)
    mode = {
        "arm": wpctrl.JointEffortControllerConfig(PANDA_ARM_JOINTS, -30.0, 30.0, force_limit=20.0),
        "gripper": wpctrl.PDJointPosMimicControllerConfig(
            PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1e3, 1e2, mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}}
        ),
    }
    ctrl = wpctrl.build_controller(mode, model, 20, 100, actuation=actuation, delay=None)
    assert ctrl["arm"].target_qpos is None
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    rng = np.random.default_rng(6)
    a = rng.uniform(-1.3, 1.3, (E, 8)).astype(f32)
    ctrl.set_action(a, s)
    b = ctrl._engine.binding
    expected = f32(0.5) * (f32(30.0) + f32(-30.0)) + (f32(0.5) * (f32(30.0) - f32(-30.0))) * np.clip(a[:, :7], -1, 1)
    np.testing.assert_array_equal(ctrl["arm"].processed_action.numpy(), expected)
    np.testing.assert_array_equal(ctrl["arm"].target_effort.numpy(), expected)
    for _ in range(ctrl.num_substeps):
        ctrl.before_simulation_step(s, c)
        np.testing.assert_array_equal(c.joint_f.numpy()[b.dof_index[:, :7]], np.clip(expected, -20.0, 20.0))
    # the built-in drive is off on those joints: target mode EFFORT, gains 0
    dof = b.dof_index[:, :7]
    assert (model.joint_target_mode.numpy()[dof] == int(newton.JointTargetMode.EFFORT)).all()
    assert (model.joint_target_ke.numpy()[dof] == 0).all() and (model.joint_target_kd.numpy()[dof] == 0).all()
    # a reset zeroes the reset envs' command and effort
    ctrl.reset(s, np.array([True, False, False, True]), control=c)
    te = ctrl["arm"].target_effort.numpy()
    np.testing.assert_array_equal(te[[0, 3]], 0.0)
    np.testing.assert_array_equal(te[[1, 2]], expected[[1, 2]])
    np.testing.assert_array_equal(c.joint_f.numpy()[dof[[0, 3]]], 0.0)


def test_effort_commands_are_delayed_like_targets():
    model = build_panda(1)
    cfg = wpctrl.JointEffortControllerConfig(PANDA_ARM_JOINTS, -10.0, 10.0, normalize_action=False)
    ctrl = wpctrl.build_controller(cfg, model, 20, 100, actuation="explicit", delay=2)
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    dof = ctrl._engine.binding.dof_index[0]
    seen = []
    for k in range(3):
        ctrl.set_action(np.full(7, float(k + 1), f32), s)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s, c)
            seen.append(float(c.joint_f.numpy()[dof][0]))
    # a 2-substep delay: zero (the reset's history) twice, then each command 2 substeps late
    assert seen == [0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0, 2.0, 3.0, 3.0, 3.0]


# --- EMA and binary gripper ---------------------------------------------------------------------------------------


def test_ema_smooths_absolute_targets_within_the_joint_limits_and_reset_sets_the_measured_pose():
    model = build_panda(2)
    alpha = 0.3
    cfg = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, -1.0, 1.0, 1e3, 1e2, ema=alpha)
    ctrl = wpctrl.build_controller(cfg, model)
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    q0 = s.joint_q.numpy()[ctrl._engine.binding.coord_index].astype(f32)
    lim = ctrl._engine.binding.qlimits
    prev = q0.copy()
    rng = np.random.default_rng(7)
    for _ in range(4):
        a = rng.uniform(-1.5, 1.5, (2, 7)).astype(f32)
        ctrl.set_action(a, s)
        u = np.clip(a, -1, 1) * f32(1.0)
        prev = np.clip(f32(alpha) * u + (f32(1.0) - f32(alpha)) * prev, lim[:, 0], lim[:, 1])
        np.testing.assert_allclose(ctrl.target_qpos.numpy(), prev, atol=2e-7)
    ctrl.reset(s, np.array([False, True]))
    np.testing.assert_array_equal(ctrl.target_qpos.numpy()[1], q0[1])
    ctrl.set_action(np.zeros((2, 7), f32), s)
    np.testing.assert_allclose(ctrl.target_qpos.numpy()[1], (1 - f32(alpha)) * q0[1], atol=2e-7)


def test_binary_gripper_takes_the_action_sign():
    model = build_panda(3)
    cfg = wpctrl.PDJointPosMimicControllerConfig(
        PANDA_GRIPPER_JOINTS,
        -0.01,
        0.04,
        1e3,
        1e2,
        mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}},
        binary=True,
    )
    ctrl = wpctrl.build_controller(cfg, model)
    s = model.state()
    ctrl.reset(s)
    ctrl.set_action(np.array([[0.0], [-1e-6], [5.0]], f32), s)
    expected = np.array([0.04, -0.01, 0.04], f32)
    np.testing.assert_array_equal(ctrl.processed_action.numpy()[:, 0], expected)
    np.testing.assert_array_equal(ctrl.target_qpos.numpy(), np.stack([expected, expected], axis=1))
    with pytest.raises(wpctrl.ConfigError, match=r"binary: a binary command sets absolute targets"):
        wpctrl.build_controller(
            wpctrl.PDJointPosControllerConfig(PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1, 1, use_delta=True, binary=True),
            model,
        )
    with pytest.raises(wpctrl.ConfigError, match=r"ema: expected a number 0 < alpha <= 1"):
        wpctrl.build_controller(wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, -1, 1, 1, 1, ema=1.5), model)


def test_graph_capture_replays_dc_motor_and_effort_rows_bitwise():
    model = build_panda(E)
    mode = {
        "arm": _arm(wpctrl.DCMotor(50.0, 2.0), kp=800.0),
        "gripper": wpctrl.JointEffortControllerConfig(PANDA_GRIPPER_JOINTS, -5.0, 5.0),
    }
    ctrl = wpctrl.build_controller(mode, model, 20, 100, actuation="explicit", track_effort=True)
    rng = np.random.default_rng(8)
    s = _random_state(model, rng)
    c = model.control()
    ctrl.reset(s, control=c)
    a = wp.array(rng.uniform(-1, 1, (E, 9)).astype(f32))

    def step():
        ctrl.set_action(a, s)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s, c)

    step()
    eager = (c.joint_f.numpy().copy(), ctrl.applied_effort.numpy().copy())
    with wp.ScopedCapture(device="cpu") as cap:
        step()
    c.joint_f.zero_()
    ctrl.applied_effort.fill_(0.0)
    wp.capture_launch(cap.graph)
    np.testing.assert_array_equal(c.joint_f.numpy(), eager[0])
    np.testing.assert_array_equal(ctrl.applied_effort.numpy(), eager[1])
    assert np.abs(eager[0]).max() > 1.0


def test_dc_motor_rollout_on_mujoco_tracks_finite_and_stays_in_the_envelope():
    """64 Pandas with a DC-motor arm on MuJoCo-Warp: finite tracking, every applied torque inside the envelope of
    the measured velocity (checked from the effort readout and the state after each substep)."""
    n = 64
    model = build_panda(n)
    sat, vmax, lim = 60.0, 2.5, 87.0
    mode = {
        "arm": wpctrl.PDJointPosControllerConfig(
            PANDA_ARM_JOINTS, -0.1, 0.1, 400.0, 40.0, lim, use_delta=True, actuator=wpctrl.DCMotor(sat, vmax)
        ),
        "gripper": wpctrl.PDJointPosMimicControllerConfig(
            PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1e3, 1e2, mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}}
        ),
    }
    ctrl = wpctrl.build_controller(mode, model, 20, 100, actuation="explicit", explicit_pd="stable", track_effort=True)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    s0, s1, c = model.state(), model.state(), model.control()
    ctrl.reset(s0, control=c)
    rng = np.random.default_rng(9)
    dof = ctrl._engine.binding.dof_index[:, :7]
    worst = 0.0
    for _ in range(10):
        ctrl.set_action(rng.uniform(-1, 1, (n, 8)).astype(f32), s0)
        for _ in range(ctrl.num_substeps):
            qd = s0.joint_qd.numpy()[dof].astype(np.float64)
            ctrl.before_simulation_step(s0, c)
            tau = ctrl["arm"].applied_effort.numpy().astype(np.float64)
            corner = vmax * (1 + lim / sat)
            v = np.clip(qd, -corner, corner)
            hi = np.minimum(sat * (1 - v / vmax), lim)
            lo = np.maximum(sat * (-1 - v / vmax), -lim)
            worst = max(worst, float(np.max(tau - hi)), float(np.max(lo - tau)))
            solver.step(s0, s1, c, None, DT)
            s0, s1 = s1, s0
    assert np.isfinite(s0.joint_q.numpy()).all()
    assert worst <= 1e-3
    assert math.isfinite(worst)
