"""Independent numpy re-derivations of ManiSkill 3.0.1's PushCube-v1 / PickCube-v1 definitions (read from
``mani_skill/envs/tasks/tabletop/push_cube.py`` / ``pick_cube.py`` and ``agents/robots/panda/panda.py``), for the
tests: evaluation, dense reward, observation of a state given as ManiSkill's state dict plus the TCP pose.

Nothing here imports wpctrl.
"""

from __future__ import annotations

import numpy as np

HALF = 0.02


def push_evaluate(cube_p, goal_p):
    placed = (np.linalg.norm(cube_p[:, :2] - goal_p[:, :2], axis=1) < 0.1) & (cube_p[:, 2] < HALF + 5e-3)
    return {"success": placed}


def push_dense(tcp_p, cube_p, goal_p, success):
    push_pt = cube_p + np.array([-HALF - 0.005, 0.0, 0.0])
    d = np.linalg.norm(push_pt - tcp_p, axis=1)
    reward = 1 - np.tanh(5 * d)
    reached = d < 0.01
    place = 1 - np.tanh(5 * np.linalg.norm(cube_p[:, :2] - goal_p[:, :2], axis=1))
    reward = reward + place * reached
    z = 1 - np.tanh(5 * np.abs(cube_p[:, 2] - HALF))
    reward = reward + place * z * reached
    return np.where(success, 4.0, reward)


def pick_evaluate(cube_p, goal_p, qvel, grasped):
    placed = np.linalg.norm(goal_p - cube_p, axis=1) <= 0.025
    # ManiSkill compares float32 velocities with the Python float 0.2, which torch takes as float32
    static = np.abs(qvel[:, :7]).astype(np.float32).max(axis=1) <= np.float32(0.2)
    return {"success": placed & static, "is_obj_placed": placed, "is_robot_static": static, "is_grasped": grasped}


def pick_dense(tcp_p, cube_p, goal_p, qvel, info):
    reward = 1 - np.tanh(5 * np.linalg.norm(cube_p - tcp_p, axis=1))
    g = info["is_grasped"].astype(float)
    reward = reward + g
    reward = reward + (1 - np.tanh(5 * np.linalg.norm(goal_p - cube_p, axis=1))) * g
    static = 1 - np.tanh(5 * np.linalg.norm(qvel[:, :7], axis=1))
    reward = reward + static * info["is_obj_placed"]
    return np.where(info["success"], 5.0, reward)


def state_parts(state: dict, goal_name: str) -> dict:
    """Cube pose, goal position, qpos, qvel of a ManiSkill state dict (numpy, (N, ...))."""
    cube = np.asarray(state["actors"]["cube"], np.float64)
    robot = np.asarray(state["articulations"]["panda"], np.float64)
    return {
        "cube_p": cube[:, :3],
        "cube_q": cube[:, 3:7],
        "goal_p": np.asarray(state["actors"][goal_name], np.float64)[:, :3],
        "qpos": robot[:, 13:22],
        "qvel": robot[:, 22:31],
    }


def flat_obs(task: str, parts: dict, tcp_pose, grasped=None):
    """ManiSkill's flattened obs_mode="state" vector: agent qpos, qvel, then the task's extras in its dict order."""
    cols = [parts["qpos"], parts["qvel"]]
    if task == "PickCube-v1":
        cols.append(np.asarray(grasped, float)[:, None])
    cols += [tcp_pose, parts["goal_p"], np.hstack([parts["cube_p"], parts["cube_q"]])]
    if task == "PickCube-v1":
        cols += [parts["cube_p"] - tcp_pose[:, :3], parts["goal_p"] - parts["cube_p"]]
    return np.hstack(cols)
