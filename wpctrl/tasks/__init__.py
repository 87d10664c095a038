"""ManiSkill's table-top tasks (``PushCube-v1``, ``PickCube-v1``) on Newton, with wpctrl as the control layer.

``make(env_id, num_envs, ...)`` builds a vectorised env with the API of ManiSkill's GPU envs (``ManiSkillVectorEnv``):
the same observations (``obs_mode="state"``: the flattened state vector, entries and order as ManiSkill's), rewards,
success and evaluation flags, control modes and action spaces, and ManiSkill's state dict, so a ManiSkill state,
action sequence or policy moves across unchanged. ``replay`` runs ManiSkill's recorded episodes on it.

Needs the ``tasks`` extra (MuJoCo-Warp, Newton's mesh importer, torch) and ManiSkill's Panda asset (the ``maniskill``
extra, or ``asset_dir`` / ``WPCTRL_MANISKILL_ASSETS``).
"""

from __future__ import annotations

from .definitions import PICK_CUBE, PUSH_CUBE, TASKS, TaskSpec
from .factory import CONTROL_MODES, OBS_MODES, make
from .physics import TaskPhysics
from .replay import load_episodes, replay

__all__ = [
    "CONTROL_MODES",
    "OBS_MODES",
    "PICK_CUBE",
    "PUSH_CUBE",
    "TASKS",
    "TaskPhysics",
    "TaskSpec",
    "load_episodes",
    "make",
    "replay",
]
