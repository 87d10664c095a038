"""Actuator networks (Isaac Lab's ActuatorNetMLP / ActuatorNetLSTM conventions) evaluated in Warp, against the same
TorchScript network run in torch with the histories / hidden states kept in numpy, per env, with partial resets.

Both network kernels (``kernel="unrolled"``: weights compiled in; ``"tiled"``: weights in shared memory, rows in
tiles) on every supported structure: each activation, depth 1 to 6, MLP input orders and history taps, LSTM depth and
width with a head, random and trained weights; a batch that is not a multiple of the tile size (Warp's cooperative
CPU blocks run the tiled kernel's 64-row tiles on the CPU); CUDA when there is a device."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import torch
import warp as wp
from actuator_nets import LSTMNet
from conftest import HAS_CUDA, build_panda

import wpctrl
from wpctrl.kernels import actuator_net as KN
from wpctrl.robots import PANDA_ARM_JOINTS

KERNELS = ("unrolled", "tiled")
MLP_KERNELS = (*KERNELS, "3xtf32")


pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")
f32 = np.float32
E = 3
J = 7


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
    b = ctrl  # the controlled joints' coord_index / dof_index
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


@pytest.mark.parametrize("kernel", MLP_KERNELS)
@pytest.mark.parametrize("order", ["pos_vel", "vel_pos"])
def test_mlp_actuator_equals_torch_with_history_and_partial_reset(tmp_path, order, kernel):
    mlp = torch.nn.Sequential(
        torch.nn.Linear(6, 16), torch.nn.Softsign(), torch.nn.Linear(16, 16), torch.nn.ELU(0.7), torch.nn.Linear(16, 1)
    )
    path, net = _scripted(mlp, tmp_path, "mlp")
    idx, ps, vs, ts = (0, 2, 4), 1.3, 0.2, 25.0
    act = wpctrl.ActuatorNet(path, input_idx=idx, pos_scale=ps, vel_scale=vs, torque_scale=ts, input_order=order,
                             kernel=kernel)  # fmt: skip
    cfg = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 0.0, 0.0, 40.0, normalize_action=False,
                                            actuator=act)  # fmt: skip
    model = build_panda(E)
    ctrl = wpctrl.build_controller(cfg, model, 100, 100, actuation="explicit", track_effort=True)
    assert ctrl._engine.part("actuator_models").nets[0].kernel_kind == kernel  # private: the variant that runs
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


@pytest.mark.parametrize("kernel", KERNELS)
def test_lstm_actuator_equals_torch_with_hidden_state_and_partial_reset(tmp_path, kernel):
    path, net = _scripted(LSTMNet(hidden=8, layers=2), tmp_path, "lstm")
    act = wpctrl.ActuatorNet(path, saturation_effort=30.0, velocity_limit=6.0, kernel=kernel)
    cfg = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 0.0, 0.0, 1e9, normalize_action=False,
                                            actuator=act)  # fmt: skip
    model = build_panda(E)
    ctrl = wpctrl.build_controller(cfg, model, 100, 100, actuation="explicit", track_effort=True)
    assert ctrl._engine.part("actuator_models").nets[0].kernel_kind == kernel  # private: the variant that runs
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


class _Reference:
    """An actuator network in torch as Isaac Lab runs it: the MLP's histories / the LSTM's state per (env, joint)."""

    def __init__(self, net, act: wpctrl.ActuatorNet, lstm: tuple[int, int] | None, envs: int):
        self.net, self.act, self.lstm, self.E = net, act, lstm, envs
        if lstm is None:
            self.hist_e = np.zeros((envs, max(act.input_idx) + 1, J), f32)
            self.hist_v = np.zeros_like(self.hist_e)
        else:
            self.h = torch.zeros(lstm[0], envs * J, lstm[1])
            self.c = torch.zeros(lstm[0], envs * J, lstm[1])

    def reset(self, mask: np.ndarray) -> None:
        if self.lstm is None:
            self.hist_e[mask] = 0.0
            self.hist_v[mask] = 0.0
        else:
            m = torch.from_numpy(mask)
            self.h.view(self.lstm[0], self.E, J, -1)[:, m] = 0.0
            self.c.view(self.lstm[0], self.E, J, -1)[:, m] = 0.0

    def step(self, q, qd, target) -> np.ndarray:
        a, E = self.act, self.E
        with torch.no_grad():
            if self.lstm is None:
                self.hist_e = np.roll(self.hist_e, 1, axis=1)
                self.hist_v = np.roll(self.hist_v, 1, axis=1)
                self.hist_e[:, 0] = target - q
                self.hist_v[:, 0] = qd
                idx = list(a.input_idx)
                pos = self.hist_e[:, idx].transpose(0, 2, 1).reshape(E * J, -1) * f32(a.pos_scale)
                vel = self.hist_v[:, idx].transpose(0, 2, 1).reshape(E * J, -1) * f32(a.vel_scale)
                x = np.concatenate([pos, vel] if a.input_order == "pos_vel" else [vel, pos], axis=1)
                u = self.net(torch.from_numpy(x)).numpy()
            else:
                pos, vel = (target - q) * f32(a.pos_scale), qd * f32(a.vel_scale)
                x = np.stack([pos, vel] if a.input_order == "pos_vel" else [vel, pos], axis=2).reshape(E * J, 1, 2)
                u, (self.h, self.c) = self.net(torch.from_numpy(x), (self.h, self.c))
                u = u.numpy()
        return u.reshape(E, J) * f32(a.torque_scale)


def _check_against_torch(act, net, lstm, envs: int = E, device: str = "cpu", steps: int = 6, kernel=None):
    """Random states and targets for ``steps`` substeps with a partial reset halfway: the computed effort equals torch's
    forward of the same weights (1e-5), and the applied one is its clamp to the force limit."""
    cfg = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 0.0, 0.0, 40.0, normalize_action=False,
                                            actuator=act)  # fmt: skip
    model = build_panda(envs, device)
    ctrl = wpctrl.build_controller(cfg, model, 100, 100, actuation="explicit", track_effort=True)
    if kernel is not None:
        assert ctrl._engine.part("actuator_models").nets[0].kernel_kind == kernel  # private: the variant
    ref = _Reference(net, act, lstm, envs)
    rng = np.random.default_rng(7)
    s, c = model.state(), model.control()
    ctrl.reset(s, control=c)
    b = ctrl  # the controlled joints' coord_index / dof_index
    worst = 0.0
    for k in range(steps):
        q = s.joint_q.numpy()
        q[b.coord_index] = rng.uniform(-1.0, 1.0, b.coord_index.shape).astype(f32)
        s.joint_q.assign(q)
        qd = s.joint_qd.numpy()
        qd[b.dof_index] = rng.uniform(-3.0, 3.0, b.dof_index.shape).astype(f32)
        s.joint_qd.assign(qd)
        if k == steps // 2:
            mask = np.arange(envs) % 3 == 1
            ctrl.reset(s, wp.array(mask, dtype=wp.bool, device=device), control=c)
            ref.reset(mask)
        target = rng.uniform(-1.0, 1.0, (envs, J)).astype(f32)
        ctrl.set_action(wp.array(target, dtype=wp.float32, device=device), s)
        ctrl.before_simulation_step(s, c)
        u = ref.step(q[b.coord_index], qd[b.dof_index], target)
        np.testing.assert_allclose(ctrl.computed_effort.numpy(), u, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(c.joint_f.numpy()[b.dof_index], np.clip(u, -40.0, 40.0), rtol=1e-5, atol=1e-5)
        worst = max(worst, float(np.abs(u).max()))
    assert worst > 0.5  # the network produces real torques (a test of something)


def _mlp(*layers):
    torch.manual_seed(3)
    net = torch.nn.Sequential(*layers)
    for p in net.parameters():
        torch.nn.init.uniform_(p, -0.7, 0.7)
    return net


@functools.lru_cache(maxsize=1)
def _trained_mlp():
    """A 6-32-32-1 softsign MLP (the shape of Isaac Lab's ANYdrive network) fitted by Adam to a DC-motor-like map
    from position errors and velocities to torque: weights with the structure training leaves."""
    torch.manual_seed(5)
    net = torch.nn.Sequential(torch.nn.Linear(6, 32), torch.nn.Softsign(), torch.nn.Linear(32, 32), torch.nn.Softsign(),
                              torch.nn.Linear(32, 1))  # fmt: skip
    x = torch.rand(256, 6) * 2 - 1
    y = torch.tanh(3.0 * x[:, :1] - 0.8 * x[:, 3:4] + 0.5 * (x[:, :1] - x[:, 1:2])) * 0.8
    opt = torch.optim.Adam(net.parameters(), lr=2e-2)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small products: threads only contend
    try:
        for _ in range(200):
            opt.zero_grad()
            loss = torch.nn.functional.mse_loss(net(x), y)
            loss.backward()
            opt.step()
    finally:
        torch.set_num_threads(threads)
    assert float(loss.detach()) < 5e-3, float(loss.detach())  # it learned the map
    return net


NETWORKS = {
    # every activation, depth 6, two history taps
    "activations": (lambda: _mlp(torch.nn.Linear(4, 8), torch.nn.ReLU(), torch.nn.Linear(8, 8), torch.nn.Tanh(),
                                 torch.nn.Linear(8, 8), torch.nn.Sigmoid(), torch.nn.Linear(8, 8),
                                 torch.nn.LeakyReLU(0.1), torch.nn.Linear(8, 8), torch.nn.Identity(),
                                 torch.nn.Linear(8, 8), torch.nn.ELU(0.5), torch.nn.Linear(8, 1)),
                    {"input_idx": (0, 3), "pos_scale": 2.0, "vel_scale": 0.3, "torque_scale": 8.0}, None),
    # one Linear layer over the current sample only (no history kept)
    "linear": (lambda: _mlp(torch.nn.Linear(2, 1)), {"input_idx": (0,), "torque_scale": 10.0}, None),
    "trained": (_trained_mlp, {"input_idx": (0, 1, 2), "pos_scale": 1.5, "vel_scale": 0.25, "torque_scale": 30.0},
                None),
    # one LSTM layer of 4 units, velocity first, a head with an activation
    "lstm_1x4": (lambda: _LSTMHead(), {"input_order": "vel_pos", "pos_scale": 2.0, "vel_scale": 0.4,
                                       "torque_scale": 5.0}, (1, 4)),
    # widths that are no multiple of 8 (the tensor-core kernel pads them) and narrowing layers
    "odd_widths": (lambda: _mlp(torch.nn.Linear(6, 5), torch.nn.Tanh(), torch.nn.Linear(5, 7), torch.nn.Softsign(),
                                torch.nn.Linear(7, 3), torch.nn.ELU(0.9), torch.nn.Linear(3, 1)),
                   {"input_idx": (0, 1, 4), "pos_scale": 1.2, "vel_scale": 0.3, "torque_scale": 12.0}, None),
    "lstm_2x3": (lambda: _LSTMHead(layers=2, hidden=3, head=False), {"torque_scale": 9.0}, (2, 3)),
    # the tensor-core kernel's widest operands: 64 units (8 tiles of 8), 16 inputs (2 tiles)
    "wide": (lambda: _mlp(torch.nn.Linear(16, 64), torch.nn.Softsign(), torch.nn.Linear(64, 40), torch.nn.Tanh(),
                          torch.nn.Linear(40, 1)),
             {"input_idx": tuple(range(8)), "pos_scale": 1.1, "vel_scale": 0.2, "torque_scale": 6.0}, None),
}  # fmt: skip


class _LSTMHead(torch.nn.Module):
    def __init__(self, layers=1, hidden=4, head=True):
        super().__init__()
        torch.manual_seed(4)
        self.lstm = torch.nn.LSTM(2, hidden, layers, batch_first=True)
        if head:
            self.head = torch.nn.Sequential(torch.nn.Linear(hidden, 4), torch.nn.Tanh(), torch.nn.Linear(4, 1))
        else:
            self.head = torch.nn.Sequential(torch.nn.Linear(hidden, 1))
        for p in self.parameters():
            torch.nn.init.uniform_(p, -0.8, 0.8)

    def forward(self, x, hc: tuple[torch.Tensor, torch.Tensor]):
        out, (h, c) = self.lstm(x, hc)
        return self.head(out), (h, c)


@pytest.mark.parametrize("kernel", MLP_KERNELS)
@pytest.mark.parametrize("name", list(NETWORKS))
def test_network_shapes_equal_torch(tmp_path, name, kernel):
    """Every kernel on every shape; the tensor-core kernel (on the CPU: its per-row build, with the GPU's TF32 split
    and the packed weights) refuses the LSTMs, naming why."""
    make, kw, lstm = NETWORKS[name]
    module = make()
    path = tmp_path / f"{name}.pt"
    torch.jit.script(module).save(str(path))
    net = torch.jit.load(str(path))
    act = wpctrl.ActuatorNet(path, kernel=kernel, **kw)
    if kernel == "3xtf32" and lstm is not None:
        with pytest.raises(wpctrl.ConfigError, match=r"kernel: expected another kernel than '3xtf32' for an LSTM"):
            _check_against_torch(act, net, lstm, kernel=kernel)
        return
    _check_against_torch(act, net, lstm, kernel=kernel)


@pytest.mark.parametrize("kernel", ["tiled"])
@pytest.mark.parametrize("kind", ["mlp", "lstm"])
def test_partial_tile_or_block_on_cpu_blocks(tmp_path, monkeypatch, kind, kernel):
    """Warp's cooperative CPU blocks run the tiled kernel as on a GPU, 13 envs x 7 joints = 91 rows: its second
    64-row tile 27 rows full and 37 threads past the end that still take part in the tile products."""
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", True)
    if kind == "mlp":
        make, kw, lstm = NETWORKS["trained"]
        net = make()
    else:
        net, kw, lstm = LSTMNet(hidden=8, layers=2), {"saturation_effort": 30.0, "velocity_limit": 6.0}, (2, 8)
        torch.manual_seed(0)
        for p in net.parameters():
            torch.nn.init.uniform_(p, -0.6, 0.6)
    act = wpctrl.ActuatorNet(net, kernel=kernel, **kw)
    _check_against_torch(act, net, lstm, envs=13, kernel=kernel)


@pytest.mark.skipif(not HAS_CUDA, reason="needs a CUDA device: the kernels' GPU build (fast math, 64-row tiles)")
@pytest.mark.parametrize("kernel", [*MLP_KERNELS, "auto"])
@pytest.mark.parametrize("name", ["trained", "activations", "lstm_2x8", "odd_widths", "lstm_2x3", "wide"])
def test_networks_equal_torch_on_cuda(name, kernel):
    """On the GPU, with 13 envs (91 rows: one full and one partial 64-row tile, two full and one partial 32-row
    block of the tensor-core kernel's warps; ``"auto"`` runs the unrolled kernel for so few
    rows)."""
    if kernel == "3xtf32" and name.startswith("lstm"):
        pytest.skip("the tensor-core kernel runs MLPs (its refusal of an LSTM is tested on the CPU)")
    if name == "lstm_2x8":
        net, kw, lstm = LSTMNet(hidden=8, layers=2), {"saturation_effort": 30.0, "velocity_limit": 6.0}, (2, 8)
        torch.manual_seed(0)
        for p in net.parameters():
            torch.nn.init.uniform_(p, -0.6, 0.6)
    else:
        make, kw, lstm = NETWORKS[name]
        net = make()
    act = wpctrl.ActuatorNet(net, kernel=kernel, **kw)
    kind = "unrolled" if kernel == "auto" else kernel
    _check_against_torch(act, net, lstm, envs=13, device="cuda:0", kernel=kind)


@pytest.mark.skipif(not HAS_CUDA, reason="needs a CUDA device: the tensor-core kernel's GPU build")
def test_large_mlp_runs_on_the_tensor_cores_by_default_on_cuda():
    """An MLP past the unrolled kernel's size (6-80-80-1: 6,960 multiply-adds per row) runs, with ``kernel="auto"``,
    on the tensor cores of an sm_80+ GPU (else tiled) and gives torch's efforts: 91 rows, the last warp partly full."""
    net = _mlp(torch.nn.Linear(6, 80), torch.nn.Softsign(), torch.nn.Linear(80, 80), torch.nn.Softsign(),
               torch.nn.Linear(80, 1))  # fmt: skip
    act = wpctrl.ActuatorNet(net, input_idx=(0, 1, 2), pos_scale=1.2, vel_scale=0.3, torque_scale=5.0)
    want = "3xtf32" if wp.get_device("cuda:0").arch >= KN.MMA_MIN_SM else "tiled"
    _check_against_torch(act, net, None, envs=13, device="cuda:0", kernel=want)


def test_kernel_choice_and_size_limit():
    small = KN.NetLayout(dense=((6, 32, 5, 0.0, 0, 0), (32, 32, 5, 0.0, 0, 0), (32, 1, 0, 0.0, 0, 0)), lstm=(),
                         taps=(0, 1, 2), history=3, pos_first=True, rows=7)  # fmt: skip
    assert small.macs == 6 * 32 + 32 * 32 + 32 and KN.choose_kernel(small, "auto") == "unrolled"
    big = small._replace(dense=((6, 64, 5, 0.0, 0, 0), (64, 64, 5, 0.0, 0, 0), (64, 1, 0, 0.0, 0, 0)))
    assert big.macs > KN.UNROLLED_MAX_MACS and KN.choose_kernel(big, "auto") == "tiled"  # the CPU
    # past the unrolled kernel's size an MLP runs on the tensor cores of sm_80 or later, if its layers fit them
    assert [KN.choose_kernel(big, "auto", arch) for arch in (75, 80, 90)] == ["tiled", "3xtf32", "3xtf32"]
    assert KN.choose_kernel(small, "auto", 90) == "unrolled"
    wide = big._replace(dense=((6, 136, 5, 0.0, 0, 0), (136, 32, 5, 0.0, 0, 0), (32, 1, 0, 0.0, 0, 0)))
    assert wide.macs > KN.UNROLLED_MAX_MACS and KN.choose_kernel(wide, "auto", 90) == "tiled"
    assert KN.mma_unsupported(wide) == "a layer 136 wide (padded to 8; at most 128)"
    assert KN.mma_unsupported(big._replace(dense=((6, 128, 5, 0.0, 0, 0), (128, 1, 0, 0.0, 0, 0)))) is None
    assert KN.choose_kernel(big, "unrolled") == "unrolled"
    lstm = small._replace(dense=((32, 1, 0, 0.0, 0, 0),), lstm=((2, 32, 0, 0, 0, 0), (32, 32, 0, 0, 0, 0)), taps=())
    assert lstm.macs == 4 * 32 * 34 + 4 * 32 * 64 + 32 and KN.choose_kernel(lstm, "auto") == "tiled"
    assert KN.choose_kernel(lstm, "auto", 90) == "tiled"  # the tensor-core kernel runs MLPs only
    model = build_panda(1)
    huge = torch.nn.Sequential(torch.nn.Linear(6, 200), torch.nn.Tanh(), torch.nn.Linear(200, 100),
                               torch.nn.Linear(100, 1))  # fmt: skip
    cfg = wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS, None, None, 0, 0, normalize_action=False,
                                            actuator=wpctrl.ActuatorNet(huge))  # fmt: skip
    with pytest.raises(wpctrl.ConfigError, match=r"21601 weights and biases; the tiled kernel holds at most 16384"):
        wpctrl.build_controller(cfg, model, actuation="explicit")


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
    for kernel in ("fast", "split", "split2", "split4"):  # the split kernel (measured slower everywhere) is gone
        with pytest.raises(wpctrl.ConfigError, match=rf"kernel: expected 'auto', 'unrolled', '3xtf32' or 'tiled', "
                           rf"got '{kernel}'"):  # fmt: skip
            build(torch.nn.Sequential(torch.nn.Linear(6, 1)), kernel=kernel)
    with pytest.raises(wpctrl.ConfigError, match=r"kernel: expected another kernel than '3xtf32' for a layer 136 wide "
                       r"\(padded to 8; at most 128\), got '3xtf32'"):  # fmt: skip
        build(torch.nn.Sequential(torch.nn.Linear(6, 130), torch.nn.Linear(130, 1)), kernel="3xtf32")
