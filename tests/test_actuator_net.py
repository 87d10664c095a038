"""Actuator networks (Isaac Lab's ActuatorNetMLP / ActuatorNetLSTM conventions) evaluated in Warp, against the same
TorchScript network run in torch with the histories / hidden states kept in numpy, per env, with partial resets."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from conftest import build_panda

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS

pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")
f32 = np.float32
E = 3
J = 7


class _LSTMNet(torch.nn.Module):
    """legged_gym / Isaac Lab's actuator LSTM: torques, (h, c) = net(x, (h, c)) on x of shape (batch, 1, 2)."""

    def __init__(self, hidden=8, layers=2):
        super().__init__()
        self.lstm = torch.nn.LSTM(2, hidden, layers, batch_first=True)
        self.linear = torch.nn.Linear(hidden, 1)

    def forward(self, x, hc: tuple[torch.Tensor, torch.Tensor]):
        out, (h, c) = self.lstm(x, hc)
        return self.linear(out), (h, c)


def _scripted(module, tmp_path, name):
    torch.manual_seed(0)
    for p in module.parameters():
        torch.nn.init.uniform_(p, -0.6, 0.6)
    path = tmp_path / f"{name}.pt"
    torch.jit.script(module).save(str(path))
    return path, torch.jit.load(str(path))


def _rollout(ctrl, model, steps, rng, reset_at=None):
    """Random states and targets per substep; yields (q, qd, target, tau, reset mask or None) for each substep."""
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    b = ctrl._engine.binding
    for k in range(steps):
        q = s.joint_q.numpy()
        q[b.coord_index] = rng.uniform(-1.0, 1.0, b.coord_index.shape).astype(f32)
        s.joint_q.assign(q)
        qd = s.joint_qd.numpy()
        qd[b.dof_index] = rng.uniform(-3.0, 3.0, b.dof_index.shape).astype(f32)
        s.joint_qd.assign(qd)
        mask = None
        if reset_at is not None and k == reset_at:
            mask = np.array([False, True, False])
            ctrl.reset(s, mask, control=c)
        target = rng.uniform(-1.0, 1.0, (E, J)).astype(f32)
        ctrl.set_action(target, s)
        ctrl.before_simulation_step(s, c)
        yield q[b.coord_index], qd[b.dof_index], target, c.joint_f.numpy()[b.dof_index], mask


