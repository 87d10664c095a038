"""Mutations: set_action."""

from .model import M

MUTATIONS = [
    M(
        "mimic_offset_dropped",
        "wpctrl/kernels/pd_set_action.py",
        "t[r] = t[wp.static(max(SRC[r], 0))] * row_f[r, ROW_F_MUL] + row_f[r, ROW_F_OFF]",
        "t[r] = t[wp.static(max(SRC[r], 0))] * row_f[r, ROW_F_MUL]",
        "a mimic follower ignores its offset",
        ("tests/test_semantics.py",),
    ),
    M(
        "nan_check_skips_last_column",
        "wpctrl/kernels/pd_set_action.py",
        "            ok = ok & int(wp.isfinite(a[c]))\n",
        "            if c < wp.static(A - 1):\n                ok = ok & int(wp.isfinite(a[c]))\n",
        "the joint kernel's NaN/Inf check skips the last action column",
        ("tests/test_semantics.py",),
    ),
    M(
        "mimic_multiplier_dropped",
        "wpctrl/kernels/pd_set_action.py",
        "t[r] = t[wp.static(max(SRC[r], 0))] * row_f[r, ROW_F_MUL] + row_f[r, ROW_F_OFF]",
        "t[r] = t[wp.static(max(SRC[r], 0))] + row_f[r, ROW_F_OFF]",
        "a mimic follower ignores its multiplier",
        ("tests/test_semantics.py",),
    ),
    M(
        "binary_zero_closes",
        "wpctrl/kernels/pd_set_action.py",
        "                    if a[c] < 0.0:\n",
        "                    if a[c] <= 0.0:\n",
        "a binary command of exactly 0 closes (it opens: upper for a >= 0)",
        ("tests/test_actuator_models.py",),
    ),
    M(
        "base_yaw_sign_flipped",
        "wpctrl/kernels/pd_set_action.py",
        "vt[r] = cy * ax + (-sy) * ay",
        "vt[r] = cy * ax + sy * ay",
        "the ego-centric base velocity rotates vy by the wrong sign of the yaw",
        ("tests/test_base_controllers.py",),
    ),
    M(
        "ee_nan_check_own_columns",
        "wpctrl/kernels/ee.py",
        "        if not _action_finite(action_in, env):\n            return\n",
        "        bad = int(0)\n"
        "        for k in range(3 + 3 * pose):\n"
        "            if not wp.isfinite(action_in[env, col0 + k]):\n"
        "                bad = 1\n"
        "        if bad != 0:\n"
        "            return\n",
        "the EE kernel checks NaN/Inf only in its own action columns",
        ("tests/test_ee.py",),
    ),
    M(
        "ema_coefficient_swapped",
        "wpctrl/kernels/pd_set_action.py",
        "al * t[r] + (1.0 - al) * tp",
        "(1.0 - al) * t[r] + al * tp",
        "the EMA weights the previous target with alpha",
        ("tests/test_actuator_models.py",),
    ),
    M(
        "target_delta_from_measured",
        "wpctrl/kernels/pd_set_action.py",
        "                    t[r] = t[r] + x[c]\n",
        "                    t[r] = q[r] + x[c]\n",
        "use_target deltas start from the measured position",
        ("tests/test_semantics.py",),
    ),
    M(
        "normalize_without_clip",
        "wpctrl/kernels/pd.py",
        "    c = wp.clamp(a, -1.0, 1.0)\n",
        "    c = a\n",
        "normalised actions are scaled without clipping to [-1, 1]",
        ("tests/test_semantics.py",),
    ),
    M(
        "clip_targets_skips_followers",
        "wpctrl/kernels/pd_set_action.py",
        "                if wp.static(CLIP):\n"
        "                    t[r] = wp.clamp(t[r], row_f[r, ROW_F_QLO], row_f[r, ROW_F_QHI])\n",
        "                if wp.static(False):\n"
        "                    t[r] = wp.clamp(t[r], row_f[r, ROW_F_QLO], row_f[r, ROW_F_QHI])\n",
        'clip_targets="joint_limits" leaves mimic followers unclamped',
        ("tests/test_actuation.py",),
    ),
    M(
        "rejected_env_stops_counting",
        "wpctrl/kernels/pd_set_action.py",
        "step_out[env] = step_out[env] + host_substeps",
        "step_out[env] = step_out[env]",
        "an env whose action is rejected loses the substeps the host counted",
        ("tests/test_launches.py",),
    ),
    M(
        "elided_set_action_skips_control",
        "wpctrl/engine/core.py",
        'ln.bind("joint_target_q_out", None if known is None else known[0])',
        'ln.bind("joint_target_q_out", None)',
        "without per-substep work, set_action no longer writes the position targets into the known Control",
        ("tests/test_launches.py",),
    ),
]
