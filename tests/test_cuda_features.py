"""CUDA parity of the features beyond the Panda's joint controllers (skipped without a GPU): base controllers,
multi-axis joints, actuator models and networks, effort rows, EMA / binary commands. The same controller on the CPU
and on CUDA gets the same states and actions; targets and torques agree, and a graph replay on CUDA equals its eager
run bitwise."""

from __future__ import annotations

import newton
import newton.examples
import numpy as np
import pytest
import warp as wp
from conftest import HAS_CUDA

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, panda

pytestmark = [
    pytest.mark.skipif(not HAS_CUDA, reason="no CUDA device: these tests compare CUDA against the CPU"),
    pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning"),
]
f32 = np.float32
E = 64
GRIP = {"panda_finger_joint2": {"joint": "panda_finger_joint1"}}


def _panda_builder():
    return panda()


def _humanoid_builder():
    b = newton.ModelBuilder()
    b.add_mjcf(newton.examples.get_asset("nv_humanoid.xml"))
    return b


def _run(device, make_builder, make_mode, actuation, steps, seed, graph=False, **kw):
    """Joint targets, velocity targets and joint_f after every substep of ``steps`` control steps."""
    with wp.ScopedDevice(device):
        builder = newton.ModelBuilder()
        builder.replicate(make_builder(), E)
        model = builder.finalize(device=device)
        ctrl = wpctrl.build_controller(make_mode(), model, 20, 100, actuation=actuation, **kw)
        s, c = model.state(), model.control()
        ctrl.reset(s, control=c)
        rng = np.random.default_rng(seed)
        nq, nqd = model.joint_coord_count, model.joint_dof_count
        q0 = s.joint_q.numpy().copy()
        act = wp.zeros(ctrl.action_space.shape, dtype=wp.float32, device=device)

        def step():
            ctrl.set_action(act, s)
            for _ in range(ctrl.num_substeps):
                ctrl.before_simulation_step(s, c)

        g = None
        if graph:
            with wp.ScopedCapture(device=device) as cap:
                step()
            g = cap.graph
        out = []
        for _ in range(steps):
            q = q0 + rng.uniform(-0.2, 0.2, nq).astype(f32)
            s.joint_q.assign(q)
            s.joint_qd.assign(rng.uniform(-2, 2, nqd).astype(f32))
            act.assign(rng.uniform(-1.2, 1.2, ctrl.action_space.shape).astype(f32))
            if g is not None:
                wp.capture_launch(g)
            else:
                step()
            out.append((c.joint_target_q.numpy().copy(), c.joint_target_qd.numpy().copy(), c.joint_f.numpy().copy()))
        return out


def _base_mode():
    # a Fetch-like dict on the Panda: the arm's first three joints play the base (x, y, yaw) for parity purposes
    return {
        "base": wpctrl.PDBaseVelControllerConfig(PANDA_ARM_JOINTS[:3], -1.0, 1.0, 100.0),
        "arm": wpctrl.PDJointPosControllerConfig(PANDA_ARM_JOINTS[3:], -0.1, 0.1, 400.0, 40.0, use_delta=True, ema=0.5),
        "gripper": wpctrl.PDJointPosMimicControllerConfig(
            PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1e3, 1e2, mimic=GRIP, binary=True
        ),  # fmt: skip
    }


def _actuator_mode():
    return {
        "arm": wpctrl.PDJointPosControllerConfig(
            PANDA_ARM_JOINTS[:4], -0.1, 0.1, 400.0, 40.0, 87.0, use_delta=True, actuator=wpctrl.DCMotor(60.0, 2.0)
        ),  # fmt: skip
        "wrist": wpctrl.PDJointPosControllerConfig(
            PANDA_ARM_JOINTS[4:],
            -0.1,
            0.1,
            100.0,
            5.0,
            12.0,
            use_delta=True,
            actuator=wpctrl.PositionBasedEffortLimit([-2.0, 0.0, 2.0], [4.0, 12.0, 6.0]),
        ),  # fmt: skip
        "gripper": wpctrl.JointEffortControllerConfig(PANDA_GRIPPER_JOINTS, -5.0, 5.0),
    }


def _net_mode():
    import torch

    torch.manual_seed(0)
    mlp = torch.nn.Sequential(torch.nn.Linear(6, 16), torch.nn.Softsign(), torch.nn.Linear(16, 1))

    class _LSTM(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.lstm = torch.nn.LSTM(2, 8, 2, batch_first=True)
            self.linear = torch.nn.Linear(8, 1)

    return {
        "arm": wpctrl.PDJointPosControllerConfig(
            PANDA_ARM_JOINTS[:4],
            -0.1,
            0.1,
            0.0,
            0.0,
            87.0,
            use_delta=True,
            actuator=wpctrl.ActuatorNet(mlp, torque_scale=20.0),
        ),  # fmt: skip
        "wrist": wpctrl.PDJointPosControllerConfig(
            PANDA_ARM_JOINTS[4:],
            -0.1,
            0.1,
            0.0,
            0.0,
            12.0,
            use_delta=True,
            actuator=wpctrl.ActuatorNet(_LSTM(), torque_scale=5.0),
        ),  # fmt: skip
        "gripper": wpctrl.PDJointPosMimicControllerConfig(PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1e3, 1e2, mimic=GRIP),
    }


def _humanoid_mode():
    import xml.etree.ElementTree as ET

    names = [j.get("name") for j in ET.parse(newton.examples.get_asset("nv_humanoid.xml")).getroot().iter("joint")]
    hinges = [n for n in names if n not in (None, "root")]
    return {"body": wpctrl.PDJointPosControllerConfig(hinges, -0.2, 0.2, 100.0, 5.0, 50.0, use_delta=True),
            "balance_passive_force": False}  # fmt: skip


CASES = {
    "base_ema_binary": (_panda_builder, _base_mode, "implicit", {}),
    "dc_position_effort": (_panda_builder, _actuator_mode, "explicit", {"delay": (0, 2), "track_effort": True}),
    "actuator_nets": (_panda_builder, _net_mode, "explicit", {"track_effort": True}),
    "humanoid_multi_axis": (_humanoid_builder, _humanoid_mode, "explicit", {}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_cpu_cuda_parity_and_graph_replay(case):
    make_builder, make_mode, actuation, kw = CASES[case]
    cpu = _run("cpu", make_builder, make_mode, actuation, 4, 11, **kw)
    gpu = _run("cuda:0", make_builder, make_mode, actuation, 4, 11, **kw)
    for (tq_c, tqd_c, f_c), (tq_g, tqd_g, f_g) in zip(cpu, gpu):
        np.testing.assert_allclose(tq_g, tq_c, rtol=0, atol=1e-5)
        np.testing.assert_allclose(tqd_g, tqd_c, rtol=0, atol=1e-5)
        np.testing.assert_allclose(f_g, f_c, rtol=1e-4, atol=2e-3)  # FMA contraction on CUDA
    replay = _run("cuda:0", make_builder, make_mode, actuation, 4, 11, graph=True, **kw)
    for a, b in zip(gpu, replay):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(y, x)
