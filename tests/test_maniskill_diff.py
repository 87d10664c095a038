"""Differential tests against the real ManiSkill 3.0.1: every agent whose assets ship in the mani-skill wheel, each of
its stock control modes. The same states and actions drive ManiSkill's own controller (PhysX CPU, ``Empty-v1``,
driven directly: ``set_action`` and ``before_simulation_step``, no physics step) and wpctrl's, built from
``wpctrl.maniskill.load_robot(uid)`` with the modes it translated from the agent class. Before every control step
both get the same joint state (random, around the agent's keyframe). Checked: processed actions (1e-6) and, after
every substep, the drive position / velocity targets PhysX holds (1e-6); end-effector rows by ManiSkill's CPU IK
(Pinocchio CLIK, what runs on PhysX CPU): wpctrl's CLIK converges where ManiSkill's did and its target reaches
ManiSkill's target pose (2e-4). Modes ManiSkill itself cannot run are listed, with the reason, in
``test_modes_maniskill_cannot_run_are_refused``.
"""

from __future__ import annotations

import copy
import dataclasses
import zlib

import newton
import numpy as np
import pytest

import wpctrl

pytest.importorskip("mani_skill", reason="the maniskill extra (mani-skill) is not installed")  # a dev dependency
pytestmark = [pytest.mark.filterwarnings("ignore"), pytest.mark.slow]  # the real ManiSkill side by side

from maniskill_side import AGENTS, CANNOT_RUN, ManiSkillSide  # noqa: E402

from wpctrl.binding import bind_joints  # noqa: E402
from wpctrl.maniskill import control_modes, load_robot  # noqa: E402

CLIK = {"solver_iterations": 100, "tolerance": 1e-4, "clik_dt": 0.1, "clik_damping": 1e-6}
STEPS = 4


def _cases():
    out = []
    for uid in AGENTS:
        for mode in control_modes(uid):
            if (uid, mode) not in CANNOT_RUN:
                out.append((uid, mode))
    return out


CASES = _cases()
_ROBOTS: dict[str, object] = {}


def _robot(uid):
    if uid not in _ROBOTS:
        _ROBOTS[uid] = load_robot(uid)
    return _ROBOTS[uid]


def _with_cpu_ik(mode):
    """ManiSkill on PhysX CPU solves EE targets with Pinocchio's CLIK: give wpctrl's EE configs its parameters."""

    def fix(cfg):
        if isinstance(cfg, wpctrl.PDEEPosControllerConfig):
            solver = dict(cfg.delta_solver_config or {})
            solver.update(CLIK)
            return dataclasses.replace(cfg, delta_solver_config=solver)
        return cfg

    mode = copy.deepcopy(mode)
    if isinstance(mode, dict):
        return {k: (v if k == "balance_passive_force" else fix(v)) for k, v in mode.items()}
    return fix(mode)


def _ee_children(ctrl, mode):
    if isinstance(mode, dict):
        return {uid: ctrl[uid] for uid, c in mode.items() if isinstance(c, wpctrl.PDEEPosControllerConfig)}
    return {"__single__": ctrl} if isinstance(mode, wpctrl.PDEEPosControllerConfig) else {}


def _sample_q(rng, base, limits):
    q = base + rng.normal(0.0, 0.05, base.shape)
    lo, hi = limits[:, 0], limits[:, 1]
    finite = np.isfinite(lo) & np.isfinite(hi)
    margin = 0.02 * (hi - lo)
    q[finite] = np.clip(q[finite], lo[finite] + margin[finite], hi[finite] - margin[finite])
    return q.astype(np.float32)


@pytest.mark.parametrize(("uid", "mode_name"), CASES, ids=[f"{u}-{m}" for u, m in CASES])
def test_against_maniskill(uid, mode_name):
    side_by_side(uid, mode_name)


