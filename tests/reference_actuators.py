"""Actuator models, action smoothing and binary commands in numpy, for the property tests' reference
(``reference_np.py``). Written from the configs' documentation (``wpctrl.config.actuators``, the joint configs'
``ema`` / ``binary`` fields), not from the kernels:

- ``DCMotor``: ``clip(u, max(s (-1 - v / v_max), -L), min(s (1 - v / v_max), L))`` with v the measured velocity (the
  corner-velocity clip of Isaac Lab and Newton is the same as clamping both bounds into [-L, L]); s and v_max per env.
- ``PositionBasedEffortLimit``: ``|tau| <= min(f(q), L)``, f the linear interpolation of the table at the measured
  position, the end values held outside it, a repeated position a step (left-continuous).
- ``ema``: ``alpha * target + (1 - alpha) * previous target``, clamped to the joint's limits, on the commanding joints.
- ``binary``: the column's upper bound for an action >= 0, its lower bound below.
"""

from __future__ import annotations

import numpy as np

from wpctrl.config import DCMotor, PositionBasedEffortLimit

F32 = np.float32
TABLE_TOL = 5e-4
"""[N·m or N] A position table's limit in float32 (one multiply-add of a rounded slope and intercept per piece) against
this float64 interpolation."""


def _bcast(value, n: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, dtype=F32), (n,)).copy()


class ActuatorModel:
    """One config's actuator model over its n joints and N envs (per-env DC-motor parameters)."""

    def __init__(self, config, num_envs: int, n: int):
        act = getattr(config, "actuator", None)
        self.kind = "dc" if isinstance(act, DCMotor) else "table" if isinstance(act, PositionBasedEffortLimit) else None
        self.sat_effort = np.full((num_envs, n), np.inf, F32)
        self.vel_limit = np.full((num_envs, n), np.inf, F32)
        if self.kind == "dc":
            self.sat_effort[:] = _bcast(act.saturation_effort, n)
            self.vel_limit[:] = _bcast(act.velocity_limit, n)
        elif self.kind == "table":
            self.x = np.asarray(act.positions, F32).astype(np.float64)
            self.y = np.asarray(act.efforts, F32).astype(np.float64)

    def table(self, q: np.ndarray) -> np.ndarray:
        """f(q): the end values outside, a step at a repeated position (left-continuous), linear in between."""
        x, y = self.x, self.y
        q = np.asarray(q, np.float64)
        out = np.where(q <= x[0], y[0], y[-1])
        for k in range(len(x) - 2, -1, -1):  # the first piece whose right end is >= q wins: walk from the last
            if x[k + 1] > x[k]:
                piece = y[k] + (y[k + 1] - y[k]) * (q - x[k]) / (x[k + 1] - x[k])
                out = np.where((q > x[0]) & (q <= x[k + 1]), piece, out)
        return out

    def apply(self, u: np.ndarray, q: np.ndarray, qd: np.ndarray, lim: np.ndarray):
        """(applied effort, (N, n) bool: |u| within the table's rounding of its limit, where either count is right)."""
        near = np.zeros(u.shape, bool)
        if self.kind == "dc":
            s = np.asarray(qd, F32) / self.vel_limit
            hi = np.clip(self.sat_effort * (F32(1.0) - s), -lim, lim)
            lo = np.clip(self.sat_effort * (F32(-1.0) - s), -lim, lim)
            return np.clip(u, lo, hi).astype(F32), near
        if self.kind == "table":
            fl = np.minimum(self.table(q), lim)
            near = np.abs(np.abs(u) - fl) <= TABLE_TOL
            return np.clip(u, -fl, fl).astype(F32), near
        return np.clip(u, -lim, lim), near


def smooth(config, target: np.ndarray, previous: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """``ema``: ``alpha * target + (1 - alpha) * previous`` within the joints' (n, 2) limits; the target as it is
    without ``ema``."""
    alpha = getattr(config, "ema", None)
    if alpha is None:
        return target
    a = F32(alpha)
    return np.clip(a * target + (F32(1.0) - a) * previous, limits[:, 0], limits[:, 1]).astype(F32)


def binary(config, a: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray | None:
    """``binary``: the upper bound where the action is >= 0, the lower one below; None without ``binary``."""
    if not getattr(config, "binary", False):
        return None
    return np.where(np.asarray(a, F32) < 0, low, high).astype(F32)
