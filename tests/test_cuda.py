"""CUDA checks (skipped without a GPU): CPU vs CUDA parity, graph replay == eager bitwise, zero-copy torch input.

Run on a CUDA device; the recorded results are in docs/testing.md.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import warp as wp
from conftest import HAS_CUDA
from harness import Harness, delta_arm, gripper

pytestmark = pytest.mark.skipif(not HAS_CUDA, reason="no CUDA device")

MODES = {
    "target_delta_interp": lambda: {"arm": delta_arm(use_target=True, interpolate=True), "gripper": gripper()},
    "delta": lambda: {"arm": delta_arm(), "gripper": gripper()},
}


def _run(device, mode, actuation, acts, qs, resets, graph=False):
    n = acts.shape[1]
    with wp.ScopedDevice(device):
        h = Harness(copy.deepcopy(mode), num_envs=n, actuation=actuation, device=device)
        h.put(qs[0], qs[0])
        h.ctrl.reset(h.state)
        act = wp.zeros((n, 8), dtype=wp.float32, device=device)
        mask = wp.zeros(n, dtype=wp.bool, device=device)

        def step():
            h.ctrl.set_action(act, h.state)
            for _ in range(h.ctrl.num_substeps):
                h.ctrl.before_simulation_step(h.state, h.control)

        g = None
        if graph:
            with wp.ScopedCapture(device=device) as cap:
                step()
            g = cap.graph
        out = []
        for i in range(acts.shape[0]):
            h.put(qs[i], qs[i])
            act.assign(acts[i])
            if g is not None:
                wp.capture_launch(g)
            else:
                step()
            if resets[i] is not None:
                mask.assign(resets[i])
                h.ctrl.reset(h.state, env_ids=mask)
            # .numpy() of a CPU array is a view of live memory: copy each step's values
            out.append(
                (
                    h.ctrl.target_qpos.numpy().copy(),
                    h.drive_q(),
                    h.drive_qd(),
                    h.joint_f(),
                    h.ctrl.step_counter.numpy().copy(),
                )
            )
        return out


def _streams(n=256, steps=6, seed=0):
    rng = np.random.default_rng(seed)
    acts = rng.uniform(-1.3, 1.3, (steps, n, 8)).astype(np.float32)
    acts[2, 5, 3] = np.nan
    qs = rng.uniform(-1, 1, (steps, n, 9)).astype(np.float32)
    resets = [rng.random(n) < 0.2 if i % 2 else None for i in range(steps)]
    return acts, qs, resets


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
@pytest.mark.parametrize("mode", list(MODES))
def test_cpu_cuda_parity(mode, actuation):
    acts, qs, resets = _streams()
    cpu = _run("cpu", MODES[mode](), actuation, acts, qs, resets)
    gpu = _run("cuda:0", MODES[mode](), actuation, acts, qs, resets)
    for a, b in zip(cpu, gpu):
        for x, y in zip(a[:3], b[:3]):  # targets and drive targets [rad, m, rad/s]
            np.testing.assert_allclose(x, y, atol=1e-6, rtol=1e-6)
        # torques [N m]: CUDA contracts Kp * (q* - q) into an FMA; a float32 ulp of q times Kp = 1000 is ~1e-4
        np.testing.assert_allclose(a[3], b[3], atol=2e-4, rtol=1e-5)
        np.testing.assert_array_equal(a[4], b[4])  # step_counter


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
@pytest.mark.parametrize("mode", list(MODES))  # "delta" + implicit: the elided substep launch (set_action only)
def test_cuda_graph_replay_bitwise(mode, actuation):
    acts, qs, resets = _streams(n=1024, seed=1)
    eager = _run("cuda:0", MODES[mode](), actuation, acts, qs, resets)
    graph = _run("cuda:0", MODES[mode](), actuation, acts, qs, resets, graph=True)
    for a, b in zip(eager, graph):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


def test_cuda_torch_zero_copy():
    torch = pytest.importorskip("torch")
    if not torch.cuda.is_available():
        pytest.skip("torch has no CUDA")
    from wpctrl.controllers.inputs import _action_array

    t = torch.rand(64, 8, device="cuda:0")
    view = _action_array(t, 64, 8, wp.get_device("cuda:0"), None)
    assert view.ptr == t.data_ptr()
    h = Harness({"arm": delta_arm(), "gripper": gripper()}, num_envs=64, device="cuda:0")
    with wp.ScopedDevice("cuda:0"):
        h.ctrl.reset(h.state)
        h.ctrl.set_action(t, h.state)
        ref = Harness({"arm": delta_arm(), "gripper": gripper()}, num_envs=64, device="cuda:0")
        ref.ctrl.reset(ref.state)
        ref.ctrl.set_action(t.cpu().numpy(), ref.state)
        np.testing.assert_array_equal(h.ctrl.target_qpos.numpy(), ref.ctrl.target_qpos.numpy())


def test_demo_on_cuda(tmp_path):
    """The demo on the GPU tracks as on the CPU (tests/test_demo.py's bounds): every value finite, no env diverged,
    the arm within a few centi-radians of the policy's sinusoid."""
    import json

    from wpctrl.demo import main

    args = ["--device", "cuda:0", "--envs", "64", "--seconds", "1.5", "--seed", "1", "--out", str(tmp_path)]
    assert main([*args, "--no-progress"]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["all_finite"] and s["envs"] == 64 and s["control_steps"] == 30
    assert s["nonfinite_envs"] == 0 and s["bad_actions"] == 0 and s["diverged_at_s"] is None
    assert s["tracking_rms"]["arm"] < 0.06 and s["tracking_rms"]["gripper"] < 0.015
    assert s["tracking_rms"]["arm"] <= s["tracking_max"]["arm"] < 0.3


def test_cuda_fused_inertia_and_coupled_drive_match_cpu():
    """The fused H^-1 kernel (unrolled on CUDA, runtime loops on the CPU) and the coupled drive built on it: CUDA
    against CPU on the same random Panda configurations and targets."""
    from conftest import build_panda

    import wpctrl
    from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS

    n = 64
    out = {}
    for device in ("cpu", "cuda:0"):
        with wp.ScopedDevice(device):
            model = build_panda(n, device=device)
            cfg = {
                "arm": wpctrl.PDJointPosControllerConfig(
                    PANDA_ARM_JOINTS, None, None, 1e3, 1e2, 50.0, normalize_action=False
                ),
                "gripper": wpctrl.PDJointPosControllerConfig(
                    PANDA_GRIPPER_JOINTS, None, None, 1e3, 1e2, 50.0, normalize_action=False
                ),
            }
            ctrl = wpctrl.build_controller(cfg, model, 100, 100, actuation="explicit", explicit_pd="coupled")
            assert ctrl._engine._fused.unroll == (device != "cpu")
            lo, hi = model.joint_limit_lower.numpy(), model.joint_limit_upper.numpy()
            r = np.random.default_rng(3)
            q = r.uniform(lo, hi).astype(np.float32)
            qd = r.normal(0.0, 1.0, q.shape).astype(np.float32)
            s, c = model.state(), model.control()
            s.joint_q.assign(q)
            s.joint_qd.assign(qd)
            resp = wp.zeros((n, 9), dtype=wp.float32)
            ctrl._engine._fused.launch_response(s.joint_q, resp)
            target = (q.reshape(n, 9) + r.normal(0.0, 0.3, (n, 9))).astype(np.float32)
            ctrl.set_action(wp.array(target, dtype=wp.float32), s)
            ctrl.before_simulation_step(s, c)
            out[device] = (resp.numpy().astype(np.float64), c.joint_f.numpy().astype(np.float64))
    np.testing.assert_allclose(out["cuda:0"][0], out["cpu"][0], rtol=1e-5)
    np.testing.assert_allclose(out["cuda:0"][1], out["cpu"][1], rtol=1e-4, atol=1e-3)
    assert np.abs(out["cpu"][1]).max() > 1.0
