"""The Franka Emika Panda built in code.

:func:`panda` builds a Franka Emika Panda (7 revolute arm joints and 2 prismatic fingers) as a
:class:`newton.ModelBuilder` from literal constants transcribed from ManiSkill 3.0.1's ``panda_v2.urdf``
(kinematics, limits and inertials; no meshes). Nothing is read from disk at run time.

The URDF's fixed joints (the base to the world, the flange ``panda_link8``, the hand ``panda_hand``, the TCP and the
finger pads) are collapsed the way ``ModelBuilder.add_urdf(..., collapse_fixed_joints=True)`` does it in Newton 1.8:

* ``panda_link0`` is welded to the world, so it disappears and ``panda_joint1`` has the world as parent;
* ``panda_link8`` and ``panda_hand_tcp`` (massless) and ``panda_hand`` (0.73 kg) are merged into ``panda_link7``;
* the massless finger pads are merged into their fingers;
* the finger joints hang off ``panda_link7`` with the flange and hand transforms folded into their parent frames.

The result has 9 bodies and 9 joints (7 revolute + 2 prismatic) in URDF order, and nothing fixed.

Units: lengths [m], angles [rad], masses [kg], inertias [kg·m²] about the centre of mass, efforts [N·m or N],
velocities [rad/s or m/s].
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import newton
import numpy as np
import warp as wp

from ..config.robot_description import RobotDescription, register_description
from ..engine.hostmath import qaxis, qrotate, rpy_quat, tmul

__all__ = [
    "PANDA_ARM_JOINTS",
    "PANDA_BODIES",
    "PANDA_FRAMES",
    "PANDA_GRIPPER_JOINTS",
    "PANDA_INITIAL_Q",
    "PANDA_JOINTS",
    "PANDA_REST_QPOS",
    "panda",
]

PANDA_ARM_JOINTS: list[str] = [f"panda_joint{i}" for i in range(1, 8)]
"""The 7 revolute arm joints, base to wrist."""
PANDA_GRIPPER_JOINTS: list[str] = ["panda_finger_joint1", "panda_finger_joint2"]
"""The 2 prismatic finger joints (left, right)."""
PANDA_JOINTS: list[str] = PANDA_ARM_JOINTS + PANDA_GRIPPER_JOINTS
"""All 9 joints in model order (ManiSkill's active-joint order)."""
PANDA_BODIES: list[str] = [f"panda_link{i}" for i in range(1, 8)] + ["panda_leftfinger", "panda_rightfinger"]
"""The 9 bodies in model order; ``panda_link7`` carries the merged flange and hand."""

PANDA_REST_QPOS: tuple[float, ...] = (
    0.0,
    math.pi / 8,
    0.0,
    -5 * math.pi / 8,
    0.0,
    3 * math.pi / 4,
    math.pi / 4,
    0.04,
    0.04,
)
"""ManiSkill's Panda rest keyframe [rad x7, m x2], fingers fully open at their 0.04 m upper limit."""

PANDA_INITIAL_Q: tuple[float, ...] = PANDA_REST_QPOS[:7] + (0.035, 0.035)
"""Default initial pose of :func:`panda`: the rest keyframe with the fingers at 0.035 m, 5 mm inside their
[0, 0.04] m range. A finger started exactly on its limit sits in the limit spring from the first step; 0.035 m is the
opening measured stable on Newton 1.8."""

# ----------------------------------------------------------------------------------------------------------------------
# URDF facts (panda_v2.urdf, ManiSkill 3.0.1). Every inertial origin has rpy = 0.

_Inertial = tuple[float, tuple[float, float, float], tuple[float, float, float, float, float, float]]
# link: (mass [kg], centre of mass in the link frame [m], (ixx, ixy, ixz, iyy, iyz, izz) about the COM [kg·m²]).
# Links absent from this table are massless. panda_link0 is listed for completeness: it is welded to the world.
# fmt: off
_LINK_INERTIALS: dict[str, _Inertial] = {
    "panda_link0": (0.629769, (-0.041018, -0.00014, 0.049974),
                    (0.00315, 8.2904e-07, 0.00015, 0.00388, 8.2299e-06, 0.004285)),
    "panda_link1": (4.970684, (0.003875, 0.002081, -0.04762),
                    (0.70337, -0.000139, 0.006772, 0.70661, 0.019169, 0.009117)),
    "panda_link2": (0.646926, (-0.003141, -0.02872, 0.003495),
                    (0.007962, -0.003925, 0.010254, 0.02811, 0.000704, 0.025995)),
    "panda_link3": (3.228604, (2.7518e-02, 3.9252e-02, -6.6502e-02),
                    (0.037242, -0.004761, -0.011396, 0.036155, -0.012805, 0.01083)),
    "panda_link4": (3.587895, (-5.317e-02, 1.04419e-01, 2.7454e-02),
                    (0.025853, 0.007796, -0.001332, 0.019552, 0.008641, 0.028323)),
    "panda_link5": (1.225946, (-1.1953e-02, 4.1065e-02, -3.8437e-02),
                    (0.035549, -0.002117, -0.004037, 0.029474, 0.000229, 0.008627)),
    "panda_link6": (1.666555, (6.0149e-02, -1.4117e-02, -1.0517e-02),
                    (0.001964, 0.000109, -0.001158, 0.004354, 0.000341, 0.005433)),
    "panda_link7": (0.735522, (1.0517e-02, -4.252e-03, 6.1597e-02),
                    (0.012516, -0.000428, -0.001196, 0.010027, -0.000741, 0.004815)),
    "panda_hand": (0.73, (-0.01, 0.0, 0.03),
                   (0.001, 0.0, 0.0, 0.0025, 0.0, 0.0017)),
    "panda_leftfinger": (0.015, (0.0, 0.0, 0.0),
                         (2.3749999999999997e-06, 0.0, 0.0, 2.3749999999999997e-06, 0.0, 7.5e-07)),
    "panda_rightfinger": (0.015, (0.0, 0.0, 0.0),
                          (2.3749999999999997e-06, 0.0, 0.0, 2.3749999999999997e-06, 0.0, 7.5e-07)),
}
# fmt: on

_HALF_PI = 1.5707963267948966

# (name, type, parent link, child link, origin xyz [m], origin rpy [rad], axis, lower, upper, effort, velocity),
# parents before children. Limits are [rad] / [rad/s] / [N·m] for revolute, [m] / [m/s] / [N] for prismatic.
# Not transcribed on purpose: <dynamics damping> (0.003 arm, 0.3 fingers) and friction (0): the model has no passive
# damping or friction, as ManiSkill's controllers overwrite both; <safety_controller> (unused by simulators).
# panda_finger_joint2 also carries <mimic joint="panda_finger_joint1"/> (multiplier 1, offset 0): see mimic_fingers.
_JointRow = tuple[str, str, str, str, tuple, tuple, tuple, float, float, float, float]
# fmt: off
_JOINTS: list[_JointRow] = [
    ("panda_joint1", "revolute", "panda_link0", "panda_link1", (0, 0, 0.333), (0, 0, 0), (0, 0, 1),
     -2.8973, 2.8973, 87.0, 2.1750),
    ("panda_joint2", "revolute", "panda_link1", "panda_link2", (0, 0, 0), (-_HALF_PI, 0, 0), (0, 0, 1),
     -1.7628, 1.7628, 87.0, 2.1750),
    ("panda_joint3", "revolute", "panda_link2", "panda_link3", (0, -0.316, 0), (_HALF_PI, 0, 0), (0, 0, 1),
     -2.8973, 2.8973, 87.0, 2.1750),
    ("panda_joint4", "revolute", "panda_link3", "panda_link4", (0.0825, 0, 0), (_HALF_PI, 0, 0), (0, 0, 1),
     -3.0718, -0.0698, 87.0, 2.1750),
    ("panda_joint5", "revolute", "panda_link4", "panda_link5", (-0.0825, 0.384, 0), (-_HALF_PI, 0, 0), (0, 0, 1),
     -2.8973, 2.8973, 12.0, 2.6100),
    ("panda_joint6", "revolute", "panda_link5", "panda_link6", (0, 0, 0), (_HALF_PI, 0, 0), (0, 0, 1),
     -0.0175, 3.7525, 12.0, 2.6100),
    ("panda_joint7", "revolute", "panda_link6", "panda_link7", (0.088, 0, 0), (_HALF_PI, 0, 0), (0, 0, 1),
     -2.8973, 2.8973, 12.0, 2.6100),
    ("panda_joint8", "fixed", "panda_link7", "panda_link8", (0, 0, 0.107), (0, 0, 0), (0, 0, 0),
     0.0, 0.0, 0.0, 0.0),
    ("panda_hand_joint", "fixed", "panda_link8", "panda_hand", (0, 0, 0), (0, 0, -0.7853981633974483), (0, 0, 0),
     0.0, 0.0, 0.0, 0.0),
    ("panda_hand_tcp_joint", "fixed", "panda_hand", "panda_hand_tcp", (0, 0, 0.1034), (0, 0, 0), (0, 0, 0),
     0.0, 0.0, 0.0, 0.0),
    ("panda_finger_joint1", "prismatic", "panda_hand", "panda_leftfinger", (0, 0, 0.0584), (0, 0, 0), (0, 1, 0),
     0.0, 0.04, 100.0, 0.2),
    ("panda_leftfinger_pad_joint", "fixed", "panda_leftfinger", "panda_leftfinger_pad", (0, 0, 0.0455), (0, 0, 0),
     (0, 0, 0), 0.0, 0.0, 0.0, 0.0),
    ("panda_finger_joint2", "prismatic", "panda_hand", "panda_rightfinger", (0, 0, 0.0584), (0, 0, 0), (0, -1, 0),
     0.0, 0.04, 100.0, 0.2),
    ("panda_rightfinger_pad_joint", "fixed", "panda_rightfinger", "panda_rightfinger_pad", (0, 0, 0.0455), (0, 0, 0),
     (0, 0, 0), 0.0, 0.0, 0.0, 0.0),
]
# fmt: on
_ROOT_LINK = "panda_link0"

# Visual-only capsules (link, segment start, segment end [m] in the link frame, radius [m]) and boxes
# (link, centre [m], yaw about the link z [rad], half extents [m]): rough outlines for viewers, no mass, no collision.
# panda_link0 shapes go on the world (body -1); hand shapes are expressed in the hand frame and moved onto link7.
_VISUAL_CAPSULES = [
    ("panda_link0", (0, 0, 0.06), (0, 0, 0.22), 0.07),
    ("panda_link1", (0, 0, -0.19), (0, 0, -0.03), 0.06),
    ("panda_link2", (0, 0, 0), (0, -0.2, 0), 0.06),
    ("panda_link3", (0, 0, -0.15), (0, 0, 0), 0.06),
    ("panda_link3", (0, 0, 0), (0.0825, 0, 0), 0.055),
    ("panda_link4", (0, 0, 0), (-0.0825, 0.1, 0), 0.055),
    ("panda_link5", (0, 0, -0.26), (0, 0, -0.02), 0.055),
    ("panda_link6", (0, 0, 0), (0.088, 0, 0), 0.05),
    ("panda_link7", (0, 0, 0), (0, 0, 0.09), 0.045),
]
_VISUAL_BOXES = [
    ("panda_hand", (0, 0, 0.03), (0.03, 0.1, 0.03)),
    ("panda_leftfinger", (0, 0.01, 0.027), (0.01, 0.01, 0.027)),
    ("panda_rightfinger", (0, -0.01, 0.027), (0.01, 0.01, 0.027)),
]


# ----------------------------------------------------------------------------------------------------------------------
# Small float64 rigid-transform helpers. Quaternions are (x, y, z, w) like Warp's; a transform is (p, q).


def _qmat(q: np.ndarray) -> np.ndarray:
    return np.column_stack([qrotate(q, e) for e in np.eye(3)])


def _tident() -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])


