"""The names the tasks accept, as plain data: task ids, the Panda's ManiSkill control modes and the observation
modes. Nothing here imports Warp, Newton or torch, so the command lines check ``--task`` and ``--control-mode``
(and ``wpctrl.tasks`` imports) in milliseconds; ``tests/test_first_hour.py`` keeps these lists equal to the ones the
tasks are built from (:data:`wpctrl.tasks.TASKS`, :func:`wpctrl.robots.panda_control_modes`)."""

from __future__ import annotations

__all__ = ["CONTROL_MODES", "DEFAULT_CONTROL_MODE", "OBS_MODES", "TASK_IDS", "TASK_MODULES"]

TASK_MODULES: dict[str, str] = {"PushCube-v1": "push_cube", "PickCube-v1": "pick_cube"}
"""The built-in tasks: ManiSkill env id -> its module under ``wpctrl/tasks/`` (imported when the task is first used)."""

TASK_IDS: tuple[str, ...] = tuple(TASK_MODULES)
"""The ManiSkill tasks :func:`wpctrl.tasks.make` builds."""

CONTROL_MODES: tuple[str, ...] = (
    "pd_joint_delta_pos",
    "pd_joint_pos",
    "pd_joint_target_delta_pos",
    "pd_joint_vel",
    "pd_joint_pos_vel",
    "pd_joint_delta_pos_vel",
    "pd_ee_delta_pos",
    "pd_ee_delta_pose",
    "pd_ee_pose",
    "pd_ee_target_delta_pos",
    "pd_ee_target_delta_pose",
)
"""The Panda's ManiSkill control modes, ManiSkill's order (``pd_joint_delta_pos``, its default, first): the modes of
:func:`wpctrl.robots.panda_control_modes` that ManiSkill defines (not wpctrl's torque-level modes)."""

DEFAULT_CONTROL_MODE = "pd_joint_delta_pos"

OBS_MODES: tuple[str, ...] = ("state", "state_dict")
"""The observation modes of the tasks (no cameras)."""
