"""An actuator network run in the substep kernel's launch (``ActuatorNet.launch="fused"``, what ``"auto"`` picks
where it is allowed) against the same mode run as two launches (``"separate"``: the substep kernel, then the unrolled
network kernel): the same joint_f, drive targets, effort readout, substep counter, history and LSTM state after every
substep, bit for bit, over control steps of 5 substeps with random states, a partial reset and a later controller's
rows. Which launch ``"auto"`` picks, and ``"fused"`` refused with the reason where the mode does not allow it."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from conftest import HAS_CUDA, build_panda
from user_models import indices, put

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS

torch = pytest.importorskip("torch", reason="torch is a dev dependency (the networks are torch modules)")

from actuator_nets import LSTMNet  # noqa: E402

pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")

f32 = np.float32
E = 5
MIMIC = {"panda_finger_joint2": {"joint": "panda_finger_joint1"}}


def _network(kind):
    torch.manual_seed(3)
    if kind == "mlp":
        net = torch.nn.Sequential(torch.nn.Linear(6, 16), torch.nn.Softsign(), torch.nn.Linear(16, 16),
                                  torch.nn.ELU(0.7), torch.nn.Linear(16, 1))  # fmt: skip
    else:
        net = LSTMNet(hidden=5, layers=2)
    for p in net.parameters():
        torch.nn.init.uniform_(p, -0.6, 0.6)
    return net.eval()


def _build(kind, launch, device="cpu", **joint_kw):
    act = wpctrl.ActuatorNet(_network(kind), pos_scale=2.0, vel_scale=0.3, torque_scale=300.0, saturation_effort=40.0,
                             velocity_limit=5.0, kernel="unrolled", launch=launch)  # fmt: skip
    mode = {
        "gripper": wpctrl.PDJointPosMimicControllerConfig(PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1e3, 1e2, mimic=MIMIC),
        "arm": wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, -1.0, 1.0, 0.0, 0.0, 60.0, use_delta=True,
                                                 actuator=act, **joint_kw),
    }  # fmt: skip
    model = build_panda(E, device)
    ctrl = wpctrl.build_controller(mode, model, 20, 100, actuation="explicit", track_effort=True)
    return model, ctrl


def fused(ctrl) -> bool:
    """Whether the mode's network runs in the substep kernel's launch (private: the engine's choice, made at build)."""
    models = ctrl._engine.part("actuator_models")
    return models.fused is not None


def _run(kind, launch, device="cpu"):
    """Everything the mode writes after each substep of 4 control steps (a partial reset after the second)."""
    model, ctrl = _build(kind, launch, device)
    # values that differ per env, read by both parts of the one launch: the network rows' DC envelope and force
    # limits, the gripper's gains (the substep threads' PD rows)
    per_env = np.linspace(0.4, 1.6, E, dtype=f32)[:, None]
    ctrl["arm"].set_drive_properties(saturation_effort=40.0 * per_env * np.ones((E, 7), f32),
                                     velocity_limit=5.0 * per_env * np.ones((E, 7), f32),
                                     force_limit=60.0 / per_env * np.ones((E, 7), f32))  # fmt: skip
    ctrl["gripper"].set_drive_properties(stiffness=1e3 * per_env * np.ones((E, 2), f32),
                                         damping=1e2 * per_env * np.ones((E, 2), f32))  # fmt: skip
    rng = np.random.default_rng(11)
    names = [*PANDA_ARM_JOINTS, *PANDA_GRIPPER_JOINTS]
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    arm, models = ctrl["arm"], ctrl._engine.part("actuator_models")
    out = []
    for step in range(4):
        if step == 2:
            ctrl.reset(s, env_ids=wp.array([1, 3], dtype=wp.int32, device=device), control=c)
        ctrl.set_action(wp.array(rng.uniform(-1.0, 1.0, (E, ctrl.action_dim)).astype(f32), device=device), s)
        for _ in range(ctrl.num_substeps):
            s = model.state()
            put(s, model, names, rng.uniform(-1.0, 1.0, (E, 9)).astype(f32), rng.uniform(-4.0, 4.0, (E, 9)).astype(f32))
            ctrl.before_simulation_step(s, c)
            g = models.nets[0]
            arrays = (c.joint_f, c.joint_target_q, arm.computed_effort, arm.applied_effort, arm.saturation_count,
                      ctrl._engine.core.step, g.hist, g.lstm_h, g.lstm_c)  # fmt: skip
            out.append([a.numpy().copy() for a in arrays])  # (on the CPU .numpy() is a view: copy)
    return out, ctrl


CUDA = pytest.mark.skipif(not HAS_CUDA, reason="needs a CUDA device: the GPU build of both paths")


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=CUDA)])
@pytest.mark.parametrize("kind", ["mlp", "lstm"])
def test_fused_launch_equals_the_two_launches(kind, device):
    """Bit for bit on the CPU; on CUDA to float32 rounding (the fused kernel is compiled with the network kernel's fast
    math, the substep kernel without: the same code here, no division in these PD rows, but not promised bitwise)."""
    ref, sep = _run(kind, "separate", device=device)
    got, ctrl = _run(kind, "fused", device=device)
    # private: one launch per substep, of the fused kernel, the network's own launch never recorded; the reference
    # really ran two (the substep kernel, then the network's own launch)
    assert not _ran_two_launches(ctrl) and ctrl._engine.part("actuator_models").nets[0]._launch is None
    assert _ran_two_launches(sep)
    assert len(ref) == 4 * ctrl.num_substeps == 20
    saturated = 0
    for k, (a, b) in enumerate(zip(ref, got)):
        for i, (x, y) in enumerate(zip(a, b)):
            if device == "cpu" or x.dtype != f32:
                np.testing.assert_array_equal(y, x, err_msg=f"substep {k}, output {i}")
            else:
                np.testing.assert_allclose(y, x, rtol=1e-5, atol=1e-5, err_msg=f"substep {k}, output {i}")
        saturated += int(a[4].sum())
    # the outputs are not trivial: non-zero efforts on every arm DOF, some clamped by the envelope, moving targets
    assert np.count_nonzero(ref[-1][0]) >= E * 7 and saturated > 0
    assert not np.array_equal(ref[4][1], ref[5][1])


