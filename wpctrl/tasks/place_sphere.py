"""PlaceSphere-v1 (``mani_skill/envs/tasks/tabletop/place_sphere.py``, ``PlaceSphereEnv``): pick up a ball and set it
in a shallow bin, then let go with the ball at rest and the arm still.

Scene: a 2 cm ball (``actors.build_sphere``, density 1000, the scene's default material) and a kinematic bin
(``_build_bin``: a 5 cm square floor 5 mm thick and four 5 mm walls rising 1 cm above it, around a 4 cm square inside).
Episode: the ball on the table at xy ~ U([-0.1, -0.1], [-0.05, 0.1]), the bin on the table at xy ~ U([0, -0.1], [0.1,
0.1]), neither turned; the Panda at the table scene's rest pose. Success: the ball on the bin's floor (xy within 5 mm
of the bin's centre, z 2.25 cm +- 5 mm above it), the ball static, not grasped. Dense reward (max 13): reach the ball
(x2); grasped: 4 + place over the floor; on the bin: 6 + (open the gripper, 16 once let go + keep the ball still + keep
the arm still) / 3.
"""

from __future__ import annotations

import warp as wp

from .definitions import Actor, Box, ObsField, Sphere
from .funcs import (
    Sim,
    actor_pos,
    actor_pose7,
    actor_static,
    arm_static,
    flag,
    gripper_opening,
    is_grasping,
    set_actor_pose,
    still_reward,
    tcp_pos,
    tcp_pose7,
    vec1,
    vec7,
)
from .registry import Task, register_task

__all__ = ["PlaceSphere", "bin_boxes"]

RADIUS = 0.02
"""``PlaceSphereEnv.radius``: the ball's radius [m]."""
INNER_HALF = 0.02
"""``inner_side_half_len``: half the side of the bin's inside [m]."""
WALL_HALF = 0.0025
"""``short_side_half_size``: half the thickness of the bin's floor and walls [m]."""
BLOCK_HALF = (WALL_HALF, 2 * WALL_HALF + INNER_HALF, 2 * WALL_HALF + INNER_HALF)
"""``block_half_size``: the floor's half sizes as ManiSkill lists them (thickness first) [m]."""
EDGE_HALF = (WALL_HALF, 2 * WALL_HALF + INNER_HALF, 2 * WALL_HALF)
"""``edge_block_half_size``: a wall's half sizes (thickness, length, height) [m]."""
ON_XY_TOL, ON_Z_TOL = 0.005, 0.005
"""``evaluate``: ``xy_flag = ||offset[:2]|| <= 0.005``,
``z_flag = |offset[2] - radius - block_half_size[0]| <= 0.005`` [m]."""
STATIC_LIN, STATIC_ANG = 1.0e-2, 0.5
"""``evaluate``: ``obj.is_static(lin_thresh=1e-2, ang_thresh=0.5)`` [m/s, rad/s]."""
ROBOT_STATIC = 0.2
"""``compute_dense_reward``: ``agent.is_static(0.2)``, every arm joint slower than 0.2 rad/s."""
UNGRASPED = 16.0
"""``ungrasp_reward[~is_obj_grasped] = 16.0``."""
MAX_REWARD = 13.0
"""``reward[info["success"]] = 13``; ``compute_normalized_dense_reward``: ``max_reward = 13.0``."""
INFO_KEYS = ("is_obj_grasped", "is_obj_on_bin", "is_obj_static")
SUCCESS, GRASPED, ON_BIN, STATIC = 0, 1, 2, 3
"""Columns of ``sim.info``: ``success``, then :data:`INFO_KEYS` (``evaluate()``'s dict order)."""
SPHERE, BIN = 0, 1
"""The actors' indices (the ball is also contact column 0)."""
_FLOOR_TOP = WALL_HALF + RADIUS
"""The ball's centre above the bin's when it rests on the floor (``radius + block_half_size[0]``)."""
WALLS = (1, 2, 3, 4)
"""The bin's walls among its shapes (:func:`bin_boxes`)."""
PHYSICS = {"contact_solref": (0.0025, 2.0), "shape_solref": (("bin", WALLS, (0.03, 1.0)),)}
"""The task's departures from :class:`~wpctrl.tasks.TaskPhysics`'s defaults, both so that the ball comes to rest in
the bin as soon as PhysX's does (ManiSkill's motion-planning demos end one to four steps after it rests).

- ``contact_solref``: contacts of the same stiffness with twice the damping, so an impact gives back as little as
  PhysX's (restitution 0). The ball, let go above the bin, lands at 35 cm/s on the floor and a wall's top edge at
  once (the 4 cm inside leaves a 2 cm ball 2.7 mm of play). MuJoCo's critically damped contacts let it sink in and
  push it back out along the edge's slanted normal, so it rolls off its landing. MuJoCo's stiffness is
  ``1 / (tau zeta)^2``: halving the time constant and doubling the damping ratio keeps it (and so the fingers' depth
  in what they press) and doubles the damping.
- ``shape_solref``: the walls' contacts spread over about one PhysX step (10 ms). A ball rolling into a wall's top
  edge (measured in ManiSkill at 2-8 cm/s, ``tests/test_task_place_sphere.py``): PhysX takes the whole impact in
  the one step it arrives in, where the edge's upward push is a fifth of a step's weight; the ball rises 0.01 mm,
  its floor and edge contacts hold it, and it is still from the next step on. MuJoCo's 0.6 ms steps resolve what
  rigid Coulomb friction predicts instead: the ball sticks on the edge, pivots up on it (0.03 mm), swings back and
  rolls away at a third of its speed (at 4 cm/s: 1.45 cm/s, over ManiSkill's 1 cm/s static threshold), resting
  steps later. With the walls' time constant at 30 ms (a ball-wall pair's 16 ms, MuJoCo's mix of both shapes') the
  edge pushes for as long as a PhysX step and the ball is left with 0.2-0.7 cm/s. Walls of 20-40 ms replay alike;
  15 and 60 ms lose demos. The floor keeps the task's contacts: softer, it loses every demo.

The other tasks keep the defaults: as every task's, the damping costs LiftPegUpright's demos (``docs/tasks.md``)."""


