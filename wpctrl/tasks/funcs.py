"""The device side a task module is written against: :class:`Sim`, one struct that carries where every entity of
env ``e`` sits in Newton's arrays and the arrays themselves, and the ``@wp.func`` helpers that read and write a
task's actors, goal markers and the Panda through it (ManiSkill's ``actor.pose``, ``agent.tcp``,
``agent.is_grasping``, ``agent.is_static``).

Indices: actor ``i`` is the task's ``i``-th :class:`~wpctrl.tasks.definitions.Actor` (its declared order, markers
not counted), marker ``i`` its ``i``-th :class:`~wpctrl.tasks.definitions.Marker`, contact column ``j`` its ``j``-th
entry of ``contact_actors``. Quaternions are Warp's ``(x, y, z, w)`` inside, ManiSkill's ``(w, x, y, z)`` where a
value leaves for an observation (:func:`pose7`).

Random draws: ``wp.randf(rng)`` advances the ``rng`` variable it is given; a ``@wp.func`` gets a copy. So a task's
``initialize`` draws with ``wp.randf`` itself, in ManiSkill's order, and nothing draws after it.
"""

from __future__ import annotations

import math

import warp as wp

from .definitions import PANDA_ARM_DOF, PANDA_GRIPPER_WIDTH

__all__ = ["GRASP_MAX_ANGLE", "GRASP_MIN_FORCE", "Sim", "vec1", "vec7"]

GRASP_MIN_FORCE = 0.5
"""``Panda.is_grasping(min_force=0.5, ...)`` [N] (``mani_skill/agents/robots/panda/panda.py``)."""
GRASP_MAX_ANGLE = 85.0
"""``Panda.is_grasping(..., max_angle=85)`` [deg] between a finger's contact force and its opening direction."""
_GRASP_COS = math.cos(math.radians(GRASP_MAX_ANGLE))

vec1 = wp.types.vector(length=1, dtype=float)
vec7 = wp.types.vector(length=7, dtype=float)


@wp.struct
class Sim:
    """Env 0's index of every entity (add ``e`` times the per-env stride) and the arrays of the current state."""

    nq: int
    """Per-env stride of ``joint_q`` (env e's coordinates start at ``e * nq``)."""
    joint_q: wp.array[float]
    nqd: int
    """Per-env stride of ``joint_qd``."""
    joint_qd: wp.array[float]
    nb: int
    """Per-env stride of the bodies."""
    body_q: wp.array[wp.transform]
    """The bodies' world poses (forward kinematics of ``joint_q``)."""
    actor_q0: wp.array[wp.int32]
    """Per actor: env 0's free-joint coordinates (p, q xyzw); ``actor_qd0`` its 6 DOFs (v, w, world frame)."""
    actor_qd0: wp.array[wp.int32]
    actor_body0: wp.array[wp.int32]
    robot_q0: int
    """Env 0's first robot coordinate (9 of them, ManiSkill's qpos order); its DOFs start at ``robot_qd0``."""
    robot_qd0: int
    tcp_body0: int
    lfinger_body0: int
    rfinger_body0: int
    finger_force: wp.array2d[wp.vec3]
    """``[2e + i, j]``: the contact force on env e's finger i (0 left, 1 right) from its contact actor j."""
    finger_friction: wp.array2d[wp.vec3]
    """The same entries' friction (tangential) part. ManiSkill's pairwise contact forces are PhysX's reported contact
    impulses, which hold the normal part only: ``finger_force - finger_friction``."""
    marker_pos: wp.array2d[wp.vec3]
    """(num_envs, markers) the goal markers' positions."""
    marker_quat: wp.array2d[wp.vec4]
    """(num_envs, markers) their orientations, wxyz."""
    info: wp.array2d[wp.bool]
    """(num_envs, 1 + len(info_keys)): ``evaluate()``'s flags, ``success`` first, then the task's ``info_keys``."""
    param: wp.array2d[float]
    """(num_envs, len(episode_params)) the numbers each env's scene was drawn with (a column of zeros without any)."""


@wp.func
def wxyz(q: wp.quat) -> wp.vec4:
    return wp.vec4(q[3], q[0], q[1], q[2])


@wp.func
def pose7(p: wp.vec3, q: wp.quat) -> vec7:
    """A pose as ManiSkill observes it: ``[p, q wxyz]``."""
    w = wxyz(q)
    return vec7(p[0], p[1], p[2], w[0], w[1], w[2], w[3])


