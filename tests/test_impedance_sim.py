"""The impedance controllers in closed loop on MuJoCo-Warp with gravity on (the Panda, its gravity taken by the
controller: ``balance_passive_force`` off): a 10 cm step tracked in 1 s, decoupled axes, the null-space posture
kept while the TCP holds, stability at 100 Hz over 10 s of random workspace targets, joint impedance tracking."""

from __future__ import annotations

import copy

import newton
import numpy as np
import pytest
from conftest import build_panda

import wpctrl
from wpctrl.robots import panda_control_modes


class Loop:
    """N Pandas under a mode with MuJoCo-Warp (gravity on, no contacts)."""

    def __init__(self, mode_name: str, num_envs: int, control_freq=20, sim_freq=100, **arm_kw):
        mode = copy.deepcopy(panda_control_modes()[mode_name])
        for k, v in arm_kw.items():
            setattr(mode["arm"], k, v)
        mode["balance_passive_force"] = False  # gravity acts on the robot; the controller compensates it
        self.model = build_panda(num_envs)
        self.ctrl = wpctrl.build_controller(mode, self.model, control_freq, sim_freq)
        self.arm = self.ctrl["arm"]
        self.solver = newton.solvers.SolverMuJoCo(self.model, disable_contacts=True)
        self.s0, self.s1, self.control = self.model.state(), self.model.state(), self.model.control()
        newton.eval_fk(self.model, self.s0.joint_q, self.s0.joint_qd, self.s0)
        self.ctrl.reset(self.s0, control=self.control)
        self.dt = 1.0 / sim_freq
        self.coord = self.ctrl._engine.binding.coord_index[:, self.arm._rows]

    def step(self, action):
        self.ctrl.set_action(np.asarray(action, np.float32), self.s0)
        for _ in range(self.ctrl.num_substeps):
            self.ctrl.before_simulation_step(self.s0, self.control)
            self.solver.step(self.s0, self.s1, self.control, None, self.dt)
            self.s0, self.s1 = self.s1, self.s0

    def tcp(self) -> np.ndarray:
        return self.arm.fk_jacobian(self.s0)[0].numpy().astype(np.float64)

    def q(self) -> np.ndarray:
        return self.s0.joint_q.numpy()[self.coord].astype(np.float64)


def _euler_xyz(wxyz: np.ndarray) -> np.ndarray:
    w, x, y, z = np.moveaxis(wxyz, -1, 0)
    return np.stack(
        [
            np.arctan2(-2 * (y * z - w * x), 1 - 2 * (x * x + y * y)),
            np.arcsin(np.clip(2 * (x * z + w * y), -1, 1)),
            np.arctan2(-2 * (x * y - w * z), 1 - 2 * (y * y + z * z)),
        ],
        axis=-1,
    )


def _abs_action(pose: np.ndarray, grip: float = 1.0) -> np.ndarray:
    """``osc_ee_pose`` actions: [x, y, z, Euler XYZ] of root-frame poses, and the gripper."""
    return np.concatenate([pose[:, :3], _euler_xyz(pose[:, 3:]), np.full((pose.shape[0], 1), grip)], axis=1)


def test_osc_tracks_a_10cm_step_in_1s_with_decoupled_axes():
    """A 10 cm step along x (env 0), y (env 1) and z (env 2) of the TCP target: within 2 mm after 1 s; the other two
    axes move less than 5 % of the step at every control step; the orientation holds."""
    loop = Loop("osc_ee_pose", 3)
    start = loop.tcp()
    target = start.copy()
    for e in range(3):
        target[e, e] += 0.1
    action = _abs_action(target)
    worst_cross = 0.0
    for _ in range(20):  # 1 s at 20 Hz
        loop.step(action)
        d = loop.tcp()[:, :3] - start[:, :3]
        for e in range(3):
            worst_cross = max(worst_cross, float(np.abs(np.delete(d[e], e)).max()) / 0.1)
    end = loop.tcp()
    err = np.linalg.norm(end[:, :3] - target[:, :3], axis=1)
    assert (err < 2e-3).all(), err
    assert worst_cross < 0.05, worst_cross
    dot = np.abs((end[:, 3:] * start[:, 3:]).sum(axis=1))
    assert (2 * np.arccos(np.clip(dot, -1, 1)) < 0.02).all()  # < 1.2° of the start orientation


