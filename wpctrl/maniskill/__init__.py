"""ManiSkill's robots on Newton: ``load_robot(uid)`` gives a Newton builder of the agent's own asset and its control
modes as wpctrl configs, translated field by field from the agent class.

Needs the ``maniskill`` extra (``pip install -e ".[maniskill]"`` in a source checkout: mani-skill 3.0.1); ManiSkill
is imported only here. No SAPIEN scene is created: the agent class's ``_controller_configs`` are read from an
instance whose scene set-up is skipped (its ``__init__`` runs with ManiSkill's ``BaseAgent.__init__`` stubbed out,
so per-robot attributes such as Fetch's joint lists are set), with a stand-in ``robot`` whose ``active_joints`` are
the asset's active joints in ManiSkill's order. A user's own ManiSkill agent class works the same way.

What ManiSkill's loader does, and what the Newton builder gets of it:

- applied: ``fix_root_link`` (a floating root is a free joint), the keyframe's qpos and root pose, the agent's
  ``urdf_config`` contact materials (PhysX's static friction as Newton's ``shape_material_mu``, restitution),
  ``disable_self_collisions`` (the importer's ``enable_self_collisions=False``), the SRDF's excluded link pairs
  (shape collision filter pairs), MJCF geoms with ``condim="1"`` frictionless and geoms outside any body (the floor)
  left out, as ManiSkill's MJCF loader does; URDF ``<mimic>`` tags become Newton mimic constraints (Newton's
  importer);
- not applied, no Newton equivalent: PhysX's ``dynamic_friction`` (Newton has one coefficient),
  ``patch_radius`` / ``min_patch_radius`` (PhysX's torsional contact patch), the ``urdf_config`` ``density`` (SAPIEN
  uses it only for links without an inertial), ``load_multiple_collisions`` (SAPIEN splits a collision mesh file
  into its convex pieces; Newton keeps one shape per mesh), ManiSkill's scene-wide default material (friction 0.3:
  a scene setting; Newton's shapes keep ``ShapeConfig``'s default), visual shapes, cameras and sensors.

Joint dynamics (limits, armature, damping, friction from the file) and inertials are Newton's import of the same
file.
"""

from __future__ import annotations

import copy
import dataclasses
import os
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .assets import active_joint_names, newton_builder, set_joint_positions, set_root_pose
from .collision import apply_materials, apply_mjcf_friction, filter_srdf_pairs
from .impedance import add_impedance_modes

__all__ = [
    "ManiSkillRobot",
    "active_joint_names",
    "add_impedance_modes",
    "control_modes",
    "load_robot",
    "translate_config",
    "translate_mode",
]


def _mani_skill():
    try:
        import mani_skill  # noqa: F401
        from mani_skill.agents.base_agent import BaseAgent
        from mani_skill.agents.registration import REGISTERED_AGENTS
    except ImportError as e:  # pragma: no cover - the extra is installed in the test environment
        from ..extras import missing

        raise ImportError(missing("wpctrl.maniskill", "maniskill", e, torch=True)) from e
    return BaseAgent, REGISTERED_AGENTS


@dataclass
class Keyframe:
    """A ManiSkill keyframe: ``qpos`` by active-joint name [rad or m] and the root ``pose`` ``[x, y, z, qw, qx, qy,
    qz]`` (or None)."""

    qpos: dict[str, float]
    pose: list[float] | None


@dataclass
class ManiSkillRobot:
    """A ManiSkill agent's robot and control modes, for Newton and wpctrl."""

    uid: str
    agent_class: type
    asset_path: str
    fix_root_link: bool
    joint_names: list[str]
    """ManiSkill's active joints, in its qpos order."""
    control_modes: dict[str, Any]
    """``{mode: {uid: wpctrl config, ..., "balance_passive_force": bool} | wpctrl config}``, from the agent class."""
    keyframes: dict[str, Keyframe]
    keyframe: str | None
    """The keyframe the builder holds (its qpos as the initial ``joint_q``, its pose as the root's)."""
    builder: Any = field(repr=False, default=None)
    """A ``newton.ModelBuilder`` holding one robot (``replicate`` it for many envs)."""


