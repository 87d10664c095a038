"""An actuator network run in the substep kernel's launch (``ActuatorModels.fuse``, the benchmark's ``*_fused``
variants) against the same mode run as two launches (the substep kernel, then the unrolled network kernel): the
same joint_f, drive targets, effort readout, substep counter, history and LSTM state after every substep, bit for
bit, over control steps of 5 substeps with random states, a partial reset and a later controller's rows."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from conftest import HAS_CUDA, build_panda
from user_models import put

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS

torch = pytest.importorskip("torch", reason="torch is a dev dependency (the networks are torch modules)")
pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")

f32 = np.float32
E = 5
MIMIC = {"panda_finger_joint2": {"joint": "panda_finger_joint1"}}


class _LSTMNet(torch.nn.Module):
    def __init__(self, hidden=5, layers=2):
        super().__init__()
        self.lstm = torch.nn.LSTM(2, hidden, layers, batch_first=True)
        self.linear = torch.nn.Linear(hidden, 1)

    def forward(self, x, hc: tuple[torch.Tensor, torch.Tensor]):
        out, (h, c) = self.lstm(x, hc)
        return self.linear(out), (h, c)


def _network(kind):
    torch.manual_seed(3)
    if kind == "mlp":
        net = torch.nn.Sequential(torch.nn.Linear(6, 16), torch.nn.Softsign(), torch.nn.Linear(16, 16),
                                  torch.nn.ELU(0.7), torch.nn.Linear(16, 1))  # fmt: skip
    else:
        net = _LSTMNet()
    for p in net.parameters():
        torch.nn.init.uniform_(p, -0.6, 0.6)
    return net.eval()


def _build(kind, fused, device="cpu", **joint_kw):
    act = wpctrl.ActuatorNet(_network(kind), pos_scale=2.0, vel_scale=0.3, torque_scale=300.0, saturation_effort=40.0,
                             velocity_limit=5.0, kernel="unrolled")  # fmt: skip
    mode = {
        "gripper": wpctrl.PDJointPosMimicControllerConfig(PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1e3, 1e2, mimic=MIMIC),
        "arm": wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, -1.0, 1.0, 0.0, 0.0, 60.0, use_delta=True,
                                                 actuator=act, **joint_kw),
    }  # fmt: skip
    model = build_panda(E, device)
    ctrl = wpctrl.build_controller(mode, model, 20, 100, actuation="explicit", track_effort=True)
    if fused:
        ctrl._engine.part("actuator_models").fuse(ctrl._engine)  # private: the benchmark's switch
    return model, ctrl


def _run(kind, fused, device="cpu"):
    """Everything the mode writes after each substep of 4 control steps (a partial reset after the second)."""
    model, ctrl = _build(kind, fused, device)
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
    ref, _ = _run(kind, fused=False, device=device)
    got, ctrl = _run(kind, fused=True, device=device)
    # private: one launch per substep, of the fused kernel; the network's own launch never recorded
    assert ctrl._engine._launch_substep._cmd.kernel.key.startswith("wpctrl_substep_actuator_net")
    assert ctrl._engine.part("actuator_models").nets[0]._launch is None
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


@pytest.mark.parametrize(
    ("joint_kw", "why"),
    [({"interpolate": True}, "interpolated targets"), ({"delay": 1}, "a command delay")],
)
def test_fuse_refuses_targets_the_network_rows_cannot_read(joint_kw, why):
    if "delay" in joint_kw:
        act = wpctrl.ActuatorNet(_network("mlp"), kernel="unrolled")
        mode = {"arm": wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 0, 0, actuator=act)}
        ctrl = wpctrl.build_controller(mode, build_panda(E), 20, 100, actuation="explicit", delay=1)
    else:
        _, ctrl = _build("mlp", False, **joint_kw)
    with pytest.raises(wpctrl.ConfigError, match=f"substep's launch: not with {why}"):
        ctrl._engine.part("actuator_models").fuse(ctrl._engine)


def test_fuse_refuses_other_kernels_and_a_started_mode():
    act = wpctrl.ActuatorNet(_network("mlp"), kernel="tiled")
    mode = {"arm": wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 0, 0, actuator=act)}
    ctrl = wpctrl.build_controller(mode, build_panda(E), 20, 100, actuation="explicit")
    with pytest.raises(wpctrl.ConfigError, match="needs one network with the unrolled kernel"):
        ctrl._engine.part("actuator_models").fuse(ctrl._engine)
    model, ctrl = _build("mlp", False)
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    ctrl.set_action(np.zeros((E, ctrl.action_dim), f32), s)
    ctrl.before_simulation_step(s, c)
    with pytest.raises(wpctrl.ConfigError, match="before the first substep"):
        ctrl._engine.part("actuator_models").fuse(ctrl._engine)
