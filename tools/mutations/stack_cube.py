"""Mutations: StackCube-v1 (wpctrl/tasks/stack_cube.py)."""

from .model import M

_TESTS = ("tests/test_task_stack_cube.py",)

MUTATIONS = [
    M(
        "stack_success_while_grasped",
        "wpctrl/tasks/stack_cube.py",
        "    s.info[e, SUCCESS] = on_b and static and not grasped\n",
        "    s.info[e, SUCCESS] = on_b and static\n",
        "StackCube's success accepts cube A still held in the gripper",
        _TESTS,
    ),
    M(
        "stack_placement_one_radius",
        "wpctrl/tasks/stack_cube.py",
        "wp.length(wp.vec2(x, y) - a) > 2.0 * PLACEMENT_RADIUS",
        "wp.length(wp.vec2(x, y) - a) > PLACEMENT_RADIUS",
        "the reset keeps the cubes one sampler radius apart instead of the sum of both radii",
        _TESTS,
    ),
    M(
        "stack_ungrasp_half_width",
        "wpctrl/tasks/funcs.py",
        "return (qpos(s, e, 7) + qpos(s, e, 8)) / PANDA_GRIPPER_WIDTH",
        "return (qpos(s, e, 7) + qpos(s, e, 8)) / (0.5 * PANDA_GRIPPER_WIDTH)",
        "the ungrasp reward divides the finger opening by one finger's range instead of the gripper's width",
        _TESTS,
    ),
    M(
        "stack_obs_cube_b_to_cube_a",
        "wpctrl/tasks/stack_cube.py",
        "    return actor_pos(s, e, CUBE_B) - actor_pos(s, e, CUBE_A)\n",
        "    return actor_pos(s, e, CUBE_A) - actor_pos(s, e, CUBE_B)\n",
        "the cubeA_to_cubeB_pos observation points from B to A",
        _TESTS,
    ),
]
