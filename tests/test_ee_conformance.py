"""Replay ManiSkill's recorded end-effector traces (tests/data/conformance/ee) through wpctrl, step by step.

Each trace ran the real ManiSkill 3.0.1 PDEEPose/PDEEPos controller (arm) and the mimic gripper on a real PhysX Panda,
under one of ManiSkill's two IK semantics (``setup.semantics``): "gpu" (one damped least-squares step, pytorch
kinematics) or "cpu" (Pinocchio CLIK). The replay is generic: the configs, the frame, the solver and the CLIK
parameters come from the trace, so other recorded cases (frames, solvers, absolute poses, resets, interpolation,
unreachable targets) replay the same way. The Newton Panda is ``add_urdf`` of tests/data/panda_v2_dynamics.urdf
(``panda_hand_tcp`` merged into ``panda_link7``: the controller finds it through ``urdf_path``), 2 envs fed the same
recorded states. Checks, per step:

- the processed actions (1e-6), the measured EE pose (5e-6), the target pose (1e-5, quaternions up to sign);
- gpu: the task-space step ``J(q0)·(target_qpos − q0)`` with the trace's Jacobian (2e-5) — ``target_qpos`` itself is
  ill-conditioned along J's null direction (README of the traces);
- cpu: where ManiSkill's IK succeeded, FK(target_qpos) reaches ManiSkill's target pose (2e-4) and ours succeeded too;
  where it failed (away from the threshold), ours failed too and the target is the measured q;
- gripper targets (1e-6), start positions, and the drive targets at every substep against the targets (with
  interpolation: ``start + (target − start)/K · i``), and the use_target state ``{"target_pose"}``.
"""

from __future__ import annotations

import json
from pathlib import Path

import newton
import numpy as np
import pytest
import warp as wp
from conftest import CONFORMANCE, PANDA_URDF

import wpctrl
from wpctrl import config as C

EE_DIR = CONFORMANCE / "ee"
CASES = sorted(p.stem for p in EE_DIR.glob("*.json")) if EE_DIR.exists() else ["gpu_pd_ee_delta_pose"]
NUM_ENVS = 2
_CLS = {
    "PDEEPoseController": wpctrl.PDEEPoseControllerConfig,
    "PDEEPosController": wpctrl.PDEEPosControllerConfig,
    "PDJointPosController": C.PDJointPosControllerConfig,
    "PDJointPosMimicController": C.PDJointPosMimicControllerConfig,
}


def f32(x):
    return np.asarray(x, dtype=np.float32)


def quat_dist(a, b) -> float:
    """max-abs distance of two wxyz quaternions, up to sign."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(min(np.abs(a - b).max(), np.abs(a + b).max()))


def rot_angle(a, b) -> float:
    """Angle [rad] between two wxyz rotations (2 atan2(|v|, |w|) of a⁻¹b: accurate for small angles)."""
    aw, av = float(a[0]), np.asarray(a[1:], np.float64)
    bw, bv = float(b[0]), np.asarray(b[1:], np.float64)
    w = aw * bw + av @ bv
    v = aw * bv - bw * av - np.cross(av, bv)
    return 2.0 * float(np.arctan2(np.linalg.norm(v), abs(w)))


def load(name: str) -> dict:
    path = EE_DIR / f"{name}.json"
    return json.loads(path.read_text())


def mode_from_trace(trace: dict) -> dict:
    """The ManiSkill control-mode dict with wpctrl's classes; the IK iterations of the trace's semantics."""
    mode = {}
    for uid, c in trace["setup"]["controllers"].items():
        fields = {k: v for k, v in c["config"].items() if k != "controller_cls"}
        if "ee_link" in fields:
            fields["urdf_path"] = str(PANDA_URDF)  # the trace keeps the packaged URDF's basename
            kin = c.get("kinematics", {})
            solver = dict(fields.get("delta_solver_config") or {})
            if trace["setup"]["semantics"] == "cpu":
                pin = kin.get("pinocchio_call", {})
                solver.update(
                    solver_iterations=int(pin.get("max_iterations", 100)),
                    tolerance=float(pin.get("eps", 1e-4)),
                    clik_dt=float(pin.get("dt", 0.1)),
                    clik_damping=float(pin.get("damp", 1e-6)),
                )
            elif "lm_lambda" in kin:
                solver["lm_lambda"] = float(kin["lm_lambda"])
            fields["delta_solver_config"] = solver
        mode[uid] = _CLS[c["cls"]](**fields)
    return mode


def urdf_panda(num_envs: int) -> newton.Model:
    robot = newton.ModelBuilder()
    robot.add_urdf(str(PANDA_URDF), collapse_fixed_joints=True, floating=False)
    builder = newton.ModelBuilder()
    builder.replicate(robot, num_envs)
    return builder.finalize(device="cpu")


class EEReplay:
    def __init__(self, trace: dict):
        setup = trace["setup"]
        self.trace = trace
        self.model = urdf_panda(NUM_ENVS)
        self.ctrl = wpctrl.build_controller(
            mode_from_trace(trace), self.model, control_freq=setup["control_freq"], sim_freq=setup["sim_freq"]
        )
        assert self.ctrl.joint_names == setup["active_joint_names"]
        self.state = self.model.state()
        self.fk_state = self.model.state()
        self.control = self.model.control()
        self.coord = self.ctrl.coord_index  # (envs, 9)
        self.ee_uid = next(u for u, c in setup["controllers"].items() if "ee_link" in c["config"])

    def put(self, qpos, state=None):
        state = state or self.state
        q = state.joint_q.numpy()
        q[self.coord] = f32(qpos)
        state.joint_q.assign(q)

    def fk(self, arm_q: np.ndarray) -> np.ndarray:
        """EE poses (envs, 7) of the arm positions ``arm_q`` (envs, n_arm), by the controller's own FK."""
        arm = self.ctrl[self.ee_uid]
        q = self.fk_state.joint_q.numpy()
        q[self.coord[:, arm._rows]] = arm_q
        self.fk_state.joint_q.assign(q)
        return arm.fk_jacobian(self.fk_state)[0].numpy()


