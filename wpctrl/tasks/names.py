"""The names the tasks accept, as plain data: task ids, the Panda's ManiSkill control modes and the observation
modes. Nothing here imports Warp, Newton or torch, so the command lines check ``--task`` and ``--control-mode``
(and ``wpctrl.tasks`` imports) in milliseconds; ``tests/test_first_hour.py`` keeps these lists equal to the ones the
tasks are built from (:data:`wpctrl.tasks.TASKS`, :func:`wpctrl.robots.panda_control_modes`)."""

from __future__ import annotations

from typing import NamedTuple

__all__ = [
    "CONTROL_MODES",
    "DEFAULT_CONTROL_MODE",
    "OBS_MODES",
    "ROBOTS",
    "SCRIPTED_TASKS",
    "TASK_ACTORS",
    "TASK_IDS",
    "TASK_MODULES",
    "TaskActors",
    "default_robot",
    "main_object",
]

TASK_MODULES: dict[str, str] = {
    "PushCube-v1": "push_cube",
    "PickCube-v1": "pick_cube",
    "PullCube-v1": "pull_cube",
    "StackCube-v1": "stack_cube",
    "LiftPegUpright-v1": "lift_peg_upright",
    "PegInsertionSide-v1": "peg_insertion_side",
    "PlaceSphere-v1": "place_sphere",
}
"""The built-in tasks: ManiSkill env id -> its module under ``wpctrl/tasks/`` (imported when the task is first used).
One line per task."""


ROBOTS: dict[str, str] = {
    "panda": "panda_v2.urdf",
    "panda_wristcam": "panda_v3.urdf",
}
"""The robots the tasks build (``make(..., robot_uids=...)``, ManiSkill's ``robot_uids``) -> ManiSkill's URDF of it
under ``assets/robots/panda/``: ``mani_skill/agents/robots/panda/panda.py`` (``Panda.urdf_path``) and
``panda_wristcam.py`` (``PandaWristCam``: the same arm, hand and controllers with a RealSense camera on the hand, a
0.564 kg link with a collision box). Both have the Panda's 9 joints, so their state-dict entries, observations and
control modes are the same; only the articulation's name and the hand's load differ."""


class TaskActors(NamedTuple):
    """What a recording of a task holds besides the Panda, for the replay's checks before anything is built."""

    main: str
    """The actor a replay follows (the recordings' ``header.main_object``: the object the task moves)."""
    state: tuple[str, ...]
    """The actors of ManiSkill's state dict, in its order (the table first)."""
    robot: str = "panda"
    """ManiSkill's default robot of the task (its env's ``__init__(robot_uids=...)``): the articulation of a state
    dict or trajectory file that names no other."""


TASK_ACTORS: dict[str, TaskActors] = {
    "PushCube-v1": TaskActors("cube", ("table-workspace", "cube", "goal_region")),
    "PickCube-v1": TaskActors("cube", ("table-workspace", "cube", "goal_site")),
    "PullCube-v1": TaskActors("cube", ("table-workspace", "cube", "goal_region")),
    "StackCube-v1": TaskActors("cubeA", ("table-workspace", "cubeA", "cubeB"), "panda_wristcam"),
    "LiftPegUpright-v1": TaskActors("peg", ("table-workspace", "peg")),
    "PegInsertionSide-v1": TaskActors("peg", ("table-workspace", "peg", "box_with_hole"), "panda_wristcam"),
    "PlaceSphere-v1": TaskActors("sphere", ("table-workspace", "sphere", "bin")),
}
"""ManiSkill task id -> its recorded actors (:class:`TaskActors`), one line per task, as ManiSkill 3.0.1's state dicts
name them (its ``get_state_dict()`` after a reset). A task may be listed before wpctrl builds it: :data:`TASK_IDS`
says which ones it builds."""


def default_robot(env_id: str) -> str:
    """ManiSkill's default robot of ``env_id`` (``"panda"`` for a task not in :data:`TASK_ACTORS`)."""
    entry = TASK_ACTORS.get(env_id)
    return entry.robot if entry is not None else "panda"


def main_object(env_id: str) -> str:
    """The actor a replay of ``env_id``'s recordings follows (``"cube"`` for a task not in :data:`TASK_ACTORS`)."""
    entry = TASK_ACTORS.get(env_id)
    return entry.main if entry is not None else "cube"


TASK_IDS: tuple[str, ...] = tuple(TASK_MODULES)
"""The ManiSkill tasks :func:`wpctrl.tasks.make` builds."""

SCRIPTED_TASKS: tuple[str, ...] = ("PushCube-v1", "PickCube-v1")
"""The tasks :mod:`wpctrl.tasks.scripted` solves with a scripted policy (``wpctrl demo --task``)."""

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
