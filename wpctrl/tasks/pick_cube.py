"""PickCube-v1 (``mani_skill/envs/tasks/tabletop/pick_cube.py``, ``PickCubeEnv`` with ``PICK_CUBE_CONFIGS["panda"]``
of ``pick_cube_cfgs.py``): pick a cube up and hold it still at a goal in the air.

Scene: a 4 cm cube (``actors.build_cube``, density 1000, the scene's default material) and the sphere ``goal_site``
(kinematic, no collision). Episode: the cube flat on the table at xy ~ U[-0.1, 0.1]^2 with a uniform yaw; the goal
at xy ~ U[-0.1, 0.1]^2, z = half size + U[0, 0.3]. Success: the cube within ``goal_thresh`` of the goal and the arm
static. Dense reward (max 5): reach + grasped + grasped * place + placed * static.
"""

from __future__ import annotations

import warp as wp

from .definitions import Actor, Box, Marker, ObsField
from .funcs import (
    Sim,
    actor_pos,
    arm_speed,
    arm_static,
    flag,
    goal_pos,
    is_grasping,
    marker_pos,
    obj_pose,
    set_actor_pose,
    set_marker_pos,
    tcp_pos,
    tcp_pose7,
    vec1,
    yaw_quat,
)
from .registry import Task, register_task

__all__ = ["PickCube"]

CUBE_HALF_SIZE = 0.02
"""``PICK_CUBE_CONFIGS["panda"]["cube_half_size"]`` [m]."""
GOAL_THRESH = 0.025
"""``["goal_thresh"]`` [m]: the goal sphere's radius and the placed distance (inclusive)."""
CUBE_SPAWN_HALF_SIZE = 0.1
"""``["cube_spawn_half_size"]`` [m]: cube and goal xy ~ U[-h, h]^2 around ``cube_spawn_center`` (0, 0)."""
MAX_GOAL_HEIGHT = 0.3
"""``["max_goal_height"]`` [m]: goal z = cube half size + U[0, max]."""
STATIC_THRESHOLD = 0.2
"""``evaluate``: ``self.agent.is_static(0.2)`` [rad/s]."""
INFO_KEYS = ("is_obj_placed", "is_robot_static", "is_grasped")
SUCCESS, PLACED, STATIC, GRASPED = 0, 1, 2, 3
"""Columns of ``sim.info``: ``success``, then :data:`INFO_KEYS`."""
CUBE, GOAL = 0, 0
"""The cube's actor index (and contact column), the goal's marker index."""


@wp.func
def pick_cube_initialize(s: Sim, e: int, rng: wp.uint32):
    x = (wp.randf(rng) * 2.0 - 1.0) * CUBE_SPAWN_HALF_SIZE
    y = (wp.randf(rng) * 2.0 - 1.0) * CUBE_SPAWN_HALF_SIZE
    yaw = wp.randf(rng) * 2.0 * wp.pi  # random_quaternions(lock_x=True, lock_y=True)
    set_actor_pose(s, e, CUBE, wp.vec3(x, y, CUBE_HALF_SIZE), yaw_quat(yaw))
    gx = (wp.randf(rng) * 2.0 - 1.0) * CUBE_SPAWN_HALF_SIZE
    gy = (wp.randf(rng) * 2.0 - 1.0) * CUBE_SPAWN_HALF_SIZE
    set_marker_pos(s, e, GOAL, wp.vec3(gx, gy, CUBE_HALF_SIZE + wp.randf(rng) * MAX_GOAL_HEIGHT))


@wp.func
def pick_cube_evaluate(s: Sim, e: int):
    placed = wp.length(marker_pos(s, e, GOAL) - actor_pos(s, e, CUBE)) <= GOAL_THRESH
    static = arm_static(s, e, STATIC_THRESHOLD)
    s.info[e, SUCCESS] = placed and static
    s.info[e, PLACED] = placed
    s.info[e, STATIC] = static
    s.info[e, GRASPED] = is_grasping(s, e, CUBE)


@wp.func
def pick_cube_dense_reward(s: Sim, e: int) -> float:
    cube_p = actor_pos(s, e, CUBE)
    goal = marker_pos(s, e, GOAL)
    # compute_dense_reward: reaching + is_grasped + is_grasped * place + is_obj_placed * static (arm qvel, no fingers)
    r = 1.0 - wp.tanh(5.0 * wp.length(cube_p - tcp_pos(s, e)))
    if s.info[e, GRASPED]:
        r = r + 1.0 + (1.0 - wp.tanh(5.0 * wp.length(goal - cube_p)))
    if s.info[e, PLACED]:
        r = r + 1.0 - wp.tanh(5.0 * arm_speed(s, e))
    return r


@wp.func
def obs_is_grasped(s: Sim, e: int) -> vec1:
    return flag(s.info[e, GRASPED])


@wp.func
def obs_tcp_to_obj_pos(s: Sim, e: int) -> wp.vec3:
    return actor_pos(s, e, CUBE) - tcp_pos(s, e)


@wp.func
def obs_obj_to_goal_pos(s: Sim, e: int) -> wp.vec3:
    return marker_pos(s, e, GOAL) - actor_pos(s, e, CUBE)


@register_task("PickCube-v1", max_episode_steps=50)
class PickCube(Task):
    cube_half_size = CUBE_HALF_SIZE
    goal_thresh = GOAL_THRESH
    cube_spawn_half_size = CUBE_SPAWN_HALF_SIZE
    max_goal_height = MAX_GOAL_HEIGHT
    actors = (
        Actor("cube", (Box((CUBE_HALF_SIZE,) * 3),), build_height=CUBE_HALF_SIZE),
        Marker("goal_site"),
    )
    contact_actors = ("cube",)
    obs_extra = (
        ObsField("extra", "is_grasped", 1, obs_is_grasped, boolean=True),
        ObsField("extra", "tcp_pose", 7, tcp_pose7),
        ObsField("extra", "goal_pos", 3, goal_pos),
        ObsField("extra", "obj_pose", 7, obj_pose),
        ObsField("extra", "tcp_to_obj_pos", 3, obs_tcp_to_obj_pos),
        ObsField("extra", "obj_to_goal_pos", 3, obs_obj_to_goal_pos),
    )
    info_keys = INFO_KEYS
    max_reward = 5.0  # compute_dense_reward: reward[info["success"]] = 5; compute_normalized_dense_reward: / 5
    initialize = pick_cube_initialize
    evaluate = pick_cube_evaluate
    dense_reward = pick_cube_dense_reward
