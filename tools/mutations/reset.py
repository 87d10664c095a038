"""Mutations: reset."""

from .model import M

MUTATIONS = [
    M(
        "reset_keeps_joint_f",
        "wpctrl/kernels/pd.py",
        "            joint_f_out[di] = 0.0\n",
        "            joint_f_out[di] = joint_f_out[di]\n",
        "a reset given a Control leaves the explicit joint_f of the reset envs",
        ("tests/test_semantics.py",),
    ),
    M(
        "partial_reset_ignores_mask",
        "wpctrl/kernels/pd.py",
        "        if not env_mask_in[env]:\n            return\n    if r == 0:",
        "        if not env_mask_in[env]:\n            pass\n    if r == 0:",
        "a reset with a bool mask resets every env",
        ("tests/test_semantics.py",),
    ),
    M(
        "velocity_target_kept_on_reset",
        "wpctrl/kernels/pd.py",
        "    target_qvel_out[env, r] = v\n",
        "    target_qvel_out[env, r] = target_qvel_out[env, r]\n",
        "a reset keeps the stale velocity target (ManiSkill's behaviour, not wpctrl's)",
        ("tests/test_semantics.py",),
    ),
    M(
        "posvel_first_reset_ignores_velocity",
        "wpctrl/kernels/pd.py",
        "if first != 0 and kind == ROW_POS and vel_target:",
        "if first == 2 and kind == ROW_POS and vel_target:",
        "the first reset of a PDJointPosVel does not take the measured velocity",
        ("tests/test_semantics.py",),
    ),
    M(
        "delay_history_not_refilled",
        "wpctrl/kernels/pd.py",
        "            delay_q_out[i, env, r] = held\n",
        "            delay_q_out[i, env, r] = delay_q_out[i, env, r]\n",
        "a reset leaves the previous episode's commands in the delay ring",
        ("tests/test_actuation.py",),
    ),
    M(
        "effort_count_not_zeroed_on_reset",
        "wpctrl/kernels/pd.py",
        "        saturation_count_out[env, r] = 0\n",
        "        saturation_count_out[env, r] = saturation_count_out[env, r]\n",
        "a reset keeps the saturation count",
        ("tests/test_actuation.py",),
    ),
]
