"""StackCube-v1 (``mani_skill/envs/tasks/tabletop/stack_cube.py``, ``StackCubeEnv``): pick up cube A and stack it on
cube B, then let go with cube A resting there.

Scene: two 4 cm cubes (``actors.build_cube``, density 1000, the scene's default material), ``cubeA`` and ``cubeB``;
no goal marker. Episode: a common xy offset ~ U[-0.1, 0.1]^2, then each cube's own xy drawn by a
``UniformPlacementSampler`` over [-0.1, 0.1] x [-0.2, 0.2], cube B's redrawn (up to 100 times) until it lies more than
two collision radii from cube A's; both flat on the table with a uniform yaw each. Success: cube A on cube B (xy
within the half-diagonal + 5 mm, z 4 cm +- 5 mm above it), cube A static and not grasped. Dense reward (max 8):
reach cube A (x2); grasped: 4 + place on B; on B: 6 + (open the gripper + keep cube A still) / 2.
"""

from __future__ import annotations

import math

import warp as wp

from .definitions import Actor, Box, ObsField
from .funcs import (
    Sim,
    actor_pos,
    actor_pose7,
    actor_static,
    gripper_opening,
    is_grasping,
    set_actor_pose,
    still_reward,
    tcp_pos,
    tcp_pose7,
    vec7,
    yaw_quat,
)
from .registry import Task, register_task

__all__ = ["StackCube"]

CUBE_HALF_SIZE = 0.02
"""``_load_scene``: ``cube_half_size = [0.02] * 3`` and ``build_cube(half_size=0.02)`` for both cubes [m]."""
SPAWN_HALF = 0.1
"""``_initialize_episode``: the common offset ``xy = torch.rand((b, 2)) * 0.2 - 0.1`` [m]."""
REGION_X, REGION_Y = 0.1, 0.2
"""``region = [[-0.1, -0.2], [0.1, 0.2]]``: the ``UniformPlacementSampler`` bounds of each cube's xy, x in
[-0.1, 0.1], y in [-0.2, 0.2] [m]."""
PLACEMENT_RADIUS = math.sqrt(2.0) * CUBE_HALF_SIZE + 0.001
"""``radius = torch.linalg.norm(torch.tensor([0.02, 0.02])) + 0.001`` [m]: each cube's sampler radius; cube B's
draw is kept when it is more than the sum of both radii from cube A's (``UniformPlacementSampler.sample``)."""
PLACEMENT_TRIALS = 100
"""``sampler.sample(radius, 100)``: draws before giving up (cube B's sample then stays at 0)."""
ON_XY_TOL = math.sqrt(2.0) * CUBE_HALF_SIZE + 0.005
"""``evaluate``: ``xy_flag = ||offset[:2]|| <= ||cube_half_size[:2]|| + 0.005`` [m]."""
ON_Z_TOL = 0.005
"""``evaluate``: ``z_flag = |offset[2] - 2 * half size| <= 0.005`` [m]."""
STATIC_LIN, STATIC_ANG = 1.0e-2, 0.5
"""``evaluate``: ``cubeA.is_static(lin_thresh=1e-2, ang_thresh=0.5)`` [m/s, rad/s]."""
INFO_KEYS = ("is_cubeA_grasped", "is_cubeA_on_cubeB", "is_cubeA_static")
SUCCESS, GRASPED, ON_B, STATIC = 0, 1, 2, 3
"""Columns of ``sim.info``: ``success``, then :data:`INFO_KEYS` (``evaluate()``'s dict order)."""
CUBE_A, CUBE_B = 0, 1
"""The cubes' actor indices (cube A is also contact column 0)."""


@wp.func
def _standard_yaw_quat(yaw: float) -> wp.quat:
    """``random_quaternions(lock_x=True, lock_y=True)``'s quaternion of a yaw: ``matrix_to_quaternion`` returns it
    with w >= 0."""
    q = yaw_quat(yaw)
    if q[3] < 0.0:
        q = wp.quat(-q[0], -q[1], -q[2], -q[3])
    return q


@wp.func
def stack_cube_initialize(s: Sim, e: int, rng: wp.uint32):
    ox = wp.randf(rng) * 2.0 * SPAWN_HALF - SPAWN_HALF  # the common offset xy
    oy = wp.randf(rng) * 2.0 * SPAWN_HALF - SPAWN_HALF
    # the sampler's first draw (cube A) is taken as it is; cube B's is redrawn until clear of it (else left at 0)
    ax = wp.randf(rng) * 2.0 * REGION_X - REGION_X
    ay = wp.randf(rng) * 2.0 * REGION_Y - REGION_Y
    a = wp.vec2(ax, ay)
    b = wp.vec2(0.0, 0.0)
    found = bool(False)  # noqa: UP018  (Warp: a variable the loop below may reassign, not a constant)
    for _trial in range(PLACEMENT_TRIALS):
        if found:
            break
        x = wp.randf(rng) * 2.0 * REGION_X - REGION_X
        y = wp.randf(rng) * 2.0 * REGION_Y - REGION_Y
        if wp.length(wp.vec2(x, y) - a) > 2.0 * PLACEMENT_RADIUS:
            b = wp.vec2(x, y)
            found = True
    yaw_a = wp.randf(rng) * 2.0 * wp.pi
    yaw_b = wp.randf(rng) * 2.0 * wp.pi
    set_actor_pose(s, e, CUBE_A, wp.vec3(ox + a[0], oy + a[1], CUBE_HALF_SIZE), _standard_yaw_quat(yaw_a))
    set_actor_pose(s, e, CUBE_B, wp.vec3(ox + b[0], oy + b[1], CUBE_HALF_SIZE), _standard_yaw_quat(yaw_b))