def check_pose(got: np.ndarray, ref, tol: float, what: str):
    for e in range(got.shape[0]):
        np.testing.assert_allclose(got[e, :3], f32(ref[:3]), atol=tol, rtol=0, err_msg=f"{what} position (env {e})")
        assert quat_dist(got[e, 3:], ref[3:]) <= tol, f"{what} quaternion (env {e}): {got[e, 3:]} vs {ref[3:]}"


def check_internals(rp: EEReplay, recorded: dict, where: str):
    for uid, internals in recorded.items():
        child = rp.ctrl[uid]
        keys = ("start_qpos",) if uid == rp.ee_uid else ("start_qpos", "target_qpos")
        for key in keys:
            if key in internals:
                got = getattr(child, key).numpy()
                np.testing.assert_allclose(
                    got,
                    np.broadcast_to(f32(internals[key]), got.shape),
                    atol=1e-6,
                    rtol=0,
                    err_msg=f"{where} {uid}.{key}",
                )
        if uid == rp.ee_uid and internals.get("target_pose") is not None:
            check_pose(child.target_pose.numpy(), internals["target_pose"], 1e-5, f"{where} {uid}.target_pose")


@pytest.mark.parametrize("case", CASES)
def test_ee_action_spaces(case):
    trace = load(case)
    setup = trace["setup"]
    ctrl = EEReplay(trace).ctrl
    np.testing.assert_array_equal(ctrl.single_action_space.low, f32(setup["env_action_space"]["low"]))
    np.testing.assert_array_equal(ctrl.single_action_space.high, f32(setup["env_action_space"]["high"]))
    assert ctrl.action_mapping == {k: tuple(v) for k, v in setup["action_mapping"].items()}
    for uid, c in setup["controllers"].items():
        child = ctrl[uid]
        orig = c["original_action_space"]
        if orig is None:
            assert child._original_single_action_space is None
        else:
            np.testing.assert_array_equal(child._original_single_action_space.low, f32(orig["low"]))
            np.testing.assert_array_equal(child._original_single_action_space.high, f32(orig["high"]))
        # ManiSkill builds unbounded (None) bounds as NaN; wpctrl uses -inf/+inf
        low = np.nan_to_num(np.array(c["single_action_space"]["low"], dtype=np.float32), nan=-np.inf)
        np.testing.assert_array_equal(child.single_action_space.low, low)
    assert type(ctrl[EEReplay(trace).ee_uid]).__name__ == setup["controllers"]["arm"]["cls"]


def _reset(rp: EEReplay, rec: dict, env_ids):
    rp.put(rec["qpos"])
    rp.ctrl.reset(rp.state, env_ids=env_ids)
    arm = rp.ctrl[rp.ee_uid]
    check_pose(arm.ee_pose.numpy(), rec["ee_pose_at_base"], 5e-6, "reset ee_pose")
    np.testing.assert_allclose(arm.target_qpos.numpy(), np.broadcast_to(f32(rec["qpos"][:7]), (NUM_ENVS, 7)), atol=0)
    check_internals(rp, rec["controllers"], "reset")


