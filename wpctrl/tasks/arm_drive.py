"""The tasks' arm drive as PhysX's TGS solver applies it (``TaskPhysics.arm_drive = "physx_tgs"``).

ManiSkill's PhysX does not solve the arm's joint drives to convergence: each of its 15 position iterations per 10 ms
step is a sub-step in which every drive row gets one implicit PD impulse, root to tip, each with its own joint's
response (:mod:`wpctrl.kernels.tgs_drive`). A fast move of the Panda's coupled shoulder joints then falls short of
the rigid-body answer, which MuJoCo's built-in drive gives: in the first saturated steps of a ``pd_ee_delta_pos``
episode ``panda_joint1`` moves 25 % further on MuJoCo than on PhysX, and the open fingers that follow clip the cube.
Here the same pass runs before each MuJoCo step (16 per physics step, PhysX's 15 sub-steps), on the arm controller's
own targets and per-env gains, and writes the torques into ``Control.joint_f``; MuJoCo's drive of those DOFs is
switched off before its solver is built. The gripper keeps MuJoCo's drive. MuJoCo's contacts act between the passes,
as PhysX's do between its iterations.

Host side; needs the arm controller's joints to form one articulation chain (the Panda's).
"""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from ..config import ConfigError
from ..kernels import inertia
from ..kernels.tgs_drive import tgs_sweep_kernel

__all__ = ["ArmDrive"]


class ArmDrive:
    """PhysX's TGS drive of a task's arm joints (module docstring): :meth:`begin_step` at each physics step, after
    the controller's ``before_simulation_step``; :meth:`before_solver_step` before every MuJoCo step. Both only launch
    (capturable)."""

    def __init__(self, ctrl, model: newton.Model, physics_dt: float, solver_dt: float):
        arm = ctrl.children.get("arm") if hasattr(ctrl, "children") else None
        if arm is None:
            raise ConfigError("TaskPhysics.arm_drive: 'physx_tgs' drives the control mode's 'arm' controller, and this "
                              "mode has none (use arm_drive='mujoco')")  # fmt: skip
        dof, coord, joint = arm.dof_index, arm.coord_index, arm.joint_index
        if (np.diff(dof, axis=1) <= 0).any():  # PhysX visits the rows root to tip
            raise ConfigError(f"TaskPhysics.arm_drive: 'physx_tgs' needs the arm controller's joints root to tip "
                              f"(increasing DOF indices), got DOFs {dof[0].tolist()}")  # fmt: skip
        layout, why = inertia.chain_layout(model, joint, dof)
        if layout is None:
            raise ConfigError(f"TaskPhysics.arm_drive: 'physx_tgs' needs the arm's joints in one chain ({why}); use "
                              f"arm_drive='mujoco'")  # fmt: skip
        dev = model.device
        n, rows = dof.shape
        self.dofs = dof
        """(num_envs, rows) the arm's DOF indices, in the order the pass visits them."""
        self._chain = inertia.FusedChain(layout, model)
        self._dof = wp.array(np.ascontiguousarray(dof), dtype=wp.int32, device=dev)
        self._coord = wp.array(np.ascontiguousarray(coord), dtype=wp.int32, device=dev)
        self._gains = (arm.stiffness, arm.damping, arm.force_limit)  # live per-env views: changes reach the pass
        self._block = wp.zeros((n, rows, rows), dtype=float, device=dev)
        self._response = wp.zeros((n, rows), dtype=float, device=dev)
        self._impulse = wp.zeros((n, rows), dtype=float, device=dev)
        self._velocity_target = int(bool(arm.sets_target_qvel))
        self._h, self._window = float(solver_dt), float(physics_dt)
        self._device = dev

    def switch_off_solver_drive(self, model: newton.Model) -> None:
        """Turn MuJoCo's own drive of the arm's DOFs off (effort mode, zero gains): call before the solver is built,
        which makes no actuator for a DOF in effort mode."""
        dofs = self.dofs.reshape(-1)
        mode = model.joint_target_mode.numpy()
        ke, kd = model.joint_target_ke.numpy(), model.joint_target_kd.numpy()
        mode[dofs] = int(newton.JointTargetMode.EFFORT)
        ke[dofs] = 0.0
        kd[dofs] = 0.0
        model.joint_target_mode.assign(mode)
        model.joint_target_ke.assign(ke)
        model.joint_target_kd.assign(kd)

    def begin_step(self, state: newton.State) -> None:
        """The physics step's start: the arm's inverse inertia block at this pose and no impulse yet."""
        self._chain.launch_response(state.joint_q, self._response, self._block)
        self._impulse.zero_()

    def before_solver_step(self, state: newton.State, control: newton.Control) -> None:
        """One pass over the arm's drive rows from ``state`` and the controller's targets in ``control``; writes the
        torques into ``control.joint_f``."""
        kp, kd, limit = self._gains
        wp.launch(
            tgs_sweep_kernel,
            dim=self._dof.shape[0],
            inputs=[self._coord, self._dof, kp, kd, limit, self._block, self._h, self._window, self._velocity_target,
                    state.joint_q, state.joint_qd, control.joint_target_q, control.joint_target_qd, self._impulse],
            outputs=[control.joint_f],
            device=self._device,
        )  # fmt: skip