class _StubJoint:
    def __init__(self, name: str):
        self.name = name


class _StubRobot:
    """What ``_controller_configs`` of ManiSkill's agents read from ``self.robot``: the active joints' names."""

    def __init__(self, names: list[str]):
        self.active_joints = [_StubJoint(n) for n in names]
        self.active_joints_map = {j.name: j for j in self.active_joints}


def _agent_class(uid_or_class):
    BaseAgent, registered = _mani_skill()
    if isinstance(uid_or_class, str):
        if uid_or_class not in registered:
            known = sorted(registered)
            raise ValueError(f"load_robot: unknown ManiSkill agent uid {uid_or_class!r}; registered: {known}")
        return registered[uid_or_class].agent_cls
    if isinstance(uid_or_class, type) and issubclass(uid_or_class, BaseAgent):
        return uid_or_class
    raise TypeError(f"load_robot: expected a ManiSkill agent uid or agent class, got {uid_or_class!r}")


def _asset_path(cls) -> str:
    path = cls.urdf_path if getattr(cls, "urdf_path", None) is not None else cls.mjcf_path
    if path is None:
        raise ValueError(f"load_robot: {cls.__name__} has neither urdf_path nor mjcf_path")
    path = os.path.expanduser(str(path).format(PACKAGE_ASSET_DIR=_package_asset_dir()))
    if not os.path.exists(path):
        raise FileNotFoundError(
            f"load_robot: {cls.__name__}'s asset {path} is not installed (ManiSkill downloads it on first use: "
            f"python -m mani_skill.utils.download_asset {getattr(cls, 'uid', cls.__name__)})"
        )
    return path


def _package_asset_dir() -> str:
    import mani_skill

    return os.path.join(os.path.dirname(mani_skill.__file__), "assets")


def _agent_instance(cls, joint_names: list[str]):
    """An instance of ``cls`` whose ``__init__`` ran without ManiSkill's scene set-up, with a stand-in robot."""
    BaseAgent, _ = _mani_skill()
    original = BaseAgent.__init__

    def skip(self, *args, **kwargs):  # the subclass's own attributes are set before it calls super().__init__
        return None

    agent = cls.__new__(cls)
    BaseAgent.__init__ = skip
    try:
        try:
            cls.__init__(agent, None)
        except TypeError:
            cls.__init__(agent)
    except Exception:  # noqa: BLE001 - a subclass whose __init__ needs the scene: its class attributes still serve
        pass
    finally:
        BaseAgent.__init__ = original
    agent.robot = _StubRobot(joint_names)
    return agent


def translate_config(config):
    """A wpctrl config of the same class name with the same field values as the ManiSkill ``config`` (for a
    user's subclass of a ManiSkill config: the nearest base class wpctrl has)."""
    import wpctrl

    name = type(config).__name__
    target = None
    for base in type(config).__mro__:
        candidate = getattr(wpctrl, base.__name__, None)
        if candidate is not None and dataclasses.is_dataclass(candidate):
            target = candidate
            break
    if target is None:
        raise TypeError(f"translate_config: ManiSkill's {name} has no wpctrl counterpart")
    ours = {f.name for f in dataclasses.fields(target)}
    values = {}
    for f in dataclasses.fields(config):
        if f.name == "controller_cls":
            continue
        if f.name not in ours:
            raise TypeError(f"translate_config: {name}.{f.name} has no counterpart in wpctrl.{target.__name__}")
        v = copy.deepcopy(getattr(config, f.name))
        if isinstance(v, np.ndarray):
            v = v.tolist()
        values[f.name] = v
    return target(**values)


def translate_mode(mode):
    """A ManiSkill control mode (a config, or a dict of them with ``balance_passive_force``) as wpctrl configs."""
    if isinstance(mode, dict):
        return {k: (v if k == "balance_passive_force" else translate_config(v)) for k, v in mode.items()}
    return translate_config(mode)


def control_modes(uid_or_agent_class) -> dict:
    """The agent's own control modes as wpctrl configs (what :func:`load_robot` gives as ``control_modes``, less the
    impedance modes it adds, without building the robot)."""
    cls = _agent_class(uid_or_agent_class)
    agent = _agent_instance(cls, active_joint_names(_asset_path(cls)))
    return {name: translate_mode(mode) for name, mode in agent._controller_configs.items()}