def _ran_two_launches(ctrl) -> bool:
    """After a substep: the substep kernel ran alone and the network had its own launch (private attributes)."""
    eng = ctrl._engine
    return not eng._launch_substep._cmd.kernel.key.startswith("wpctrl_substep_actuator_net") and all(
        g._launch is not None for g in eng.part("actuator_models").nets
    )


def _one_substep(ctrl, model):
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    ctrl.set_action(np.zeros((E, ctrl.action_dim), f32), s)
    ctrl.before_simulation_step(s, c)


def test_auto_runs_the_network_in_the_substeps_launch_where_allowed():
    """The default (``launch="auto"``, ``kernel="auto"``: the unrolled kernel for this network) runs one launch."""
    act = wpctrl.ActuatorNet(_network("lstm"))
    assert act.launch == "auto"
    model = build_panda(E)
    mode = {"arm": wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 0, 0, actuator=act)}
    ctrl = wpctrl.build_controller(mode, model, 20, 100, actuation="explicit")
    assert fused(ctrl)
    _one_substep(ctrl, model)
    assert ctrl._engine._launch_substep._cmd.kernel.key.startswith("wpctrl_substep_actuator_net")
    assert not _ran_two_launches(ctrl)


def _mode_that_cannot_fuse(why, launch):
    """A mode where the network cannot run in the substep's launch, for each reason."""
    act = lambda **kw: wpctrl.ActuatorNet(_network("mlp"), launch=launch, **kw)  # noqa: E731
    arm = lambda joints, **kw: wpctrl.PDJointPosControllerConfig(joints, None, None, 0, 0, **kw)  # noqa: E731
    kw = {"actuation": "explicit"}
    if why == "delay":
        mode, kw["delay"] = {"arm": arm(PANDA_ARM_JOINTS, actuator=act())}, 1
    elif why == "interpolate":
        mode = {"arm": arm(PANDA_ARM_JOINTS, actuator=act(), interpolate=True)}
    elif why == "tiled":
        mode = {"arm": arm(PANDA_ARM_JOINTS, actuator=act(kernel="tiled"))}
    else:  # two networks
        mode = {"a": arm(PANDA_ARM_JOINTS[:3], actuator=act()), "b": arm(PANDA_ARM_JOINTS[3:], actuator=act())}
    return mode, kw


