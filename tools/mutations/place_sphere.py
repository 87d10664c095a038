"""Mutations: PlaceSphere-v1 (wpctrl/tasks/place_sphere.py)."""

from .model import M

_TESTS = ("tests/test_task_place_sphere.py",)

MUTATIONS = [
    M(
        "place_sphere_physics_undamped",
        "wpctrl/tasks/place_sphere.py",
        'PHYSICS = {"contact_solref": (0.0025, 2.0), ',
        'PHYSICS = {"contact_solref": (0.0035, 1.43), ',
        "PlaceSphere's contacts damped less than twice the defaults at the same stiffness (the ball rolls off its "
        "landing)",
        _TESTS,
    ),
    M(
        "place_sphere_stiff_walls",
        "wpctrl/tasks/place_sphere.py",
        '"shape_solref": (("bin", WALLS, (0.03, 1.0)),)}',
        '"shape_solref": ()}',
        "PlaceSphere's bin walls get the other shapes' contacts (a ball rolled into a wall's edge pivots on it and "
        "rolls back)",
        _TESTS,
    ),
    M(
        "place_success_while_grasped",
        "wpctrl/tasks/place_sphere.py",
        "    s.info[e, SUCCESS] = on_bin and static and not grasped\n",
        "    s.info[e, SUCCESS] = on_bin and static\n",
        "PlaceSphere's success accepts the ball still held in the gripper",
        _TESTS,
    ),
    M(
        "place_ungrasp_reward_one",
        "wpctrl/tasks/place_sphere.py",
        "UNGRASPED = 16.0\n",
        "UNGRASPED = 1.0\n",
        "the ungrasp reward of a released ball is 1 (StackCube's) instead of PlaceSphere's 16",
        _TESTS,
    ),
    M(
        "place_no_robot_static_term",
        "wpctrl/tasks/place_sphere.py",
        "        if arm_static(s, e, ROBOT_STATIC):\n            arm_still = 1.0\n",
        "",
        "the reward on the bin leaves out the arm's stillness term",
        _TESTS,
    ),
    M(
        "place_bin_x_range",
        "wpctrl/tasks/place_sphere.py",
        "    bx = wp.randf(rng) * 0.1\n",
        "    bx = wp.randf(rng) * 0.1 - 0.05\n",
        "the bin's x is drawn over [-0.05, 0.05] instead of [0, 0.1]",
        _TESTS,
    ),
    M(
        "place_sphere_shape_radius",
        "wpctrl/tasks/scene.py",
        "env.add_shape_sphere(body, xform=xform, radius=shape.radius,",
        "env.add_shape_sphere(body, xform=xform, radius=0.5 * shape.radius,",
        "a task actor's sphere shape is built with half its declared radius",
        _TESTS,
    ),
    M(
        "place_floor_height",
        "wpctrl/tasks/place_sphere.py",
        "_FLOOR_TOP = WALL_HALF + RADIUS\n",
        "_FLOOR_TOP = 2.0 * WALL_HALF + RADIUS\n",
        "the ball's resting height above the bin counts the whole floor thickness",
        _TESTS,
    ),
]