def _wp_transform(t: tuple[np.ndarray, np.ndarray]) -> wp.transform:
    p, q = t
    return wp.transform(wp.vec3(*(float(v) for v in p)), wp.quat(*(float(v) for v in q)))


def _steiner(mass: float, d: np.ndarray) -> np.ndarray:
    """Parallel-axis term m (|d|² I - d dᵀ) [kg·m²]."""
    return mass * (float(d @ d) * np.eye(3) - np.outer(d, d))


def _inertia_matrix(i6: Sequence[float]) -> np.ndarray:
    ixx, ixy, ixz, iyy, iyz, izz = i6
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], dtype=np.float64)


# ----------------------------------------------------------------------------------------------------------------------
# Collapse of the fixed joints.


def _collapse(inertia_merge: str):
    """Fold the fixed joints of ``_JOINTS`` into their movable ancestors.

    Returns:
        ``(bodies, joints, survivor)``: ``bodies`` maps each kept link to ``(mass, com, inertia 3x3)`` in its own frame;
        ``joints`` lists the movable joint rows with their parent link replaced by the surviving ancestor (``None`` for
        the world) and their origin by the folded parent transform; ``survivor`` maps every link to
        ``(surviving link or None, transform from the survivor's frame to the link's frame)``.
    """
    survivor: dict[str, tuple[str | None, tuple[np.ndarray, np.ndarray]]] = {_ROOT_LINK: (None, _tident())}
    joints = []
    for row in _JOINTS:
        name, jtype, parent, child, xyz, rpy = row[:6]
        s, x_sp = survivor[parent]
        x_pc = tmul(x_sp, (np.asarray(xyz, dtype=np.float64), rpy_quat(rpy)))
        if jtype == "fixed":
            survivor[child] = (s, x_pc)
        else:
            survivor[child] = (child, _tident())
            joints.append((row, s, x_pc))

    kept = [row[3] for row, _, _ in joints]
    bodies = {}
    for link in kept:
        # (name, mass, COM in the link frame, inertia about the part COM in the link frame, part frame origin)
        parts = []
        for name, (s, x_sl) in survivor.items():
            if s != link or name not in _LINK_INERTIALS:
                continue
            m, c, i6 = _LINK_INERTIALS[name]
            r = _qmat(x_sl[1])
            parts.append(
                (name, m, x_sl[0] + r @ np.asarray(c, dtype=np.float64), r @ _inertia_matrix(i6) @ r.T, x_sl[0])
            )
        mass = sum(p[1] for p in parts)
        com = sum(p[1] * p[2] for p in parts) / mass
        if inertia_merge == "newton":
            # Newton 1.8 ModelBuilder.collapse_fixed_joints: each merged child adds R I Rᵀ + m S(p) with p the child
            # *frame origin* in the survivor frame, and the survivor's own tensor is not re-centred on the new COM.
            inertia = sum(p[3] + (_steiner(p[1], p[4]) if p[0] != link else 0.0) for p in parts)
        else:
            # Rigid composite about the merged COM (what a separate fixed link would contribute physically).
            inertia = sum(p[3] + _steiner(p[1], p[2] - com) for p in parts)
        bodies[link] = (mass, com, inertia)
    return bodies, joints, survivor


