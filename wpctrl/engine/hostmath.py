"""Float64 helpers for build-time geometry on the host: quaternions and rigid transforms, and :class:`LinkFrames`, a
robot description's link tree (the frames of links that Newton's importer merged away) in those terms. Quaternions are
(x, y, z, w), Warp's order. Private module: the end-effector part (:mod:`.parts.ee`) and the robots
(:mod:`wpctrl.robots`) use it."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

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


def qrotate(q: Sequence[float], v: Sequence[float]) -> np.ndarray:
    """``v`` rotated by the unit quaternion ``q``."""
    x, y, z, w = q
    u = np.array([x, y, z])
    v = np.asarray(v, dtype=np.float64)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def tmul(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The rigid transform ``a b`` of two ``(position, quaternion)`` pairs."""
    return np.asarray(a[0], np.float64) + qrotate(a[1], b[0]), qmul(a[1], b[1])


@dataclass(frozen=True)
class LinkFrames:
    """A robot description's link tree with each joint's origin: the frames of links that a model may lack.

    Newton's importer merges a link hung on a fixed joint into its parent (``collapse_fixed_joints``), and a fixed
    base into the world; the end-effector part then finds such a link, or where the first moving joint sits on the
    merged base, here. Rows are ``(joint, fixed, parent link, child link, origin position [m], origin quaternion
    xyzw)``; the origin is the child's frame in the parent's at zero joint position.
    """

    rows: tuple[tuple[str, bool, str, str, np.ndarray, np.ndarray], ...]
    source: str = ""
    """Where the description came from, for messages (a URDF path, a robot's name)."""

    @classmethod
    def from_description(cls, description) -> LinkFrames:
        """From a :class:`wpctrl.config.robot_description.RobotDescription` (a URDF's joint rows)."""
        rows = description.joints
        return cls(
            tuple((r[0], r[1] == "fixed", r[2], r[3], np.asarray(r[4], np.float64), rpy_quat(r[5])) for r in rows),
            description.source,
        )

    @property
    def links(self) -> set[str]:
        return {r[2] for r in self.rows} | {r[3] for r in self.rows}

    @property
    def root(self) -> str | None:
        """The only link that is no joint's child, or None."""
        roots = self.links - {r[3] for r in self.rows}
        return next(iter(roots)) if len(roots) == 1 else None

    def joint_of(self, link: str):
        """The row whose child is ``link``, or None (the root, or a link not described)."""
        return next((r for r in self.rows if r[3] == link), None)

    def joint(self, name: str):
        """The row of the joint ``name``, or None."""
        return next((r for r in self.rows if r[0] == name), None)
