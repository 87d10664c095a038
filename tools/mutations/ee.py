"""Mutations: end effector, state."""

from .model import M

MUTATIONS = [
    M(
        "ee_rotation_not_norm_clipped",
        "wpctrl/kernels/ee_math.py",
        "            if nrm > 1.0:\n",
        "            if nrm > 10.0:\n",
        "the EE rotation action is not clipped to norm 1",
        ("tests/test_ee.py",),
    ),
    M(
        "ee_use_target_ignored",
        "wpctrl/kernels/ee.py",
        "                prev = _read_pose(target_pose_out, env)\n",
        "                prev = t_ee\n",
        "EE use_target composes on the measured pose",
        ("tests/test_ee.py",),
    ),
    M(
        "set_state_keeps_control",
        "wpctrl/controllers/base_controller.py",
        "        eng.forget_control()  # the Control's drive targets are now stale: the next substep rewrites them\n",
        "",
        "set_state leaves the known Control's stale drive targets",
        ("tests/test_launches.py",),
    ),
]
