"""ManiSkill 3.0.1's table-top tasks as data: the scene, the episode initialisation, the observation layout, success and
reward constants of ``PushCube-v1`` and ``PickCube-v1`` with the Panda (host only, no device, no ManiSkill import).

Every number here is ManiSkill's, from the source file named beside it; ``tests/test_tasks_maniskill.py`` checks them
against the installed mani-skill (its classes' attributes and a live env's objects), so a difference cannot go unseen.

Frames and units as ManiSkill's: world frame with the table top at z = 0, metres, radians, kilograms; quaternions
``(w, x, y, z)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "PANDA_REST_QPOS",
    "PANDA_ROOT_POSE",
    "PICK_CUBE",
    "PUSH_CUBE",
    "TASKS",
    "TABLE",
    "ObsField",
    "TableScene",
    "TaskSpec",
]

# mani_skill/utils/scene_builder/table/scene_builder.py (TableSceneBuilder.build / initialize)


@dataclass(frozen=True)
class TableScene:
    """The table scene of ``TableSceneBuilder``: one kinematic box and a ground plane below it."""

    height: float = 0.9196429
    """Table height [m]: the top is at z = 0, the ground at z = -height."""
    half_size: tuple[float, float, float] = (2.418 / 2, 1.209 / 2, 0.9196429 / 2)
    """The collision box's half sizes in the table actor's frame [m]."""
    box_offset: tuple[float, float, float] = (0.0, 0.0, 0.9196429 / 2)
    """The box's centre in the actor frame [m]."""
    actor_position: tuple[float, float, float] = (-0.12, 0.0, -0.9196429)
    """The actor's world position [m]; its orientation is +90 degrees about z (``euler2quat(0, 0, pi/2)``)."""
    actor_yaw: float = math.pi / 2
    name: str = "table-workspace"
    static_friction: float = 0.3
    """ManiSkill's scene default material (``SceneConfig``/``sapien_env``): static = dynamic friction 0.3,
    restitution 0, for every shape without a material of its own (table, ground, cube, robot links)."""
    restitution: float = 0.0


TABLE = TableScene()

