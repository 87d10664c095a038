"""ManiSkill's table-top tasks (``PushCube-v1``, ``PickCube-v1``, ``PullCube-v1``, ``StackCube-v1``,
``LiftPegUpright-v1``, ``PegInsertionSide-v1``) on Newton, with wpctrl as the control layer.

``make(env_id, num_envs, ...)`` builds a vectorised env with the API of ManiSkill's GPU envs (``ManiSkillVectorEnv``):
the same observations (``obs_mode="state"``: the flattened state vector, entries and order as ManiSkill's), rewards,
success and evaluation flags, control modes and action spaces, and ManiSkill's state dict, so a ManiSkill state,
action sequence or policy moves across unchanged. ``replay`` runs ManiSkill's recorded episodes on it.

A task is one module (``push_cube.py``, ``pick_cube.py``): a :class:`Task` subclass registered with
:func:`register_task`, its scene, observation fields, evaluation and reward declared once (``docs/tasks.md``, "Adding
a task"). :data:`TASKS` maps the ids to the tasks; ``PUSH_CUBE`` / ``PICK_CUBE`` are the two built-in ones.

Needs the ``tasks`` extra (MuJoCo-Warp, Newton's mesh importer, torch) and ManiSkill's Panda asset (the ``maniskill``
extra, or ``asset_dir`` / ``WPCTRL_MANISKILL_ASSETS``).
"""

from __future__ import annotations

from .factory import CONTROL_MODES, OBS_MODES, make, task_physics
from .physics import TaskPhysics
from .randomization import TaskRandomization
from .recording import load_episodes
from .registry import TASKS, Task, get_task, register_task
from .replay import replay

TaskSpec = Task
"""The base class of the tasks (:class:`Task`), by its former name."""

__all__ = [
    "CONTROL_MODES",
    "OBS_MODES",
    "PICK_CUBE",
    "PUSH_CUBE",
    "TASKS",
    "Task",
    "TaskPhysics",
    "TaskRandomization",
    "TaskSpec",
    "get_task",
    "load_episodes",
    "make",
    "register_task",
    "replay",
    "task_physics",
]

_BUILT_IN = {"PUSH_CUBE": "PushCube-v1", "PICK_CUBE": "PickCube-v1"}


def __getattr__(name: str):
    """``PUSH_CUBE`` / ``PICK_CUBE``: the built-in tasks, their modules imported (with Warp) on first use."""
    if name in _BUILT_IN:
        return TASKS[_BUILT_IN[name]]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
