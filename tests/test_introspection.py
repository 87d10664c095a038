"""What a controller tells about itself: where its joints are in Newton's arrays (per env, for a child too), their
limits, whether a substep launches, its plan as text; and that the engine behind it finds no attribute by searching.

The indices are checked against the model itself (``Model.joint_q_start`` / ``joint_qd_start`` of each world's
joint of that name, the model's own limits), not against wpctrl's binding.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import build_panda

import wpctrl
from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS, panda_control_modes

N = 3


def _model_indices(model, names):
    """(num_envs, n) coordinate, DOF and joint indices of ``names`` in each world, read from the model's labels."""
    labels = [lb.rsplit("/", 1)[-1] for lb in model.joint_label]
    world = model.joint_world.numpy()
    q_start, qd_start = model.joint_q_start.numpy(), model.joint_qd_start.numpy()
    joints = np.array([[next(j for j in range(len(labels)) if world[j] == e and labels[j] == n) for n in names]
                       for e in range(model.world_count)])  # fmt: skip
    return q_start[joints], qd_start[joints], joints


def test_joint_indices_limits_and_children_follow_the_model():
    model = build_panda(N)
    ctrl = wpctrl.build_controller(panda_control_modes()["pd_joint_delta_pos"], model)
    names = list(PANDA_ARM_JOINTS) + list(PANDA_GRIPPER_JOINTS)
    q, qd, joints = _model_indices(model, names)
    np.testing.assert_array_equal(ctrl.coord_index, q)
    np.testing.assert_array_equal(ctrl.dof_index, qd)
    np.testing.assert_array_equal(ctrl.joint_index, joints)
    lo, hi = model.joint_limit_lower.numpy(), model.joint_limit_upper.numpy()
    np.testing.assert_array_equal(ctrl.joint_limits, np.stack([lo[qd[0]], hi[qd[0]]], axis=1))
    assert ctrl.joint_mapping == {"arm": (0, 7), "gripper": (7, 9)}
    for uid, (a, b) in ctrl.joint_mapping.items():
        child = ctrl[uid]
        np.testing.assert_array_equal(child.coord_index, q[:, a:b])
        np.testing.assert_array_equal(child.dof_index, qd[:, a:b])
        np.testing.assert_array_equal(child.joint_limits, ctrl.joint_limits[a:b])
    # copies: writing one does not move the controller's joints
    ctrl.coord_index[:] = 0
    np.testing.assert_array_equal(ctrl.coord_index, q)
    assert ctrl.model is model


def test_substep_launch_and_the_plan_text():
    model = build_panda(1)
    mode = panda_control_modes()["pd_joint_delta_pos"]
    elided = wpctrl.build_controller(mode, model)
    explicit = wpctrl.build_controller(panda_control_modes()["pd_joint_delta_pos"], model, actuation="explicit")
    assert not elided.substep_launch and explicit.substep_launch
    text = explicit.describe()
    assert "1 envs x 9 rows" in text and "explicit (naive)" in text and "panda_joint7" in text
    assert "per-substep launch: no (elided)" in elided.describe()
    assert elided.coupled_iterations is None


def test_the_engine_finds_nothing_by_searching():
    """Private: an attribute the engine does not define raises (no search through its core and parts), and a part
    name that is no part is refused rather than reported absent."""
    ctrl = wpctrl.build_controller(panda_control_modes()["pd_joint_delta_pos"], build_panda(1))
    eng = ctrl._engine
    assert "__getattr__" not in type(eng).__dict__
    for name in ("kp", "target_qpos", "delay", "nominal"):
        with pytest.raises(AttributeError):
            getattr(eng, name)
    assert eng.part("delay") is None and eng.part("drive_properties") is not None
    with pytest.raises(KeyError, match="drive"):
        eng.part("drive")
