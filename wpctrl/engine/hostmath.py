"""Float64 quaternion helpers for build-time geometry on the host (URDF frames, link offsets). Quaternions are
(x, y, z, w), Warp's order. Private module: the end-effector part (:mod:`.parts.ee`) and the built-in Panda
(:mod:`wpctrl.robots.panda_model`) use them."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def qmul(a: Sequence[float], b: Sequence[float]) -> np.ndarray:
    """The quaternion product ``a b``."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def qaxis(axis: Sequence[float], angle: float) -> np.ndarray:
    """The rotation by ``angle`` [rad] about ``axis`` (normalised here)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    s = math.sin(0.5 * angle)
    return np.array([a[0] * s, a[1] * s, a[2] * s, math.cos(0.5 * angle)])


def rpy_quat(rpy: Sequence[float]) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw [rad]: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = (float(v) for v in rpy)
    return qmul(qmul(qaxis((0, 0, 1), y), qaxis((0, 1, 0), p)), qaxis((1, 0, 0), r))
