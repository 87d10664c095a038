"""Binding joint names to Newton's arrays: replicated worlds (fast path) and worlds that differ (per-world path)."""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from wpctrl.binding import _replicated_table, _resolve, bind_joints
from wpctrl.robots import PANDA_ARM_JOINTS, panda


def _slow_table(model, names):
    labels = list(model.joint_label)
    jworld, jtype, qd = model.joint_world.numpy(), model.joint_type.numpy(), model.joint_qd_start.numpy()
    return np.stack(
        [
            _resolve(names, labels, np.nonzero(jworld == w)[0].tolist(), w, jtype, qd)[0]
            for w in range(model.world_count)
        ]
    )


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
    np.testing.assert_array_equal(fast, _slow_table(model, names))


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
    np.testing.assert_array_equal(binding.joint_index, _slow_table(model, PANDA_ARM_JOINTS))
    # world 1's coordinates are shifted by the free joint's 7 coordinates and 6 DOFs
    assert binding.q_base[1] - binding.q_base[0] == 9 + 7
    assert binding.qd_base[1] - binding.qd_base[0] == 9 + 6
    labels = np.array(model.joint_label, dtype=object)
    assert (labels[binding.joint_index] == np.array([f"panda/{n}" for n in PANDA_ARM_JOINTS], dtype=object)).all()
