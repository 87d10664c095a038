"""A ManiSkill robot's asset on Newton: its active-joint order as SAPIEN builds it, and a Newton builder of it.

Host only, no ManiSkill import here. SAPIEN's loaders add links breadth-first from the root, a link's children in the
file's order, and every 1-DOF joint is an active joint, so the active-joint order (ManiSkill's qpos order) is that
breadth-first order. ManiSkill's MJCF loader turns a body with several hinges into a chain of dummy links, one per
hinge in the file's order, which the same breadth-first walk visits level by level. Newton's importers make the same
robot, with MJCF multi-hinge bodies as one multi-axis (D6) joint per body (wpctrl binds each hinge by its name).
"""

from __future__ import annotations

import math
import os
import re
import warnings
import xml.etree.ElementTree as ET
from collections import deque

import newton
import numpy as np
import warp as wp

_ACTIVE_URDF = ("revolute", "continuous", "prismatic")


def active_joint_names(asset_path: str) -> list[str]:
    """ManiSkill's active joints of a URDF or MJCF robot, in its qpos order (SAPIEN's breadth-first build order)."""
    if asset_path.lower().endswith(".xml"):
        return _mjcf_active(asset_path)
    return _urdf_active(asset_path)


def _urdf_active(path: str) -> list[str]:
    root = ET.parse(path).getroot()
    joints = root.findall("joint")
    children: dict[str, list] = {}
    child_links = set()
    for j in joints:
        parent, child = j.find("parent").get("link"), j.find("child").get("link")
        children.setdefault(parent, []).append(j)
        child_links.add(child)
    roots = [lk.get("name") for lk in root.findall("link") if lk.get("name") not in child_links]
    out: list[str] = []
    queue = deque(roots[:1])
    while queue:
        link = queue.popleft()
        for j in children.get(link, []):
            if j.get("type") in _ACTIVE_URDF:
                out.append(j.get("name"))
            queue.append(j.find("child").get("link"))
    return out


def _mjcf_active(path: str) -> list[str]:
    world = ET.parse(path).getroot().find("worldbody")

    def expand(body) -> list:
        """A link's children as (joint name or None, child link) after splitting multi-hinge bodies into chains."""
        kids = []
        for ch in body.findall("body"):
            hinges = [j.get("name") for j in ch.findall("joint") if j.get("type", "hinge") in ("hinge", "slide")]
            node = expand(ch)
            for h in reversed(hinges[1:]):
                node = [(h, node)]
            kids.append((hinges[0] if hinges else None, node))
        return kids

    out: list[str] = []
    queue = deque([expand(b) for b in world.findall("body")[:1]])
    while queue:
        for name, child in queue.popleft():
            if name:
                out.append(name)
            queue.append(child)
    return out


def newton_builder(
    asset_path: str,
    *,
    fix_root_link: bool,
    root_pose=None,
    collapse_fixed_joints: bool = False,
    **importer_kwargs,
) -> newton.ModelBuilder:
    """One robot in a fresh ``newton.ModelBuilder``: Newton's URDF / MJCF importer, the root fixed or floating as the
    agent says, placed at ``root_pose`` (``[x, y, z, qw, qx, qy, qz]``, ManiSkill's order; the identity if None)."""
    builder = newton.ModelBuilder()
    xform = _transform(root_pose)
    kw = dict(importer_kwargs)
    if asset_path.lower().endswith(".xml"):
        # ManiSkill's agent is the articulation alone: geoms outside any body (the floor) are not part of it
        ignore = [re.escape(n) + "$" for n in _mjcf_world_geoms(asset_path)]
        kw["ignore_names"] = [*kw.get("ignore_names", ()), *ignore]
        builder.add_mjcf(asset_path, xform=xform, floating=not fix_root_link, hide_visuals=True, **kw)
    else:
        # SAPIEN resolves package://a/b in the URDF's folder or the nearest ancestor holding a/b
        kw.setdefault("package_dirs", _ancestors(os.path.dirname(os.path.abspath(asset_path))))
        builder.add_urdf(
            asset_path,
            xform=xform,
            floating=not fix_root_link,
            hide_visuals=True,
            collapse_fixed_joints=collapse_fixed_joints,
            **kw,
        )
    return builder


def _ancestors(folder: str) -> list[str]:
    out = [folder]
    while os.path.dirname(out[-1]) != out[-1]:
        out.append(os.path.dirname(out[-1]))
    return out


def _mjcf_world_geoms(path: str) -> list[str]:
    """Names of the geoms directly under ``<worldbody>`` (static scenery, not the robot)."""
    out = []
    for world in ET.parse(path).getroot().findall("worldbody"):
        for g in world.findall("geom"):
            if g.get("name"):
                out.append(g.get("name"))
            else:
                warnings.warn(f"{path}: an unnamed <geom> outside any body stays in the builder", stacklevel=3)
    return out


def _transform(pose):
    if pose is None:
        return None
    p = [float(x) for x in pose]
    w, x, y, z = p[3:7]
    return wp.transform(wp.vec3(*p[:3]), wp.quat(x, y, z, w))


def set_joint_positions(builder: newton.ModelBuilder, qpos: dict[str, float]) -> list[str]:
    """Write ``{joint name: position}`` into the builder's initial ``joint_q`` (one coordinate per joint; an MJCF
    hinge merged into a multi-axis joint by its axis); returns the names not found."""
    from ..binding import _axis_in_label, _short

    labels = list(builder.joint_label)
    q_start = list(builder.joint_q_start) + [len(builder.joint_q)]
    qd_start = list(builder.joint_qd_start) + [builder.joint_dof_count]
    types = list(builder.joint_type)
    by_name: dict[str, tuple[int, int]] = {}
    for j, label in enumerate(labels):
        short = _short(label)
        n = qd_start[j + 1] - qd_start[j]
        if int(types[j]) in (int(newton.JointType.REVOLUTE), int(newton.JointType.PRISMATIC)):
            by_name.setdefault(short, (j, 0))
        elif int(types[j]) == int(newton.JointType.D6):
            by_name.setdefault(short, (j, -1))
            for name in qpos:
                k = _axis_in_label(name, short, n)
                if k is not None:
                    by_name.setdefault(name, (j, k))
    missing = []
    for name, value in qpos.items():
        hit = by_name.get(name)
        if hit is None or hit[1] < 0:
            missing.append(name)
            continue
        j, k = hit
        builder.joint_q[q_start[j] + k] = float(value)
    return missing


def set_root_pose(builder: newton.ModelBuilder, pose) -> None:
    """The free root joint's coordinates from ``[x, y, z, qw, qx, qy, qz]`` (ManiSkill's order; Newton's free joint
    holds ``[x, y, z, qx, qy, qz, qw]``)."""
    types = list(builder.joint_type)
    if not types or int(types[0]) != int(newton.JointType.FREE):
        return
    p = [float(x) for x in pose]
    q = np.array(p[3:7], np.float64)
    q /= max(math.sqrt(float((q * q).sum())), 1e-12)
    s = builder.joint_q_start[0]
    builder.joint_q[s : s + 7] = [p[0], p[1], p[2], float(q[1]), float(q[2]), float(q[3]), float(q[0])]
