"""Scripted solutions of the tasks in ManiSkill's ``pd_ee_delta_pos`` mode, as functions of the flattened
``obs_mode="state"`` observation: the same function drives ManiSkill's env and wpctrl's (their observations are the
same), so it generates episodes on one simulator to replay on the other, and solves the tasks in the demo.

Both are stateless (each action follows from the current observation alone) and work on a batch ``(num_envs,
obs_dim)`` of torch observations. The action is ``[dx, dy, dz, gripper]`` normalised to [-1, 1]: ``0.1 * a`` metres
of TCP motion in the robot's root frame (ManiSkill's frame ``root_translation``; the Panda's root is not rotated),
gripper +1 open, -1 closed.
"""

from __future__ import annotations

from .registry import TASKS

__all__ = ["pick_cube_policy", "policy_for", "push_cube_low_policy", "push_cube_policy"]

_STEP = 0.1
"""pd_ee_delta_pos: metres of TCP motion per unit action."""
_PUSH_HOVER_Z = 0.08
"""PushCube: TCP height [m] above the table top while moving behind the cube."""
_PUSH_Z = 0.03
"""PushCube: TCP height [m] above the table top while pushing (the fingertips clear the table)."""


def _fields(env_id: str, obs):
    s = TASKS[env_id].obs_slices()["extra"]
    return obs[:, s["tcp_pose"]][:, :3], obs[:, s["obj_pose"]][:, :3], obs[:, s["goal_pos"]]


def _towards(target, tcp, gain: float = 1.0):
    return ((target - tcp) * (gain / _STEP)).clamp(-1.0, 1.0)


def push_cube_policy(obs):
    """PushCube-v1, the solve of ManiSkill's recorded PushCube episodes, gripper closed throughout: move the TCP to
    5 cm behind the cube (-x) at 8 cm height; once within 1 cm of that point in xy, lower it to 3 cm (4.5 cm behind
    the cube's centre); once lower than 3.6 cm, push along +x at ``6 * (goal x - cube x)`` (1 to 8 cm per control
    step), keeping the TCP at the cube's y and 3 cm height; when the cube's centre is within 1.5 cm (in x) of the
    goal's, hold (zero action). The fingertips stay clear of the table (compare :func:`push_cube_low_policy`)."""
    import torch

    tcp, cube, goal = _fields("PushCube-v1", obs)
    hover = torch.stack([cube[:, 0] - 0.05, cube[:, 1], torch.full_like(cube[:, 2], _PUSH_HOVER_Z)], dim=1)
    lower = torch.stack([cube[:, 0] - 0.045, cube[:, 1], torch.full_like(cube[:, 2], _PUSH_Z)], dim=1)
    # lowering: within 1 cm (xy) of the hover point, or already on the way down near the lowering line
    over = ((tcp[:, :2] - hover[:, :2]).norm(dim=1) < 0.01) | (
        (tcp[:, 2] < _PUSH_HOVER_Z - 0.003) & ((tcp[:, :2] - lower[:, :2]).norm(dim=1) < 0.01))  # fmt: skip
    low = tcp[:, 2] < _PUSH_Z + 0.006
    pushing = low & (tcp[:, 0] < cube[:, 0])
    arm = torch.where(over[:, None], _towards(lower, tcp), _towards(hover, tcp))
    push = torch.stack([(6.0 * (goal[:, 0] - cube[:, 0])).clamp(0.1, 0.8), (cube[:, 1] - tcp[:, 1]) / _STEP,
                        (_PUSH_Z - tcp[:, 2]) / _STEP], dim=1).clamp(-1.0, 1.0)  # fmt: skip
    arm = torch.where(pushing[:, None], push, arm)
    arm = torch.where((goal[:, 0] - cube[:, 0] < 0.015)[:, None], torch.zeros_like(arm), arm)
    return torch.cat([arm, -torch.ones_like(arm[:, :1])], dim=1)


def push_cube_low_policy(obs):
    """PushCube-v1 pushed low: close the gripper, hover behind the cube, go down to the cube's centre height (the
    fingertips a few millimetres above the table, touching it at times), push the cube along +x in bursts of up to
    6 cm per control step until its centre is 4 cm past the goal's. Its episodes exercise the fingertip-table
    contact, where MuJoCo and PhysX differ (docs/tasks.md)."""
    import torch

    tcp, cube, goal = _fields("PushCube-v1", obs)
    behind = cube.clone()
    behind[:, 0] = cube[:, 0] - (TASKS["PushCube-v1"].cube_half_size + 0.025)
    aligned = ((tcp[:, 1] - cube[:, 1]).abs() < 0.01) & (tcp[:, 0] < behind[:, 0] + 0.01)
    low = tcp[:, 2] < cube[:, 2] + 0.01
    hover = behind.clone()
    hover[:, 2] = cube[:, 2] + 0.05
    push = behind.clone()
    push[:, 0] = goal[:, 0] + 0.04 - (TASKS["PushCube-v1"].cube_half_size + 0.025)
    push[:, 1] = goal[:, 1]
    target = torch.where(aligned[:, None], torch.where(low[:, None], push, behind), hover)
    # rise before moving sideways when not aligned and low
    target[:, 2] = torch.where(~aligned & low, cube[:, 2] + 0.05, target[:, 2])
    pushing = aligned & low
    gain = torch.where(pushing, 0.5, 0.8)[:, None]
    limit = torch.where(pushing, 0.6, 1.0)[:, None]  # push at up to 6 cm per control step
    arm = torch.maximum(torch.minimum((target - tcp) * (gain / _STEP), limit), -limit)
    return torch.cat([arm, -torch.ones_like(arm[:, :1])], dim=1)


def pick_cube_policy(obs):
    """PickCube-v1: open, move above the cube, descend to its centre, close until grasped, carry the cube to the
    goal and hold it there."""
    import torch

    tcp, cube, goal = _fields("PickCube-v1", obs)
    grasped = obs[:, TASKS["PickCube-v1"].obs_slices()["extra"]["is_grasped"]][:, 0] > 0.5
    dxy = (cube[:, :2] - tcp[:, :2]).norm(dim=1)
    above = cube.clone()
    above[:, 2] = cube[:, 2] + 0.06
    over = dxy < 0.008
    at = over & ((tcp[:, 2] - cube[:, 2]).abs() < 0.006)
    carry = tcp + (goal - cube)
    target = torch.where(over[:, None], cube, above)
    target[:, 2] = torch.where(~over & (tcp[:, 2] < cube[:, 2] + 0.03), cube[:, 2] + 0.06, target[:, 2])
    target = torch.where(grasped[:, None], carry, target)
    target = torch.where((at & ~grasped)[:, None], tcp, target)
    gain = torch.where(grasped, 0.6, 0.8)[:, None]
    arm = ((target - tcp) * (gain / _STEP)).clamp(-1.0, 1.0)
    grip = torch.where(grasped | at, -1.0, 1.0)[:, None]
    return torch.cat([arm, grip], dim=1)


POLICIES = {"PushCube-v1": push_cube_policy, "PickCube-v1": pick_cube_policy}
"""The scripted policies by task (:data:`wpctrl.tasks.names.SCRIPTED_TASKS` lists the same ids)."""


def policy_for(env_id: str):
    """The scripted policy of a task (for ``control_mode="pd_ee_delta_pos"``); a task without one is refused, listing
    those that have one."""
    if env_id not in POLICIES:
        from ..config import ConfigError

        raise ConfigError(f"scripted: no scripted policy for {env_id!r}; the tasks with one are {list(POLICIES)}")
    return POLICIES[env_id]
