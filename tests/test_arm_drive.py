"""The tasks' arm drive as PhysX's TGS solver applies it (``TaskPhysics.arm_drive="physx_tgs"``, the default;
:mod:`wpctrl.tasks.arm_drive`, :mod:`wpctrl.kernels.tgs_drive`).

- One pass of the kernel against a numpy re-derivation written in PhysX's own form (``computeImplicitDriveParams`` /
  ``computeDriveImpulse``: the row's accumulated impulse over the step, the new total clamped to the force limit
  times the step, the change applied to the joint velocity through the inverse inertia block), rows saturating and
  rows already at their limit included.
- In a task env: MuJoCo makes no actuator for the arm's DOFs (the gripper keeps its two), the pass reads the arm
  controller's live per-env gains, and ``arm_drive="mujoco"`` keeps MuJoCo's drive.
- Side by side with the real ManiSkill: ``tests/test_policy_replay.py`` (the arm's first steps from the policy
  episodes' states within 1-2.5 mrad of PhysX's, where MuJoCo's drive is 8-17 mrad off).
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from wpctrl import ConfigError
from wpctrl.kernels.tgs_drive import tgs_sweep_kernel

torch = pytest.importorskip("torch")

import wpctrl.tasks as T  # noqa: E402


def _physx_pass(q, qd, tq, tqd, A, kp, kd, limit, impulse, h, window, velocity_target):
    """One position iteration of PhysX's TGS articulation drive over the rows, in its own terms: per row the drive
    descriptor of ``computeImplicitDriveParamsForceDrive`` (a = h (h Kp + Kd), x = 1 / (1 + a r), bias coefficient
    Kp x h) and the new total impulse of ``computeDriveImpulse`` (TGS: impulse multiplier 1), clamped to +-L T; the
    change moves every row's velocity through A. Returns the torques (change / h) and the new impulses."""
    v = qd.astype(np.float64).copy()
    impulse = impulse.astype(np.float64).copy()
    tau = np.zeros_like(v)
    for r in range(len(v)):
        vt = tqd[r] if velocity_target else 0.0
        a = h * (h * kp[r] + kd[r])
        x = 1.0 / (1.0 + a * A[r, r])
        bias = kp[r] * x * h
        total = impulse[r] + v[r] * (-x * a) + x * h * kd[r] * vt + bias * (tq[r] - q[r])
        total = np.clip(total, -limit[r] * window, limit[r] * window)
        delta = total - impulse[r]
        impulse[r] = total
        v += A[:, r] * delta
        tau[r] = delta / h
    return tau, impulse


@pytest.mark.parametrize("velocity_target", [0, 1])
def test_one_pass_is_physx_tgs_drive_step(velocity_target):
    rng = np.random.default_rng(3 + velocity_target)
    envs, rows, dofs, coords = 4, 7, 10, 11
    h, window = 0.01 / 16, 0.01
    M = rng.normal(size=(envs, rows, rows))
    A = np.einsum("eij,ekj->eik", M, M) + 0.5 * np.eye(rows)  # SPD, as S H^-1 S^T
    kp = rng.uniform(0.0, 2000.0, (envs, rows)).astype(np.float32)
    kd = rng.uniform(0.0, 200.0, (envs, rows)).astype(np.float32)
    limit = rng.uniform(5.0, 100.0, (envs, rows)).astype(np.float32)
    q = rng.normal(size=envs * coords).astype(np.float32)
    qd = rng.normal(size=envs * dofs).astype(np.float32)
    tq = (q + rng.normal(scale=0.3, size=q.shape)).astype(np.float32)  # some rows saturate
    tqd = rng.normal(size=qd.shape).astype(np.float32)
    impulse = (rng.uniform(-1.0, 1.0, (envs, rows)) * limit * window).astype(np.float32)
    impulse[0, 2] = limit[0, 2] * window  # at its limit already
    coord = np.array([[e * coords + 1 + r for r in range(rows)] for e in range(envs)], np.int32)
    dof = np.array([[e * dofs + 2 + r for r in range(rows)] for e in range(envs)], np.int32)
    f = np.full(envs * dofs, 7.0, np.float32)  # DOFs outside the rows keep what they hold
    dev = "cpu"
    arr = lambda a, dt=float: wp.array(a, dtype=dt, device=dev)  # noqa: E731
    imp, out = arr(impulse), arr(f)
    wp.launch(tgs_sweep_kernel, dim=envs,
              inputs=[arr(coord, wp.int32), arr(dof, wp.int32), arr(kp), arr(kd), arr(limit), arr(A.astype(np.float32)),
                      h, window, velocity_target, arr(q), arr(qd), arr(tq), arr(tqd), imp],
              outputs=[out], device=dev)  # fmt: skip
    got_f, got_imp = out.numpy(), imp.numpy()
    for e in range(envs):
        tau, new = _physx_pass(q[coord[e]], qd[dof[e]], tq[coord[e]], tqd[dof[e]], A[e], kp[e], kd[e], limit[e],
                               impulse[e], h, window, velocity_target)  # fmt: skip
        np.testing.assert_allclose(got_f[dof[e]], tau, rtol=2e-4, atol=2e-3 * np.abs(tau).max())
        np.testing.assert_allclose(got_imp[e], new, rtol=1e-4, atol=1e-6)
        assert np.all(np.abs(got_imp[e]) <= limit[e] * window * (1 + 1e-6))
    assert got_f[dof[0, 2]] <= 1e-3 * limit[0, 2]  # a row at its limit pushes no further that way
    untouched = np.setdiff1d(np.arange(envs * dofs), dof.ravel())
    np.testing.assert_array_equal(got_f[untouched], 7.0)