def _per_dof(value: float | Sequence[float], name: str, n: int = 9) -> list[float]:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"panda(): {name} must be a finite float or a sequence of {n} finite floats, got {value!r}")
    return [float(v) for v in arr]


def panda(
    *,
    label_prefix: str = "panda",
    armature: float | Sequence[float] = 0.0,
    mimic_fingers: bool = False,
    initial_q: Sequence[float] | None = None,
    actuator_mode: newton.JointTargetMode = newton.JointTargetMode.POSITION_VELOCITY,
    inertia_merge: Literal["newton", "exact"] = "newton",
    visual_shapes: bool = True,
    tcp_site: bool = True,
) -> newton.ModelBuilder:
    """Build one Franka Panda, fixed base at the origin, Z up.

    Joints ``{label_prefix}/panda_joint1`` ... ``/panda_joint7`` (revolute) and ``/panda_finger_joint1``,
    ``/panda_finger_joint2`` (prismatic), with the URDF's limits, effort limits and velocity limits; bodies
    ``{label_prefix}/panda_link1`` ... ``/panda_link7``, ``/panda_leftfinger``, ``/panda_rightfinger``. ``panda_joint1``
    is attached to the world directly (no base joint). Drive gains, passive damping, passive stiffness and friction are
    0; joint-limit springs keep Newton's builder defaults (``limit_ke`` 1e4, ``limit_kd`` 10), like ``add_urdf``.

    Args:
        label_prefix: Prefix of every joint, body, shape and articulation label (``f"{label_prefix}/{urdf_name}"``);
            the articulation label is ``label_prefix``. An empty prefix gives the bare URDF names.
        armature: Joint armature [kg·m² or kg], one value for all 9 DOFs or a sequence of 9 in joint order.
        mimic_fingers: Also couple ``panda_finger_joint2`` to ``panda_finger_joint1`` with Newton's joint mimic
            (``set_joint_mimic``, offset 0, multiplier 1), as the URDF's ``<mimic>`` tag (and SAPIEN's tendon) does.
            Off by default: the fingers are then two independent DOFs, both driven by ManiSkill's mimic controller.
        initial_q: 9 joint positions [rad x7, m x2] written to ``joint_q`` and ``joint_target_q``. Defaults to
            :data:`PANDA_INITIAL_Q`: ManiSkill's rest keyframe with the fingers at 0.035 m instead of 0.04 m (just
            inside their [0, 0.04] m limit, measured stable). Pass :data:`PANDA_REST_QPOS` for the exact keyframe.
            Must lie within the joint limits.
        actuator_mode: ``joint_target_mode`` of every DOF. The default POSITION_VELOCITY makes solvers that honour it
            (MuJoCo, Kamino) install a built-in drive that tracks both ``joint_target_q`` and ``joint_target_qd``, which
            ManiSkill's position, velocity and position-velocity controllers all need; its gains stay 0 until a
            controller writes them. ``add_urdf`` uses POSITION. Use NONE or EFFORT for torque-only control.
        inertia_merge: How the hand's inertia is folded into ``panda_link7``. ``"newton"`` (default) reproduces
            ``add_urdf(collapse_fixed_joints=True)`` of Newton 1.8 (to float32 round-off): Newton shifts the
            hand tensor by the hand *frame* origin (0.107 m) rather than by its COM offset and does not re-centre on the
            merged COM, which overstates link7's Ixx and Iyy about the merged COM by about 0.006 kg·m² (+38 %, +44 %).
            ``"exact"`` uses the rigid-composite inertia about the merged COM (equivalent to keeping the hand as a
            fixed link, as SAPIEN/PhysX does). Mass and COM are identical in both modes.
        visual_shapes: Add rough, massless, non-colliding capsules and boxes for viewers (the base outline goes on the
            world, body -1). They never take part in contacts, so they cannot disturb the arm or touch the ground.
        tcp_site: Keep the URDF's ``panda_hand_tcp`` frame (merged into ``panda_link7``) as a Newton site labelled
            ``{label_prefix}/panda_hand_tcp``: the EE controllers' ``ee_link``. A site is a massless, non-colliding,
            invisible reference shape, so the dynamics (and MuJoCo's articulation) do not change.

    Returns:
        A fresh ``newton.ModelBuilder`` (default up axis Z and gravity) holding one articulation. Use
        ``ModelBuilder.replicate`` or ``add_world`` to make environments.

    Raises:
        ValueError: ``initial_q`` is not 9 finite values within the joint limits, ``armature`` has the wrong shape,
            or ``inertia_merge`` is unknown.
    """
    if inertia_merge not in ("newton", "exact"):
        raise ValueError(f"panda(): inertia_merge must be 'newton' or 'exact', got {inertia_merge!r}")
    arm = _per_dof(armature, "armature")
    q0 = _per_dof(PANDA_INITIAL_Q if initial_q is None else initial_q, "initial_q")
    bodies, joints, survivor = _collapse(inertia_merge)
    for k, (row, _, _) in enumerate(joints):
        name, lower, upper = row[0], row[7], row[8]
        if not lower <= q0[k] <= upper:
            raise ValueError(
                f"panda(): initial_q[{k}] = {q0[k]!r} for {name!r} is outside its limits [{lower}, {upper}]"
            )

    def label(name: str) -> str:
        return f"{label_prefix}/{name}" if label_prefix else name

    # World pose of every kept link at q0 (so Model.body_q starts consistent with joint_q).
    world: dict[str | None, tuple[np.ndarray, np.ndarray]] = {None: _tident()}
    for k, (row, parent, x_p) in enumerate(joints):
        jtype, child, axis = row[1], row[3], row[6]
        if jtype == "revolute":
            motion = (np.zeros(3), qaxis(axis, q0[k]))
        else:
            motion = (np.asarray(axis, dtype=np.float64) * q0[k], np.array([0.0, 0.0, 0.0, 1.0]))
        world[child] = tmul(tmul(world[parent], x_p), motion)

    builder = newton.ModelBuilder()
    body_of: dict[str, int] = {}
    for row, _, _ in joints:
        link = row[3]
        mass, com, inertia = bodies[link]
        body_of[link] = builder.add_link(
            xform=_wp_transform(world[link]),
            com=wp.vec3(*(float(v) for v in com)),
            inertia=wp.mat33(*(float(v) for v in inertia.ravel())),
            mass=float(mass),
            label=label(link),
        )

    joint_ids = []
    for k, (row, parent, x_p) in enumerate(joints):
        name, jtype, _, child, _, _, axis, lower, upper, effort, velocity = row
        add = builder.add_joint_revolute if jtype == "revolute" else builder.add_joint_prismatic
        j = add(
            -1 if parent is None else body_of[parent],
            body_of[child],
            parent_xform=_wp_transform(x_p),
            child_xform=wp.transform_identity(),
            axis=wp.vec3(*(float(v) for v in axis)),
            target_q=q0[k],
            target_qd=0.0,
            target_ke=0.0,
            target_kd=0.0,
            damping=0.0,
            stiffness=0.0,
            limit_lower=lower,
            limit_upper=upper,
            armature=arm[k],
            effort_limit=effort,
            velocity_limit=velocity,
            friction=0.0,
            actuator_mode=actuator_mode,
            label=label(name),
        )
        q_start = builder.joint_q_start[j]
        builder.joint_q[q_start] = q0[k]
        builder.joint_target_q[q_start] = q0[k]
        joint_ids.append(j)
    builder.add_articulation(joint_ids, label=label_prefix or "panda")

    if mimic_fingers:
        builder.set_joint_mimic(joint_ids[8], joint_ids[7], coeffs=(0.0, 1.0))

    if visual_shapes:
        _add_visual_shapes(builder, body_of, survivor, label)
    if tcp_site:
        link, x_tcp = survivor["panda_hand_tcp"]
        builder.add_site(body_of[link], xform=_wp_transform(x_tcp), label=label("panda_hand_tcp"))
    return builder


