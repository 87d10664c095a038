"""The tasks' scene on Newton: ManiSkill's Panda (its own ``panda_v2.urdf``, or ``panda_v3.urdf`` with the wrist
camera: collision meshes, SRDF pairs), the table box, the ground and the task's actors (free bodies of boxes and
capsules), ``num_envs`` times in separate worlds at the same place (as ManiSkill's GPU sim keeps its sub-scenes),
with the contact, friction and joint-limit settings of :class:`~wpctrl.tasks.physics.TaskPhysics`.

The Panda's asset is read from the installed mani-skill package (found without importing it) or from ``asset_dir`` /
the ``WPCTRL_MANISKILL_ASSETS`` variable (a copy of ``mani_skill/assets``). Only the collision geometry is loaded:
the URDF's visual elements are dropped before Newton reads it.
"""

from __future__ import annotations

import importlib.util
import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import newton
import numpy as np
import warp as wp

from ..config import ConfigError
from ..maniskill.collision import filter_srdf_pairs
from .definitions import PANDA_DOF, PANDA_ROOT_POSE, TABLE, TABLE_REST_QPOS, Actor, Box, Capsule, Sphere
from .names import ROBOTS
from .physics import TaskPhysics, mujoco_friction
from .registry import Task

__all__ = ["PANDA_FINGER_MATERIAL", "Scene", "build_scene", "panda_urdf_path"]

PANDA_FINGER_MATERIAL = {"static_friction": 2.0, "dynamic_friction": 2.0, "restitution": 0.0}
"""ManiSkill's ``Panda.urdf_config``: the ``gripper`` material of ``panda_leftfinger`` / ``panda_rightfinger``
(``mani_skill/agents/robots/panda/panda.py``). Its PhysX torsional patch radius (0.1 m) has no exact MuJoCo counterpart;
``TaskPhysics.finger_torsion`` adds MuJoCo's torsional friction on the fingers instead (off by default)."""
FINGER_LINKS = ("panda_leftfinger", "panda_rightfinger")
TCP_LINK = "panda_hand_tcp"


def panda_urdf_path(asset_dir: str | None = None, robot_uids: str = "panda") -> str:
    """ManiSkill's URDF of ``robot_uids`` (:data:`~wpctrl.tasks.names.ROBOTS`: ``panda_v2.urdf`` for ``panda``):
    under ``asset_dir``, else ``$WPCTRL_MANISKILL_ASSETS``, else the installed mani-skill package's ``assets``
    folder."""
    root = asset_dir or os.environ.get("WPCTRL_MANISKILL_ASSETS")
    if root is None:
        spec = importlib.util.find_spec("mani_skill")
        if spec is None or not spec.submodule_search_locations:
            from ..extras import install_hint

            raise ImportError(
                f"wpctrl.tasks needs ManiSkill's Panda asset: install the tasks extra ({install_hint('tasks', True)})"
                " or point asset_dir / WPCTRL_MANISKILL_ASSETS at a copy of mani_skill/assets"
            )
        root = os.path.join(list(spec.submodule_search_locations)[0], "assets")
    path = os.path.join(root, "robots", "panda", ROBOTS[robot_uids])
    if not os.path.isfile(path):
        raise FileNotFoundError(f"wpctrl.tasks: ManiSkill's Panda asset {path} does not exist")
    return path


def _collision_only_urdf(path: str) -> str:
    """The URDF's text without its visual elements, mesh paths made absolute."""
    tree = ET.parse(path)
    folder = os.path.dirname(os.path.abspath(path))
    for link in tree.getroot().iter("link"):
        for visual in link.findall("visual"):
            link.remove(visual)
    for mesh in tree.getroot().iter("mesh"):
        name = mesh.get("filename", "")
        if name and not os.path.isabs(name) and "://" not in name:
            mesh.set("filename", os.path.join(folder, name))
    return ET.tostring(tree.getroot(), encoding="unicode")


