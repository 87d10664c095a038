"""ManiSkill's state dict for the tasks' envs: ``get_state_dict()`` / ``set_state_dict(d, env_idx)`` in ManiSkill's
layout, so ``newton_env.set_state_dict(maniskill_env.get_state_dict())`` puts the Newton envs into ManiSkill's
state, and back.

``{"actors": {name: (N, 13)}, "articulations": {"panda": (N, 31)}}``: an actor's ``[p (3), q wxyz (4), linear
velocity (3), angular velocity (3)]`` (world frame, the actor's frame origin), the Panda's ``[root pose (7), root
velocity (6), qpos (9), qvel (9)]`` under the robot's name (``env.robot_uids``: ``panda`` or ``panda_wristcam``; a
state dict of the other robot is refused, naming both). The actors are the table and the task's declared ones, in
that order. The table (kinematic on PhysX) and the robot's root are fixed on Newton: a state whose table pose or
robot root differs from the scene's is refused. A goal marker (kinematic, no collision) is a per-env pose. A state
dict of another task (an actor missing or one the task does not have) is refused, naming the actor. A ManiSkill
state dict's ``"controller"`` entry (controller state of ``use_target`` modes) is restored with ``ctrl.set_state``.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..config import ConfigError
from ._validate import STATE_ACTOR_WIDTH as _ACTOR_DIM
from ._validate import row_vectors
from .definitions import PANDA_DOF, PANDA_ROOT_POSE, TABLE

__all__ = ["StateDictMixin"]

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
        """Zero-copy torch views: joint coordinates (N, nq), DOFs (N, nqd), marker positions (N, M, 3) and
        orientations (N, M, 4, wxyz)."""
        sc = self.scene
        n, m = self.num_envs, len(self.task_spec.markers)
        q = wp.to_torch(self.state.joint_q).view(n, sc.coords_per_env)
        qd = wp.to_torch(self.state.joint_qd).view(n, sc.dofs_per_env)
        return q, qd, wp.to_torch(self.marker_pos)[:, :m], wp.to_torch(self.marker_quat)[:, :m]

    @property
    def actor_names(self) -> list[str]:
        """ManiSkill's non-static actors of the task, in its state-dict order."""
        return [TABLE.name] + [a.name for a in self.task_spec.actors]

    def get_state_dict(self) -> dict:
        """The current state in ManiSkill's layout (new torch tensors on the env's device)."""
        torch = self._torch
        sc = self.scene
        n = self.num_envs
        q, qd, mpos, mquat = self._views()
        r, rd = sc.robot_coord0, sc.robot_dof0
        zeros6 = torch.zeros(n, 6, device=self.device)
        actors = {TABLE.name: torch.as_tensor(table_state(), device=self.device).expand(n, _ACTOR_DIM).clone()}
        for a in self.task_spec.bodies:
            c, cd = sc.actor_coord0[a.name], sc.actor_dof0[a.name]
            actors[a.name] = torch.cat([q[:, c : c + 3], q[:, c + 6 : c + 7], q[:, c + 3 : c + 6], qd[:, cd : cd + 6]],
                                       dim=1)  # fmt: skip
        for k, mk in enumerate(self.task_spec.markers):
            actors[mk.name] = torch.cat([mpos[:, k], mquat[:, k], zeros6], dim=1)
        root = torch.as_tensor(np.asarray(PANDA_ROOT_POSE, np.float32), device=self.device).expand(n, 7)
        robot = torch.cat([root, zeros6, q[:, r : r + PANDA_DOF], qd[:, rd : rd + PANDA_DOF]], dim=1)
        out = {
            "actors": {name: actors[name] for name in self.actor_names},
            "articulations": {self.robot_uids: robot.clone()},
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
        entries, controller = self._check_state_dict(state, rows, idx)
        q, qd, mpos, mquat = self._views()
        sc = self.scene
        for a in self.task_spec.bodies:
            c, cd, pose = sc.actor_coord0[a.name], sc.actor_dof0[a.name], entries[a.name]
            q[idx, c : c + 3] = pose[:, 0:3]
            q[idx, c + 3 : c + 6] = pose[:, 4:7]
            q[idx, c + 6] = pose[:, 3]
            qd[idx, cd : cd + 6] = pose[:, 7:13]
        for k, mk in enumerate(self.task_spec.markers):
            mpos[idx, k] = entries[mk.name][:, 0:3]
            mquat[idx, k] = entries[mk.name][:, 3:7]
        r, rd, robot = sc.robot_coord0, sc.robot_dof0, entries[self.robot_uids]
        q[idx, r : r + PANDA_DOF] = robot[:, 13 : 13 + PANDA_DOF]
        qd[idx, rd : rd + PANDA_DOF] = robot[:, 13 + PANDA_DOF :]
        self._after_state_write(mask)
        if controller:
            self.ctrl.set_state(controller)

    def _check_state_dict(self, state, rows: int, idx) -> tuple[dict, dict]:
        """Every entry the scene needs, as float32 (rows, D) torch tensors on the env's device, and the controller
        state to restore (``{uid: {key: full (num_envs, D) tensor}}``, empty without a ``"controller"`` entry), after
        checking keys, shapes, finiteness and the fixed parts (table, robot root): nothing is written before."""
        from ._validate import state_dict_arrays

        torch = self._torch
        out = state_dict_arrays(state, self.actor_names, self.task_spec.env_id, "set_state_dict: ", rows=rows,
                                robot_width=_ROBOT_DIM, robot=self.robot_uids)  # fmt: skip
        table = table_state()
        if np.abs(out[TABLE.name][:, :7] - table[:7]).max(initial=0.0) > _TOL:
            bad = int(np.abs(out[TABLE.name][:, :7] - table[:7]).max(axis=1).argmax())
            raise ConfigError(f"set_state_dict: state['actors'][{TABLE.name!r}] has the pose "
                              f"{out[TABLE.name][bad, :7].tolist()} (row {bad}); the table is fixed on Newton at "
                              f"{table[:7].tolist()}")  # fmt: skip
        root = np.asarray(PANDA_ROOT_POSE, np.float32)
        arm = out[self.robot_uids]
        if np.abs(arm[:, :7] - root).max(initial=0.0) > _TOL:
            bad = int(np.abs(arm[:, :7] - root).max(axis=1).argmax())
            raise ConfigError(f"set_state_dict: state['articulations'][{self.robot_uids!r}] has the root pose "
                              f"{arm[bad, :7].tolist()} (row {bad}); the Panda's root is fixed at "
                              f"{root.tolist()}")  # fmt: skip
        entries = {k: torch.as_tensor(np.ascontiguousarray(a), device=self.device) for k, a in out.items()}
        return entries, self._checked_controller_state(state.get("controller"), rows, idx)

    def _checked_controller_state(self, controller, rows: int, idx) -> dict:
        """A state dict's ``"controller"`` entry (``{uid: {key: (rows, D) or (D,)}}``, ManiSkill's
        ``agent.get_controller_state()``) merged into the controller's current state of every env, checked against
        the mode's stateful controllers."""
        if not controller:
            return {}
        current = self.ctrl.get_state()
        if not isinstance(controller, dict):
            raise ConfigError(f"set_state_dict: state['controller'] expected a dict {{controller: {{key: values}}}}, "
                              f"got {type(controller).__name__}")  # fmt: skip
        full = {}
        for uid, entry in controller.items():
            if uid not in current:
                raise ConfigError(f"set_state_dict: state['controller'][{uid!r}] is not a stateful controller of "
                                  f"{self.control_mode} (expected one of {sorted(current)})")  # fmt: skip
            if not isinstance(entry, dict):
                raise ConfigError(f"set_state_dict: state['controller'][{uid!r}] expected a dict of "
                                  f"{sorted(current[uid])}, got {type(entry).__name__}")  # fmt: skip
            full[uid] = {}
            for k, v in entry.items():
                name = f"state['controller'][{uid!r}][{k!r}]"
                if k not in current[uid]:
                    raise ConfigError(f"set_state_dict: {name} is not part of the controller's state (expected "
                                      f"{sorted(current[uid])})")  # fmt: skip
                arr = wp.to_torch(current[uid][k]).clone()
                a = row_vectors(v, name, rows, int(arr.shape[1]), "set_state_dict")
                arr[idx] = self._torch.as_tensor(a, dtype=arr.dtype, device=arr.device)
                full[uid][k] = arr
        return full