def test_osc_null_space_posture_is_kept_while_the_tcp_holds():
    """Started off the posture along the arm's self-motion (the null direction of J), the arm returns to the posture
    while the TCP holds its pose; without null-space control it stays off."""
    results = {}
    for nullspace in ("position", "none"):
        loop = Loop("osc_ee_pose", 1, nullspace_control=nullspace)
        q0 = loop.q()[0]
        _, jac = loop.arm.fk_jacobian(loop.s0)
        null = np.linalg.svd(jac.numpy()[0].astype(np.float64))[2][-1]  # J null = 0
        q = loop.s0.joint_q.numpy()
        q[loop.coord[0]] = (q0 + 0.25 * null).astype(np.float32)
        loop.s0.joint_q.assign(q)
        newton.eval_fk(loop.model, loop.s0.joint_q, loop.s0.joint_qd, loop.s0)
        loop.ctrl.reset(loop.s0, control=loop.control)
        loop.arm.target_qpos.assign(q0[None, :].astype(np.float32))  # the commanded posture
        hold = loop.tcp()
        action = _abs_action(hold)
        tcp_err = 0.0
        for _ in range(60):  # 3 s
            loop.step(action)
            tcp_err = max(tcp_err, float(np.linalg.norm(loop.tcp()[0, :3] - hold[0, :3])))
        results[nullspace] = (float(np.abs((loop.q()[0] - q0) @ null)), tcp_err)
    off_with, tcp_with = results["position"]
    off_without, _ = results["none"]
    assert off_with < 0.25 * 0.2, results  # 80 % of the way back to the posture
    assert off_without > 0.25 * 0.6, results  # without it the self-motion is not corrected
    assert tcp_with < 3e-3, results


def test_osc_is_stable_at_100hz_for_10s_of_random_targets():
    """Control at 100 Hz (one substep per control step), a new random workspace target every 0.5 s for 10 s: the
    state stays finite, the joints inside their limits, and each target is reached to a few mm."""
    loop = Loop("osc_ee_pose", 2, control_freq=100, sim_freq=100)
    rng = np.random.default_rng(0)
    start = loop.tcp()
    errs = []
    for _ in range(20):
        target = start.copy()
        target[:, :3] += rng.uniform([-0.15, -0.2, -0.2], [0.15, 0.2, 0.15], (2, 3))
        action = _abs_action(target)
        action[:, 3:6] += rng.uniform(-0.3, 0.3, (2, 3))
        for _ in range(50):
            loop.step(action)
            assert np.isfinite(loop.s0.joint_q.numpy()).all() and np.isfinite(loop.s0.joint_qd.numpy()).all()
        errs.append(np.linalg.norm(loop.tcp()[:, :3] - target[:, :3], axis=1))
    q = loop.q()
    lo, hi = loop.ctrl._engine.binding.qlimits[:7].T
    assert ((q >= lo - 0.05) & (q <= hi + 0.05)).all()
    assert np.median(errs) < 5e-3, np.array(errs)


def test_joint_impedance_delta_mode_tracks_joint_targets():
    """``joint_impedance_delta_pos`` (inertial and gravity compensation) under gravity: +0.1 rad on every arm joint
    per control step for 3 steps, then hold: every joint within 2 mrad of its target after 1 s."""
    loop = Loop("joint_impedance_delta_pos", 2)
    q0 = loop.q()
    for _ in range(3):
        loop.step(np.concatenate([np.tile([[1.0, 1.0, -1.0, 1.0, -1.0, 1.0, 1.0]], (2, 1)), np.ones((2, 1))], 1))
    want = q0 + 0.3 * np.array([1.0, 1.0, -1.0, 1.0, -1.0, 1.0, 1.0])
    for _ in range(20):
        loop.step(np.concatenate([(want - loop.q()) / 0.1, np.ones((2, 1))], 1))
    assert np.abs(loop.q() - want).max() < 2e-3, loop.q() - want


@pytest.mark.parametrize("mode_name", ["osc_ee_delta_pose", "joint_impedance_delta_pos"])
def test_modes_hold_still_under_gravity(mode_name):
    """A zero action under gravity for 1 s: the arm holds (gravity compensated by the controller) to 1 mrad."""
    loop = Loop(mode_name, 2)
    q0 = loop.q()
    zero = np.zeros((2, loop.ctrl.action_dim), np.float32)
    zero[:, -1] = 1.0
    for _ in range(20):
        loop.step(zero)
    assert np.abs(loop.q() - q0).max() < 1e-3, loop.q() - q0


@pytest.mark.parametrize("mode_name", ["osc_ee_delta_pose", "joint_impedance_delta_pos"])
def test_demo_runs_an_impedance_mode_and_plots_its_torques(mode_name, tmp_path):
    """``python -m wpctrl demo --control-mode osc_ee_delta_pose`` (and joint impedance): finite, tracking, the arm's
    commanded and applied torques recorded for the figure (one panel per arm joint)."""
    import json

    from wpctrl.demo import main

    out = tmp_path / "demo"
    assert (
        main(["--envs", "2", "--seconds", "1.5", "--no-progress", "--control-mode", mode_name, "--out", str(out)]) == 0
    )
    s = json.loads((out / "summary.json").read_text())
    assert s["all_finite"] and s["control_mode"] == mode_name
    first = next(iter(s["tracking_rms"]))
    assert s["tracking_rms"][first] < (0.06 if mode_name.startswith("osc") else 0.1), s["tracking_rms"]
    assert (out / "tracking.png").stat().st_size > 10_000