@wp.func
def actor_pos(s: Sim, e: int, i: int) -> wp.vec3:
    c = s.actor_q0[i] + e * s.nq
    return wp.vec3(s.joint_q[c], s.joint_q[c + 1], s.joint_q[c + 2])


@wp.func
def actor_quat(s: Sim, e: int, i: int) -> wp.quat:
    c = s.actor_q0[i] + e * s.nq
    return wp.quat(s.joint_q[c + 3], s.joint_q[c + 4], s.joint_q[c + 5], s.joint_q[c + 6])


@wp.func
def actor_pose7(s: Sim, e: int, i: int) -> vec7:
    return pose7(actor_pos(s, e, i), actor_quat(s, e, i))


@wp.func
def obj_pose(s: Sim, e: int) -> vec7:
    """The ``obj_pose`` observation field of a task whose object is its first actor (``obj.pose.raw_pose``)."""
    return actor_pose7(s, e, 0)


@wp.func
def actor_lin_vel(s: Sim, e: int, i: int) -> wp.vec3:
    """``actor.linear_velocity``: actor i's linear velocity (world frame)."""
    c = s.actor_qd0[i] + e * s.nqd
    return wp.vec3(s.joint_qd[c], s.joint_qd[c + 1], s.joint_qd[c + 2])


@wp.func
def actor_ang_vel(s: Sim, e: int, i: int) -> wp.vec3:
    """``actor.angular_velocity``: actor i's angular velocity (world frame)."""
    c = s.actor_qd0[i] + e * s.nqd
    return wp.vec3(s.joint_qd[c + 3], s.joint_qd[c + 4], s.joint_qd[c + 5])


@wp.func
def actor_static(s: Sim, e: int, i: int, lin_thresh: float, ang_thresh: float) -> bool:
    """``Actor.is_static(lin_thresh, ang_thresh)``: ||linear velocity|| <= lin_thresh [m/s] and ||angular velocity||
    <= ang_thresh [rad/s] (``mani_skill/utils/structs/actor.py``)."""
    return wp.length(actor_lin_vel(s, e, i)) <= lin_thresh and wp.length(actor_ang_vel(s, e, i)) <= ang_thresh


@wp.func
def set_actor_pose(s: Sim, e: int, i: int, p: wp.vec3, q: wp.quat):
    """Place actor i of env e (its velocities are left as they are: the reset zeroes them before ``initialize``)."""
    c = s.actor_q0[i] + e * s.nq
    for k in range(3):
        s.joint_q[c + k] = p[k]
    for k in range(4):
        s.joint_q[c + 3 + k] = q[k]


@wp.func
def zero_actor_velocity(s: Sim, e: int, i: int):
    c = s.actor_qd0[i] + e * s.nqd
    for k in range(6):
        s.joint_qd[c + k] = 0.0


@wp.func
def yaw_quat(yaw: float) -> wp.quat:
    """A rotation by ``yaw`` about z (ManiSkill's ``random_quaternions(lock_x=True, lock_y=True)``, ``euler2quat``)."""
    return wp.quat(0.0, 0.0, wp.sin(0.5 * yaw), wp.cos(0.5 * yaw))


@wp.func
def marker_pos(s: Sim, e: int, i: int) -> wp.vec3:
    return s.marker_pos[e, i]


@wp.func
def goal_pos(s: Sim, e: int) -> wp.vec3:
    """The ``goal_pos`` observation field of a task whose goal is its first marker (``goal.pose.p``)."""
    return s.marker_pos[e, 0]


@wp.func
def set_marker_pos(s: Sim, e: int, i: int, p: wp.vec3):
    s.marker_pos[e, i] = p


@wp.func
def tcp_pos(s: Sim, e: int) -> wp.vec3:
    """``agent.tcp.pose.p``: the ``panda_hand_tcp`` link's position."""
    return wp.transform_get_translation(s.body_q[s.tcp_body0 + e * s.nb])


@wp.func
def tcp_pose7(s: Sim, e: int) -> vec7:
    tcp = s.body_q[s.tcp_body0 + e * s.nb]
    return pose7(wp.transform_get_translation(tcp), wp.transform_get_rotation(tcp))


@wp.func
def qpos(s: Sim, e: int, j: int) -> float:
    return s.joint_q[s.robot_q0 + e * s.nq + j]