@dataclass
class Scene:
    """A built scene: the Newton model and where each task entity sits in its arrays (env 0's index + stride)."""

    model: newton.Model
    num_envs: int
    coords_per_env: int
    dofs_per_env: int
    bodies_per_env: int
    robot_coord0: int
    """Env 0's first robot coordinate (the robot's 9 joint positions follow, ManiSkill's qpos order)."""
    robot_dof0: int
    actor_coord0: dict[str, int]
    """Env 0's free joint of each task actor, by name: 7 coordinates (p, q xyzw)."""
    actor_dof0: dict[str, int]
    """Env 0's free joint of each task actor: 6 DOFs (linear, angular velocity, world frame)."""
    actor_body0: dict[str, int]
    actor_shapes0: dict[str, tuple[int, ...]]
    """Env 0's collision shapes of each task actor, in its declared order."""
    shapes_per_env: int
    tcp_body0: int
    finger_bodies0: tuple[int, int]
    shape_mu: dict[str, float]
    """MuJoCo friction coefficient by material (``default``, ``gripper``, a task actor's name where it has its own)
    after the combination rule."""


def _panda_builder(urdf: str, physics: TaskPhysics, qpos: tuple[float, ...]) -> newton.ModelBuilder:
    robot = newton.ModelBuilder()
    robot.rigid_gap = float(physics.contact_gap)
    newton.solvers.SolverMuJoCo.register_custom_attributes(robot)
    p = PANDA_ROOT_POSE
    robot.add_urdf(
        _collision_only_urdf(urdf),
        xform=wp.transform(wp.vec3(*p[:3]), wp.quat(p[4], p[5], p[6], p[3])),
        floating=False,
        enable_self_collisions=True,
    )
    filter_srdf_pairs(robot, urdf)
    for name, q in zip([f"panda_joint{i}" for i in range(1, 8)] + ["panda_finger_joint1", "panda_finger_joint2"],
                       qpos):  # fmt: skip
        j = next(i for i, lb in enumerate(robot.joint_label) if lb.rsplit("/", 1)[-1] == name)
        robot.joint_q[robot.joint_q_start[j]] = q
    return robot


def build_scene(task: Task, num_envs: int, device, physics: TaskPhysics, asset_dir: str | None = None,
                robot_uids: str = "panda") -> Scene:  # fmt: skip
    """``num_envs`` worlds of ``task``'s scene (the robot ``robot_uids``, the table, the task's actors), finalized on
    ``device``."""
    _check_shape_solref(task, physics)
    urdf = panda_urdf_path(asset_dir, robot_uids)
    materials = {"default": TABLE.static_friction, "gripper": PANDA_FINGER_MATERIAL["static_friction"]}
    materials.update({a.name: a.static_friction for a in task.bodies if a.static_friction is not None})
    mu = mujoco_friction(materials, physics.friction_combine)
    env = newton.ModelBuilder()
    env.rigid_gap = float(physics.contact_gap)
    newton.solvers.SolverMuJoCo.register_custom_attributes(env)
    env.add_builder(_panda_builder(urdf, physics, TABLE_REST_QPOS[robot_uids]))
    bodies = [lb.rsplit("/", 1)[-1] for lb in env.body_label]
    for s, b in enumerate(env.shape_body):
        env.shape_material_mu[s] = mu["gripper"] if b >= 0 and bodies[b] in FINGER_LINKS else mu["default"]
        env.shape_material_restitution[s] = 0.0
    static = newton.ModelBuilder.ShapeConfig(mu=mu["default"], restitution=TABLE.restitution, density=0.0)
    yaw = wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), TABLE.actor_yaw)
    centre = wp.vec3(*TABLE.actor_position) + wp.quat_rotate(yaw, wp.vec3(*TABLE.box_offset))
    env.add_shape_box(-1, xform=wp.transform(centre, yaw), hx=TABLE.half_size[0], hy=TABLE.half_size[1],
                      hz=TABLE.half_size[2], cfg=static, label=TABLE.name)  # fmt: skip
    env.add_shape_plane(-1, xform=wp.transform(wp.vec3(0.0, 0.0, -TABLE.height), wp.quat_identity()),
                        width=0.0, length=0.0, cfg=static, label="ground")  # fmt: skip
    shapes0 = {}
    for actor in task.bodies:
        first = env.shape_count
        _add_actor(env, actor, mu.get(actor.name, mu["default"]))
        shapes0[actor.name] = tuple(range(first, env.shape_count))
    n_shapes = env.shape_count

    builder = newton.ModelBuilder()
    newton.solvers.SolverMuJoCo.register_custom_attributes(builder)
    builder.replicate(env, int(num_envs))
    model = builder.finalize(device=device)
    _apply_mujoco_attributes(model, physics, n_shapes, int(num_envs), shapes0)

    labels = [lb.rsplit("/", 1)[-1] for lb in model.body_label]
    jq = model.joint_q_start.numpy()
    jqd = model.joint_qd_start.numpy()
    jlabels = [lb.rsplit("/", 1)[-1] for lb in model.joint_label]
    j1 = jlabels.index("panda_joint1")
    free = {a.name: jlabels.index(f"{a.name}_free_joint") for a in task.bodies}
    scene = Scene(
        model=model,
        num_envs=int(num_envs),
        coords_per_env=model.joint_coord_count // num_envs,
        dofs_per_env=model.joint_dof_count // num_envs,
        bodies_per_env=model.body_count // num_envs,
        robot_coord0=int(jq[j1]),
        robot_dof0=int(jqd[j1]),
        actor_coord0={name: int(jq[j]) for name, j in free.items()},
        actor_dof0={name: int(jqd[j]) for name, j in free.items()},
        actor_body0={a.name: labels.index(a.name) for a in task.bodies},
        actor_shapes0=shapes0,
        shapes_per_env=n_shapes,
        tcp_body0=labels.index(TCP_LINK),
        finger_bodies0=(labels.index(FINGER_LINKS[0]), labels.index(FINGER_LINKS[1])),
        shape_mu=mu,
    )
    _check_layout(scene)
    return scene


