"""Mutations: PullCube-v1 (wpctrl/tasks/pull_cube.py)."""

from .model import M

MUTATIONS = [
    M(
        "pull_goal_in_front",
        "wpctrl/tasks/pull_cube.py",
        "set_marker_pos(s, e, GOAL, wp.vec3(x - GOAL_OFFSET, y, GOAL_Z))",
        "set_marker_pos(s, e, GOAL, wp.vec3(x + GOAL_OFFSET, y, GOAL_Z))",
        "PullCube's goal is drawn 0.2 m in +x of the cube (PushCube's side) instead of behind it",
        ("tests/test_task_pull_cube.py::test_reset_draws_follow_maniskills_distribution",),
    ),
    M(
        "pull_success_radius_wider",
        "wpctrl/tasks/pull_cube.py",
        "cube_p[1] - goal[1])) < GOAL_RADIUS\n",
        "cube_p[1] - goal[1])) < 1.01 * GOAL_RADIUS\n",
        "PullCube's success accepts the cube 1 mm outside the goal radius",
        ("tests/test_task_pull_cube.py::test_success_radius_edge_and_no_height_condition",),
    ),
    M(
        "pull_reward_pull_point_behind",
        "wpctrl/tasks/pull_cube.py",
        "d = wp.length(cube_p + wp.vec3(PULL_OFFSET, 0.0, 0.0) - tcp_pos(s, e))",
        "d = wp.length(cube_p - wp.vec3(PULL_OFFSET, 0.0, 0.0) - tcp_pos(s, e))",
        "PullCube's reaching reward leads the TCP to the cube's -x face (a push) instead of the +x one (a pull)",
        ("tests/test_task_pull_cube.py::test_state_dict_round_trips_exactly_and_obs_reward_success_are_maniskills",),
    ),
    M(
        "pull_reward_reached_radius",
        "wpctrl/tasks/pull_cube.py",
        "    if d < REACHED:\n",
        "    if d < 2.0 * REACHED:\n",
        "PullCube's place term starts 2 cm from the pull point instead of 1 cm",
        ("tests/test_task_pull_cube.py::test_place_reward_waits_until_the_tcp_reaches_the_pull_point",),
    ),
]