@pytest.mark.parametrize("case", CASES)
def test_ee_replay(case):
    trace = load(case)
    setup = trace["setup"]
    semantics = setup["semantics"]
    rp = EEReplay(trace)
    ctrl, arm = rp.ctrl, rp.ctrl[rp.ee_uid]
    cols = setup["action_mapping"][rp.ee_uid]
    arm_rows = arm._rows
    kin = setup["controllers"][rp.ee_uid].get("kinematics", {})
    eps = float(kin.get("pinocchio_call", {}).get("eps", 1e-4))
    K = setup["sim_steps_per_control"]
    interpolate = bool(setup["controllers"][rp.ee_uid]["config"]["interpolate"])

    _reset(rp, trace["reset"], None)
    events = {ev["before_step"]: ev for ev in trace.get("events", [])}
    checked_ik = 0
    for st in trace["steps"]:
        k = st["step"]
        if k in events:
            _reset(rp, events[k]["after_reset"], list(range(NUM_ENVS)))
        rp.put(st["qpos_before"])
        ctrl.set_action(np.tile(f32(st["action"]), (NUM_ENVS, 1)), rp.state)
        where = f"step {k}"
        for uid, pa in st["processed_action"].items():
            got = ctrl[uid].processed_action.numpy()
            np.testing.assert_allclose(got, np.broadcast_to(f32(pa), got.shape), atol=1e-6, rtol=0, err_msg=where)
        check_pose(arm.ee_pose.numpy(), st["ee_pose_at_base_before"], 5e-6, f"{where} ee_pose")
        check_internals(rp, st["after_set_action"]["controllers"], f"{where} after set_action")

        tq = arm.target_qpos.numpy()
        q0 = f32(st["qpos_before"])[: tq.shape[1]]
        assert np.array_equal(tq[0], tq[1]), f"{where}: the two envs differ"
        ik = st.get("ik")
        if ik is not None and semantics == "gpu":
            jac = np.asarray(ik["jacobian"], np.float64)
            ref = jac @ (np.asarray(ik["returned"], np.float64) - q0)
            got = jac @ (tq[0].astype(np.float64) - q0)
            np.testing.assert_allclose(got, ref, atol=2e-5, rtol=0, err_msg=f"{where} J(q0)·(target_qpos − q0)")
            checked_ik += 1
        elif ik is not None:
            pin = ik["pinocchio"]
            target = st["after_set_action"]["controllers"][rp.ee_uid]["target_pose"]
            ours = arm.ik_success.numpy()
            borderline = abs(float(np.linalg.norm(pin["error"])) - eps) < 0.1 * eps
            if pin["success"]:
                assert ours.all(), f"{where}: ManiSkill's IK converged, ours did not"
                reached = rp.fk(tq)
                for e in range(NUM_ENVS):
                    assert np.abs(reached[e, :3] - f32(target[:3])).max() <= 2e-4, f"{where} FK(target_qpos) position"
                    assert rot_angle(reached[e, 3:], target[3:]) <= 2e-4, f"{where} FK(target_qpos) rotation"
                checked_ik += 1
            elif not borderline:
                assert not ours.any(), f"{where}: ManiSkill's IK failed, ours converged"
                np.testing.assert_array_equal(tq, np.broadcast_to(q0, tq.shape), err_msg=f"{where} failed IK holds")
                checked_ik += 1

        # Drive targets at every substep: the targets (interpolated), the gripper as recorded.
        start = ctrl.start_qpos.numpy()
        target = ctrl.target_qpos.numpy()
        for sub in st["substeps"]:
            ctrl.before_simulation_step(rp.state, rp.control)
            drive = rp.control.joint_target_q.numpy()[rp.coord]
            i = sub["index"] + 1
            expect = target.copy()
            if interpolate:
                expect[:, arm_rows] = start[:, arm_rows] + ((target - start) / np.float32(K))[:, arm_rows] * np.float32(
                    i
                )
            np.testing.assert_allclose(drive, expect, atol=1e-6, rtol=0, err_msg=f"{where} substep {i} drive")
            others = [j for j in range(drive.shape[1]) if j not in range(arm_rows.start, arm_rows.stop)]
            np.testing.assert_allclose(
                drive[:, others],
                np.broadcast_to(f32(sub["drive_target"])[others], (NUM_ENVS, len(others))),
                atol=1e-6,
                rtol=0,
                err_msg=f"{where} substep {i} gripper drive",
            )
            assert (ctrl.step_counter.numpy() == sub["controller_step_counter"][rp.ee_uid]).all()
            rp.put(sub["qpos_after"])
        state = ctrl.get_state()
        if setup["controllers"][rp.ee_uid]["config"]["use_target"]:
            pose = state[rp.ee_uid]["target_pose"].numpy()
            check_pose(pose, st["obs_after"][-7:], 1e-5, f"{where} get_state target_pose")
        else:
            assert rp.ee_uid not in state
        assert cols[1] - cols[0] == arm.action_dim
    assert checked_ik >= len(trace["steps"]) // 2


def test_state_roundtrip():
    trace = load("gpu_pd_ee_target_delta_pose")
    rp = EEReplay(trace)
    rp.put(trace["reset"]["qpos"])
    rp.ctrl.reset(rp.state)
    arm = rp.ctrl["arm"]
    saved = rp.ctrl.get_state()["arm"]["target_pose"].numpy().copy()
    rp.ctrl.set_action(np.zeros((NUM_ENVS, 7), np.float32) + 0.5, rp.state)
    assert not np.allclose(arm.target_pose.numpy(), saved)
    rp.ctrl.set_state({"arm": {"target_pose": saved}})
    np.testing.assert_allclose(arm.target_pose.numpy(), saved, atol=1e-7)
    with pytest.raises(ValueError, match="target_pose"):
        rp.ctrl.set_state({"arm": {"target_pose": np.zeros((NUM_ENVS, 6), np.float32)}})
    assert Path(PANDA_URDF).exists() and wp.get_device().is_cpu