def _add_visual_shapes(builder: newton.ModelBuilder, body_of: dict[str, int], survivor, label) -> None:
    cfg = newton.ModelBuilder.ShapeConfig(
        density=0.0, has_shape_collision=False, has_particle_collision=False, collision_group=0, is_visible=True
    )
    grey, dark = wp.vec3(0.9, 0.9, 0.92), wp.vec3(0.25, 0.25, 0.28)

    def place(link: str, local: tuple[np.ndarray, np.ndarray]) -> tuple[int, wp.transform]:
        s, x_sl = survivor[link]
        body = -1 if s is None else body_of[s]
        return body, _wp_transform(tmul(x_sl, local))

    for n, (link, a, b, radius) in enumerate(_VISUAL_CAPSULES):
        a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        d = b - a
        length = float(np.linalg.norm(d))
        z = np.array([0.0, 0.0, 1.0])
        axis = np.cross(z, d / length)
        if np.linalg.norm(axis) < 1e-9:
            rot = np.array([0.0, 0.0, 0.0, 1.0]) if d[2] > 0 else qaxis((1, 0, 0), math.pi)
        else:
            rot = qaxis(axis, math.acos(float(np.clip(d[2] / length, -1.0, 1.0))))
        body, xform = place(link, (0.5 * (a + b), rot))
        builder.add_shape_capsule(
            body,
            xform=xform,
            radius=radius,
            half_height=0.5 * length,
            cfg=cfg,
            color=grey,
            label=label(f"{link}/visual{n}"),
        )
    for n, (link, centre, half) in enumerate(_VISUAL_BOXES):
        body, xform = place(link, (np.asarray(centre, dtype=np.float64), np.array([0.0, 0.0, 0.0, 1.0])))
        builder.add_shape_box(
            body, xform=xform, hx=half[0], hy=half[1], hz=half[2], cfg=cfg, color=dark, label=label(f"{link}/visual{n}")
        )


