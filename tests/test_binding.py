"""Binding joint names to Newton's arrays: replicated worlds (fast path) and worlds that differ (per-world path),
against a search of the model's joint labels written here."""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from wpctrl.binding import _replicated_table, bind_joints
from wpctrl.robots import PANDA_ARM_JOINTS, panda


def _label_table(model, names):
    """(worlds, len(names)) index of each named joint in each world, found here by label (its last '/' part)."""
    world = model.joint_world.numpy()
    out = np.full((model.world_count, len(names)), -1, np.int64)
    for j, label in enumerate(model.joint_label):
        short = label.rsplit("/", 1)[-1]
        if short in names and world[j] >= 0:
            assert out[world[j], names.index(short)] == -1  # one joint of that name per world
            out[world[j], names.index(short)] = j
    assert (out >= 0).all()
    return out


def test_replicated_fast_path_matches_the_per_world_search():
    b = newton.ModelBuilder()
    b.replicate(panda(), 5)
    model = b.finalize(device="cpu")
    names = PANDA_ARM_JOINTS[::-1]
    labels = list(model.joint_label)
    fast, _ = _replicated_table(
        model, names, labels, model.joint_world.numpy(), model.joint_type.numpy(), model.joint_qd_start.numpy(), 5
    )
    assert fast is not None
    np.testing.assert_array_equal(fast, _label_table(model, names))
    binding = bind_joints(model, names)
    np.testing.assert_array_equal(binding.joint_index, fast)
    np.testing.assert_array_equal(binding.coord_index, model.joint_q_start.numpy()[fast])
    np.testing.assert_array_equal(binding.dof_index, model.joint_qd_start.numpy()[fast])


def test_worlds_that_differ_bind_world_by_world():
    b = newton.ModelBuilder()
    for w in range(3):
        b.begin_world()
        if w == 1:  # an extra articulation before the robot in world 1 only
            link = b.add_link(mass=1.0, inertia=wp.mat33(np.eye(3) * 0.01))
            j = b.add_joint_free(link, label="box/free")
            b.add_articulation([j])
        b.add_builder(panda())
        b.end_world()
    model = b.finalize(device="cpu")
    binding = bind_joints(model, PANDA_ARM_JOINTS)
    assert binding.num_envs == 3
    joints = _label_table(model, PANDA_ARM_JOINTS)
    np.testing.assert_array_equal(binding.joint_index, joints)
    np.testing.assert_array_equal(binding.coord_index, model.joint_q_start.numpy()[joints])
    np.testing.assert_array_equal(binding.dof_index, model.joint_qd_start.numpy()[joints])
    # world 1's coordinates are shifted by the free joint's 7 coordinates and 6 DOFs
    assert binding.q_base[1] - binding.q_base[0] == 9 + 7
    assert binding.qd_base[1] - binding.qd_base[0] == 9 + 6
    labels = np.array(model.joint_label, dtype=object)
    assert (labels[binding.joint_index] == np.array([f"panda/{n}" for n in PANDA_ARM_JOINTS], dtype=object)).all()