def load_robot(
    uid_or_agent_class,
    *,
    keyframe: str | None = "default",
    root_pose=None,
    collapse_fixed_joints: bool = False,
    **importer_kwargs,
) -> ManiSkillRobot:
    """The ManiSkill agent ``uid_or_agent_class`` (a registered uid such as ``"fetch"``, or an agent class) on Newton.

    Args:
        uid_or_agent_class: A ManiSkill agent uid or ``BaseAgent`` subclass.
        keyframe: The agent keyframe whose qpos (and root pose) the builder starts from: ``"default"`` (the agent's
            first keyframe), a keyframe name, or None (zeros, identity pose).
        root_pose: Overrides the keyframe's root pose, ``[x, y, z, qw, qx, qy, qz]``.
        collapse_fixed_joints: Merge fixed-joint links into their parents (Newton's importer option).
        **importer_kwargs: Passed to ``ModelBuilder.add_urdf`` / ``add_mjcf``.

    Returns:
        A :class:`ManiSkillRobot`: ``builder`` (one robot), ``control_modes`` (wpctrl configs: the agent's modes and,
        for an arm with an end-effector mode, wpctrl's ``osc_ee_delta_pose``, ``osc_ee_pose`` and
        ``joint_impedance_delta_pos``: :func:`add_impedance_modes`), ``keyframes``, ``joint_names`` (ManiSkill's
        active-joint order).
    """
    cls = _agent_class(uid_or_agent_class)
    asset = _asset_path(cls)
    names = active_joint_names(asset)
    agent = _agent_instance(cls, names)
    modes = {name: translate_mode(mode) for name, mode in agent._controller_configs.items()}
    add_impedance_modes(modes)
    keyframes = {}
    for kname, kf in (getattr(cls, "keyframes", None) or {}).items():
        q = np.asarray(kf.qpos, dtype=np.float64).reshape(-1)
        if q.size != len(names):  # ManiSkill's own reset to it would fail
            warnings.warn(
                f"load_robot: {cls.__name__}'s keyframe {kname!r} has {q.size} qpos values for {len(names)} active "
                "joints; it is left out",
                stacklevel=2,
            )
            continue
        pose = getattr(kf, "pose", None)
        p = None if pose is None else [*map(float, pose.p), *map(float, pose.q)]
        keyframes[kname] = Keyframe(dict(zip(names, q.tolist())), p)
    chosen = (next(iter(keyframes), None) if keyframe == "default" else keyframe) if keyframes else None
    if chosen is not None and chosen not in keyframes:
        raise ValueError(f"load_robot: {cls.__name__} has no keyframe {chosen!r}; keyframes: {list(keyframes)}")
    kf = keyframes.get(chosen) if chosen else None
    fix_root = bool(getattr(cls, "fix_root_link", True))
    pose = root_pose if root_pose is not None else (kf.pose if kf else None)
    importer_kwargs.setdefault("enable_self_collisions", not bool(getattr(cls, "disable_self_collisions", False)))
    builder = newton_builder(
        asset, fix_root_link=fix_root, root_pose=pose if fix_root else None,
        collapse_fixed_joints=collapse_fixed_joints, **importer_kwargs,
    )  # fmt: skip
    apply_materials(builder, getattr(cls, "urdf_config", None))
    if asset.lower().endswith(".xml"):
        apply_mjcf_friction(builder, asset)
    else:
        filter_srdf_pairs(builder, asset)
    if not fix_root and pose is not None:
        set_root_pose(builder, pose)
    if kf is not None:
        missing = set_joint_positions(builder, kf.qpos)
        if missing:
            raise ValueError(f"load_robot: keyframe {chosen!r} names joints the Newton model lacks: {missing}")
    return ManiSkillRobot(
        uid=getattr(cls, "uid", cls.__name__),
        agent_class=cls,
        asset_path=asset,
        fix_root_link=fix_root,
        joint_names=names,
        control_modes=modes,
        keyframes=keyframes,
        keyframe=chosen,
        builder=builder,
    )
