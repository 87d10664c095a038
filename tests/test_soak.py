"""Soak: 4,096 Pandas x 2,000 control steps (5 substeps each) of random actions with NaN/Inf bursts and random
partial resets, without a solver.

A synthetic measured state replaces the physics: at every substep each joint moves a fixed fraction of the way to
its drive target (plus a small push from the explicit torque), and its velocity is that move over dt. Two controllers
run the same action stream on two states: run A also resets random envs (writing a fresh random pose into them,
with env-id lists and bool masks, with and without a Control), run B never resets. Checked throughout:

- no non-finite value ever reaches the targets, the torques, or Newton's control and state arrays;
- a reset env holds: start = target = the measured q, velocity targets 0, and the next substep drives it to q;
- ``bad_action_count`` counts exactly the env-steps whose action held NaN/Inf;
- envs that were never reset in A are bit-identical to the same envs in B (targets, start, processed actions,
  counters, control and state arrays), so a partial reset never leaks into other envs.

Runtime on the 2-core CPU of the development container (Warp's CPU device): about 45 s per actuation mode, 95 s
for both. ``WPCTRL_SOAK_STEPS`` overrides the step count.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
from conftest import build_panda

import wpctrl
from wpctrl import config as C
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, PANDA_JOINTS

NUM_ENVS = 4096
NUM_STEPS = int(os.environ.get("WPCTRL_SOAK_STEPS", "2000"))
CONTROL_FREQ, SIM_FREQ = 20, 100
K = SIM_FREQ // CONTROL_FREQ
DT = 1.0 / SIM_FREQ


def _mode(actuation: str) -> dict:
    if actuation == "explicit":
        # Virtual-target deltas, interpolated, with the ManiSkill Panda gains; mimic gripper.
        return {
            "arm": C.PDJointPosControllerConfig(
                PANDA_ARM_JOINTS, -0.1, 0.1, 1e3, 1e2, 87.0, use_delta=True, use_target=True, interpolate=True
            ),
            "gripper": C.PDJointPosMimicControllerConfig(PANDA_GRIPPER_JOINTS, -0.01, 0.04, 1e3, 1e2, 100.0),
        }
    # Position + velocity targets on the arm (raw actions, no clipping), velocity-driven fingers.
    return {
        "arm": C.PDJointPosVelControllerConfig(
            PANDA_ARM_JOINTS, None, None, 1e3, 1e2, 87.0, normalize_action=False, vel_lower=-1.0, vel_upper=1.0
        ),
        "gripper": C.PDJointVelControllerConfig(PANDA_GRIPPER_JOINTS, -0.05, 0.05, 1e2, 100.0),
    }


class Run:
    """One controller, its state and control, with (N, 9) numpy views of Newton's flat arrays (CPU: shared)."""

    def __init__(self, model, mode, actuation):
        self.ctrl = wpctrl.build_controller(mode, model, CONTROL_FREQ, SIM_FREQ, actuation=actuation)
        self.state = model.state()
        self.control = model.control()
        N, J = NUM_ENVS, len(PANDA_JOINTS)
        self.q = self.state.joint_q.numpy().reshape(N, J)
        self.qd = self.state.joint_qd.numpy().reshape(N, J)
        self.tq = self.control.joint_target_q.numpy().reshape(N, J)
        self.tqd = self.control.joint_target_qd.numpy().reshape(N, J)
        self.f = self.control.joint_f.numpy().reshape(N, J)
        assert np.shares_memory(self.q, self.state.joint_q.numpy())

    def substep(self, vel_cols: np.ndarray):
        self.ctrl.before_simulation_step(self.state, self.control)
        q_old = self.q.copy()
        step = np.float32(0.3) * (self.tq - self.q) + np.float32(1e-5) * self.f
        step[:, vel_cols] = np.float32(DT) * self.tqd[:, vel_cols]  # velocity-driven joints follow their target
        self.q += step
        self.qd[:] = (self.q - q_old) / np.float32(DT)

    def snapshot(self) -> dict:
        c = self.ctrl
        return {
            "target_qpos": c.target_qpos.numpy(),
            "target_qvel": c.target_qvel.numpy(),
            "start_qpos": c.start_qpos.numpy(),
            "processed_action": c.processed_action.numpy(),
            "step": c.step_counter.numpy(),
            "bad": c.bad_action_count.numpy(),
            "q": self.q,
            "qd": self.qd,
            "tq": self.tq,
            "tqd": self.tqd,
            "f": self.f,
        }


def _assert_finite(run: Run, where: str):
    for k, v in run.snapshot().items():
        if v.dtype.kind == "f" and not np.isfinite(v).all():
            bad = np.argwhere(~np.isfinite(v))[0]
            raise AssertionError(f"{where}: non-finite {k} at {bad.tolist()}")


