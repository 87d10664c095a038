"""Robot descriptions for links a Newton model lacks: what an end-effector config's ``urdf_path`` names, read once
when the mode is built.

Newton's URDF importer merges a link hung on a fixed joint into its parent (``collapse_fixed_joints``) and a fixed
base into the world. The end-effector chain itself always comes from the model's arrays; only such a merged link
(ManiSkill's ``panda_hand_tcp``), or where the first moving joint sits on a merged base, is looked up in a robot
description: the joints of ``urdf_path`` (names, parent and child links, origins; no geometry), or, without a
readable file, the descriptions robot modules registered (:func:`register_description`; importing
:mod:`wpctrl.robots` registers the built-in Panda's). The engine receives the result as data on the controller's
spec and reads no file.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

JointRow = tuple[str, str, str, str, tuple[float, float, float], tuple[float, float, float]]
"""``(joint name, URDF joint type, parent link, child link, origin xyz [m], origin rpy [rad])``."""


@dataclass(frozen=True)
class RobotDescription:
    """A robot's joints as its URDF declares them, and where they came from (for messages)."""

    joints: tuple[JointRow, ...]
    source: str


@dataclass(frozen=True)
class Descriptions:
    """What one controller may consult for links its model lacks: ``urdf_path``'s description when the file exists
    (none when it cannot be parsed), else the registered ones; ``error`` says why ``urdf_path`` could not be read."""

    urdf_path: str | None
    found: tuple[RobotDescription, ...]
    error: str | None = None

    @property
    def from_file(self) -> bool:
        """Whether ``urdf_path`` names an existing file (its description, or its read error, is the answer)."""
        return self.urdf_path is not None and os.path.exists(self.urdf_path)


def read_urdf(path: str) -> RobotDescription:
    """The joints of the URDF file ``path``. Raises OSError or ``xml.etree.ElementTree.ParseError``."""
    rows = []
    for j in ET.parse(path).getroot().findall("joint"):
        o = j.find("origin")
        xyz = tuple(float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split())
        rpy = tuple(float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split())
        rows.append((j.get("name"), j.get("type"), j.find("parent").get("link"), j.find("child").get("link"), xyz, rpy))
    return RobotDescription(tuple(rows), repr(path))


_REGISTERED: list[RobotDescription] = []


def register_description(description: RobotDescription) -> None:
    """Make a robot's description known: a controller whose ``urdf_path`` is None or names no file locates links
    its model lacks in the first registered description holding them. Robot modules register theirs on import."""
    if all(d.source != description.source for d in _REGISTERED):
        _REGISTERED.append(description)


def descriptions_for(urdf_path: str | None) -> Descriptions:
    """The descriptions a controller with this ``urdf_path`` consults (read now, once per build)."""
    if urdf_path is not None and os.path.exists(urdf_path):
        try:
            return Descriptions(urdf_path, (read_urdf(urdf_path),))
        except (OSError, ET.ParseError) as e:
            return Descriptions(urdf_path, (), str(e))
    error = None if urdf_path is None else f"[Errno 2] No such file or directory: {urdf_path!r}"
    return Descriptions(urdf_path, tuple(_REGISTERED), error)
