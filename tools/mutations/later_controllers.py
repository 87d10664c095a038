"""Mutations: smoothing, effort readout, bases and DOF indices on later controllers / other models."""

from .model import M

MUTATIONS = [
    M(
        "ema_alpha_of_row_0",
        "wpctrl/kernels/pd_set_action.py",
        "al = row_f[r, ROW_F_ALPHA]",
        "al = row_f[0, ROW_F_ALPHA]",
        "every smoothed joint uses the first row's EMA weight (one alpha per mode, not per controller)",
        ("tests/test_actuator_setups.py",),
    ),
    M(
        "effort_limit_of_env_0",
        "wpctrl/kernels/pd_substep.py",
        "lim[r] = force_limit[lb, r]",
        "lim[r] = force_limit[0, r]",
        "the explicit clamp and the effort readout use env 0's force limit",
        ("tests/test_actuator_setups.py", "tests/test_actuation.py"),
    ),
    M(
        "base_yaw_row_not_offset",
        "wpctrl/config/rows.py",
        'elif k in ("mimic_src", "yaw_row"):',
        'elif k in ("mimic_src",):',
        "a mobile base after another controller rotates by the yaw of a row of that controller",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "substep_dofs_at_coordinate_stride",
        "wpctrl/kernels/step_layout.py",
        "di[r] = env * qd_stride + wp.static(QDOFF[r])",
        "di[r] = env * q_stride + wp.static(QDOFF[r])",
        "replicated envs with more coordinates than DOFs (floating bases): env e's DOFs at the coordinate stride",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "set_action_velocity_target_at_coordinate",
        "wpctrl/kernels/pd_set_action.py",
        "                    joint_target_qd_out[di[r]] = vt[r]\n",
        "                    joint_target_qd_out[qi[r]] = vt[r]\n",
        "set_action writes velocity targets at the coordinate index (wrong on floating bases)",
        ("tests/test_construction_orders.py",),
    ),
]