@wp.func
def stack_cube_evaluate(s: Sim, e: int):
    offset = actor_pos(s, e, CUBE_A) - actor_pos(s, e, CUBE_B)
    xy_flag = wp.length(wp.vec2(offset[0], offset[1])) <= ON_XY_TOL
    z_flag = wp.abs(offset[2] - 2.0 * CUBE_HALF_SIZE) <= ON_Z_TOL
    on_b = xy_flag and z_flag
    static = actor_static(s, e, CUBE_A, STATIC_LIN, STATIC_ANG)
    grasped = is_grasping(s, e, CUBE_A)
    s.info[e, SUCCESS] = on_b and static and not grasped
    s.info[e, GRASPED] = grasped
    s.info[e, ON_B] = on_b
    s.info[e, STATIC] = static


@wp.func
def stack_cube_dense_reward(s: Sim, e: int) -> float:
    cube_a = actor_pos(s, e, CUBE_A)
    cube_b = actor_pos(s, e, CUBE_B)
    # compute_dense_reward: reaching, then grasp and place (cube A's goal: 2 half sizes above cube B), then on cube B
    # ungrasp (finger opening / full width; 1 once let go) and static (cube A's speed)
    r = 2.0 * (1.0 - wp.tanh(5.0 * wp.length(tcp_pos(s, e) - cube_a)))
    grasped = s.info[e, GRASPED]
    if grasped:
        goal = wp.vec3(cube_b[0], cube_b[1], cube_b[2] + 2.0 * CUBE_HALF_SIZE)
        r = 4.0 + (1.0 - wp.tanh(5.0 * wp.length(goal - cube_a)))
    if s.info[e, ON_B]:
        ungrasp = 1.0
        if grasped:
            ungrasp = gripper_opening(s, e)
        r = 6.0 + (ungrasp + still_reward(s, e, CUBE_A)) / 2.0
    return r


@wp.func
def obs_cube_a_pose(s: Sim, e: int) -> vec7:
    return actor_pose7(s, e, CUBE_A)


@wp.func
def obs_cube_b_pose(s: Sim, e: int) -> vec7:
    return actor_pose7(s, e, CUBE_B)


@wp.func
def obs_tcp_to_cube_a_pos(s: Sim, e: int) -> wp.vec3:
    return actor_pos(s, e, CUBE_A) - tcp_pos(s, e)


@wp.func
def obs_tcp_to_cube_b_pos(s: Sim, e: int) -> wp.vec3:
    return actor_pos(s, e, CUBE_B) - tcp_pos(s, e)


@wp.func
def obs_cube_a_to_cube_b_pos(s: Sim, e: int) -> wp.vec3:
    return actor_pos(s, e, CUBE_B) - actor_pos(s, e, CUBE_A)


@register_task("StackCube-v1", max_episode_steps=50)
class StackCube(Task):
    robot_uids = "panda_wristcam"  # __init__(robot_uids="panda_wristcam"): the Panda with its wrist camera
    cube_half_size = CUBE_HALF_SIZE
    actors = (
        Actor("cubeA", (Box((CUBE_HALF_SIZE,) * 3),), build_height=CUBE_HALF_SIZE),
        Actor("cubeB", (Box((CUBE_HALF_SIZE,) * 3),), build_height=CUBE_HALF_SIZE),
    )
    contact_actors = ("cubeA",)  # evaluate(): agent.is_grasping(cubeA)
    obs_extra = (
        ObsField("extra", "tcp_pose", 7, tcp_pose7),
        ObsField("extra", "cubeA_pose", 7, obs_cube_a_pose),
        ObsField("extra", "cubeB_pose", 7, obs_cube_b_pose),
        ObsField("extra", "tcp_to_cubeA_pos", 3, obs_tcp_to_cube_a_pos),
        ObsField("extra", "tcp_to_cubeB_pos", 3, obs_tcp_to_cube_b_pos),
        ObsField("extra", "cubeA_to_cubeB_pos", 3, obs_cube_a_to_cube_b_pos),
    )
    info_keys = INFO_KEYS
    max_reward = 8.0  # compute_dense_reward: reward[info["success"]] = 8; compute_normalized_dense_reward: / 8
    initialize = stack_cube_initialize
    evaluate = stack_cube_evaluate
    dense_reward = stack_cube_dense_reward