@pytest.fixture(scope="module")
def envs():
    made = {}

    def get(drive: str, mode: str = "pd_joint_delta_pos", n: int = 2):
        key = (drive, mode, n)
        if key not in made:
            made[key] = T.make("PickCube-v1", num_envs=n, control_mode=mode, auto_reset=False,
                               physics=T.task_physics("PickCube-v1", arm_drive=drive))  # fmt: skip
        return made[key]

    yield get
    for env in made.values():
        env.close()


def test_mujoco_drives_only_the_gripper_under_the_tgs_pass(envs):
    """PhysX's pass drives the seven arm joints through ``Control.joint_f``: MuJoCo has actuators for the two
    finger joints only; with ``arm_drive="mujoco"`` it has all nine."""
    assert envs("physx_tgs").solver.mjw_model.nu == 2
    assert envs("mujoco").solver.mjw_model.nu == 9


def test_the_pass_reads_the_arm_controllers_per_env_gains(envs):
    """Stiffness 0 on env 1's arm: the same joint command moves env 0's panda_joint1 and leaves env 1's still."""
    env = envs("physx_tgs")
    env.reset(seed=0)
    arm = env.ctrl.children["arm"]
    try:
        arm.set_drive_properties([1], stiffness=np.zeros(7, np.float32))
        q0 = env.get_obs()[:, 0].cpu().numpy()
        action = torch.zeros(2, 8)
        action[:, 0] = 1.0  # panda_joint1 +0.1 rad
        obs, *_ = env.step(action)
        moved = obs[:, 0].cpu().numpy() - q0
    finally:
        arm.set_drive_properties([1], stiffness=np.full(7, 1000.0, np.float32))
    assert moved[0] > 0.02, moved
    assert abs(moved[1]) < 1e-4, moved


def test_both_drives_hold_the_rest_pose(envs):
    """With no arm command the arm stays where it is under either drive (gravity is compensated, the targets are the
    current joint positions) while the gripper moves to its commanded opening."""
    for drive in ("physx_tgs", "mujoco"):
        env = envs(drive)
        env.reset(seed=0)
        q0 = env.get_obs()[:, :7].cpu().numpy()
        for _ in range(5):
            obs, *_ = env.step(torch.zeros(2, 8))
        np.testing.assert_allclose(obs[:, :7].cpu().numpy(), q0, atol=2e-4, err_msg=drive)


@pytest.mark.parametrize("value", ["tgs", "PhysX", None, 1])
def test_an_unknown_arm_drive_is_refused_naming_the_field(value):
    with pytest.raises(ConfigError, match=r"TaskPhysics\.arm_drive: expected one of \('physx_tgs', 'mujoco'\)"):
        T.TaskPhysics(arm_drive=value)
