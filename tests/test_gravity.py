"""``balance_passive_force`` (ManiSkill's agent-level gravity switch) on a real MuJoCo-Warp rollout with gravity on."""

from __future__ import annotations

import newton
import numpy as np
import pytest
import warp as wp
from conftest import build_panda

import wpctrl
from wpctrl.robots import panda_control_modes


def _zero_action_drift(mode, num_envs=2, steps=20, **kw) -> tuple[np.ndarray, newton.Model]:
    """Max |q - q0| per joint over ``num_envs`` Pandas after ``steps`` zero-action control steps (20 Hz, 100 Hz sim)."""
    model = build_panda(num_envs)
    assert np.linalg.norm(model.gravity.numpy()) > 9.0  # the model's gravity is on
    ctrl = wpctrl.build_controller(mode, model, **kw)
    solver = newton.solvers.SolverMuJoCo(model, disable_contacts=True)
    s0, s1, control = model.state(), model.state(), model.control()
    ctrl.reset(s0, control=control)
    q0 = s0.joint_q.numpy().copy()
    zero = np.zeros(ctrl.action_space.shape, np.float32)
    for _ in range(steps):
        ctrl.set_action(zero, s0)
        for _ in range(ctrl.num_substeps):
            ctrl.before_simulation_step(s0, control)
            solver.step(s0, s1, control, None, 0.01)
            s0, s1 = s1, s0
    return np.abs(s0.joint_q.numpy() - q0).reshape(num_envs, -1).max(axis=0), model


def test_on_by_default_the_arm_holds_still_with_gravity_on():
    """ManiSkill's default (no key in the dict): gravity off the robot's links; zero delta actions hold the arm."""
    mode = panda_control_modes()["pd_joint_delta_pos"]
    assert "balance_passive_force" not in mode
    drift, model = _zero_action_drift(mode)
    assert drift[:7].max() < 1e-3, drift  # 1 s, every arm joint
    # Every body of the robot (the articulation of the controlled joints) carries gravcomp 1.
    np.testing.assert_array_equal(model.mujoco.gravcomp.numpy(), 1.0)


def test_off_in_the_dict_the_arm_sags():
    mode = dict(panda_control_modes()["pd_joint_delta_pos"], balance_passive_force=False)
    drift, model = _zero_action_drift(mode)
    assert drift[1] > 0.1, drift  # joint 2 falls under gravity (measured: 0.33 rad in 1 s)
    assert getattr(model.mujoco, "gravcomp", None) is None or not model.mujoco.gravcomp.numpy().any()


def test_build_option_applies_and_must_agree_with_the_dict():
    """The keyword decides for a dict without the entry; given both ways, they must agree (a keyword that would
    silently win over the mode dict is refused, naming both)."""
    drift, _ = _zero_action_drift(panda_control_modes()["pd_joint_delta_pos"], balance_passive_force=False)
    assert drift[1] > 0.1, drift  # the keyword turned it off: joint 2 falls
    mode = dict(panda_control_modes()["pd_joint_delta_pos"], balance_passive_force=False)
    with pytest.raises(
        wpctrl.ConfigError, match=r"balance_passive_force: expected None or the mode dict's .*False.*True"
    ):
        wpctrl.build_controller(mode, build_panda(1), balance_passive_force=True)
    drift, _ = _zero_action_drift(mode, balance_passive_force=False)  # agreeing: fine
    assert drift[1] > 0.1, drift


def test_only_the_robot_loses_gravity():
    """A free box in the same world keeps gravcomp 0: only the articulation of the controlled joints is balanced."""
    from wpctrl.robots import panda

    robot = newton.ModelBuilder()
    robot.add_builder(panda())
    box = robot.add_body(xform=wp.transform((1.0, 0.0, 1.0), wp.quat_identity()), label="box")
    robot.add_shape_box(box, hx=0.05, hy=0.05, hz=0.05)
    builder = newton.ModelBuilder()
    builder.replicate(robot, 2)
    model = builder.finalize(device="cpu")
    wpctrl.build_controller(panda_control_modes()["pd_joint_delta_pos"], model)
    g = model.mujoco.gravcomp.numpy()
    labels = list(model.body_label)
    for b, label in enumerate(labels):
        assert g[b] == (0.0 if "panda" not in label else 1.0), (label, g[b])
    assert (g == 0).sum() == 2  # the two boxes


def test_other_solvers_are_refused_with_the_reason():
    model = build_panda(1)
    solver = newton.solvers.SolverFeatherstone(model)
    mode = panda_control_modes()["pd_joint_delta_pos"]
    with pytest.raises(wpctrl.ConfigError, match=r"balance_passive_force: SolverFeatherstone has no per-body gravity"):
        wpctrl.build_controller(mode, model, solver=solver)
    ctrl = wpctrl.build_controller(mode, model)
    with pytest.raises(wpctrl.ConfigError, match=r"balance_passive_force=False"):
        ctrl.attach_solver(solver)
    off = wpctrl.build_controller(mode, model, balance_passive_force=False, solver=solver)
    assert off.balance_passive_force is False


def test_bad_value_is_refused():
    mode = dict(panda_control_modes()["pd_joint_delta_pos"], balance_passive_force="yes")
    with pytest.raises(wpctrl.ConfigError, match=r"balance_passive_force: expected True or False, got 'yes'"):
        wpctrl.build_controller(mode, build_panda(1))
