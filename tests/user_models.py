"""Models the way users build them (not only ``build_panda``): envs spaced apart, robots on a floating base, and
where each joint of each env lives in Newton's flat arrays, read here from the model's own tables (independently of
wpctrl's binding)."""

from __future__ import annotations

import newton
import numpy as np

from wpctrl.robots import panda


def panda_envs(num_envs: int, spacing=(0.0, 0.0, 0.0), floating: bool = False, **kw) -> newton.Model:
    """``num_envs`` Pandas, one per world, ``spacing`` apart [m] (``replicate``'s grid); ``floating``: each Panda
    (ManiSkill's URDF) on a free joint instead of fixed to the world."""
    if floating:  # ManiSkill's Panda URDF with a free root joint (16 coordinates, 15 DOFs per env)
        from conftest import PANDA_URDF

        one = newton.ModelBuilder()
        one.add_urdf(str(PANDA_URDF), floating=True, enable_self_collisions=False, **kw)
    else:
        one = panda(**kw)
    builder = newton.ModelBuilder()
    builder.replicate(one, num_envs, spacing=spacing)
    return builder.finalize(device="cpu")


def indices(model: newton.Model, names) -> tuple[np.ndarray, np.ndarray]:
    """(num_envs, n) coordinate and DOF indices of the joints ``names`` in every world, from the model's labels and
    ``joint_q_start`` / ``joint_qd_start``."""
    labels = [lb.rsplit("/", 1)[-1] for lb in model.joint_label]
    world = model.joint_world.numpy()
    q0 = model.joint_q_start.numpy()
    qd0 = model.joint_qd_start.numpy()
    E = int(model.world_count)
    coord = np.zeros((E, len(names)), np.int64)
    dof = np.zeros((E, len(names)), np.int64)
    for j, lb in enumerate(labels):
        if lb in names and world[j] >= 0:
            coord[world[j], list(names).index(lb)] = q0[j]
            dof[world[j], list(names).index(lb)] = qd0[j]
    return coord, dof


def put(state: newton.State, model: newton.Model, names, q=None, qd=None) -> None:
    """Write (num_envs, n) positions / velocities of ``names`` into ``state``."""
    coord, dof = indices(model, names)
    if q is not None:
        a = state.joint_q.numpy()
        a[coord] = q
        state.joint_q.assign(a)
    if qd is not None:
        a = state.joint_qd.numpy()
        a[dof] = qd
        state.joint_qd.assign(a)


BASE_JOINTS = ["root_x_axis_joint", "root_y_axis_joint", "root_z_rotation_joint"]
MOBILE_ARM = ["arm_1", "arm_2", "arm_3"]


def mobile_envs(num_envs: int, yaws, arm_q=None, spacing=(0.0, 0.0, 0.0)) -> newton.Model:
    """A mobile manipulator per world (ManiSkill's Fetch-style base: world x / y prismatic joints and a yaw joint,
    then a 3-joint arm), each env at its own yaw (and arm pose) in the model's initial state."""
    import warp as wp

    b = newton.ModelBuilder()
    inertia = wp.mat33(np.eye(3) * 0.05)
    bx, by, base = (b.add_link(mass=m, inertia=inertia) for m in (2.0, 2.0, 20.0))
    joints = [
        b.add_joint_prismatic(-1, bx, axis=(1, 0, 0), label=BASE_JOINTS[0]),
        b.add_joint_prismatic(bx, by, axis=(0, 1, 0), label=BASE_JOINTS[1]),
        b.add_joint_revolute(by, base, axis=(0, 0, 1), label=BASE_JOINTS[2]),
    ]
    parent = base
    for name in MOBILE_ARM:
        child = b.add_link(mass=2.0, inertia=inertia)
        xf = wp.transform((0.0, 0.0, 0.3), wp.quat_identity())
        joints.append(b.add_joint_revolute(parent, child, parent_xform=xf, axis=(0, 1, 0), limit_lower=-2.5,
                                           limit_upper=2.5, label=name))  # fmt: skip
        parent = child
    b.add_articulation(joints, label="mobile")
    builder = newton.ModelBuilder()
    builder.replicate(b, num_envs, spacing=spacing)
    model = builder.finalize(device="cpu")
    coord, _ = indices(model, BASE_JOINTS + MOBILE_ARM)
    q = model.joint_q.numpy()
    q[coord[:, 2]] = yaws
    if arm_q is not None:
        q[coord[:, 3:]] = arm_q
    model.joint_q.assign(q)
    return model