def side_by_side(uid, mode_name):
    """ManiSkill's controller for agent ``uid`` (a uid or an agent class) and mode, and wpctrl's on
    ``load_robot(uid)``, driven with the same states and actions for ``STEPS`` control steps."""
    ms = ManiSkillSide(uid, mode_name)
    try:
        robot = _robot(uid)
        assert ms.joint_names == robot.joint_names
        builder = newton.ModelBuilder()
        builder.replicate(robot.builder, 1)
        model = builder.finalize(device="cpu")
        mode = _with_cpu_ik(robot.control_modes[mode_name])
        env = ms.env.unwrapped
        ctrl = wpctrl.build_controller(mode, model, control_freq=env.control_freq, sim_freq=env.sim_freq)
        b = bind_joints(model, ms.joint_names)
        state, control = model.state(), model.control()
        rng = np.random.default_rng(zlib.crc32(f"{robot.uid}:{mode_name}".encode()))
        kf = robot.keyframes.get(robot.keyframe) if robot.keyframe else None
        base = np.array([kf.qpos[n] for n in ms.joint_names], np.float64) if kf else np.zeros(len(ms.joint_names))
        limits = ms.qlimits

        def put(q, qd):
            ms.put(q, qd)
            jq, jqd = state.joint_q.numpy(), state.joint_qd.numpy()
            jq[b.coord_index[0]] = q
            jqd[b.dof_index[0]] = qd
            state.joint_q.assign(jq)
            state.joint_qd.assign(jqd)

        put(_sample_q(rng, base, limits), np.zeros(len(base), np.float32))
        ms.controller.reset()
        ctrl.reset(state, control=control)
        ee = _ee_children(ctrl, mode)
        ee_rows = {i for c in ee.values() for i in (ms.joint_names.index(n) for n in c.joint_names)}
        rows = np.array([i for i in range(len(ms.joint_names)) if i not in ee_rows], np.int64)
        space = ms.agent.single_action_space
        lo, hi = np.asarray(space.low, np.float64), np.asarray(space.high, np.float64)
        for k in range(STEPS):
            q = _sample_q(rng, base, limits)
            qd = rng.uniform(-0.5, 0.5, len(base)).astype(np.float32)
            put(q, qd)
            u = rng.uniform(-1.2, 1.2, lo.shape)
            finite = np.isfinite(lo) & np.isfinite(hi)
            a = np.where(finite, 0.5 * (lo + hi) + 0.5 * (hi - lo) * u, u)
            if ee:
                a = 0.3 * a  # small EE steps: CLIK converges on both sides
            a = a.astype(np.float32)
            ms.set_action(a)
            ctrl.set_action(a, state)
            for sub_uid, want in ms.processed.items():
                got = (ctrl if sub_uid == "__single__" else ctrl[sub_uid]).processed_action.numpy()[0]
                np.testing.assert_allclose(got, want.reshape(-1), atol=1e-6, err_msg=f"step {k} {sub_uid} processed")
            for sub_uid, c in ee.items():
                _check_ee(ms, c, sub_uid, q, state, k)
            for i in range(ctrl.num_substeps):
                ms.substep()
                ctrl.before_simulation_step(state, control)
                want_q, want_qd = ms.drive_targets()
                tq = control.joint_target_q.numpy()[b.coord_index[0]]
                tqd = control.joint_target_qd.numpy()[b.dof_index[0]]
                np.testing.assert_allclose(tq[rows], want_q[rows], atol=1e-6, err_msg=f"step {k} substep {i} target")
                np.testing.assert_allclose(tqd, want_qd, atol=1e-6, err_msg=f"step {k} substep {i} velocity target")
    finally:
        ms.close()


def _check_ee(ms, ctrl, sub_uid, q, state, k):
    """ManiSkill's CPU IK: where it converged (its target differs from the measured q), wpctrl's CLIK converged too
    and its joint target reaches ManiSkill's target pose; where it failed, wpctrl holds the measured q too."""
    their = ms.controller.controllers[sub_uid] if sub_uid != "__single__" else ms.controller
    rows = [ms.joint_names.index(n) for n in ctrl.joint_names]
    theirs = their._target_qpos.cpu().numpy()[0].astype(np.float64)
    ours = ctrl.target_qpos.numpy()[0].astype(np.float64)
    if np.allclose(theirs, q[rows], atol=1e-9):
        assert ctrl.ik_success.numpy()[0] == 0, f"step {k}: ManiSkill's IK failed, ours converged"
        np.testing.assert_allclose(ours, q[rows], atol=1e-6)
        return
    assert ctrl.ik_success.numpy()[0] == 1, f"step {k}: ManiSkill's IK converged, ours did not"
    tp = their._target_pose
    target = np.concatenate([tp.p.cpu().numpy()[0], tp.q.cpu().numpy()[0]]).astype(np.float64)
    saved = state.joint_q.numpy().copy()
    jq = saved.copy()
    jq[ctrl.coord_index[0]] = ours
    state.joint_q.assign(jq)
    pose, _ = ctrl._ee.fk_jacobian(state.joint_q)
    state.joint_q.assign(saved)
    p = pose.numpy()[0].astype(np.float64)
    assert np.abs(p[:3] - target[:3]).max() < 2e-4, f"step {k}: EE position {p[:3]} vs ManiSkill's {target[:3]}"
    dq = min(np.abs(p[3:] - target[3:]).max(), np.abs(p[3:] + target[3:]).max())
    assert dq < 2e-4, f"step {k}: EE orientation {p[3:]} vs ManiSkill's {target[3:]}"


