"""The joint-space response r = (H^-1)_ii per env and row: the part and its gather / gain kernels.

:class:`JointSpaceResponse` serves acceleration drives (implicit: the per-env solver gains ``Kp / r``, ``Kd / r``
written into the model and notified to the solver; explicit: the same gains in the substep kernel) and stable explicit
PD. ``r`` is refreshed once per control step in ``set_action`` (``inertia_update="control"``) or before every substep
(``"substep"``): one launch of the fused H / Cholesky kernel where the articulation allows it
(:mod:`wpctrl.kernels.inertia`), else Newton's ``JointSpaceResponse`` and a gather (:func:`_response_kernel`). The
coupled drive (:mod:`wpctrl.engine.parts.coupled_drive`) builds on it.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ...config import ConfigError
from ...kernels import inertia
from ...kernels.pd import _bidx
from .drive_properties import DriveArrays
from .part import Part

wp.set_module_options({"enable_backward": False})


@wp.kernel
def _response_kernel(
    # Rows:
    row_art_off: wp.array[wp.int32],
    row_art_dof: wp.array[wp.int32],
    # Envs:
    env_art_base: wp.array[wp.int32],
    # In:
    inverse_blocks_in: wp.array3d[float],
    # Out:
    response_out: wp.array2d[float],
):
    """Each row's joint-space response r = (H^-1)_ii [1/(kg m^2) or 1/kg] from the articulation's inverse block."""
    tid = wp.tid()
    num_rows = row_art_off.shape[0]
    env = tid // num_rows
    r = tid - env * num_rows
    i = row_art_dof[r]
    response_out[env, r] = inverse_blocks_in[env_art_base[env] + row_art_off[r], i, i]


@wp.kernel
def _accel_gains_kernel(drive: DriveArrays):
    """Implicit acceleration drive: the solver's per-env gains are Kp / r and Kd / r (r: the joint's response)."""
    tid = wp.tid()
    num_rows = drive.row_accel.shape[0]
    env = tid // num_rows
    r = tid - env * num_rows
    if drive.row_accel[r] != 0:
        di = drive.env_qd_base[env] + drive.row_qd_off[r]
        resp = drive.response[env, r]
        drive.joint_target_ke[di] = drive.kp[_bidx(drive.kp.shape[0], env), r] / resp
        drive.joint_target_kd[di] = drive.kd[_bidx(drive.kd.shape[0], env), r] / resp


class JointSpaceResponse(Part):
    name = "response"
    OPTIONAL_ARGS = ("response",)

    @staticmethod
    def wanted(plan) -> bool:
        return plan.needs_response and not plan.coupled

    def __init__(self, plan, alloc):
        self.plan = plan
        self.response = alloc.per_env(max(plan.num_rows, 1), fill=1.0)
        self._fused = None  # the fused H / Cholesky kernel (wpctrl.kernels.inertia) where the articulation allows it
        self._jsr = None  # Newton's JointSpaceResponse otherwise
        self.update_per_substep = plan.inertia_update == "substep"
        self.write_gains = plan.has_accel and not plan.explicit
        self._drive: DriveArrays | None = None  # the gains kernel's argument (made once)

    def kernel_args(self) -> dict:
        return {"response": self.response}

    def build(self, engine, model, solver) -> None:
        plan = self.plan
        binding = plan.binding
        art = model.joint_articulation.numpy()[binding.joint_index]  # (E, R)
        if (art < 0).any():
            raise ConfigError(
                "drive_mode: 'acceleration' and stable explicit PD need the joints to be in an articulation "
                "(ModelBuilder.add_articulation)"
            )
        art_dof0 = model.joint_qd_start.numpy()[model.articulation_start.numpy()[art]]
        local = binding.dof_index - art_dof0  # (E, R) DOF index inside its articulation
        base = art[:, 0]
        if ((art - base[:, None]) != (art[:1] - base[:1])).any() or (local != local[:1]).any():
            raise ConfigError("joint_names: the articulations are laid out differently across worlds")
        dev = engine.device
        self.row_art_off = wp.array((art[0] - base[0]).astype(np.int32), dtype=wp.int32, device=dev)
        self.row_art_dof = wp.array(local[0].astype(np.int32), dtype=wp.int32, device=dev)
        self.env_art_base = wp.array(base.astype(np.int32), dtype=wp.int32, device=dev)
        layout, why = inertia.chain_layout(model, binding.joint_index, binding.dof_index)
        if layout is not None:
            self._fused = inertia.FusedChain(layout, model)
        else:
            self._setup_fallback(model, why)
        self.update(engine, model)  # the model's initial pose (per-env gains of implicit acceleration drives)

    def _setup_fallback(self, model, why: str) -> None:
        from newton.actuators import JointSpaceResponse as NewtonJSR

        self._jsr = NewtonJSR(model)

    def update(self, engine, state) -> None:
        """Recompute r for the configuration in ``state``; with an implicit acceleration drive, write the per-env
        solver gains Kp / r, Kd / r into the model (and notify the solver, if one was given)."""
        if self._fused is not None:  # one launch: H from joint_q, its Cholesky factor, diag(H^-1) of the rows
            self._fused.launch_response(state.joint_q, self.response)
        else:
            self._jsr.refresh(state)
            wp.launch(
                _response_kernel,
                dim=engine.num_envs * engine.num_rows,
                inputs=[self.row_art_off, self.row_art_dof, self.env_art_base, self._jsr.inverse_blocks, self.response],
                device=engine.device,
            )
        if self.write_gains:
            if self._drive is None:  # the per-env gains, the model's, the rows' DOFs and acceleration flags, r
                self._drive = engine.part("drive_properties").arrays(engine)
            wp.launch(_accel_gains_kernel, dim=engine.num_envs * engine.num_rows, inputs=[self._drive],
                      device=engine.device)  # fmt: skip
            engine.notify_solver()

    def before_set_action(self, engine, action, state) -> None:
        if not self.update_per_substep:
            self.update(engine, state)

    def before_substep(self, engine, state, control) -> None:
        if self.update_per_substep:
            self.update(engine, state)
