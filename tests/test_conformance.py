"""Replay ManiSkill's recorded Panda traces (tests/data/conformance) through wpctrl, step by step.

Each trace ran the real ManiSkill controllers on a real PhysX Panda. We put the recorded measured state into a
Newton state before every call, and compare what wpctrl computes (processed action, targets, the drive targets
written into Newton's Control at every substep) with what ManiSkill computed, within 1e-6. The explicit-actuation
replay checks the torques against the PD law evaluated in numpy on the recorded drive targets.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import CONFORMANCE

import wpctrl
from wpctrl import config as C

CASES = ["pd_joint_pos", "pd_joint_delta_pos", "pd_joint_vel", "pd_joint_pos_vel"]
TOL = 1e-6
_CLS = {
    "PDJointPosController": C.PDJointPosControllerConfig,
    "PDJointPosMimicController": C.PDJointPosMimicControllerConfig,
    "PDJointVelController": C.PDJointVelControllerConfig,
    "PDJointPosVelController": C.PDJointPosVelControllerConfig,
    "PassiveController": C.PassiveControllerConfig,
}


def load_trace(name: str) -> dict:
    path = CONFORMANCE / f"{name}.json"
    return json.loads(path.read_text())


def mode_from_trace(trace: dict) -> dict:
    """The ManiSkill control-mode dict, rebuilt from the recorded config fields with wpctrl's classes."""
    mode = {}
    for uid, c in trace["setup"]["controllers"].items():
        fields = {k: v for k, v in c["config"].items() if k != "controller_cls"}
        mode[uid] = _CLS[c["cls"]](**fields)
    return mode


def f32(x):
    return np.asarray(x, dtype=np.float32)


class Replay:
    """A 1-env Panda model plus helpers to write recorded joint states and read Newton's arrays."""

    def __init__(self, trace: dict, panda_model, actuation: str):
        self.trace = trace
        self.model = panda_model(1)
        self.ctrl = wpctrl.build_controller(
            mode_from_trace(trace),
            self.model,
            control_freq=trace["setup"]["control_freq"],
            sim_freq=trace["setup"]["sim_freq"],
            actuation=actuation,
        )
        self.state = self.model.state()
        self.control = self.model.control()
        b = self.ctrl  # the controlled joints' coord_index / dof_index
        assert self.ctrl.joint_names == trace["setup"]["active_joint_names"]
        self.coord = b.coord_index[0]
        self.dof = b.dof_index[0]

    def put(self, qpos, qvel):
        q = self.state.joint_q.numpy()
        qd = self.state.joint_qd.numpy()
        q[self.coord] = f32(qpos)
        qd[self.dof] = f32(qvel)
        self.state.joint_q.assign(q)
        self.state.joint_qd.assign(qd)

    def drive(self):
        return (
            self.control.joint_target_q.numpy()[self.coord],
            self.control.joint_target_qd.numpy()[self.dof],
            self.control.joint_f.numpy()[self.dof],
        )


def check_internals(ctrl, recorded: dict, where: str):
    for uid, internals in recorded.items():
        child = ctrl[uid]
        for key in ("start_qpos", "target_qpos", "target_qvel"):
            if key in internals:
                got = getattr(child, key).numpy()[0]
                np.testing.assert_allclose(got, f32(internals[key]), atol=TOL, rtol=0, err_msg=f"{where} {uid}.{key}")
        if "step" in internals:
            assert int(ctrl.step_counter.numpy()[0]) == internals["step"], f"{where} {uid}.step"


@pytest.mark.parametrize("case", CASES)
def test_action_spaces(case, panda_model):
    trace = load_trace(case)
    setup = trace["setup"]
    ctrl = Replay(trace, panda_model, "implicit").ctrl
    space = setup["env_action_space"]
    assert ctrl.single_action_space.dtype == np.float32
    np.testing.assert_array_equal(ctrl.single_action_space.low, f32(space["low"]))
    np.testing.assert_array_equal(ctrl.single_action_space.high, f32(space["high"]))
    assert ctrl.action_space == ctrl.single_action_space  # one env: unbatched, as ManiSkill
    assert ctrl.action_mapping == {k: tuple(v) for k, v in setup["action_mapping"].items()}
    assert ctrl.sets_target_qpos == setup["sets_target_qpos"]
    assert ctrl.sets_target_qvel == setup["sets_target_qvel"]
    for uid, c in setup["controllers"].items():
        child = ctrl[uid]
        assert child.joint_names == c["joints"]
        np.testing.assert_array_equal(child.single_action_space.low, f32(c["single_action_space"]["low"]))
        np.testing.assert_array_equal(child.single_action_space.high, f32(c["single_action_space"]["high"]))
        orig = c["original_action_space"]
        if orig is None:
            assert child._original_single_action_space is None
        else:
            np.testing.assert_array_equal(child._original_single_action_space.low, f32(orig["low"]))
            np.testing.assert_array_equal(child._original_single_action_space.high, f32(orig["high"]))