# ----------------------------------------------------------------------------------------------------------------------
# ManiSkill 3's Panda control modes (mani_skill/agents/robots/panda/panda.py).


def _panda_frames() -> dict[str, tuple[str | None, tuple[tuple[float, ...], tuple[float, ...]]]]:
    survivor = _collapse("newton")[2]
    return {
        link: (s, (tuple(float(v) for v in x[0]), tuple(float(v) for v in x[1]))) for link, (s, x) in survivor.items()
    }


PANDA_FRAMES = _panda_frames()
"""Every link of the Panda URDF as ``(kept body or None for the world, (position [m], quaternion xyzw))`` relative to
the body it is merged into by ``collapse_fixed_joints`` (``panda_hand_tcp`` -> ``panda_link7``)."""

PANDA_DESCRIPTION = RobotDescription(
    tuple((r[0], r[1], r[2], r[3], tuple(r[4]), tuple(r[5])) for r in _JOINTS), "the built-in Panda (wpctrl.robots)"
)
"""The Panda URDF's joints. Registered on import: an EE controller locates a Panda link that its model lacks
(``panda_hand_tcp`` of ``add_urdf(collapse_fixed_joints=True)``) and the base frame there when its ``urdf_path`` is
None or names no file."""
register_description(PANDA_DESCRIPTION)