def _add_actor(env: newton.ModelBuilder, actor: Actor, mu: float) -> None:
    """One free body with the actor's collision shapes (its mass and inertia from their density); a kinematic actor
    is massless and flagged kinematic (MuJoCo-Warp drives it as a mocap body, posed from its free joint)."""
    body = env.add_body(xform=wp.transform(wp.vec3(0.0, 0.0, actor.build_height), wp.quat_identity()),
                        label=actor.name, is_kinematic=actor.kinematic)  # fmt: skip
    density = 0.0 if actor.kinematic else actor.density
    cfg = newton.ModelBuilder.ShapeConfig(mu=mu, restitution=0.0, density=density)
    for shape in actor.shapes:
        q = shape.quat
        xform = wp.transform(wp.vec3(*shape.offset), wp.quat(q[1], q[2], q[3], q[0]))
        if isinstance(shape, Box):
            env.add_shape_box(body, xform=xform, hx=shape.half_size[0], hy=shape.half_size[1], hz=shape.half_size[2],
                              label=actor.name, cfg=cfg)  # fmt: skip
        elif isinstance(shape, Capsule):  # SAPIEN's capsules lie along x, Newton's along z
            turn = wp.quat_from_axis_angle(wp.vec3(0.0, 1.0, 0.0), 0.5 * math.pi)
            xform = wp.transform(wp.transform_get_translation(xform), wp.transform_get_rotation(xform) * turn)
            env.add_shape_capsule(body, xform=xform, radius=shape.radius, half_height=shape.half_length,
                                  label=actor.name, cfg=cfg)  # fmt: skip
        elif isinstance(shape, Sphere):
            env.add_shape_sphere(body, xform=xform, radius=shape.radius, label=actor.name, cfg=cfg)
        else:
            raise TypeError(f"actor {actor.name}: unknown shape {shape!r}")