@pytest.mark.parametrize(("uid", "mode_name"), list(CANNOT_RUN), ids=[f"{u}-{m}" for u, m in CANNOT_RUN])
def test_modes_maniskill_cannot_run_are_refused(uid, mode_name):
    """ManiSkill fails on these stock modes (reason in CANNOT_RUN); wpctrl refuses them up front with a ConfigError."""
    with pytest.raises(Exception):  # noqa: B017 - ManiSkill's own failure (AssertionError, ValueError, NaN, ...)
        ms = ManiSkillSide(uid, mode_name)
        try:
            ms.set_action(np.zeros(ms.agent.single_action_space.shape, np.float32))
            ms.substep()
            t, v = ms.drive_targets()
            if np.isfinite(t).all() and np.isfinite(v).all():
                return  # ran: the test then fails (pytest.raises expected an error)
            raise FloatingPointError("ManiSkill's targets are NaN")
        finally:
            ms.close()
    robot = _robot(uid)
    builder = newton.ModelBuilder()
    builder.replicate(robot.builder, 1)
    with pytest.raises(wpctrl.ConfigError):
        wpctrl.build_controller(robot.control_modes[mode_name], builder.finalize(device="cpu"))


def _my_panda():
    """A user's own ManiSkill agent class (not registered): the Panda with another keyframe and one mode of its own."""
    import sapien
    from mani_skill.agents.base_agent import Keyframe
    from mani_skill.agents.controllers import PDJointPosControllerConfig, PDJointPosMimicControllerConfig
    from mani_skill.agents.robots.panda.panda import Panda

    class MyMimic(PDJointPosMimicControllerConfig):  # a config subclass of the user's: its base class's fields
        pass

    class MyPanda(Panda):
        uid = "my_panda"
        keyframes = dict(
            ready=Keyframe(
                qpos=np.array([0.3, 0.2, -0.1, -2.0, 0.1, 2.1, 0.5, 0.03, 0.03]),
                pose=sapien.Pose(p=[0.1, -0.2, 0.05], q=[0.9238795, 0.0, 0.0, 0.3826834]),
            )
        )

        @property
        def _controller_configs(self):
            arm = PDJointPosControllerConfig(
                self.arm_joint_names, -0.05, 0.05, 2e3, 150, 80, use_delta=True, use_target=True, interpolate=True
            )
            gripper = MyMimic(self.gripper_joint_names, -0.01, 0.04, 1e3, 100, 50)
            return dict(my_target_delta=dict(arm=arm, gripper=gripper, balance_passive_force=False))

    return MyPanda


def test_own_agent_class():
    """load_robot takes a user's own agent class: its keyframe and mode come through, and the mode runs as
    ManiSkill runs it."""
    cls = _my_panda()
    robot = load_robot(cls)
    mode = robot.control_modes["my_target_delta"]
    assert mode["balance_passive_force"] is False
    arm = mode["arm"]
    assert isinstance(arm, wpctrl.PDJointPosControllerConfig)
    assert (arm.lower, arm.upper, arm.stiffness, arm.damping, arm.force_limit) == (-0.05, 0.05, 2e3, 150, 80)
    assert arm.use_delta and arm.use_target and arm.interpolate
    assert type(mode["gripper"]) is wpctrl.PDJointPosMimicControllerConfig
    assert robot.keyframe == "ready" and robot.keyframes["ready"].qpos["panda_joint4"] == -2.0
    q = robot.builder.joint_q
    assert q[robot.builder.joint_q_start[robot.builder.joint_label.index("panda/panda_joint4")]] == -2.0
    side_by_side(cls, "my_target_delta")
