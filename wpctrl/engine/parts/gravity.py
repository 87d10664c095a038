"""``balance_passive_force``: ManiSkill's agent-level switch that takes gravity off the controlled robot's links.

ManiSkill's ``BaseAgent.set_control_mode`` disables gravity on every link of the robot unless the mode dict says
``"balance_passive_force": False``. Newton has no per-body gravity switch; MuJoCo has one, ``body_gravcomp``
(a passive force ``-m g`` per body, mapped through its Jacobian: exactly gravity removed), which Newton exposes as the
per-body model attribute ``mujoco:gravcomp``. This module finds the robot's bodies and sets that attribute to 1 on
them (creating it on a model whose builder did not register MuJoCo's attributes). Other Newton solvers do not read
it: :func:`check_solver` refuses them with the reason.
"""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from ...config import ConfigError
from .part import Part


def robot_bodies(model: newton.Model, joint_index: np.ndarray) -> np.ndarray:
    """Indices of every body of the robots that hold the joints ``joint_index`` (any shape of Newton joint ids): the
    bodies of their articulations, or, for joints outside an articulation, of the joint tree they hang in."""
    joints = np.unique(np.asarray(joint_index, np.int64).reshape(-1))
    if joints.size == 0:
        return np.zeros(0, np.int64)
    parent = model.joint_parent.numpy()
    child = model.joint_child.numpy()
    art = model.joint_articulation.numpy()
    bodies: set[int] = set()
    arts = np.unique(art[joints])
    if (arts >= 0).any():
        start = model.articulation_start.numpy()
        for a in arts[arts >= 0]:
            members = np.arange(start[a], start[a + 1])
            bodies.update(int(b) for b in child[members])
            bodies.update(int(b) for b in parent[members] if b >= 0)
    loose = joints[art[joints] < 0]
    if loose.size:  # joints outside any articulation: walk up to the tree's root, then collect its descendants
        joint_of = np.full(model.body_count, -1, np.int64)
        joint_of[child] = np.arange(len(child))
        children: dict[int, list[int]] = {}
        for j, p in enumerate(parent):
            children.setdefault(int(p), []).append(int(child[j]))
        for j in loose:
            root = int(child[j])
            while joint_of[root] >= 0 and parent[joint_of[root]] >= 0:
                root = int(parent[joint_of[root]])
            stack = [root]
            while stack:
                b = stack.pop()
                if b not in bodies:
                    bodies.add(b)
                    stack.extend(children.get(b, []))
    return np.array(sorted(bodies), np.int64)


def apply(model: newton.Model, bodies: np.ndarray) -> None:
    """Take gravity off ``bodies``: ``mujoco:gravcomp = 1`` there (read by SolverMuJoCo; notify a solver built
    before with ``ModelFlags.BODY_INERTIAL_PROPERTIES``)."""
    ns = getattr(model, "mujoco", None)
    if ns is None:
        raise ConfigError("balance_passive_force: this Newton model has no 'mujoco' attribute namespace")
    gravcomp = getattr(ns, "gravcomp", None)
    if gravcomp is None or gravcomp.shape[0] != model.body_count:
        gravcomp = wp.zeros(model.body_count, dtype=wp.float32, device=model.device)
        ns.gravcomp = gravcomp
    values = gravcomp.numpy()
    values[bodies] = 1.0
    gravcomp.assign(values)


def check_solver(solver) -> None:
    """Refuse a solver that ignores ``mujoco:gravcomp`` (every Newton solver but SolverMuJoCo), with the reason."""
    if solver is None or isinstance(solver, newton.solvers.SolverMuJoCo):
        return
    raise ConfigError(
        f"balance_passive_force: {type(solver).__name__} has no per-body gravity switch (only SolverMuJoCo honours "
        f"it, through mujoco:gravcomp); build the controller with balance_passive_force=False (or a mode dict with "
        f"'balance_passive_force': False) and handle gravity yourself, e.g. model.set_gravity((0, 0, 0)) when each "
        f"world holds only the robot"
    )


class BalancePassiveForce(Part):
    """At build: gravity off every body of the controlled robot (the controller layer checked the solver first)."""

    name = "gravity"

    @staticmethod
    def wanted(plan) -> bool:
        return plan.options.balance_passive_force

    def __init__(self, plan, alloc):
        self.bodies = None

    def build(self, engine, model, solver) -> None:
        self.bodies = robot_bodies(model, engine.plan.binding.joint_index)
        apply(model, self.bodies)