CANNOT = [
    ("delay", "a command delay"),
    ("interpolate", "interpolated targets"),
    ("tiled", "takes the unrolled kernel, this network runs the tiled"),
    ("two", "takes one network, this mode has 2"),
]


@pytest.mark.parametrize(("why", "message"), CANNOT)
def test_auto_runs_two_launches_where_the_mode_does_not_allow_one(why, message):
    """``"auto"`` falls back to the two launches, and they are right: each substep's torque is torch's MLP on the
    history (taps 0, 1, 2) of the drive target the Control holds (delayed / interpolated) minus q, and of qd."""
    mode, kw = _mode_that_cannot_fuse(why, "auto")
    model = build_panda(E)
    ctrl = wpctrl.build_controller(mode, model, 20, 100, **kw)
    assert not fused(ctrl)
    net, coord_dof = _network("mlp"), indices(model, PANDA_ARM_JOINTS)
    rng = np.random.default_rng(2)
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    hist_e, hist_v = np.zeros((E, 3, 7), f32), np.zeros((E, 3, 7), f32)
    targets = set()
    for _ in range(3):
        ctrl.set_action(rng.uniform(-1.0, 1.0, (E, ctrl.action_dim)).astype(f32), s)
        for _ in range(ctrl.num_substeps):
            q, qd = rng.uniform(-1.0, 1.0, (E, 7)).astype(f32), rng.uniform(-3.0, 3.0, (E, 7)).astype(f32)
            put(s, model, PANDA_ARM_JOINTS, q, qd)
            ctrl.before_simulation_step(s, c)
            target = c.joint_target_q.numpy()[coord_dof[0]]
            hist_e, hist_v = np.roll(hist_e, 1, axis=1), np.roll(hist_v, 1, axis=1)
            hist_e[:, 0], hist_v[:, 0] = target - q, qd
            x = np.concatenate([hist_e.transpose(0, 2, 1), hist_v.transpose(0, 2, 1)], axis=2).reshape(E * 7, 6)
            with torch.no_grad():
                u = net(torch.from_numpy(x)).numpy().reshape(E, 7)
            np.testing.assert_allclose(c.joint_f.numpy()[coord_dof[1]], u, rtol=1e-5, atol=1e-5)
            targets.add(target.tobytes())
    assert _ran_two_launches(ctrl)
    assert np.abs(u).max() > 0.1 and len(targets) >= 3  # real torques, moving targets (a test of something)


@pytest.mark.parametrize(("why", "message"), CANNOT)
def test_fused_is_refused_with_the_reason_where_the_mode_does_not_allow_it(why, message):
    mode, kw = _mode_that_cannot_fuse(why, "fused")
    with pytest.raises(
        wpctrl.ConfigError, match=rf"actuator.launch: expected 'auto' or 'separate' .*{message}.*got 'fused'"
    ):
        wpctrl.build_controller(mode, build_panda(E), 20, 100, **kw)


def test_launch_is_validated_and_fused_is_refused_beside_a_separate_network():
    with pytest.raises(
        wpctrl.ConfigError,
        match=r"PDJointPosControllerConfig.actuator.launch: expected 'auto', 'fused' or 'separate', got 'one'",
    ):
        _build("mlp", "one")
    net = lambda launch: wpctrl.ActuatorNet(_network("mlp"), launch=launch)  # noqa: E731
    mode = {
        "a": wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS[:3], None, None, 0, 0, actuator=net("separate")),
        "b": wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS[3:], None, None, 0, 0, actuator=net("fused")),
    }
    with pytest.raises(wpctrl.ConfigError, match=r"the mode's other network runs in a launch of its own"):
        wpctrl.build_controller(mode, build_panda(E), 20, 100, actuation="explicit")