@pytest.mark.parametrize("actuation", ["implicit", "explicit"])
@pytest.mark.parametrize("case", CASES)
def test_replay(case, actuation, panda_model):
    trace = load_trace(case)
    rp = Replay(trace, panda_model, actuation)
    ctrl = rp.ctrl
    # Implicit replays run the elided substep (set_action writes the drive targets), explicit ones the substep kernel.
    interpolates = any(c["config"].get("interpolate") for c in trace["setup"]["controllers"].values())
    assert ctrl.substep_launch == (actuation == "explicit" or interpolates)
    drives = trace["setup"]["drive_properties"]
    kp = f32([d["stiffness"] for d in drives])
    kd = f32([d["damping"] for d in drives])
    fl = f32([d["force_limit"] for d in drives])

    # Drive properties as ManiSkill sets them, in the model (implicit) or in wpctrl's own PD (explicit).
    m = rp.model
    if actuation == "implicit":
        np.testing.assert_array_equal(m.joint_target_ke.numpy()[rp.dof], kp)
        np.testing.assert_array_equal(m.joint_target_kd.numpy()[rp.dof], kd)
    else:
        assert not m.joint_target_ke.numpy()[rp.dof].any() and not m.joint_target_kd.numpy()[rp.dof].any()
    np.testing.assert_array_equal(m.joint_effort_limit.numpy()[rp.dof], fl)
    np.testing.assert_array_equal(m.joint_friction.numpy()[rp.dof], f32([d["friction"] for d in drives]))

    rp.put(trace["reset"]["qpos"], trace["reset"]["qvel"])
    ctrl.reset(rp.state)
    check_internals(ctrl, trace["reset"]["controllers"], "reset")

    for st in trace["steps"]:
        k = st["step"]
        rp.put(st["qpos_before"], st["qvel_before"])
        ctrl.set_action(f32(st["action"])[None, :], rp.state)
        for uid, pa in st["processed_action"].items():
            np.testing.assert_allclose(
                ctrl[uid].processed_action.numpy()[0], f32(pa), atol=TOL, rtol=0, err_msg=f"step {k} {uid} processed"
            )
        check_internals(ctrl, st["after_set_action"]["controllers"], f"step {k} after set_action")
        q_now, qd_now = f32(st["qpos_before"]), f32(st["qvel_before"])
        for sub in st["substeps"]:
            ctrl.before_simulation_step(rp.state, rp.control)
            tq, tqd, tau = rp.drive()
            where = f"step {k} substep {sub['index']}"
            np.testing.assert_allclose(tq, f32(sub["drive_target"]), atol=TOL, rtol=0, err_msg=f"{where} target_q")
            np.testing.assert_allclose(tqd, f32(sub["drive_velocity_target"]), atol=TOL, rtol=0, err_msg=f"{where} qd")
            assert int(ctrl.step_counter.numpy()[0]) == sub["controller_step_counter"]["gripper"]
            if actuation == "explicit":
                ref = np.clip(
                    kp * (f32(sub["drive_target"]) - q_now) + kd * (f32(sub["drive_velocity_target"]) - qd_now),
                    -fl,
                    fl,
                )
                np.testing.assert_allclose(tau, ref, rtol=1e-5, atol=1e-3, err_msg=f"{where} joint_f")
            else:
                assert not tau.any(), "implicit actuation must not write joint_f"
            # PhysX moved the robot: put the recorded state back in for the next substep.
            rp.put(sub["qpos_after"], sub["qvel_after"])
            q_now, qd_now = f32(sub["qpos_after"]), f32(sub["qvel_after"])
        check_internals(ctrl, st["after_step_controllers"], f"step {k} after step")
        if len(st["obs_after"]) > 18:  # use_target modes: the arm's virtual target is part of the observation
            np.testing.assert_allclose(ctrl.get_state()["arm"]["target_qpos"].numpy()[0], f32(st["obs_after"][18:]))
