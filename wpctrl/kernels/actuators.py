"""Warp functions of the actuator models that limit the PD torque inside the substep kernel (``pd_step.py``).

Private module. The DC motor's function takes the computed effort ``u`` [N·m or N], the row's measured velocity and
parameters, and the config's force limit ``lim``, and returns the applied effort. A position table is compiled into
the substep kernel as constants (:func:`table_constants`): a chain of compares and multiply-adds, no loads. The
substep kernel uses each row's model (a compile-time choice), so a mode without actuator models compiles none of
this.
"""

from __future__ import annotations

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.func
def dc_motor_clamp(u: float, qd: float, sat: float, vlim: float, lim: float):
    """DC-motor torque-speed envelope (Isaac Lab's ``DCMotor``, Newton's ``ClampingDCMotor``):
    ``clip(u, max(sat (-1 - v / vlim), -lim), min(sat (1 - v / vlim), lim))`` with the measured velocity ``v`` clipped
    to the corner velocities ``±vlim (1 + lim / sat)``, where the envelope meets ``∓lim``.

    Written without the corner velocity: clipping ``v`` there is the same as clamping both envelope bounds into
    ``[-lim, lim]`` (for ``sat, vlim > 0``, which the config checks), which leaves one division per row, an
    approximate one on CUDA (2 ulp; exact on the CPU). IEEE divisions carry a slow-path branch each, which
    serialises the rows of the one-thread-per-env substep kernel."""
    s = wp.div_approx(qd, vlim)
    hi = wp.clamp(sat * (1.0 - s), -lim, lim)
    lo = wp.clamp(sat * (-1.0 - s), -lim, lim)
    return wp.clamp(u, lo, hi)


def table_constants(positions, efforts) -> tuple:
    """A position table as the substep kernel's compile-time constants: ``(x, y, segments, slopes, intercepts)``,
    float32 values as Python floats; ``segments`` the indices ``k`` of the pieces with ``x[k + 1] > x[k]`` (a repeated
    position is a step, never interpolated across), on piece ``k`` the table is ``slopes[k] * q + intercepts[k]``
    (both rounded once to float32 from float64; 0 for a step): one multiply-add per piece, whose rounding is that of
    ``|slope * q|``, a few 1e-4 N·m for a 1,000 N·m/rad slope at 3 rad."""
    x = np.asarray(positions, np.float32).reshape(-1)
    y = np.asarray(efforts, np.float32).reshape(-1)
    seg = tuple(int(k) for k in range(x.size - 1) if x[k + 1] > x[k])
    slope = np.zeros(max(x.size - 1, 1), np.float64)
    icpt = np.zeros(max(x.size - 1, 1), np.float64)
    x64, y64 = x.astype(np.float64), y.astype(np.float64)
    for k in seg:
        slope[k] = (y64[k + 1] - y64[k]) / (x64[k + 1] - x64[k])
        icpt[k] = y64[k] - slope[k] * x64[k]
    f = [tuple(float(v) for v in a.astype(np.float32)) for a in (x, y, slope, icpt)]
    return (f[0], f[1], seg, f[2], f[3])
