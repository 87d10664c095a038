"""Mutations: the coupled drive."""

from .model import M

MUTATIONS = [
    M(
        "coupled_clamp_never_released",
        "wpctrl/kernels/coupled_drive.py",
        "if (s == 1 and w < lim[r]) or (s == -1 and w > -lim[r]):",
        "if (s == 3 and w < lim[r]) or (s == -3 and w > -lim[r]):",
        "the coupled solve never releases a clamped row",
        ("tests/test_coupled.py",),
    ),
    M(
        "coupled_d_without_dt2_kp",
        "wpctrl/kernels/coupled_drive.py",
        "d[r] = h * kde + h * h * kpe",
        "d[r] = h * kde",
        "the coupled drive's D = dt Kd + dt^2 Kp loses its Kp term",
        ("tests/test_coupled.py",),
    ),
    M(
        "coupled_h_recovery_keeps_d",
        "wpctrl/kernels/coupled_drive.py",
        "L[wp.static(ROWD[r]), wp.static(ROWD[r])] = L[wp.static(ROWD[r]), wp.static(ROWD[r])] - dprev[r]",
        "L[wp.static(ROWD[r]), wp.static(ROWD[r])] = L[wp.static(ROWD[r]), wp.static(ROWD[r])]",
        "a later active-set iteration of the coupled drive keeps the last free rows' D inside H",
        ("tests/test_coupled.py",),
    ),
    M(
        "coupled_fallback_on_the_factor",
        "wpctrl/kernels/coupled_drive.py",
        "A = inverse_block(recover(H, dprev))",
        "A = inverse_block(H)",
        "the coupled drive's fallback sweeps build A from the last factor instead of H",
        ("tests/test_coupled.py",),
    ),
    M(
        "composite_inertia_without_parallel_axis",
        "wpctrl/kernels/inertia_unrolled.py",
        "pj = pj + Iw + m * (wp.dot(rr, rr) * wp.identity(n=3, dtype=wp.float64) - wp.outer(rr, rr))",
        "pj = pj + Iw",
        "the composite form of H drops the parallel-axis term of each body's inertia about the reference point",
        ("tests/test_coupled.py",),
    ),
]
