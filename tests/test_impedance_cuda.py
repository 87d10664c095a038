"""CUDA parity of the impedance controllers (skipped without a GPU): the same states and actions on CPU and CUDA give
the same OSC and joint-impedance torques (the CUDA kernel runs the unrolled inertia pass, the CPU one the runtime
loops) and target poses; a CUDA graph of a control step replays the eager step bitwise."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import warp as wp
from conftest import HAS_CUDA, build_panda

import wpctrl
from wpctrl.robots import panda_control_modes

pytestmark = pytest.mark.skipif(not HAS_CUDA, reason="no CUDA device")

N = 64


def _mode(name: str) -> dict:
    mode = copy.deepcopy(panda_control_modes()[name])
    mode["balance_passive_force"] = False  # the controller's gravity torque on
    return mode


def _run(device, name: str, graph: bool = False):
    rng = np.random.default_rng(0)
    with wp.ScopedDevice(device):
        model = build_panda(N, device=device)
        ctrl = wpctrl.build_controller(_mode(name), model, actuation="explicit")
        state, control = model.state(), model.control()
        b = ctrl._engine.binding
        q = state.joint_q.numpy()
        q[b.coord_index[:, :7]] += rng.uniform(-0.4, 0.4, (N, 7)).astype(np.float32)
        state.joint_q.assign(q)
        qd = np.zeros(state.joint_qd.shape[0], np.float32)
        qd[b.dof_index] = rng.uniform(-0.5, 0.5, b.dof_index.shape)
        state.joint_qd.assign(qd)
        ctrl.reset(state, control=control)
        action = wp.array(rng.uniform(-1, 1, (N, ctrl.action_dim)).astype(np.float32), device=device)

        def step():
            ctrl.set_action(action, state)
            for _ in range(ctrl.num_substeps):
                ctrl.before_simulation_step(state, control)

        if graph:
            with wp.ScopedCapture(device=device) as cap:
                step()
            ctrl.reset(state, control=control)
            wp.capture_launch(cap.graph)
        else:
            step()
        arm = ctrl["arm"]
        pose = arm.target_pose.numpy() if hasattr(arm, "target_pose") else arm.target_qpos.numpy()
        return arm.target_effort.numpy().astype(np.float64), control.joint_f.numpy(), pose


@pytest.mark.parametrize("name", ["osc_ee_delta_pose", "joint_impedance_delta_pos"])
def test_cpu_and_cuda_torques_agree(name):
    cpu = _run("cpu", name)
    cuda = _run("cuda:0", name)
    scale = np.abs(cpu[0]).max()
    assert scale > 1.0
    assert np.abs(cuda[0] - cpu[0]).max() <= 1e-4 * scale
    np.testing.assert_allclose(cuda[2], cpu[2], atol=2e-6)


@pytest.mark.parametrize("name", ["osc_ee_delta_pose", "joint_impedance_delta_pos"])
def test_cuda_graph_replays_the_eager_step_bitwise(name):
    eager = _run("cuda:0", name)
    replay = _run("cuda:0", name, graph=True)
    for a, b in zip(eager, replay):
        np.testing.assert_array_equal(a, b)
