"""Warp functions of the actuator models that limit the PD torque inside the substep kernel (``pd_step.py``).

Private module. Each function takes the computed effort ``u`` [N·m or N], the row's measured state and parameters,
and the config's force limit ``lim``, and returns the applied effort. The substep kernel calls the one of each row's
model (a compile-time choice), so a mode without actuator models compiles none of this.
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.func
def dc_motor_clamp(u: float, qd: float, sat: float, vlim: float, lim: float):
    """DC-motor torque-speed envelope (Isaac Lab's ``DCMotor``, Newton's ``ClampingDCMotor``): the measured velocity
    clipped to the corner velocities ``±vlim (1 + lim / sat)`` where the envelope meets ``±lim``, then
    ``clip(u, max(sat (-1 - v / vlim), -lim), min(sat (1 - v / vlim), lim))``."""
    corner = vlim
    if sat > 0.0:
        ratio = lim / sat
        if ratio == ratio:
            corner = vlim * (1.0 + ratio)
    v = wp.clamp(qd, -corner, corner)
    hi = wp.min(sat * (1.0 - v / vlim), lim)
    lo = wp.max(sat * (-1.0 - v / vlim), -lim)
    return wp.clamp(u, lo, hi)


@wp.func
def table_interp(x: float, xs: wp.array2d[float], ys: wp.array2d[float], r: int, n: int):
    """Row ``r``'s table ``(xs[r, :n], ys[r, :n])`` linearly interpolated at ``x``, end values held outside."""
    if x <= xs[r, 0]:
        return ys[r, 0]
    if x >= xs[r, n - 1]:
        return ys[r, n - 1]
    y = ys[r, n - 1]
    for k in range(n - 1):
        x1 = xs[r, k + 1]
        if x1 >= x:
            x0 = xs[r, k]
            y0 = ys[r, k]
            if x1 == x0:
                y = y0
            else:
                y = y0 + (x - x0) / (x1 - x0) * (ys[r, k + 1] - y0)
            break
    return y


@wp.func
def position_limit_clamp(u: float, q: float, xs: wp.array2d[float], ys: wp.array2d[float], r: int, n: int, lim: float):
    """``|u| <= min(f(q), lim)``, ``f`` the row's position table (Isaac Lab's ``RemotizedPDActuator``, Newton's
    ``ClampingPositionBased``)."""
    limit = wp.min(table_interp(q, xs, ys, r, n), lim)
    return wp.clamp(u, -limit, limit)
