"""The joint-space response r = (H^-1)_ii per env and row, and the two drives built on it.

- :class:`JointSpaceResponse`: acceleration drives (implicit: the per-env solver gains ``Kp / r``, ``Kd / r`` written
  into the model and notified to the solver; explicit: the same gains in the substep kernel) and stable explicit PD.
  ``r`` is refreshed once per control step in ``set_action`` (``inertia_update="control"``) or before every substep
  (``"substep"``): one launch of the fused H / Cholesky kernel where the articulation allows it
  (:mod:`wpctrl.kernels.inertia`), else Newton's ``JointSpaceResponse`` and a gather.
- :class:`CoupledDrive`: PhysX's articulation drive, one extra launch after every substep that solves all rows jointly
  with the articulation's joint-space inertia (:mod:`wpctrl.kernels.drive`); it writes ``joint_f`` and the effort
  readout itself, and ``r`` where acceleration drives need it.
"""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from ...config import ConfigError
from ...config import rows as cfg
from ...kernels import drive as KD
from ...kernels import inertia as KI
from ...kernels import pd as K
from ...kernels.dims import PER_ENV_BLOCK_DIM
from ..launch import _Launch
from . import Part


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
        self.update_per_substep = plan.options.inertia_update == "substep"
        self.write_gains = plan.has_accel and not plan.explicit

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
        layout, why = KI.chain_layout(model, binding.joint_index, binding.dof_index)
        if layout is not None:
            self._fused = KI.FusedChain(layout, model)
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
                K._response_kernel,
                dim=engine.num_envs * engine.num_rows,
                inputs=[self.row_art_off, self.row_art_dof, self.env_art_base, self._jsr.inverse_blocks, self.response],
                device=engine.device,
            )
        if self.write_gains:
            c = engine.core
            m = engine.model
            drive = engine.part("drive")
            wp.launch(
                K._accel_gains_kernel,
                dim=engine.num_envs * engine.num_rows,
                inputs=[
                    c.row_accel,
                    c.row_qd_off,
                    c.env_qd_base,
                    drive.kp,
                    drive.kd,
                    self.response,
                    m.joint_target_ke,
                    m.joint_target_kd,
                ],
                device=engine.device,
            )
            engine.notify_solver()

    def before_set_action(self, engine, action, state) -> None:
        if not self.update_per_substep:
            self.update(engine, state)

    def before_substep(self, engine, state, control) -> None:
        if self.update_per_substep:
            self.update(engine, state)


class CoupledDrive(JointSpaceResponse):
    name = "coupled"
    OPTIONAL_ARGS = ("response", "coupled_iterations")

    @staticmethod
    def wanted(plan) -> bool:
        return plan.coupled

    def __init__(self, plan, alloc):
        super().__init__(plan, alloc)
        self.coupled_iterations = wp.zeros(plan.num_envs, dtype=wp.int32, device=alloc.device)
        self._launch: _Launch | None = None
        self.h_cache = None  # inertia_update="control": H of a control step's first substep, reused by the other K - 1
        self.max_iterations = None  # active-set iterations before the fallback sweeps (None: rows + 2); tests lower it

    def build(self, engine, model, solver) -> None:
        super().build(engine, model, solver)
        if self.plan.options.inertia_update == "control":
            n = self._fused.layout.num_dofs
            self.h_cache = wp.zeros(self.plan.num_envs, dtype=KD.coupled_matrix_type(n), device=engine.device)

    def kernel_args(self) -> dict:
        # The substep kernel leaves the effort readout to the coupled drive (it writes the clamped torque itself).
        return {"response": self.response, "computed_effort_out": None, "applied_effort_out": None,
                "saturation_count_out": None}  # fmt: skip

    def _setup_fallback(self, model, why: str) -> None:
        raise ConfigError(
            f"explicit_pd: 'coupled' needs a fixed-base articulation of revolute / prismatic joints ({why}); use "
            f"explicit_pd='stable' (its per-joint response includes floating roots and multi-axis joints) or "
            f"actuation='implicit'"
        )

    def update(self, engine, state) -> None:
        """The coupled kernel computes H (and r, for acceleration drives) itself, at every substep or
        (``inertia_update="control"``) at each control step's first; at build, r of the initial pose."""
        self._fused.launch_response(state.joint_q, self.response)

    def before_set_action(self, engine, action, state) -> None:
        pass

    def before_substep(self, engine, state, control) -> None:
        pass

    def _row_constants(self, fc) -> tuple:
        """Per row, what the coupled kernel compiles in: (articulation DOF, acceleration drive, position row, velocity
        target, coordinate offset, DOF offset from the env's first)."""
        rows, b = self.plan.rows, self.plan.binding
        pos = rows.kind == cfg.ROW_POS
        vt = ~pos | ((rows.flags & cfg.FLAG_VEL_TARGET) != 0)
        cols = (fc.layout.row_dof, rows.accel, pos, vt, b.q_off, b.qd_off)
        return tuple(tuple(int(c[r]) for c in cols) for r in range(rows.count))

    def after_substep(self, engine, state, control) -> None:
        """The coupled drive's launch: reads the targets the substep kernel just wrote, writes joint_f."""
        if self._launch is None:
            fc = self._fused
            params = fc.chain_args()
            effort = engine.part("effort")
            extra = {
                "pgs_sweeps": KD.PGS_SWEEPS,
                "max_iterations": self.max_iterations or self.plan.num_rows + 2,
                "joint_q_in": state.joint_q,
                "joint_qd_in": state.joint_qd,
                "joint_target_q_in": control.joint_target_q,
                "joint_target_qd_in": control.joint_target_qd,
                "joint_f_out": control.joint_f,
                "response_out": self.response,
                "iterations_out": self.coupled_iterations,
                "h_cache": self.h_cache,
                "step_in": engine.core.step if self.h_cache is not None else None,
                "num_substeps": engine.num_substeps,
                "computed_effort_out": None if effort is None else effort.computed_effort,
                "applied_effort_out": None if effort is None else effort.applied_effort,
                "saturation_count_out": None if effort is None else effort.saturation_count,
            }
            kernel = KD.coupled_kernel(*fc.kernel_key(), self._row_constants(fc), fast_math=engine.device.is_cuda)
            names = [a.label for a in kernel.adj.args]
            for n in names:
                if n not in params:
                    params[n] = extra[n] if n in extra else engine.arrays.lookup(n)
            self._launch = _Launch(
                kernel, engine.num_envs, {n: params[n] for n in names}, engine.device, block_dim=PER_ENV_BLOCK_DIM
            )
        ln = self._launch
        ln.bind("joint_q_in", state.joint_q)
        ln.bind("joint_qd_in", state.joint_qd)
        ln.bind("joint_target_q_in", control.joint_target_q)
        ln.bind("joint_target_qd_in", control.joint_target_qd)
        ln.bind("joint_f_out", control.joint_f)
        ln.launch()


MODEL_FLAGS = newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES
