"""Mutations: substep."""

from .model import M

MUTATIONS = [
    M(
        "stable_pd_on_the_start_state",
        "wpctrl/kernels/pd_substep.py",
        "u[r] = (kpr * (e - dt * qd[r]) + kdr * (tqd[r] - qd[r])) / (",
        "u[r] = (kpr * e + kdr * (tqd[r] - qd[r])) / (",
        "stable explicit PD evaluates its position error on the start state, not the predicted one",
        ("tests/test_acceleration.py",),
    ),
    M(
        "pd_damping_sign_flipped",
        "wpctrl/kernels/pd_substep.py",
        "u[r] = kpr * e + kdr * (tqd[r] - qd[r])",
        "u[r] = kpr * e + kdr * (qd[r] - tqd[r])",
        "the naive PD law's damping term has the wrong sign",
        ("tests/test_actuation.py",),
    ),
    M(
        "interpolation_off_by_one",
        "wpctrl/kernels/pd.py",
        "return start + step_size * float(wp.min(k, num_substeps))",
        "return start + step_size * float(wp.min(k - 1, num_substeps))",
        "interpolation lags one substep",
        ("tests/test_semantics.py",),
    ),
    M(
        "delay_off_by_one",
        "wpctrl/kernels/pd_substep.py",
        "d = wp.clamp(delay_in[env], 0, max_delay)",
        "d = wp.clamp(delay_in[env] + 1, 0, max_delay)",
        "the command delay is one substep longer than drawn",
        ("tests/test_actuation.py",),
    ),
    M(
        "force_limit_one_sided",
        "wpctrl/kernels/pd_substep.py",
        "f[r] = wp.clamp(u[r], -lim[r], lim[r])",
        "f[r] = wp.min(u[r], lim[r])",
        "explicit torques are clamped only from above",
        ("tests/test_actuation.py",),
    ),
    M(
        "saturation_count_inverted",
        "wpctrl/kernels/pd_substep.py",
        "if f[r] != u[r]:",
        "if f[r] == u[r]:",
        "the effort readout counts unsaturated substeps",
        ("tests/test_actuation.py",),
    ),
]
