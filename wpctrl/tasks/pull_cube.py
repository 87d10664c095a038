"""PullCube-v1 (``mani_skill/envs/tasks/tabletop/pull_cube.py``, ``PullCubeEnv``): pull a cube back onto a goal
region 0.2 m behind it, towards the robot.

Scene: a 4 cm cube (``actors.build_cube``, density 1000, the scene's default material) and the red-white target disc
``goal_region`` (kinematic, no collision, turned +90 degrees about y). Episode: the cube flat on the table at
xy ~ U[-0.1, 0.1]^2, no yaw; the goal at the cube's xy - (0.1 + goal_radius, 0), z = 1e-3. Success: the cube's xy
within ``goal_radius`` of the goal's (no height condition, unlike PushCube). Dense reward (max 3): reach the pull
point in front of the cube (+x, the side away from the robot), then, once within 1 cm of it, place (xy to the goal).
"""

from __future__ import annotations

import math

import warp as wp

from .definitions import Actor, Box, Marker, ObsField
from .funcs import Sim, actor_pos, goal_pos, marker_pos, obj_pose, set_actor_pose, set_marker_pos, tcp_pos, tcp_pose7
from .registry import Task, register_task

__all__ = ["PullCube"]

CUBE_HALF_SIZE = 0.02
"""``PullCubeEnv.cube_half_size`` [m]."""
GOAL_RADIUS = 0.1
"""``PullCubeEnv.goal_radius`` [m]: the target disc's radius and the success distance."""
SPAWN_HALF = 0.1
"""``_initialize_episode``: ``xyz[..., :2] = torch.rand((b, 2)) * 0.2 - 0.1`` [m]."""
GOAL_OFFSET = 0.1 + GOAL_RADIUS
"""``target_region_xyz = xyz - [0.1 + goal_radius, 0, 0]`` [m]: the goal lies this far in -x of the cube."""
GOAL_Z = 1.0e-3
"""``target_region_xyz[..., 2] = 1e-3`` [m]."""
PULL_OFFSET = CUBE_HALF_SIZE + 2 * 0.005
"""``compute_dense_reward``: ``tcp_pull_pos = obj.pose.p + [cube_half_size + 2 * 0.005, 0, 0]`` [m]."""
REACHED = 0.01
"""``compute_dense_reward``: ``reached = tcp_to_pull_pose_dist < 0.01`` [m]."""
CUBE, GOAL = 0, 0
"""The cube's actor index, the goal's marker index."""


@wp.func
def pull_cube_initialize(s: Sim, e: int, rng: wp.uint32):
    x = (wp.randf(rng) * 2.0 - 1.0) * SPAWN_HALF
    y = (wp.randf(rng) * 2.0 - 1.0) * SPAWN_HALF
    set_actor_pose(s, e, CUBE, wp.vec3(x, y, CUBE_HALF_SIZE), wp.quat_identity())
    set_marker_pos(s, e, GOAL, wp.vec3(x - GOAL_OFFSET, y, GOAL_Z))


@wp.func
def pull_cube_evaluate(s: Sim, e: int):
    cube_p = actor_pos(s, e, CUBE)
    goal = marker_pos(s, e, GOAL)
    # evaluate(): is_obj_placed = the cube's xy within goal_radius of the goal's
    s.info[e, 0] = wp.length(wp.vec2(cube_p[0] - goal[0], cube_p[1] - goal[1])) < GOAL_RADIUS


@wp.func
def pull_cube_dense_reward(s: Sim, e: int) -> float:
    cube_p = actor_pos(s, e, CUBE)
    goal = marker_pos(s, e, GOAL)
    # compute_dense_reward: the pull point 1 cm beyond the cube's +x face; "reached" within 1 cm of it
    d = wp.length(cube_p + wp.vec3(PULL_OFFSET, 0.0, 0.0) - tcp_pos(s, e))
    r = 1.0 - wp.tanh(5.0 * d)
    if d < REACHED:
        r = r + 1.0 - wp.tanh(5.0 * wp.length(wp.vec2(cube_p[0] - goal[0], cube_p[1] - goal[1])))
    return r


@register_task("PullCube-v1", max_episode_steps=50)
class PullCube(Task):
    cube_half_size = CUBE_HALF_SIZE
    goal_radius = GOAL_RADIUS
    actors = (
        Actor("cube", (Box((CUBE_HALF_SIZE,) * 3),), build_height=CUBE_HALF_SIZE),
        Marker("goal_region", (math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0)),  # euler2quat(0, pi/2, 0)
    )
    contact_actors = ("cube",)
    obs_extra = (
        ObsField("extra", "tcp_pose", 7, tcp_pose7),
        ObsField("extra", "goal_pos", 3, goal_pos),
        ObsField("extra", "obj_pose", 7, obj_pose),
    )
    max_reward = 3.0  # compute_dense_reward: reward[info["success"]] = 3; compute_normalized_dense_reward: / 3
    initialize = pull_cube_initialize
    evaluate = pull_cube_evaluate
    dense_reward = pull_cube_dense_reward
