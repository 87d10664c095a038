"""Warp functions of the actuator models that limit the PD torque inside the substep kernel
(:mod:`wpctrl.kernels.pd_step`).

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
    """A position table as the substep kernel's compile-time constants ``(x0, y0, y_last, pieces)``, float32 values as
    Python floats. ``pieces``: ``(right end, slope, intercept)`` of each piece with ``x[k + 1] > x[k]`` (a repeated
    position is a step, never interpolated across), last piece first: the kernel starts from ``y_last`` (held past
    the end), lets every piece whose right end is >= q overwrite it with ``slope * q + intercept``, so the first such
    piece wins, and holds ``y0`` at and below ``x0``. Slope and intercept are rounded once to float32 from float64:
    one multiply-add per piece, whose rounding is that of ``|slope * q|``, a few 1e-4 N·m for a 1,000 N·m/rad slope
    at 3 rad."""
    x = np.asarray(positions, np.float32).reshape(-1).astype(np.float64)
    y = np.asarray(efforts, np.float32).reshape(-1).astype(np.float64)
    pieces = []
    for k in reversed(range(x.size - 1)):
        if x[k + 1] > x[k]:
            slope = (y[k + 1] - y[k]) / (x[k + 1] - x[k])
            pieces.append(tuple(float(np.float32(v)) for v in (x[k + 1], slope, y[k] - slope * x[k])))
    return (float(x[0]), float(y[0]), float(y[-1]), tuple(pieces))