PANDA_ROOT_POSE: tuple[float, ...] = (-0.615, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
"""The Panda's root pose in both tasks (``_load_agent``: ``sapien.Pose(p=[-0.615, 0, 0])``), ``(x, y, z, qw, qx, qy,
qz)``."""
PANDA_REST_QPOS: tuple[float, ...] = (0.0, math.pi / 8, 0.0, -5 * math.pi / 8, 0.0, 3 * math.pi / 4, math.pi / 4,
                                      0.04, 0.04)  # fmt: skip
"""``TableSceneBuilder.initialize`` for ``panda``: the rest qpos; N(0, ``robot_init_qpos_noise``) is added to every
joint, then the fingers are set to 0.04 [m] again."""
ROBOT_INIT_QPOS_NOISE = 0.02
"""The tasks' default ``robot_init_qpos_noise`` [rad]."""
PANDA_ARM_DOF = 7
PANDA_DOF = 9


@dataclass(frozen=True)
class ObsField:
    """One entry of the flattened ``obs_mode="state"`` vector: ``group/name`` and its width."""

    group: str
    name: str
    size: int


_AGENT = (ObsField("agent", "qpos", PANDA_DOF), ObsField("agent", "qvel", PANDA_DOF))


@dataclass(frozen=True)
class TaskSpec:
    """What one task defines (``mani_skill/envs/tasks/tabletop/<task>.py``)."""

    env_id: str
    kind: int
    """0: PushCube, 1: PickCube (the device kernels' switch)."""
    max_episode_steps: int
    cube_half_size: float
    cube_spawn_half_size: float
    """The cube's xy is drawn from U[-h, h]^2 around the origin [m]."""
    random_cube_yaw: bool
    """PickCube: ``random_quaternions(lock_x=True, lock_y=True)`` (a yaw uniform in [0, 2 pi)); PushCube: identity."""
    goal_name: str
    """The kinematic goal marker's actor name in ManiSkill's state dict."""
    goal_quat: tuple[float, float, float, float]
    """The goal marker's orientation (wxyz): PushCube's target disc is turned +90 degrees about y."""
    goal_radius: float
    """PushCube: ``goal_radius`` (success: cube xy within it); PickCube: ``goal_thresh`` (cube within it)."""
    max_goal_height: float
    """PickCube: goal z = cube half size + U[0, max_goal_height]."""
    push_goal_offset: float
    """PushCube: goal xy = cube xy + (0.1 + goal_radius, 0); goal z = 1e-3."""
    max_reward: float
    """``compute_normalized_dense_reward`` divides by it; a success step's dense reward is set to it."""
    obs_fields: tuple[ObsField, ...]
    info_keys: tuple[str, ...]
    """``evaluate()``'s keys besides ``success`` (and ``elapsed_steps`` added by ``get_info``)."""
    static_threshold: float = 0.2
    """``Panda.is_static(0.2)``: the largest absolute velocity of the 7 arm joints [rad/s]."""
    grasp_min_force: float = 0.5
    """``Panda.is_grasping(min_force=0.5, max_angle=85)`` [N]."""
    grasp_max_angle: float = 85.0
    """[deg] between each finger's contact force and its opening direction."""

    @property
    def obs_dim(self) -> int:
        return sum(f.size for f in self.obs_fields)

    def obs_slices(self) -> dict[str, dict[str, slice]]:
        """``{group: {name: slice}}`` into the flattened observation."""
        out: dict[str, dict[str, slice]] = {}
        start = 0
        for f in self.obs_fields:
            out.setdefault(f.group, {})[f.name] = slice(start, start + f.size)
            start += f.size
        return out


PUSH_CUBE = TaskSpec(
    env_id="PushCube-v1",
    kind=0,
    max_episode_steps=50,
    cube_half_size=0.02,
    cube_spawn_half_size=0.1,
    random_cube_yaw=False,
    goal_name="goal_region",
    goal_quat=(math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0),  # euler2quat(0, pi/2, 0)
    goal_radius=0.1,
    max_goal_height=0.0,
    push_goal_offset=0.1 + 0.1,
    max_reward=4.0,
    obs_fields=_AGENT
    + (ObsField("extra", "tcp_pose", 7), ObsField("extra", "goal_pos", 3), ObsField("extra", "obj_pose", 7)),
    info_keys=(),
)
"""``push_cube.py``: success = cube xy within 0.1 of the goal and cube z < half size + 5 mm; dense reward: reach the
push point (cube - (half size + 5 mm, 0, 0)), then, once within 1 cm of it, place (xy to the goal) and keep z."""

PICK_CUBE = TaskSpec(
    env_id="PickCube-v1",
    kind=1,
    max_episode_steps=50,
    cube_half_size=0.02,
    cube_spawn_half_size=0.1,
    random_cube_yaw=True,
    goal_name="goal_site",
    goal_quat=(1.0, 0.0, 0.0, 0.0),
    goal_radius=0.025,
    max_goal_height=0.3,
    push_goal_offset=0.0,
    max_reward=5.0,
    obs_fields=_AGENT
    + (
        ObsField("extra", "is_grasped", 1),
        ObsField("extra", "tcp_pose", 7),
        ObsField("extra", "goal_pos", 3),
        ObsField("extra", "obj_pose", 7),
        ObsField("extra", "tcp_to_obj_pos", 3),
        ObsField("extra", "obj_to_goal_pos", 3),
    ),
    info_keys=("is_obj_placed", "is_robot_static", "is_grasped"),
)
"""``pick_cube.py`` (``PICK_CUBE_CONFIGS["panda"]``): success = cube within 0.025 of the goal and the arm static;
dense reward: reach + grasped + grasped * place + placed * static."""

TASKS: dict[str, TaskSpec] = {t.env_id: t for t in (PUSH_CUBE, PICK_CUBE)}
"""The tasks :func:`wpctrl.tasks.make` builds, by ManiSkill env id."""