@pytest.mark.slow
@pytest.mark.parametrize("actuation", ["explicit", "implicit"])
def test_soak(actuation):
    t0 = time.perf_counter()
    N = NUM_ENVS
    model = build_panda(N)
    # The state layout this test's (N, 9) views assume: world-major, the Panda's joints in order, 1 coordinate each.
    assert model.joint_coord_count == model.joint_dof_count == N * len(PANDA_JOINTS)
    mode = _mode(actuation)
    a, b = Run(model, mode, actuation), Run(model, mode, actuation)
    D = a.ctrl.action_space.shape[1]
    vel_cols = np.array([PANDA_JOINTS.index(s) for s in PANDA_GRIPPER_JOINTS]) if actuation == "implicit" else []
    lo = model.joint_limit_lower.numpy()[: len(PANDA_JOINTS)]
    hi = model.joint_limit_upper.numpy()[: len(PANDA_JOINTS)]
    rng = np.random.default_rng(1234)

    for r in (a, b):
        r.ctrl.reset(r.state)  # the first reset: every env
    resettable = np.arange(1, N, 2)  # the even envs are never reset: the comparison with B always has them
    ever_reset = np.zeros(N, bool)
    expected_bad = np.zeros(N, np.int64)
    burst_envs = np.zeros(N, bool)
    burst_left = 0
    resets = nan_rows = 0

    for step in range(NUM_STEPS):
        # Random partial resets in A (fresh random pose, zero velocity), then one substep of both runs, which must
        # hold the reset envs exactly at their new pose.
        if rng.random() < 0.1:
            ids = rng.choice(resettable, int(rng.integers(1, 64)), replace=False)
            mask = np.zeros(N, bool)
            mask[ids] = True
            a.q[ids] = rng.uniform(lo, hi, (ids.size, len(PANDA_JOINTS))).astype(np.float32)
            a.qd[ids] = 0.0
            with_control = bool(rng.random() < 0.5)
            a.ctrl.reset(a.state, mask if rng.random() < 0.5 else ids, control=a.control if with_control else None)
            ever_reset |= mask
            resets += 1
            q_reset = a.q[ids].copy()
            arm_rows = slice(0, len(PANDA_ARM_JOINTS))
            np.testing.assert_array_equal(a.ctrl.start_qpos.numpy()[ids], q_reset)
            if actuation == "explicit":
                np.testing.assert_array_equal(a.ctrl.target_qpos.numpy()[ids], q_reset)
            else:
                np.testing.assert_array_equal(a.ctrl["arm"].target_qpos.numpy()[ids], q_reset[:, arm_rows])
                assert not a.ctrl.target_qvel.numpy()[ids].any()
            if with_control:
                np.testing.assert_array_equal(a.tq[ids][:, arm_rows], q_reset[:, arm_rows])
                if actuation == "explicit":
                    assert not a.f[ids].any()
            assert not a.ctrl.step_counter.numpy()[ids].any()
            for r in (a, b):
                r.ctrl.before_simulation_step(r.state, r.control)  # no state update: the pose is held exactly
            pos_cols = slice(None) if actuation == "explicit" else arm_rows
            np.testing.assert_array_equal(a.tq[ids][:, pos_cols], q_reset[:, pos_cols], err_msg=f"step {step}: hold")
            if actuation == "explicit":
                np.testing.assert_array_equal(a.f[ids], np.zeros_like(a.f[ids]))  # q* = q and q̇ = 0: no torque
            else:
                assert not a.tqd[ids].any()

        # Actions: in and out of range, with NaN/Inf bursts on a few envs lasting a few steps.
        action = rng.uniform(-1.5, 1.5, (N, D)).astype(np.float32)
        if burst_left == 0 and rng.random() < 0.05:
            burst_envs = rng.random(N) < 0.01
            burst_left = int(rng.integers(1, 20))
        if burst_left:
            burst_left -= 1
            rows = np.nonzero(burst_envs)[0]
            action[rows, rng.integers(0, D, rows.size)] = rng.choice([np.nan, np.inf, -np.inf], rows.size)
        bad_rows = ~np.isfinite(action).all(axis=1)
        expected_bad += bad_rows
        nan_rows += int(bad_rows.sum())
        for r in (a, b):
            r.ctrl.set_action(action, r.state)
            for _ in range(K):
                r.substep(vel_cols)

        _assert_finite(a, f"step {step} (A)")
        _assert_finite(b, f"step {step} (B)")
        if step % 50 == 0 or step == NUM_STEPS - 1:
            np.testing.assert_array_equal(a.ctrl.bad_action_count.numpy(), expected_bad)
            np.testing.assert_array_equal(b.ctrl.bad_action_count.numpy(), expected_bad)
            keep = ~ever_reset
            sa, sb = a.snapshot(), b.snapshot()
            for k in sa:
                np.testing.assert_array_equal(sa[k][keep], sb[k][keep], err_msg=f"step {step}: never-reset {k}")

    elapsed = time.perf_counter() - t0
    # The stream exercised what it should (about 10% of steps reset, 5% start a NaN burst).
    assert resets >= NUM_STEPS // 20 and nan_rows >= NUM_STEPS // 20, (resets, nan_rows)
    assert ever_reset.sum() > N // 8
    print(
        f"\nsoak {actuation}: {N} envs x {NUM_STEPS} steps x {K} substeps, {resets} partial resets "
        f"({ever_reset.sum()} envs touched), {nan_rows} NaN/Inf env-steps, {elapsed:.1f} s"
    )
