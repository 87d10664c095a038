"""ManiSkill's state dict for the tasks' envs: ``get_state_dict()`` / ``set_state_dict(d, env_idx)`` in ManiSkill's
layout, so ``newton_env.set_state_dict(maniskill_env.get_state_dict())`` puts the Newton envs into ManiSkill's
state, and back.

``{"actors": {name: (N, 13)}, "articulations": {"panda": (N, 31)}}``: an actor's ``[p (3), q wxyz (4), linear
velocity (3), angular velocity (3)]`` (world frame; the cube's centre of mass is its centre), the Panda's
``[root pose (7), root velocity (6), qpos (9), qvel (9)]``. The table (kinematic on PhysX) and the robot's root are
fixed on Newton: a state whose table pose or robot root differs from the scene's is refused. The goal marker
(kinematic, no collision) is the per-env goal. A ManiSkill state dict's ``"controller"`` entry (controller state of
``use_target`` modes) is restored with ``ctrl.set_state``.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..config import ConfigError
from .definitions import PANDA_DOF, PANDA_ROOT_POSE, TABLE

__all__ = ["StateDictMixin"]

_ACTOR_DIM = 13
_ROBOT_DIM = 13 + 2 * PANDA_DOF
_TOL = 1e-5


def table_state() -> np.ndarray:
    """The table actor's 13 values (kinematic and fixed: zero velocities)."""
    half = 0.5 * TABLE.actor_yaw
    return np.array([*TABLE.actor_position, np.cos(half), 0.0, 0.0, np.sin(half)] + [0.0] * 6, np.float32)


