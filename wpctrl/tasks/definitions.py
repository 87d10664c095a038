"""What every ManiSkill table-top task here shares, as data: the table scene, the Panda's pose and rest qpos, and the
pieces a task module declares its scene and observation with (actors and their shapes, goal markers, observation
fields). Host only: no device, no ManiSkill import.

Every number here is ManiSkill 3.0.1's, from the source file named beside it; ``tests/test_tasks_maniskill.py``
checks them against the installed mani-skill (its classes' attributes and a live env's objects).

Frames and units as ManiSkill's: world frame with the table top at z = 0, metres, radians, kilograms; quaternions
``(w, x, y, z)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "PANDA_REST_QPOS",
    "PANDA_ROOT_POSE",
    "TABLE",
    "TABLE_REST_QPOS",
    "Actor",
    "Box",
    "Capsule",
    "Marker",
    "ObsField",
    "Sphere",
    "TableScene",
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
    restitution 0, for every shape without a material of its own (table, ground, task actors, robot links)."""
    restitution: float = 0.0


TABLE = TableScene()

PANDA_ROOT_POSE: tuple[float, ...] = (-0.615, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
"""The Panda's root pose in the table-top tasks (``_load_agent``: ``sapien.Pose(p=[-0.615, 0, 0])``), ``(x, y, z, qw,
qx, qy, qz)``."""
PANDA_REST_QPOS: tuple[float, ...] = (0.0, math.pi / 8, 0.0, -5 * math.pi / 8, 0.0, 3 * math.pi / 4, math.pi / 4,
                                      0.04, 0.04)  # fmt: skip
"""``TableSceneBuilder.initialize`` for ``panda``: the rest qpos; N(0, ``robot_init_qpos_noise``) is added to every
joint, then the fingers are set to 0.04 [m] again."""
TABLE_REST_QPOS: dict[str, tuple[float, ...]] = {
    "panda": PANDA_REST_QPOS,
    "panda_wristcam": PANDA_REST_QPOS[:6] + (-math.pi / 4,) + PANDA_REST_QPOS[7:],
}
"""``TableSceneBuilder.initialize``'s rest qpos by robot: ``panda_wristcam``'s hand is turned the other way (joint 7
at -pi/4), so its camera faces forward."""
ROBOT_INIT_QPOS_NOISE = 0.02
"""The tasks' default ``robot_init_qpos_noise`` [rad]."""
PANDA_ARM_DOF = 7
PANDA_DOF = 9
PANDA_GRIPPER_WIDTH = 0.08
"""``agent.robot.get_qlimits()[0, -1, 1] * 2`` [m]: twice the upper limit (0.04 m) of the Panda's
``panda_finger_joint2`` (``panda_v2.urdf``), the tasks' ``gripper_width``."""


# -- what a task declares ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Box:
    """A box collision shape: half sizes [m], placed at ``offset`` (and turned by ``quat``, wxyz) in its actor's
    frame (``ActorBuilder.add_box_collision``)."""

    half_size: tuple[float, float, float]
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Capsule:
    """A capsule collision shape along its frame's x axis, as SAPIEN's (``add_capsule_collision``): ``radius`` and
    ``half_length`` of the cylinder part [m]."""

    radius: float
    half_length: float
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Sphere:
    """A sphere collision shape of ``radius`` [m] centred at ``offset`` in its actor's frame
    (``add_sphere_collision``)."""

    radius: float
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Actor:
    """A rigid body of a task (ManiSkill's ``build_dynamic`` actor, or ``build_kinematic`` with ``kinematic``): its
    state-dict name, its collision shapes in its own frame, their density and PhysX static friction (None: the scene
    default, 0.3). A task whose shapes depend on the episode (:meth:`~wpctrl.tasks.registry.Task.episode_shapes`)
    declares the shapes it is built with here, the same count and kinds."""

    name: str
    shapes: tuple[Box | Capsule | Sphere, ...]
    density: float = 1000.0
    static_friction: float | None = None
    build_height: float = 0.0
    """z [m] the body is built at (the episode initialisation places it; at rest on the table reads best)."""
    kinematic: bool = False
    """ManiSkill's ``build_kinematic`` actor: it collides but never moves on its own (no mass, no gravity, pushed by
    nothing); the episode initialisation or a state dict places it. On Newton a massless kinematic root body, which
    MuJoCo-Warp drives as a mocap body; its state-dict velocities are zero."""


@dataclass(frozen=True)
class Marker:
    """A kinematic, collision-free goal marker (ManiSkill's ``build_kinematic`` / ``build_red_white_target`` goal
    actors): a per-env pose the task's episode initialisation writes, in the state dict with zero velocities."""

    name: str
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    """The orientation it is built with (wxyz); the initialisation may overwrite it."""


@dataclass(frozen=True)
class ObsField:
    """One entry of the flattened ``obs_mode="state"`` vector: ``group/name``, its width, and, for a task's extra
    fields, the device function that computes it (``(Sim, env) -> wp.types.vector(size, float)``). ``boolean``:
    ManiSkill's ``state_dict`` observation holds it as a bool tensor."""

    group: str
    name: str
    size: int
    func: object = None
    boolean: bool = False