def bin_boxes() -> tuple[Box, ...]:
    """``_build_bin``'s five boxes in the bin's frame: the floor, then the walls at -x, +x, -y, +y."""
    dx = dy = BLOCK_HALF[1] - BLOCK_HALF[0]
    dz = EDGE_HALF[2] + BLOCK_HALF[0]
    floor = Box((BLOCK_HALF[1], BLOCK_HALF[2], BLOCK_HALF[0]))
    wall_x, wall_y = EDGE_HALF, (EDGE_HALF[1], EDGE_HALF[0], EDGE_HALF[2])
    return (floor, Box(wall_x, (-dx, 0.0, dz)), Box(wall_x, (dx, 0.0, dz)), Box(wall_y, (0.0, -dy, dz)),
            Box(wall_y, (0.0, dy, dz)))  # fmt: skip


@wp.func
def place_sphere_initialize(s: Sim, e: int, rng: wp.uint32):
    # _initialize_episode: the ball's xyz[..., 0] = rand * 0.05 - 0.1, xyz[..., 1] = rand * 0.2 - 0.1, z = radius;
    # the bin's pos[:, 0] = rand * 0.1, pos[:, 1] = rand * 0.2 - 0.1, z = block_half_size[0]; neither turned
    sx = wp.randf(rng) * 0.05 - 0.1
    sy = wp.randf(rng) * 0.2 - 0.1
    bx = wp.randf(rng) * 0.1
    by = wp.randf(rng) * 0.2 - 0.1
    set_actor_pose(s, e, SPHERE, wp.vec3(sx, sy, RADIUS), wp.quat_identity())
    set_actor_pose(s, e, BIN, wp.vec3(bx, by, WALL_HALF), wp.quat_identity())


@wp.func
def place_sphere_evaluate(s: Sim, e: int):
    offset = actor_pos(s, e, SPHERE) - actor_pos(s, e, BIN)
    xy_flag = wp.length(wp.vec2(offset[0], offset[1])) <= ON_XY_TOL
    z_flag = wp.abs(offset[2] - _FLOOR_TOP) <= ON_Z_TOL
    on_bin = xy_flag and z_flag
    static = actor_static(s, e, SPHERE, STATIC_LIN, STATIC_ANG)
    grasped = is_grasping(s, e, SPHERE)
    s.info[e, SUCCESS] = on_bin and static and not grasped
    s.info[e, GRASPED] = grasped
    s.info[e, ON_BIN] = on_bin
    s.info[e, STATIC] = static


@wp.func
def place_sphere_dense_reward(s: Sim, e: int) -> float:
    ball = actor_pos(s, e, SPHERE)
    box = actor_pos(s, e, BIN)
    r = 2.0 * (1.0 - wp.tanh(5.0 * wp.length(tcp_pos(s, e) - ball)))
    grasped = s.info[e, GRASPED]
    if grasped:
        top = wp.vec3(box[0], box[1], box[2] + _FLOOR_TOP)
        r = 4.0 + (1.0 - wp.tanh(5.0 * wp.length(top - ball)))
    if s.info[e, ON_BIN]:
        ungrasp = UNGRASPED
        if grasped:
            ungrasp = gripper_opening(s, e)
        arm_still = 0.0
        if arm_static(s, e, ROBOT_STATIC):
            arm_still = 1.0
        r = 6.0 + (ungrasp + still_reward(s, e, SPHERE) + arm_still) / 3.0
    return r


@wp.func
def obs_is_grasped(s: Sim, e: int) -> vec1:
    return flag(s.info[e, GRASPED])


@wp.func
def obs_bin_pos(s: Sim, e: int) -> wp.vec3:
    return actor_pos(s, e, BIN)


@wp.func
def obs_obj_pose(s: Sim, e: int) -> vec7:
    return actor_pose7(s, e, SPHERE)


@wp.func
def obs_tcp_to_obj_pos(s: Sim, e: int) -> wp.vec3:
    return actor_pos(s, e, SPHERE) - tcp_pos(s, e)


@register_task("PlaceSphere-v1", max_episode_steps=50)
class PlaceSphere(Task):
    radius = RADIUS
    actors = (
        Actor("sphere", (Sphere(RADIUS),), build_height=RADIUS),
        Actor("bin", bin_boxes(), build_height=WALL_HALF, kinematic=True),
    )
    contact_actors = ("sphere",)  # evaluate(): agent.is_grasping(obj)
    obs_extra = (
        ObsField("extra", "is_grasped", 1, obs_is_grasped, boolean=True),
        ObsField("extra", "tcp_pose", 7, tcp_pose7),
        ObsField("extra", "bin_pos", 3, obs_bin_pos),
        ObsField("extra", "obj_pose", 7, obs_obj_pose),
        ObsField("extra", "tcp_to_obj_pos", 3, obs_tcp_to_obj_pos),
    )
    info_keys = INFO_KEYS
    max_reward = MAX_REWARD
    initialize = place_sphere_initialize
    evaluate = place_sphere_evaluate
    dense_reward = place_sphere_dense_reward
    physics = PHYSICS
