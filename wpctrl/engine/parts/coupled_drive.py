"""The coupled drive (``explicit_pd="coupled"``) as an engine part: PhysX's articulation drive, one extra launch after
every substep that solves all rows jointly with the articulation's joint-space inertia
(:mod:`wpctrl.kernels.coupled_drive`); it writes ``joint_f`` and the effort readout itself, and r = (H^-1)_ii where
acceleration drives need it (the response part's arrays: :mod:`wpctrl.engine.parts.response`).
"""

from __future__ import annotations

import warp as wp

from ...config import ConfigError
from ...config.rows import FLAG_VEL_TARGET, ROW_POS
from ...kernels import coupled_drive
from ...kernels.dims import PER_ENV_BLOCK_DIM
from ..launch import _Launch
from .response import JointSpaceResponse


class CoupledDrive(JointSpaceResponse):
    name = "coupled_drive"
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
        if self.plan.inertia_update == "control":
            n = self._fused.layout.num_dofs
            self.h_cache = wp.zeros(
                self.plan.num_envs, dtype=coupled_drive.coupled_matrix_type(n), device=engine.device
            )

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
        pos = rows.kind == ROW_POS
        vt = ~pos | ((rows.flags & FLAG_VEL_TARGET) != 0)
        cols = (fc.layout.row_dof, rows.accel, pos, vt, b.q_off, b.qd_off)
        return tuple(tuple(int(c[r]) for c in cols) for r in range(rows.count))

    def after_substep(self, engine, state, control) -> None:
        """The coupled drive's launch: reads the targets the substep kernel just wrote, writes joint_f."""
        if self._launch is None:
            fc = self._fused
            params = fc.chain_args()
            effort = engine.part("effort_readout")
            extra = {
                "pgs_sweeps": coupled_drive.PGS_SWEEPS,
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
            kernel = coupled_drive.coupled_kernel(
                *fc.kernel_key(), self._row_constants(fc), fast_math=engine.device.is_cuda
            )
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
