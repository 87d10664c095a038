"""The configs of the torque-level impedance controllers: operational-space control (OSC) of an end effector and
joint impedance.

This package is their one room, layered as the library is: :mod:`.config` (these dataclasses, host only, importing
nothing else of the room), :mod:`.spec` (a config validated into its joint rows and an :class:`~.spec.ImpedanceSpec`),
:mod:`.warp_kernels` (the set-action and torque kernels), :mod:`.engine_part` (the engine part that launches them)
and :mod:`.controllers` (the controller classes). Each config class declares its family (:mod:`wpctrl.config.family`),
which names the spec's row function and the part.

Neither controller exists in ManiSkill; both follow the conventions of its end-effector configs
(:mod:`wpctrl.config.ee`): joint names, normalised action bounds, ``frame``, ``use_delta``, ``use_target``,
``ee_link``, ``urdf_path``, ``force_limit``, ``friction``, and mix with joint configs (a gripper) in one mode dict.
Their gain options are Isaac Lab's (``impedance_mode``, ``inertial_dynamics_decoupling``, ``gravity_compensation``,
``nullspace_control``, damping from a damping ratio).

Units: positions [m], rotations [rad], task stiffness [1/s²] (with inertial decoupling: the spring acts as an
acceleration, premultiplied by the operational-space inertia) or [N/m, N·m/rad] (without), task damping [1/s] or
[N·s/m, N·m·s/rad]; joint gains likewise [1/s²] / [1/s] with inertial compensation, else [N·m/rad] / [N·m·s/rad].
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Union

from ..config.ee import PoseFrame
from ..config.family import ControllerClass, ControllerConfig, Family
from . import spec


@dataclass
class OperationalSpaceControllerConfig(ControllerConfig):
    """Operational-space control of ``ee_link``: joint torques ``τ = Jᵀ F + N τ₀ + g`` toward a target pose.

    ``F = Λ (Kp ∘ e − Kd ∘ ẋ)`` with the pose error ``e`` (position, and the rotation vector of
    ``q_target q⁻¹``) and the EE twist ``ẋ = J q̇`` in the root frame, ``Λ = (J M⁻¹ Jᵀ)⁻¹`` the operational-space
    inertia (``M``: the controlled joints' block of the articulation's mass matrix), ``N τ₀`` a joint posture term
    projected into the task's null space, ``g`` the gravity torque. The torques go to ``Control.joint_f`` before every
    solver substep, clamped to ``force_limit``."""

    controller_cls = ControllerClass("wpctrl.impedance.controllers", "OperationalSpaceController")
    family = Family(spec.osc_rows, part="wpctrl.impedance.engine_part")

    pos_lower: Union[float, Sequence[float]] = -0.1
    """Lower bound of the position action [m] (per axis or one value; a delta with ``use_delta``); None: -inf
    (unnormalised actions only)."""
    pos_upper: Union[float, Sequence[float]] = 0.1
    """Upper bound of the position action [m]."""
    rot_lower: Union[float, Sequence[float]] = -0.1
    """Lower bound of the rotation action [rad] (Euler XYZ, as the EE controllers)."""
    rot_upper: Union[float, Sequence[float]] = 0.1
    """Upper bound of the rotation action [rad]. A normalised rotation action is clipped by its norm (as ManiSkill's)
    and scaled by the half range ``(rot_upper - rot_lower) / 2`` (a positive action rotates positively)."""
    stiffness: Union[float, Sequence[float]] = 100.0
    """Task stiffness Kp per axis (x, y, z, rx, ry, rz of the root frame), one value or 6 [1/s² with inertial
    decoupling, else N/m and N·m/rad]; with ``impedance_mode`` "variable_kp" / "variable": the value before the first
    action."""
    damping: Union[None, float, Sequence[float]] = None
    """Task damping Kd per axis [1/s with decoupling, else N·s/m and N·m·s/rad]; None: ``2 damping_ratio √Kp``
    (critical damping of a unit inertia: exact with full decoupling)."""
    damping_ratio: Union[float, Sequence[float]] = 1.0
    """Damping ratio ζ of the task axes where ``damping`` is None (and the fixed ratio of "variable_kp")."""
    force_limit: Union[float, Sequence[float]] = 1e10
    """Joint effort limit [N·m or N] per joint: the torque is clamped to it (as the drives' limits)."""
    friction: Union[float, Sequence[float]] = 0.0
    """Joint friction [N·m or N], written to ``Model.joint_friction``."""
    ee_link: str = None
    """The controlled link: a body label, a site on a body, or a link of ``urdf_path`` merged into a kept body (as
    the EE controllers)."""
    urdf_path: str = None
    """Optional URDF of the robot; used only where the model lacks ``ee_link``, to find its fixed offset."""
    frame: PoseFrame = "root_translation:root_aligned_body_rotation"
    """Frames of a delta action's position and rotation, as the EE controllers (the gains always act along the root
    frame's axes)."""
    root_link_name: str | None = None
    """The root frame of the poses (a body label); None: the articulation root."""
    use_delta: bool = True
    """Actions are pose increments; False: absolute poses ``[x, y, z, rx, ry, rz]`` in the root frame."""
    use_target: bool = False
    """Compose increments on the last target pose instead of the measured EE pose."""
    normalize_action: bool = True
    """Actions in [-1, 1] are clipped and scaled onto the bounds (pose and gains)."""
    impedance_mode: Literal["fixed", "variable_kp", "variable"] = "fixed"
    """Isaac Lab's: "fixed" (the config's gains), "variable_kp" (6 more action columns: the stiffness, damping from
    ``damping_ratio``), "variable" (12 more: stiffness, then damping ratio)."""
    stiffness_limits: tuple[float, float] = (0.0, 1000.0)
    """The stiffness action's bounds (what [-1, 1] maps onto when normalised; the clip otherwise)."""
    damping_ratio_limits: tuple[float, float] = (0.0, 2.0)
    """The damping-ratio action's bounds ("variable")."""
    inertial_dynamics_decoupling: bool = True
    """Premultiply the task acceleration by Λ (stiffness and damping then act per unit inertia)."""
    partial_inertial_dynamics_decoupling: bool = False
    """Λ without the coupling of translation and rotation (two 3×3 blocks)."""
    gravity_compensation: bool = True
    """Add the gravity torque ``g(q)`` of the whole articulation at the controlled joints (not with
    ``balance_passive_force``, where the solver already takes gravity off the robot's links)."""
    nullspace_control: Literal["none", "position"] = "none"
    """"position": a joint posture PD ``τ₀ = [M] (Kp_n (q_n − q) − Kd_n q̇)`` projected into the task's null space
    (dynamically consistent with full decoupling, else through the pseudo-inverse); more than 6 joints."""
    nullspace_stiffness: Union[float, Sequence[float]] = 10.0
    """Posture stiffness per joint [1/s² with decoupling, else N·m/rad]; per-env in ``ctrl.stiffness``."""
    nullspace_damping: Union[None, float, Sequence[float]] = None
    """Posture damping per joint; None: ``2 nullspace_damping_ratio √Kp_n``."""
    nullspace_damping_ratio: Union[float, Sequence[float]] = 1.0
    """Posture damping ratio where ``nullspace_damping`` is None."""
    nullspace_target: Union[None, Sequence[float]] = None
    """Posture [rad or m] per joint; None: each env's joint positions at its last reset (``ctrl.target_qpos``,
    writable)."""
    singularity_damping: float = 1e-3
    """Near a singularity: when the smallest pivot of the Jacobi-scaled ``J M⁻¹ Jᵀ`` (unit diagonal) falls below
    this value ε, ``ε (1 − p/ε)²`` is added to its diagonal before it is inverted (0: off); see the docs."""


@dataclass
class JointImpedanceControllerConfig(ControllerConfig):
    """Joint impedance: ``τ = [M] (Kp (q* − q) − Kd q̇) + g`` toward joint targets, written to ``Control.joint_f``
    before every solver substep and clamped to ``force_limit`` (``M``: the controlled joints' block of the
    articulation's mass matrix, with ``inertial_compensation``; ``g``: the gravity torque)."""

    controller_cls = ControllerClass("wpctrl.impedance.controllers", "JointImpedanceController")
    family = Family(spec.joint_impedance_rows, part="wpctrl.impedance.engine_part")

    lower: Union[None, float, Sequence[float]]
    """Lower action bound [rad or m] (a delta bound with ``use_delta``); None takes the joint's lower limit."""
    upper: Union[None, float, Sequence[float]]
    """Upper action bound [rad or m]; None takes the joint's upper limit."""
    stiffness: Union[float, Sequence[float]]
    """Joint stiffness Kp [1/s² with inertial compensation, else N·m/rad or N/m]; per-env in ``ctrl.stiffness``."""
    damping: Union[None, float, Sequence[float]] = None
    """Joint damping Kd [1/s with inertial compensation, else N·m·s/rad or N·s/m]; None: ``2 damping_ratio √Kp``."""
    damping_ratio: Union[float, Sequence[float]] = 1.0
    """Damping ratio where ``damping`` is None (and the fixed ratio of "variable_kp")."""
    force_limit: Union[float, Sequence[float]] = 1e10
    """Joint effort limit [N·m or N]: the torque is clamped to it."""
    friction: Union[float, Sequence[float]] = 0.0
    """Joint friction [N·m or N], written to ``Model.joint_friction``."""
    use_delta: bool = False
    """Actions are increments on the measured positions (or on the last target with ``use_target``)."""
    use_target: bool = False
    """With ``use_delta``: increments on the last target."""
    normalize_action: bool = True
    """Actions in [-1, 1] are clipped and scaled onto [lower, upper] (and the gain limits)."""
    impedance_mode: Literal["fixed", "variable_kp", "variable"] = "fixed"
    """"fixed", "variable_kp" (n more action columns: the stiffness), "variable" (2 n more: stiffness, damping
    ratio)."""
    stiffness_limits: tuple[float, float] = (0.0, 1000.0)
    """The stiffness action's bounds."""
    damping_ratio_limits: tuple[float, float] = (0.0, 2.0)
    """The damping-ratio action's bounds ("variable")."""
    inertial_compensation: bool = False
    """Premultiply the PD term by M (the gains then act per unit inertia, decoupled)."""
    gravity_compensation: bool = True
    """Add the gravity torque ``g(q)`` (not with ``balance_passive_force``: see the OSC config)."""


IMPEDANCE_CONFIGS = (OperationalSpaceControllerConfig, JointImpedanceControllerConfig)