def _check_shape_solref(task: Task, physics: TaskPhysics) -> None:
    """Every ``physics.shape_solref`` entry names one of ``task``'s actors and shapes it has, refused before anything
    is built."""
    actors = {a.name: len(a.shapes) for a in task.bodies}
    for i, (actor, index, _) in enumerate(physics.shape_solref):
        if actor not in actors:
            raise ConfigError(f"TaskPhysics.shape_solref[{i}]: actor expected one of {sorted(actors)} "
                              f"({task.env_id}), got {actor!r}")  # fmt: skip
        if max(index) >= actors[actor]:
            raise ConfigError(f"TaskPhysics.shape_solref[{i}]: shape index expected < {actors[actor]} ({actor!r} has "
                              f"{actors[actor]} shapes), got {max(index)}")  # fmt: skip


def _apply_mujoco_attributes(model: newton.Model, physics: TaskPhysics, shapes_per_env: int, num_envs: int,
                             actor_shapes0: dict[str, tuple[int, ...]]) -> None:  # fmt: skip
    """Raw MuJoCo contact and joint-limit parameters on every shape / DOF (SolverMuJoCo reads them at build); with
    ``physics.finger_torsion`` the finger shapes' ``condim`` 4 and torsional friction (0 on every other shape).
    ``actor_shapes0``: each task actor's shapes in the first world, for ``physics.shape_solref``."""
    from newton._src.solvers.mujoco.constants import SOLREF_MODE_RAW

    ns = model.mujoco
    if shapes_per_env * num_envs != model.shape_count:
        raise RuntimeError(f"scene: {model.shape_count} shapes, expected {shapes_per_env * num_envs}")
    solref = np.tile(np.asarray(physics.contact_solref, np.float32), (model.shape_count, 1))
    ns.solref_mode.assign(np.full(model.shape_count, SOLREF_MODE_RAW, np.int32))
    solimp = np.tile(np.array([*physics.contact_solimp, 0.5, 2.0], np.float32), (model.shape_count, 1))
    labels = [lb.rsplit("/", 1)[-1] for lb in model.body_label]
    fingers = np.array([b >= 0 and labels[b] in FINGER_LINKS for b in model.shape_body.numpy()], bool)
    if physics.finger_solimp is not None:
        solimp[fingers, 0:3] = physics.finger_solimp
    ns.geom_solimp.assign(solimp)
    if physics.finger_solref is not None:
        solref[fingers] = physics.finger_solref
    worlds = np.arange(num_envs) * shapes_per_env
    for actor, index, value in physics.shape_solref:
        shapes = np.array([actor_shapes0[actor][k] for k in index])
        solref[(worlds[:, None] + shapes[None, :]).ravel()] = value
    ns.solref.assign(solref)
    if physics.finger_torsion > 0.0:
        ns.condim.assign(np.where(fingers, 4, ns.condim.numpy()).astype(np.int32))
        model.shape_material_mu_torsional.assign(np.where(fingers, physics.finger_torsion, 0.0).astype(np.float32))
    if physics.limit_solref is None:
        return
    ndof = model.joint_dof_count
    ns.solreflimit.assign(np.tile(np.asarray(physics.limit_solref, np.float32), (ndof, 1)))
    ns.solreflimit_mode.assign(np.full(ndof, SOLREF_MODE_RAW, np.int32))
    ns.solimplimit.assign(np.tile(np.array([*physics.limit_solimp, 0.5, 2.0], np.float32), (ndof, 1)))


def _check_layout(scene: Scene) -> None:
    """Every env's robot and actors sit at env 0's indices plus the per-env stride (replicate's layout)."""
    m = scene.model
    if m.joint_coord_count != scene.coords_per_env * scene.num_envs or m.body_count % scene.num_envs:
        raise RuntimeError("scene: the model is not num_envs equal worlds")
    if min(scene.actor_coord0.values(), default=scene.robot_coord0 + PANDA_DOF) - scene.robot_coord0 < PANDA_DOF:
        raise RuntimeError("scene: the robot's 9 coordinates are not contiguous before the actors")
    last = scene.num_envs - 1
    labels = [lb.rsplit("/", 1)[-1] for lb in m.body_label]
    for name, b in scene.actor_body0.items():
        if labels[b + last * scene.bodies_per_env] != name:
            raise RuntimeError("scene: the worlds' bodies are not laid out with a constant stride")