@pytest.mark.parametrize("order", ["pos_vel", "vel_pos"])
def test_mlp_actuator_equals_torch_with_history_and_partial_reset(tmp_path, order):
    mlp = torch.nn.Sequential(
        torch.nn.Linear(6, 16), torch.nn.Softsign(), torch.nn.Linear(16, 16), torch.nn.ELU(0.7), torch.nn.Linear(16, 1)
    )
    path, net = _scripted(mlp, tmp_path, "mlp")
    idx, ps, vs, ts = (0, 2, 4), 1.3, 0.2, 25.0
    act = wpctrl.ActuatorNet(path, input_idx=idx, pos_scale=ps, vel_scale=vs, torque_scale=ts, input_order=order)
    cfg = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 0.0, 0.0, 40.0, normalize_action=False,
                                            actuator=act)  # fmt: skip
    model = build_panda(E)
    ctrl = wpctrl.build_controller(cfg, model, 100, 100, actuation="explicit", track_effort=True)
    hist_e = np.zeros((E, 5, J), f32)
    hist_v = np.zeros((E, 5, J), f32)
    rng = np.random.default_rng(0)
    worst = 0.0
    for q, qd, target, tau, mask in _rollout(ctrl, model, 8, rng, reset_at=4):
        if mask is not None:
            hist_e[mask] = 0.0
            hist_v[mask] = 0.0
        hist_e = np.roll(hist_e, 1, axis=1)
        hist_v = np.roll(hist_v, 1, axis=1)
        hist_e[:, 0] = target - q
        hist_v[:, 0] = qd
        pos_in = np.stack([hist_e[:, i] for i in idx], axis=2).reshape(E * J, -1) * f32(ps)
        vel_in = np.stack([hist_v[:, i] for i in idx], axis=2).reshape(E * J, -1) * f32(vs)
        x = np.concatenate([pos_in, vel_in] if order == "pos_vel" else [vel_in, pos_in], axis=1)
        with torch.no_grad():
            u = net(torch.from_numpy(x)).numpy().reshape(E, J) * f32(ts)
        np.testing.assert_allclose(ctrl.computed_effort.numpy(), u, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(tau, np.clip(u, -40.0, 40.0), rtol=1e-5, atol=1e-5)
        worst = max(worst, float(np.abs(u).max()))
    assert worst > 1.0  # the network produces real torques (a test of something)


def test_lstm_actuator_equals_torch_with_hidden_state_and_partial_reset(tmp_path):
    path, net = _scripted(_LSTMNet(hidden=8, layers=2), tmp_path, "lstm")
    act = wpctrl.ActuatorNet(path, saturation_effort=30.0, velocity_limit=6.0)
    cfg = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 0.0, 0.0, 1e9, normalize_action=False,
                                            actuator=act)  # fmt: skip
    model = build_panda(E)
    ctrl = wpctrl.build_controller(cfg, model, 100, 100, actuation="explicit", track_effort=True)
    h = torch.zeros(2, E * J, 8)
    c = torch.zeros(2, E * J, 8)
    rng = np.random.default_rng(1)
    for q, qd, target, tau, mask in _rollout(ctrl, model, 8, rng, reset_at=3):
        if mask is not None:
            hv = h.view(2, E, J, 8)
            cv = c.view(2, E, J, 8)
            hv[:, torch.from_numpy(mask)] = 0.0
            cv[:, torch.from_numpy(mask)] = 0.0
        x = torch.from_numpy(np.stack([target - q, qd], axis=2).reshape(E * J, 1, 2))
        with torch.no_grad():
            u, (h, c) = net(x, (h, c))
        u = u.numpy().reshape(E, J)
        np.testing.assert_allclose(ctrl.computed_effort.numpy(), u, rtol=1e-5, atol=1e-5)
        # Isaac Lab's actuator nets are DC motors: the envelope of the measured velocity
        v = np.clip(qd.astype(np.float64), -6.0 * (1 + 1e9 / 30.0), 6.0 * (1 + 1e9 / 30.0))
        hi, lo = np.minimum(30.0 * (1 - v / 6.0), 1e9), np.maximum(30.0 * (-1 - v / 6.0), -1e9)
        np.testing.assert_allclose(tau, np.clip(u, lo, hi), rtol=1e-5, atol=1e-5)


def test_network_errors_name_the_problem(tmp_path):
    model = build_panda(1)

    def build(network, **kw):
        cfg = wpctrl.PDJointPosControllerConfig(
            PANDA_ARM_JOINTS, None, None, 0, 0, normalize_action=False, actuator=wpctrl.ActuatorNet(network, **kw)
        )
        return wpctrl.build_controller(cfg, model, actuation="explicit")

    with pytest.raises(wpctrl.ConfigError, match=r"cannot load TorchScript"):
        build(str(tmp_path / "missing.pt"))
    with pytest.raises(wpctrl.ConfigError, match=r"takes 4 inputs, expected 2 x len\(input_idx\) = 6"):
        build(torch.nn.Sequential(torch.nn.Linear(4, 1)))
    with pytest.raises(wpctrl.ConfigError, match=r"last Linear layer must have 1 output"):
        build(torch.nn.Sequential(torch.nn.Linear(6, 2)))
    with pytest.raises(wpctrl.ConfigError, match=r"layer Conv1d is not supported"):
        build(torch.nn.Sequential(torch.nn.Conv1d(1, 1, 1), torch.nn.Linear(6, 1)))
    with pytest.raises(wpctrl.ConfigError, match=r"input_idx: expected substep indices"):
        build(torch.nn.Sequential(torch.nn.Linear(6, 1)), input_idx=(0, -1, 2))
