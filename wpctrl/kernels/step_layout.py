"""The compile-time layout of the per-step kernels (:class:`StepLayout`), the per-row float table they read, and
the row-index function they share. Private module (see :mod:`wpctrl.kernels.pd_step`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import warp as wp

from ..config.rows import Rows

# Columns of the row float table ``row_f``.
ROW_F_LO = wp.constant(0)
ROW_F_HI = wp.constant(1)
ROW_F_VLO = wp.constant(2)
ROW_F_VHI = wp.constant(3)
ROW_F_MUL = wp.constant(4)
ROW_F_OFF = wp.constant(5)
ROW_F_QLO = wp.constant(6)
ROW_F_QHI = wp.constant(7)
ROW_F_ALPHA = wp.constant(8)
ROW_F_WIDTH = 9


class StepLayout(NamedTuple):
    """What the step kernels are compiled for: the control mode's rows (tuples of ints, one entry per row) and its
    options. ``q_off`` / ``qd_off`` are env 0's coordinate / DOF index of each row for a replicated layout (env e at
    ``+ e * stride``), or ``None``: per-env ``(num_envs, rows)`` index tables."""

    kind: tuple
    flags: tuple
    act_col: tuple
    vel_col: tuple
    mimic_src: tuple
    accel: tuple
    q_off: tuple | None
    qd_off: tuple | None
    action_dim: int
    clip: bool = False
    explicit: int = 0  # 0 off (implicit or coupled), 1 naive, 2 stable
    delay: bool = False
    delay_vel: bool = False  # the delay ring also holds velocity targets
    effort: bool = False
    # Ego-centric base rows (set_action only): yaw source row, axis (0 x, 1 y, -1 none), vx / vy action columns.
    yaw_row: tuple = ()
    base_axis: tuple = ()
    bx_col: tuple = ()
    by_col: tuple = ()
    # Actuator models (substep only): each row's model code (config.actuator_models.ACT_*) and position table as
    # compile-time constants (kernels.actuator_models.table_constants; () for a row without one).
    act_model: tuple = ()
    limit_table: tuple = ()


def row_float_table(rows: Rows, qlimits: np.ndarray) -> np.ndarray:
    """``(rows, 9)`` float32: the per-row bounds, mimic coupling, joint limits and EMA weight the step kernels
    read."""
    t = np.zeros((rows.count, ROW_F_WIDTH), np.float32)
    t[:, ROW_F_LO], t[:, ROW_F_HI] = rows.lo, rows.hi
    t[:, ROW_F_VLO], t[:, ROW_F_VHI] = rows.vlo, rows.vhi
    t[:, ROW_F_MUL], t[:, ROW_F_OFF] = rows.mimic_mul, rows.mimic_off
    t[:, ROW_F_QLO], t[:, ROW_F_QHI] = qlimits[:, 0], qlimits[:, 1]
    t[:, ROW_F_ALPHA] = rows.ema_alpha
    return t


def _make_row_indices(L: StepLayout):
    """``row_indices(env, ...) -> (qi, di)``: every row's coordinate / DOF index in Newton's flat arrays for ``env``,
    as ``env * stride`` plus env 0's (compile-time) index for a replicated layout, else from the index tables."""
    R = len(L.kind)
    STRIDED = L.q_off is not None
    QOFF = L.q_off if STRIDED else (0,) * R
    QDOFF = L.qd_off if STRIDED else (0,) * R
    vec_ri = wp.types.vector(length=max(R, 1), dtype=wp.int32)

    @wp.func
    def row_indices(env: int, q_idx: wp.array2d[wp.int32], qd_idx: wp.array2d[wp.int32], q_stride: int, qd_stride: int):
        qi = vec_ri()
        di = vec_ri()
        for r in range(wp.static(R)):
            if wp.static(STRIDED):
                qi[r] = env * q_stride + wp.static(QOFF[r])
                di[r] = env * qd_stride + wp.static(QDOFF[r])
            else:
                qi[r] = q_idx[env, r]
                di[r] = qd_idx[env, r]
        return qi, di

    return row_indices
