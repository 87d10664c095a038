"""Actuator models, networks, smoothing and effort readout where a user's setup differs from the defaults: on a
controller that is not the first of its mode dict, with parameters that differ per env and per controller, with
network input scales that are not 1, behind a command delay. Each against an independent reference: Newton's own
clamping components (``ClampingDCMotor``, ``ClampingPositionBased``) on the same torques and states, the same network
in torch, numpy re-derivations; the model's joint indices are read from its own tables (``user_models.indices``)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from conftest import build_panda
from user_models import indices, put

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS

torch = pytest.importorskip("torch", reason="torch is a dev dependency (the networks' reference)")

from actuator_nets import LSTMNet  # noqa: E402

pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")

f32 = np.float32
E = 3
ARM_A = list(PANDA_ARM_JOINTS[:3])
ARM_B = list(PANDA_ARM_JOINTS[3:])
MIMIC = {"panda_finger_joint2": {"joint": "panda_finger_joint1"}}


def gripper(**kw):
    return wpctrl.PDJointPosMimicControllerConfig(PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1e3, 1e2, mimic=MIMIC, **kw)


def pos(names, kp, kd, force_limit, **kw):
    return wpctrl.PDJointPosControllerConfig(list(names), None, None, kp, kd, force_limit, normalize_action=False,
                                             **kw)  # fmt: skip


def newton_clamp(component, u, q, qd):
    """Newton's clamping component (its own kernel) on efforts ``u`` at states ``q``, ``qd`` (same shapes)."""
    n = u.size
    idx = wp.array(np.arange(n, dtype=np.uint32), dtype=wp.uint32)
    src = wp.array(u.astype(f32).reshape(-1))
    dst = wp.zeros_like(src)
    component.modify_forces(src, dst, wp.array(q.astype(f32).reshape(-1)), wp.array(qd.astype(f32).reshape(-1)),
                            idx, idx)  # fmt: skip
    return dst.numpy().reshape(u.shape)


def random_state(model, names, rng, q_scale=1.0, qd_scale=4.0):
    s = model.state()
    n = len(names)
    q = rng.uniform(-q_scale, q_scale, (E, n)).astype(f32)
    qd = rng.uniform(-qd_scale, qd_scale, (E, n)).astype(f32)
    put(s, model, names, q, qd)
    return s, q, qd


# -- DC motor: per-env parameters on the second controller ----------------------------------------------------------