class StateDictMixin:
    """``get_state_dict`` / ``set_state_dict`` of :class:`~wpctrl.tasks.env.TaskEnv` (zero-copy torch views of
    Newton's ``State.joint_q`` / ``joint_qd``; writes are torch ops on the env's device, validated on the host
    first)."""

    def _views(self):
        torch = self._torch
        sc = self.scene
        n = self.num_envs
        q = wp.to_torch(self.state.joint_q).view(n, sc.coords_per_env)
        qd = wp.to_torch(self.state.joint_qd).view(n, sc.dofs_per_env)
        goal = wp.to_torch(self.goal_pos).view(n, 3)
        gq = wp.to_torch(self.goal_quat)
        del torch
        return q, qd, goal, gq

    @property
    def actor_names(self) -> list[str]:
        """ManiSkill's non-static actors of the task, in its state-dict order."""
        return [TABLE.name, "cube", self.task_spec.goal_name]

    def get_state_dict(self) -> dict:
        """The current state in ManiSkill's layout (new torch tensors on the env's device)."""
        torch = self._torch
        sc = self.scene
        n = self.num_envs
        q, qd, goal, gq = self._views()
        c, cd, r, rd = sc.cube_coord0, sc.cube_dof0, sc.robot_coord0, sc.robot_dof0
        cube = torch.cat([q[:, c : c + 3], q[:, c + 6 : c + 7], q[:, c + 3 : c + 6], qd[:, cd : cd + 6]], dim=1)
        zeros6 = torch.zeros(n, 6, device=self.device)
        table = torch.as_tensor(table_state(), device=self.device).expand(n, _ACTOR_DIM).clone()
        root = torch.as_tensor(np.asarray(PANDA_ROOT_POSE, np.float32), device=self.device).expand(n, 7)
        robot = torch.cat([root, zeros6, q[:, r : r + PANDA_DOF], qd[:, rd : rd + PANDA_DOF]], dim=1)
        out = {
            "actors": {
                TABLE.name: table,
                "cube": cube.clone(),
                self.task_spec.goal_name: torch.cat([goal, gq, zeros6], dim=1).clone(),
            },
            "articulations": {"panda": robot.clone()},
        }
        controller = self.ctrl.get_state()
        if controller:
            out["controller"] = {
                k: {kk: wp.to_torch(vv).clone() for kk, vv in v.items()} for k, v in controller.items()
            }
        return out

    def set_state_dict(self, state: dict, env_idx=None) -> None:
        """Put ``env_idx``'s envs (None: all) into ``state`` (ManiSkill's layout; each entry ``(N, D)`` with N the
        number of envs set, or ``(D,)`` for all of them). Every entry is checked on the host before anything is
        written. The drive targets of the envs set are reset to their new qpos (then the state's ``"controller"``
        entry, if any, is restored), their contact forces zeroed, and
        :meth:`~wpctrl.tasks.env.TaskEnv.get_obs` / :meth:`~wpctrl.tasks.env.TaskEnv.evaluate` describe the new
        state."""
        from ._validate import env_mask

        torch = self._torch
        mask = self._all if env_idx is None else env_mask(env_idx, self.num_envs, self.wp_device)
        idx = torch.nonzero(wp.to_torch(mask), as_tuple=False).flatten()
        rows = int(idx.numel())
        entries = self._check_state_dict(state, rows)
        q, qd, goal, gq = self._views()
        sc = self.scene
        c, cd, r, rd = sc.cube_coord0, sc.cube_dof0, sc.robot_coord0, sc.robot_dof0
        cube = entries["cube"]
        q[idx, c : c + 3] = cube[:, 0:3]
        q[idx, c + 3 : c + 6] = cube[:, 4:7]
        q[idx, c + 6] = cube[:, 3]
        qd[idx, cd : cd + 6] = cube[:, 7:13]
        robot = entries["panda"]
        q[idx, r : r + PANDA_DOF] = robot[:, 13 : 13 + PANDA_DOF]
        qd[idx, rd : rd + PANDA_DOF] = robot[:, 13 + PANDA_DOF :]
        g = entries[self.task_spec.goal_name]
        goal[idx] = g[:, 0:3]
        gq[idx] = g[:, 3:7]
        self._after_state_write(mask)
        if "controller" in state and state["controller"]:
            self._set_controller_state(state["controller"], idx)

    def _set_controller_state(self, controller: dict, idx) -> None:
        current = self.ctrl.get_state()
        full = {}
        for uid, entry in controller.items():
            if uid not in current:
                raise ConfigError(f"set_state_dict: controller state for {uid!r}, the mode's stateful controllers are "
                                  f"{sorted(current)}")  # fmt: skip
            full[uid] = {}
            for k, v in entry.items():
                arr = wp.to_torch(current[uid][k]).clone()
                arr[idx] = self._torch.as_tensor(np.asarray(v.cpu() if hasattr(v, "cpu") else v), dtype=arr.dtype,
                                                 device=arr.device).reshape(len(idx), -1)  # fmt: skip
                full[uid][k] = arr
        self.ctrl.set_state(full)

    def _check_state_dict(self, state, rows: int) -> dict:
        """Every entry the scene needs, as float32 (rows, D) torch tensors on the env's device, after checking keys,
        shapes, finiteness and the fixed parts (table, robot root)."""
        torch = self._torch
        if not isinstance(state, dict) or "actors" not in state or "articulations" not in state:
            got = sorted(state) if isinstance(state, dict) else type(state).__name__
            raise ConfigError(f"set_state_dict: expected a dict with 'actors' and 'articulations', got {got}")
        need = [("actors", name, _ACTOR_DIM) for name in self.actor_names] + [("articulations", "panda", _ROBOT_DIM)]
        out = {}
        for group, name, dim in need:
            if not isinstance(state[group], dict) or name not in state[group]:
                have = sorted(state[group]) if isinstance(state[group], dict) else type(state[group]).__name__
                raise ConfigError(f"set_state_dict: state[{group!r}] has no {name!r} entry (has {have})")
            v = state[group][name]
            v = v.detach().to("cpu") if hasattr(v, "detach") else v
            a = np.asarray(v, dtype=np.float32)
            if a.ndim == 1:
                a = np.broadcast_to(a, (rows, a.shape[0]))
            if a.shape != (rows, dim):
                raise ConfigError(
                    f"set_state_dict: state[{group!r}][{name!r}] expected shape ({rows}, {dim}), got "
                    f"{tuple(np.shape(v))}"
                )
            if not np.isfinite(a).all():
                raise ConfigError(f"set_state_dict: state[{group!r}][{name!r}] holds non-finite values")
            out[name] = a
        table = table_state()
        if np.abs(out[TABLE.name][:, :7] - table[:7]).max(initial=0.0) > _TOL:
            raise ConfigError(f"set_state_dict: the table is fixed on Newton at {table[:7].tolist()}, the state has "
                              f"{out[TABLE.name][0, :7].tolist()}")  # fmt: skip
        root = np.asarray(PANDA_ROOT_POSE, np.float32)
        if np.abs(out["panda"][:, :7] - root).max(initial=0.0) > _TOL:
            raise ConfigError(f"set_state_dict: the Panda's root is fixed at {root.tolist()}, the state has "
                              f"{out['panda'][0, :7].tolist()}")  # fmt: skip
        return {k: torch.as_tensor(np.ascontiguousarray(a), device=self.device) for k, a in out.items()}