@wp.func
def qvel(s: Sim, e: int, j: int) -> float:
    return s.joint_qd[s.robot_qd0 + e * s.nqd + j]


@wp.func
def arm_static(s: Sim, e: int, threshold: float) -> bool:
    """``Panda.is_static(threshold)``: every arm joint's |qvel| <= threshold [rad/s] (fingers not counted)."""
    static = True
    qd0 = s.robot_qd0 + e * s.nqd
    for j in range(wp.static(PANDA_ARM_DOF)):
        if wp.abs(s.joint_qd[qd0 + j]) > threshold:
            static = False
    return static


@wp.func
def gripper_opening(s: Sim, e: int) -> float:
    """``torch.sum(robot.get_qpos()[:, -2:], axis=1) / gripper_width``: how far the fingers are open, 0 to 1 (the
    ``ungrasp_reward`` of StackCube and PlaceSphere while the object is held)."""
    return (qpos(s, e, 7) + qpos(s, e, 8)) / PANDA_GRIPPER_WIDTH


@wp.func
def still_reward(s: Sim, e: int, i: int) -> float:
    """``1 - tanh(||linear_velocity|| * 10 + ||angular_velocity||)`` of actor ``i`` (StackCube's and PlaceSphere's
    ``static_reward``)."""
    return 1.0 - wp.tanh(wp.length(actor_lin_vel(s, e, i)) * 10.0 + wp.length(actor_ang_vel(s, e, i)))


@wp.func
def arm_speed(s: Sim, e: int) -> float:
    """``||qvel[:7]||``: the arm joints' speed (the fingers not counted)."""
    v2 = 0.0
    qd0 = s.robot_qd0 + e * s.nqd
    for j in range(wp.static(PANDA_ARM_DOF)):
        v2 = v2 + s.joint_qd[qd0 + j] * s.joint_qd[qd0 + j]
    return wp.sqrt(v2)


@wp.func
def _finger_grasps(force: wp.vec3, direction: wp.vec3, cos_max_angle: float) -> bool:
    """One finger of ``Panda.is_grasping``: ||f|| >= min force and angle(direction, f) <= max angle."""
    f = wp.length(force)
    if f < wp.static(GRASP_MIN_FORCE):
        return False
    return wp.dot(direction, force) >= cos_max_angle * f * wp.length(direction)


@wp.func
def finger_normal_force(s: Sim, row: int, j: int) -> wp.vec3:
    """The normal part of the contact force on finger ``row`` (``2e + i``) from contact actor j: what ManiSkill's
    ``scene.get_pairwise_contact_forces`` reports. PhysX's contact reports carry the normal impulses only, so a
    fingertip dragged across a face reports its push and not its friction."""
    return s.finger_force[row, j] - s.finger_friction[row, j]


@wp.func
def is_grasping_within(s: Sim, e: int, j: int, cos_max_angle: float) -> bool:
    """``Panda.is_grasping(actor, max_angle=a)`` for contact actor j, ``cos_max_angle = cos(a)``: both fingers push it
    with at least the minimum force, within ``a`` of their opening directions (+y of the left finger, -y of the right
    one)."""
    lf = wp.transform_get_rotation(s.body_q[s.lfinger_body0 + e * s.nb])
    rf = wp.transform_get_rotation(s.body_q[s.rfinger_body0 + e * s.nb])
    lflag = _finger_grasps(finger_normal_force(s, 2 * e, j), wp.quat_rotate(lf, wp.vec3(0.0, 1.0, 0.0)), cos_max_angle)
    rflag = _finger_grasps(finger_normal_force(s, 2 * e + 1, j), -wp.quat_rotate(rf, wp.vec3(0.0, 1.0, 0.0)),
                           cos_max_angle)  # fmt: skip
    return lflag and rflag


@wp.func
def is_grasping(s: Sim, e: int, j: int) -> bool:
    """``Panda.is_grasping(actor)`` for contact actor j, at its default ``max_angle`` (85 degrees)."""
    return is_grasping_within(s, e, j, wp.static(_GRASP_COS))


@wp.func
def param(s: Sim, e: int, k: int) -> float:
    """Env e's k-th episode parameter (the task's ``episode_params[k]``)."""
    return s.param[e, k]


@wp.func
def flag(v: bool) -> vec1:
    """A bool as a one-wide observation field (ManiSkill flattens it to 0.0 / 1.0)."""
    return vec1(wp.where(v, 1.0, 0.0))