def test_dc_motor_with_per_env_limits_on_a_later_controller_equals_newtons_component():
    """The arm is the mode's second controller; every env has its own stall effort, no-load speed, force limit and
    stiffness. Newton's ClampingDCMotor, given the same per-DOF values, clamps the same PD torques the same way."""
    from newton.actuators import ClampingDCMotor

    model = build_panda(E)
    rng = np.random.default_rng(0)
    mode = {"gripper": gripper(), "arm": pos(PANDA_ARM_JOINTS, 300.0, 20.0, 90.0, actuator=wpctrl.DCMotor(60.0, 3.0))}
    ctrl = wpctrl.build_controller(mode, model, 100, 100, actuation="explicit", track_effort=True)
    arm = ctrl["arm"]
    sat = rng.uniform(20.0, 80.0, (E, 7)).astype(f32)
    vmax = np.array([[0.5], [2.0], [6.0]], f32) * rng.uniform(0.8, 1.2, (E, 7)).astype(f32)  # very different per env
    lim = rng.uniform(30.0, 70.0, (E, 7)).astype(f32)
    kp = rng.uniform(100.0, 500.0, (E, 7)).astype(f32)
    arm.set_drive_properties(stiffness=kp, force_limit=lim, saturation_effort=sat, velocity_limit=vmax)
    np.testing.assert_array_equal(arm.velocity_limit.numpy(), vmax)
    np.testing.assert_array_equal(arm.saturation_effort.numpy(), sat)
    s, q, qd = random_state(model, PANDA_ARM_JOINTS, rng)
    c = model.control()
    ctrl.reset(model.state(), control=c)
    target = (q + rng.normal(0.0, 0.5, q.shape)).astype(f32)
    ctrl.set_action(np.hstack([np.zeros((E, 1), f32), target]), s)
    ctrl.before_simulation_step(s, c)
    _, dof = indices(model, PANDA_ARM_JOINTS)
    tau = c.joint_f.numpy()[dof]
    pd = kp * (target - q) + f32(20.0) * (f32(0.0) - qd)
    ref = newton_clamp(ClampingDCMotor(wp.array(sat.ravel()), wp.array(vmax.ravel()), wp.array(lim.ravel())), pd, q, qd)
    np.testing.assert_allclose(tau, ref, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(arm.applied_effort.numpy(), tau, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(arm.computed_effort.numpy(), pd, rtol=1e-5, atol=1e-4)
    # the per-env speeds matter: env 0's speeds on every env give other torques
    other = newton_clamp(
        ClampingDCMotor(wp.array(sat.ravel()), wp.array(np.tile(vmax[0], E)), wp.array(lim.ravel())), pd, q, qd
    )
    assert np.abs(other - ref).max() > 1.0
    # the gripper (the first controller, no actuator model) keeps ManiSkill's clamp
    _, gdof = indices(model, PANDA_GRIPPER_JOINTS)
    gq = s.joint_q.numpy()[indices(model, PANDA_GRIPPER_JOINTS)[0]]
    gqd = s.joint_qd.numpy()[gdof]
    g_target = f32(0.5) * (f32(0.04) + f32(-0.01))  # a normalised action of 0: the middle of the range
    g_pd = f32(1e3) * (g_target - gq) + f32(1e2) * (f32(0.0) - gqd)
    np.testing.assert_allclose(c.joint_f.numpy()[gdof], np.clip(g_pd, -1e10, 1e10), rtol=1e-5, atol=1e-4)


def test_randomised_dc_parameters_are_the_ones_applied_per_env():
    """randomize_drive_properties (abs) on the second controller: the torque of each env is Newton's ClampingDCMotor
    at the values the controller reports for that env."""
    from newton.actuators import ClampingDCMotor

    model = build_panda(E)
    rng = np.random.default_rng(1)
    mode = {"gripper": gripper(), "arm": pos(PANDA_ARM_JOINTS, 400.0, 10.0, 80.0, actuator=wpctrl.DCMotor(60.0, 3.0))}
    ctrl = wpctrl.build_controller(mode, model, 100, 100, actuation="explicit")
    arm = ctrl["arm"]
    arm.randomize_drive_properties(saturation_effort=(10.0, 70.0), velocity_limit=(0.3, 5.0), mode="abs", seed=5)
    sat, vmax = arm.saturation_effort.numpy(), arm.velocity_limit.numpy()
    assert np.ptp(vmax[:, 0]) > 0.5 and np.ptp(sat[:, 0]) > 5.0  # the envs differ
    s, q, qd = random_state(model, PANDA_ARM_JOINTS, rng)
    c = model.control()
    ctrl.reset(model.state(), control=c)
    target = (q + rng.normal(0.0, 0.5, q.shape)).astype(f32)
    ctrl.set_action(np.hstack([np.zeros((E, 1), f32), target]), s)
    ctrl.before_simulation_step(s, c)
    tau = c.joint_f.numpy()[indices(model, PANDA_ARM_JOINTS)[1]]
    pd = f32(400.0) * (target - q) + f32(10.0) * (f32(0.0) - qd)
    lim = np.full(E * 7, 80.0, f32)
    ref = newton_clamp(ClampingDCMotor(wp.array(sat.ravel()), wp.array(vmax.ravel()), wp.array(lim)), pd, q, qd)
    np.testing.assert_allclose(tau, ref, rtol=1e-5, atol=1e-4)


# -- position tables: one per controller ----------------------------------------------------------------------------


def test_position_tables_on_two_controllers_each_equal_newtons_component():
    """Two controllers with different tables after a gripper: each joint is clamped by its own controller's table."""
    from newton.actuators import ClampingPositionBased

    model = build_panda(E)
    rng = np.random.default_rng(2)
    ta = ([-1.0, 0.0, 1.0], [5.0, 40.0, 10.0])
    tb = ([-0.5, 0.5], [30.0, 2.0])
    mode = {
        "gripper": gripper(),
        "a": pos(ARM_A, 500.0, 5.0, 1e9, actuator=wpctrl.PositionBasedEffortLimit(*ta)),
        "b": pos(ARM_B, 500.0, 5.0, 25.0, actuator=wpctrl.PositionBasedEffortLimit(*tb)),
    }
    ctrl = wpctrl.build_controller(mode, model, 100, 100, actuation="explicit")
    s, q, qd = random_state(model, PANDA_ARM_JOINTS, rng, q_scale=1.5)
    c = model.control()
    ctrl.reset(model.state(), control=c)
    target = (q + rng.normal(0.0, 0.5, q.shape)).astype(f32)
    ctrl.set_action(np.hstack([np.zeros((E, 1), f32), target]), s)
    ctrl.before_simulation_step(s, c)
    tau = c.joint_f.numpy()[indices(model, PANDA_ARM_JOINTS)[1]]
    pd = f32(500.0) * (target - q) + f32(5.0) * (f32(0.0) - qd)
    for cols, (x, y), lim in ((slice(0, 3), ta, 1e9), (slice(3, 7), tb, 25.0)):
        comp = ClampingPositionBased(lookup_positions=tuple(x), lookup_efforts=tuple(y))
        comp.finalize(wp.get_device("cpu"), pd[:, cols].size)
        ref = np.clip(newton_clamp(comp, pd[:, cols], q[:, cols], qd[:, cols]), -lim, lim)
        np.testing.assert_allclose(tau[:, cols], ref, rtol=1e-5, atol=1e-4)
        table = np.interp(q[:, cols].astype(np.float64), x, y)
        assert (np.abs(pd[:, cols]) > table).any()  # the table binds on this controller's joints


# -- actuator networks: scales, order, a later controller, per-env envelopes, delay ---------------------------------


def init(module, seed=0):
    torch.manual_seed(seed)
    for p in module.parameters():
        torch.nn.init.uniform_(p, -0.6, 0.6)
    return module.eval()


def substeps(ctrl, model, names, rng, steps, targets_in=None):
    """Random joint states before every substep (one control step of K = 1 each); yields what each substep saw:
    (q, qd, the drive target the Control holds after it, joint_f)."""
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    coord, dof = indices(model, names)
    width = ctrl.action_dim
    for k in range(steps):
        s, q, qd = random_state(model, names, rng)
        a = np.zeros((E, width), f32)
        a[:, width - len(names) :] = rng.uniform(-1.0, 1.0, (E, len(names))) if targets_in is None else targets_in[k]
        ctrl.set_action(a, s)
        ctrl.before_simulation_step(s, c)
        yield q, qd, c.joint_target_q.numpy()[coord], c.joint_f.numpy()[dof]


@pytest.mark.parametrize(("order", "kernel"), [("pos_vel", "auto"), ("vel_pos", "auto"), ("pos_vel", "tiled")])
def test_lstm_with_input_scales_on_a_later_controller_equals_torch(order, kernel, monkeypatch):
    """An LSTM actuator on the second controller with pos/vel/torque scales that are not 1 and a per-env DC
    envelope: torch's LSTM on the scaled inputs (in ``input_order``), the output times torque_scale, then Newton's
    ClampingDCMotor at each env's values. Also with the tiled kernel (on Warp's cooperative CPU blocks)."""
    from newton.actuators import ClampingDCMotor

    monkeypatch.setattr(wp.config, "enable_cpu_blocks", kernel != "auto")
    net = init(LSTMNet(hidden=6, layers=2))
    ps, vs, ts = 2.5, 0.3, 40.0
    act = wpctrl.ActuatorNet(net, pos_scale=ps, vel_scale=vs, torque_scale=ts, input_order=order,
                             saturation_effort=50.0, velocity_limit=8.0, kernel=kernel)  # fmt: skip
    model = build_panda(E)
    mode = {"a": pos(ARM_A, 200.0, 10.0, 45.0), "b": pos(ARM_B, 0.0, 0.0, 60.0, actuator=act)}
    ctrl = wpctrl.build_controller(mode, model, 100, 100, actuation="explicit", track_effort=True)
    sat = np.array([[50.0], [20.0], [5.0]], f32) * np.ones((E, 4), f32)
    vmax = np.array([[8.0], [1.0], [3.0]], f32) * np.ones((E, 4), f32)
    lim = np.array([[2.0], [60.0], [60.0]], f32) * np.ones((E, 4), f32)  # env 0's force limit binds first
    ctrl["b"].set_drive_properties(saturation_effort=sat, velocity_limit=vmax, force_limit=lim)
    n = len(ARM_B)
    h = torch.zeros(2, E * n, 6)
    cs = torch.zeros(2, E * n, 6)
    rng = np.random.default_rng(3)
    for q, qd, tq, tau in substeps(ctrl, model, PANDA_ARM_JOINTS, rng, 5):
        err, vel = (tq - q)[:, 3:], qd[:, 3:]
        pair = [err * f32(ps), vel * f32(vs)] if order == "pos_vel" else [vel * f32(vs), err * f32(ps)]
        x = torch.from_numpy(np.stack(pair, axis=2).reshape(E * n, 1, 2).astype(f32))
        with torch.no_grad():
            u, (h, cs) = net(x, (h, cs))
        u = u.numpy().reshape(E, n) * f32(ts)
        np.testing.assert_allclose(ctrl["b"].computed_effort.numpy(), u, rtol=1e-4, atol=1e-4)
        ref = newton_clamp(
            ClampingDCMotor(wp.array(sat.ravel()), wp.array(vmax.ravel()), wp.array(lim.ravel())),
            u,
            q[:, 3:],
            vel,
        )
        np.testing.assert_allclose(tau[:, 3:], ref, rtol=1e-4, atol=1e-4)
        # the first controller: ManiSkill's PD law and clamp, untouched by the network
        pd = f32(200.0) * (tq - q)[:, :3] + f32(10.0) * (f32(0.0) - qd[:, :3])
        np.testing.assert_allclose(tau[:, :3], np.clip(pd, -45.0, 45.0), rtol=1e-5, atol=1e-4)
    assert np.abs(u).max() > 5.0  # real torques (a test of something)
    assert np.abs(tau[0, 3:]).max() <= 2.0 + 1e-5 and np.abs(u[0]).max() > 2.0  # env 0's own force limit bound


@pytest.mark.parametrize("kernel", ["auto", "3xtf32"])
def test_mlp_with_history_and_per_env_envelope_on_a_later_controller_equals_torch(kernel):
    """An MLP actuator (history taps (0, 2), input scales not 1) on the second controller, whose rows start at the
    arm's fourth joint, with a DC envelope and force limits that differ per env: torch's MLP on the scaled history,
    times torque_scale, then Newton's ClampingDCMotor at each env's values. Also on the tensor-core kernel (on the
    CPU: its per-row build of the same splits and packed weights)."""
    from newton.actuators import ClampingDCMotor

    mlp = init(torch.nn.Sequential(torch.nn.Linear(4, 16), torch.nn.Softsign(), torch.nn.Linear(16, 1)), seed=6)
    idx, ps, vs, ts = (0, 2), 1.7, 0.4, 30.0
    act = wpctrl.ActuatorNet(mlp, input_idx=idx, pos_scale=ps, vel_scale=vs, torque_scale=ts, saturation_effort=50.0,
                             velocity_limit=8.0, kernel=kernel)  # fmt: skip
    model = build_panda(E)
    mode = {"a": pos(ARM_A, 200.0, 10.0, 45.0), "b": pos(ARM_B, 0.0, 0.0, 60.0, actuator=act)}
    ctrl = wpctrl.build_controller(mode, model, 100, 100, actuation="explicit", track_effort=True)
    assert ctrl._engine.part("actuator_models").nets[0].kernel_kind == ("unrolled" if kernel == "auto" else kernel)
    sat = np.array([[50.0], [20.0], [5.0]], f32) * np.ones((E, 4), f32)
    vmax = np.array([[8.0], [1.0], [3.0]], f32) * np.ones((E, 4), f32)
    lim = np.array([[2.0], [60.0], [60.0]], f32) * np.ones((E, 4), f32)  # env 0's force limit binds first
    ctrl["b"].set_drive_properties(saturation_effort=sat, velocity_limit=vmax, force_limit=lim)
    hist_e = np.zeros((E, 3, 4), f32)
    hist_v = np.zeros((E, 3, 4), f32)
    rng = np.random.default_rng(8)
    for q, qd, tq, tau in substeps(ctrl, model, PANDA_ARM_JOINTS, rng, 5):
        hist_e = np.roll(hist_e, 1, axis=1)
        hist_v = np.roll(hist_v, 1, axis=1)
        hist_e[:, 0], hist_v[:, 0] = (tq - q)[:, 3:], qd[:, 3:]
        x = np.concatenate([np.stack([hist_e[:, i] for i in idx], 2).reshape(E * 4, 2) * f32(ps),
                            np.stack([hist_v[:, i] for i in idx], 2).reshape(E * 4, 2) * f32(vs)], axis=1)  # fmt: skip
        with torch.no_grad():
            u = mlp(torch.from_numpy(x)).numpy().reshape(E, 4) * f32(ts)
        np.testing.assert_allclose(ctrl["b"].computed_effort.numpy(), u, rtol=1e-4, atol=1e-4)
        envelope = ClampingDCMotor(wp.array(sat.ravel()), wp.array(vmax.ravel()), wp.array(lim.ravel()))
        np.testing.assert_allclose(tau[:, 3:], newton_clamp(envelope, u, q[:, 3:], qd[:, 3:]), rtol=1e-4, atol=1e-4)
        pd = f32(200.0) * (tq - q)[:, :3] + f32(10.0) * (f32(0.0) - qd[:, :3])
        np.testing.assert_allclose(tau[:, :3], np.clip(pd, -45.0, 45.0), rtol=1e-5, atol=1e-4)
    assert np.abs(u).max() > 5.0  # real torques (a test of something)
    assert np.abs(tau[0, 3:]).max() <= 2.0 + 1e-5 and np.abs(u[0]).max() > 2.0  # env 0's own force limit bound


def test_effort_controller_after_a_gripper_with_per_env_limits():
    """A JointEffortController as the mode's second controller, per-joint bounds, force limits that differ per env:
    its columns scale onto its own bounds and each env's torque is clamped to that env's limits, in both actuations."""
    lo = np.array([-30.0, -20.0, -10.0, -40.0, -5.0, -8.0, -1.0], f32)
    hi = -lo * np.array([1.0, 0.5, 2.0, 1.0, 1.0, 0.25, 3.0], f32)
    for actuation in ("implicit", "explicit"):
        model = build_panda(E)
        mode = {"gripper": gripper(), "arm": wpctrl.JointEffortControllerConfig(PANDA_ARM_JOINTS, lo, hi)}
        ctrl = wpctrl.build_controller(mode, model, 20, 100, actuation=actuation)
        lim = np.array([[3.0], [15.0], [100.0]], f32) * np.ones((E, 7), f32)
        ctrl["arm"].set_drive_properties(force_limit=lim)
        s, c = model.state(), model.control()
        ctrl.reset(s, control=c)
        a = np.random.default_rng(8).uniform(-1.2, 1.2, (E, 8)).astype(f32)
        ctrl.set_action(a, s)
        ctrl.before_simulation_step(s, c)
        want = f32(0.5) * (hi + lo) + f32(0.5) * (hi - lo) * np.clip(a[:, 1:], -1, 1)
        np.testing.assert_allclose(ctrl["arm"].processed_action.numpy(), want, rtol=1e-6, atol=1e-5)
        tau = c.joint_f.numpy()[indices(model, PANDA_ARM_JOINTS)[1]]
        np.testing.assert_allclose(tau, np.clip(want, -lim, lim), rtol=1e-6, atol=1e-5)
        assert (np.abs(want[0]) > 3.0).any()  # env 0's limit binds


def test_mlp_on_a_later_controller_reads_the_delayed_target():
    """An MLP (input scales not 1, history taps (0, 1, 3)) on the second controller of a mode built with a command
    delay: the network's position error is the delayed target minus q, as torch computes it from the Control's
    drive target, and that target is the command of ``delay`` substeps ago."""
    mlp = init(torch.nn.Sequential(torch.nn.Linear(6, 8), torch.nn.Tanh(), torch.nn.Linear(8, 1)), seed=1)
    idx, ps, vs, ts = (0, 1, 3), 0.7, 1.9, 12.0
    act = wpctrl.ActuatorNet(mlp, input_idx=idx, pos_scale=ps, vel_scale=vs, torque_scale=ts)
    model = build_panda(E)
    mode = {"gripper": gripper(), "arm": pos(PANDA_ARM_JOINTS, 0.0, 0.0, 1e9, actuator=act)}
    ctrl = wpctrl.build_controller(mode, model, 100, 100, actuation="explicit", delay=2)
    rng = np.random.default_rng(4)
    steps = 7
    commands = rng.uniform(-1.0, 1.0, (steps, E, 7)).astype(f32)
    hist_e = np.zeros((E, 4, 7), f32)
    hist_v = np.zeros((E, 4, 7), f32)
    q0 = model.state().joint_q.numpy()[indices(model, PANDA_ARM_JOINTS)[0]]
    for k, (q, qd, tq, tau) in enumerate(substeps(ctrl, model, PANDA_ARM_JOINTS, rng, steps, commands)):
        want_target = commands[k - 2] if k >= 2 else q0  # the reset filled the history with the reset pose
        np.testing.assert_allclose(tq, want_target, atol=1e-7)
        hist_e = np.roll(hist_e, 1, axis=1)
        hist_v = np.roll(hist_v, 1, axis=1)
        hist_e[:, 0] = tq - q
        hist_v[:, 0] = qd
        x = np.concatenate(
            [np.stack([hist_e[:, i] for i in idx], 2).reshape(E * 7, 3) * f32(ps),
             np.stack([hist_v[:, i] for i in idx], 2).reshape(E * 7, 3) * f32(vs)], axis=1
        )  # fmt: skip
        with torch.no_grad():
            u = mlp(torch.from_numpy(x)).numpy().reshape(E, 7) * f32(ts)
        np.testing.assert_allclose(tau, u, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("kernel", ["auto", "tiled"])
def test_two_networks_in_one_mode_keep_their_own_weights_scales_and_state(kernel, monkeypatch):
    """An MLP on the first controller and an LSTM on the second, different scales: each row gets its own network
    (also with the tiled kernel, on Warp's cooperative CPU blocks)."""
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", kernel != "auto")
    mlp = init(torch.nn.Sequential(torch.nn.Linear(2, 5), torch.nn.ELU(0.5), torch.nn.Linear(5, 1)), seed=2)
    lstm = init(LSTMNet(hidden=4, layers=1), seed=3)
    mode = {
        "a": pos(ARM_A, 0.0, 0.0, 1e9, actuator=wpctrl.ActuatorNet(mlp, input_idx=(0,), pos_scale=3.0, vel_scale=0.5,
                                                                      torque_scale=7.0, kernel=kernel)),
        "b": pos(ARM_B, 0.0, 0.0, 1e9, actuator=wpctrl.ActuatorNet(lstm, pos_scale=0.25, vel_scale=2.0,
                                                                      torque_scale=-9.0, kernel=kernel)),
    }  # fmt: skip
    model = build_panda(E)
    ctrl = wpctrl.build_controller(mode, model, 100, 100, actuation="explicit")
    want = "tiled" if kernel != "auto" else "unrolled"
    assert [g.kernel_kind for g in ctrl._engine.part("actuator_models").nets] == [want, want]  # private: the kernels
    h = torch.zeros(1, E * 4, 4)
    cs = torch.zeros(1, E * 4, 4)
    rng = np.random.default_rng(5)
    for q, qd, tq, tau in substeps(ctrl, model, PANDA_ARM_JOINTS, rng, 4):
        e, v = tq - q, qd
        xa = np.stack([e[:, :3] * f32(3.0), v[:, :3] * f32(0.5)], axis=2).reshape(E * 3, 2)
        with torch.no_grad():
            ua = mlp(torch.from_numpy(xa)).numpy().reshape(E, 3) * f32(7.0)
            xb = torch.from_numpy(np.stack([e[:, 3:] * f32(0.25), v[:, 3:] * f32(2.0)], axis=2).reshape(E * 4, 1, 2))
            ub, (h, cs) = lstm(xb, (h, cs))
        np.testing.assert_allclose(tau[:, :3], ua, rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(tau[:, 3:], ub.numpy().reshape(E, 4) * f32(-9.0), rtol=1e-4, atol=1e-4)


def test_mlp_layers_without_bias_leaky_relu_and_dropout_equal_torch():
    """A Linear layer without a bias, LeakyReLU's slope, a Sigmoid and (in eval) a Dropout, read from the module:
    the network's torque equals torch's on the same inputs."""
    mlp = init(
        torch.nn.Sequential(
            torch.nn.Linear(2, 6, bias=False), torch.nn.LeakyReLU(0.3), torch.nn.Dropout(0.5), torch.nn.Linear(6, 4),
            torch.nn.Sigmoid(), torch.nn.Linear(4, 1),
        ),
        seed=4,
    )  # fmt: skip
    act = wpctrl.ActuatorNet(mlp, input_idx=(0,), pos_scale=2.0, vel_scale=0.5, torque_scale=30.0)
    model = build_panda(E)
    ctrl = wpctrl.build_controller(
        pos(PANDA_ARM_JOINTS, 0.0, 0.0, 1e9, actuator=act), model, 100, 100, actuation="explicit"
    )
    rng = np.random.default_rng(9)
    for q, qd, tq, tau in substeps(ctrl, model, PANDA_ARM_JOINTS, rng, 2):
        x = np.stack([(tq - q) * f32(2.0), qd * f32(0.5)], axis=2).reshape(E * 7, 2)
        with torch.no_grad():
            u = mlp(torch.from_numpy(x)).numpy().reshape(E, 7) * f32(30.0)
        np.testing.assert_allclose(tau, u, rtol=1e-4, atol=1e-4)


# -- smoothing and binary commands on several controllers -----------------------------------------------------------


def test_ema_weights_and_binary_command_stay_with_their_own_controller():
    """Two smoothed controllers with different weights and bounds, then a binary gripper: numpy float32 of
    ``alpha * target + (1 - alpha) * previous`` clamped to each joint's limits, per controller, and the gripper's
    sign rule."""
    model = build_panda(E)
    lim = np.stack([model.joint_limit_lower.numpy(), model.joint_limit_upper.numpy()], 1)
    coord, _ = indices(model, PANDA_ARM_JOINTS)
    qlim = lim[indices(model, PANDA_ARM_JOINTS)[1][0]]
    mode = {
        "a": wpctrl.PDJointPosControllerConfig(ARM_A, -2.0, 2.0, 1e3, 1e2, ema=0.2),
        "b": wpctrl.PDJointPosControllerConfig(ARM_B, -0.5, 3.0, 1e3, 1e2, ema=0.9),
        "gripper": gripper(binary=True),
    }
    ctrl = wpctrl.build_controller(mode, model)
    s = model.state()
    ctrl.reset(s)
    prev = s.joint_q.numpy()[coord].astype(f32)
    alpha = np.array([0.2] * 3 + [0.9] * 4, f32)
    low = np.array([-2.0] * 3 + [-0.5] * 4, f32)
    high = np.array([2.0] * 3 + [3.0] * 4, f32)
    rng = np.random.default_rng(6)
    for _ in range(3):
        a = rng.uniform(-1.5, 1.5, (E, 8)).astype(f32)
        a[:, 7] = [-0.5, 0.0, 0.5]
        ctrl.set_action(a, s)
        x = np.clip(a[:, :7], -1, 1)
        u = f32(0.5) * (high + low) + f32(0.5) * (high - low) * x
        prev = np.clip(alpha * u + (f32(1.0) - alpha) * prev, qlim[:, 0], qlim[:, 1])
        np.testing.assert_allclose(np.hstack([ctrl["a"].target_qpos.numpy(), ctrl["b"].target_qpos.numpy()]), prev,
                                   atol=2e-6)  # fmt: skip
        grip = np.array([-0.01, 0.04, 0.04], f32)
        np.testing.assert_array_equal(ctrl["gripper"].target_qpos.numpy(), np.stack([grip, grip], 1))


# -- effort readout: per-env limits on a later controller -----------------------------------------------------------


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
def test_effort_readout_with_per_env_limits_on_a_later_controller(actuation):
    """track_effort on the second controller, force limits that differ per env: the PD law, its clamp to each env's
    limit and the count of saturated substeps, against numpy, over two control steps of K = 2."""
    model = build_panda(E)
    mode = {"a": pos(ARM_A, 100.0, 5.0, 1e9), "b": pos(ARM_B, 800.0, 30.0, 50.0)}
    ctrl = wpctrl.build_controller(mode, model, 50, 100, actuation=actuation, track_effort=True)
    lim = np.array([[5.0], [50.0], [500.0]], f32) * np.ones((E, 4), f32)
    ctrl["b"].set_drive_properties(force_limit=lim)
    rng = np.random.default_rng(7)
    s0 = model.state()
    c = model.control()
    ctrl.reset(s0, control=c)
    count = np.zeros((E, 4), np.int64)
    for _ in range(2):
        s, q, qd = random_state(model, PANDA_ARM_JOINTS, rng)
        target = (q + rng.normal(0.0, 0.2, q.shape)).astype(f32)
        ctrl.set_action(target, s)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s, c)
            u = f32(800.0) * (target[:, 3:] - q[:, 3:]) + f32(30.0) * (f32(0.0) - qd[:, 3:])
            f = np.clip(u, -lim, lim)
            count += np.abs(u) > lim
            np.testing.assert_allclose(ctrl["b"].computed_effort.numpy(), u, rtol=1e-5, atol=1e-4)
            np.testing.assert_allclose(ctrl["b"].applied_effort.numpy(), f, rtol=1e-5, atol=1e-4)
            np.testing.assert_array_equal(ctrl["b"].saturation_count.numpy(), count)
    assert count[0].sum() > count[2].sum()  # the tight env saturates more (the per-env limit is the one used)
    ctrl.reset(s0, env_ids=[1], control=c)
    count[1] = 0
    np.testing.assert_array_equal(ctrl["b"].saturation_count.numpy(), count)
