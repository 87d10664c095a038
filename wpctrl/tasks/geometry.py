"""A scene whose geometry differs per env and per episode: ManiSkill's tasks that draw their actors' sizes in
``_load_scene`` from the episode seed (PegInsertionSide-v1: the peg's length and width, the hole's size and place),
rebuilt on Newton by resizing the shapes of the worlds in place (host only: numpy in, Newton's model arrays out).

Every world is built with the task's declared shapes (``Actor.shapes``); :func:`apply_episode_geometry` then writes
each env's shapes of ``task.episode_shapes(params[e])`` into ``Model.shape_scale`` / ``shape_transform`` /
``shape_collision_radius`` and the dynamic actors' mass, centre of mass and inertia (their declared density) into the
``body_*`` arrays. The caller tells the solver (``notify_model_changed(GEOMETRY_FLAGS)``), which copies them into
MuJoCo-Warp's per-world ``geom_size`` / ``geom_pos`` / bounds and ``body_mass`` / ``body_inertia``: nothing is
rebuilt, the worlds keep their indices, and a captured step stays valid.
"""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from ..config import ConfigError
from .definitions import Actor, Box

__all__ = ["GEOMETRY_FLAGS", "apply_episode_geometry", "box_inertia"]

GEOMETRY_FLAGS = newton.ModelFlags.SHAPE_PROPERTIES | newton.ModelFlags.BODY_INERTIAL_PROPERTIES
"""What :func:`apply_episode_geometry` changes, for ``solver.notify_model_changed``."""


def box_inertia(shapes: tuple[Box, ...], density: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass [kg], centre of mass (3,) and inertia about it (3, 3) of solid boxes of one ``density`` [kg/m^3], by
    Newton's own mass-property functions (those its builder used for the declared shapes)."""
    parts = []
    for b in shapes:
        m, c, i = newton.geometry.compute_inertia_shape(newton.GeoType.BOX, wp.vec3(*b.half_size), None, density)
        q = wp.quat(b.quat[1], b.quat[2], b.quat[3], b.quat[0])
        parts.append((m, np.asarray(wp.quat_rotate(q, c)) + np.asarray(b.offset, float), i, q))
    mass = sum(m for m, _, _, _ in parts)
    com = sum(m * c for m, c, _, _ in parts) / mass if mass > 0.0 else np.zeros(3)
    inertia = sum(np.asarray(newton.geometry.transform_inertia(m, i, wp.vec3(*(c - com)), q), float).reshape(3, 3)
                  for m, c, i, q in parts)  # fmt: skip
    return mass, com, inertia


def _checked_shapes(task, actor: Actor, shapes, env: int) -> tuple[Box, ...]:
    shapes = tuple(shapes)
    if len(shapes) != len(actor.shapes) or not all(isinstance(s, Box) for s in shapes):
        raise ConfigError(f"task {task.env_id}: episode_shapes()[{actor.name!r}] for env {env} expected "
                          f"{len(actor.shapes)} Box shapes (as declared), got {shapes!r}")  # fmt: skip
    for s in shapes:
        if not all(np.isfinite(s.half_size)) or min(s.half_size) <= 0.0 or not all(np.isfinite(s.offset)):
            raise ConfigError(f"task {task.env_id}: episode_shapes()[{actor.name!r}] for env {env}: a box needs finite "
                              f"positive half sizes and a finite offset, got {s!r}")  # fmt: skip
    return shapes


def apply_episode_geometry(scene, task, params: np.ndarray) -> bool:
    """Give env e's actors the shapes of ``task.episode_shapes(params[e])`` (all envs; every value checked before
    anything is written). Returns whether anything changed (the solver must then be notified with
    :data:`GEOMETRY_FLAGS`)."""
    model, n = scene.model, scene.num_envs
    bodies = {a.name: a for a in task.bodies}
    per_env = [task.episode_shapes(np.asarray(params[e], float)) for e in range(n)]
    if not any(per_env):
        return False
    scale = model.shape_scale.numpy()
    xform = model.shape_transform.numpy()
    radius = model.shape_collision_radius.numpy()
    mass, inv_mass = model.body_mass.numpy(), model.body_inv_mass.numpy()
    com, inertia, inv_inertia = model.body_com.numpy(), model.body_inertia.numpy(), model.body_inv_inertia.numpy()
    for e, shapes_of in enumerate(per_env):
        for name, shapes in shapes_of.items():
            if name not in bodies:
                raise ConfigError(f"task {task.env_id}: episode_shapes() names {name!r}, not one of its actors "
                                  f"{sorted(bodies)}")  # fmt: skip
            actor = bodies[name]
            shapes = _checked_shapes(task, actor, shapes, e)
            for s0, box in zip(scene.actor_shapes0[name], shapes):
                i = s0 + e * scene.shapes_per_env
                scale[i] = box.half_size
                q = box.quat
                xform[i] = [*box.offset, q[1], q[2], q[3], q[0]]
                radius[i] = float(np.linalg.norm(box.half_size))  # the bounding sphere in the shape's frame
            if actor.kinematic:
                continue
            b = scene.actor_body0[name] + e * scene.bodies_per_env
            m, c, inert = box_inertia(shapes, actor.density)
            mass[b], inv_mass[b], com[b] = m, 1.0 / m, c
            inertia[b], inv_inertia[b] = inert, np.linalg.inv(inert)
    model.shape_scale.assign(scale)
    model.shape_transform.assign(xform)
    model.shape_collision_radius.assign(radius)
    for arr, value in ((model.body_mass, mass), (model.body_inv_mass, inv_mass), (model.body_com, com),
                       (model.body_inertia, inertia), (model.body_inv_inertia, inv_inertia)):  # fmt: skip
        arr.assign(value)
    return True
