"""The device engine of one control mode: its arrays, its recorded kernel launches, the model's drive properties.

One control mode (all rows of a single config or a ManiSkill ``{uid: config}`` dict) is one :class:`_Engine` with
one kernel launch per stage: ``set_action`` (1 launch), ``substep`` (1 launch per solver substep) and ``reset``
(1 launch, plus a one-thread counter bump when delays are drawn). Launches are recorded once and re-bound only where
an argument changed (:class:`_Launch`).

Actuation state (issue 10), owned here: the per-env drive properties ``kp``/``kd``/``force_limit``/``friction``
(num_envs, rows), initialised from the config and used by the explicit law, the acceleration gains and the model
mirror; the device RNG counter; the optional delay ring buffer and effort readout (``None`` when off: the substep
kernel variant compiled without them runs, moving no extra bytes).

A mode without per-substep work (:attr:`_Engine.per_substep` False: implicit actuation, no interpolating row, no
command delay, no effort readout, no per-substep inertia update) has drive targets that do not change between
substeps: ``set_action`` writes them into the Control it knows (the last one given to ``substep`` or ``reset``) and
``substep`` launches nothing, unless it is handed a Control other than that one (a small write there, which it then
knows). The per-env substep counter is then ``step + host_substeps``, the host counting the substeps since the last
``set_action`` (see ``kernels/pd.py``). End-effector rows are ordinary position rows here: their EE launch writes
their ``target_qpos`` before the joint launch, which writes them into the Control with the others.
"""

from __future__ import annotations

import newton
import numpy as np
import warp as wp

from ..binding import JointBinding
from ..config import rows as cfg
from ..kernels import actuation as KA
from ..kernels import drive as KD
from ..kernels import inertia as KI
from ..kernels import pd as K
from ..kernels import pd_step as KS
from ..kernels.dims import PER_ENV_BLOCK_DIM, step_block_dim
from .drive_props import _DrivePropertiesMixin
from .launch import _index_table, _Launch, _Targets


class _Engine(_DrivePropertiesMixin):
    """Device arrays and launches of one control mode (all rows, all envs)."""

    def __init__(
        self,
        rows: cfg.Rows,
        binding: JointBinding,
        model: newton.Model,
        num_substeps: int,
        actuation: str,
        explicit_pd: str = "naive",
        inertia_update: str = "control",
        sim_dt: float = 0.01,
        delay: tuple[int, int] | None = None,
        track_effort: bool = False,
        clip_targets: bool = False,
        seed: int = 0,
    ):
        self.rows = rows
        self.binding = binding
        self.model = model
        self.device = model.device
        self.num_envs = binding.num_envs
        self.num_rows = rows.count
        self.action_dim = rows.action_dim
        self.num_substeps = num_substeps
        self.explicit = actuation == "explicit"
        self.explicit_mode = 0 if not self.explicit else {"stable": 2, "coupled": 3}.get(explicit_pd, 1)
        self.coupled = self.explicit_mode == 3  # the coupled drive: its own launch after the substep kernel
        self.sim_dt = float(sim_dt)
        self.inertia_update = inertia_update
        self.solver = None  # notified after per-env gain edits (implicit acceleration drive)
        dev = self.device
        E, R = self.num_envs, self.num_rows

        def up(a, dtype):
            return wp.array(np.ascontiguousarray(a), dtype=dtype, device=dev)

        E_pad = -(-E // 32) * 32 + 32
        if E_pad & (E_pad - 1) == 0:
            E_pad += 32

        def per_env(cols: int, dtype=wp.float32, fill=None) -> wp.array:
            """A ``(num_envs, cols)`` array stored column-major (a transposed ``(cols, E_pad)`` buffer): the
            one-thread-per-env step kernels then access it coalesced (a warp reads one column of 32 envs, 128 B),
            while every kernel and view still indexes it ``[env, col]``. The column stride ``E_pad`` is a multiple of
            32 elements that is not a power of two: with a power-of-two stride (e.g. 2^20 envs) a thread's rows fall
            on the same DRAM channel / L2 set and camp there."""
            if cols == 0:
                return wp.zeros((E, 0), dtype=dtype, device=dev)
            buf = wp.zeros((cols, E_pad), dtype=dtype, device=dev)
            view = buf[:, :E].transpose()
            if fill is not None:
                np_dtype = np.int32 if dtype == wp.int32 else np.float32
                view.assign(np.ascontiguousarray(np.broadcast_to(np.asarray(fill, dtype=np_dtype), (E, cols))))
            return view

        self.row_kind = up(rows.kind, wp.int32)
        self.row_flags = up(rows.flags, wp.int32)
        self.row_q_off = up(binding.q_off, wp.int32)
        self.row_qd_off = up(binding.qd_off, wp.int32)
        self.env_q_base = up(binding.q_base, wp.int32)
        self.env_qd_base = up(binding.qd_base, wp.int32)
        # Coordinate / DOF index of every (env, row) (kernels/pd.py, _at): env 0's row plus env * stride for a
        # replicated layout, else a flat (num_envs, rows) table; either way no chain of table loads.
        q_idx, self.q_stride = _index_table(binding.coord_index.reshape(E, R))
        qd_idx, self.qd_stride = _index_table(binding.dof_index.reshape(E, R))
        strided = q_idx.shape[0] == 1 and qd_idx.shape[0] == 1  # (one env: stride 0)
        if not strided:  # both flat, so that a step kernel indexes either table by env
            q_idx, self.q_stride = binding.coord_index.reshape(E, R).astype(np.int32), 0
            qd_idx, self.qd_stride = binding.dof_index.reshape(E, R).astype(np.int32), 0
        self.q_idx = up(q_idx, wp.int32)
        self.qd_idx = up(qd_idx, wp.int32)
        # Per-env drive properties (num_envs, rows), from the config; the nominal (config) values for "scale" draws.
        self.kp = per_env(R, fill=rows.kp)
        self.kd = per_env(R, fill=rows.kd)
        self.force_limit = per_env(R, fill=rows.force_limit)
        self.friction = per_env(R, fill=rows.friction)
        self.nominal = up(np.stack([rows.kp, rows.kd, rows.force_limit, rows.friction]).reshape(4, R), wp.float32)
        self.rng_counter = wp.zeros(1, dtype=wp.int32, device=dev)
        self.seed = int(seed)
        # Target clamping: the joints' limits [rad or m] (env 0's, as the binding reads them; +-inf: unlimited).
        self.clip_targets = bool(clip_targets)
        # The per-row floats of the step kernels: action bounds, mimic coupling, joint limits (kernels/pd_step.py).
        self.row_f = up(KS.row_float_table(rows, binding.qlimits.astype(np.float32).reshape(R, 2)), wp.float32)
        # Views of its joint-limit columns, for the EE kernels (Warp cannot slice an empty dimension).
        self.row_qlo = self.row_f[:, KS.ROW_F_QLO] if R else wp.zeros(0, dtype=wp.float32, device=dev)
        self.row_qhi = self.row_f[:, KS.ROW_F_QHI] if R else wp.zeros(0, dtype=wp.float32, device=dev)
        # Command delay: per-env d in [delay_min, delay_max] substeps, a ring of the last max_delay + 1 commands.
        self.delay_range = delay
        self.delay = self.delay_head = self.delay_q = self.delay_qd = None
        if delay is not None:
            D = int(delay[1])
            self.delay = wp.full(E, int(delay[0]), dtype=wp.int32, device=dev)
            self.delay_head = per_env(R, wp.int32)
            self.delay_q = wp.zeros((D + 1, R, E_pad), dtype=wp.float32, device=dev)[:, :, :E].transpose((0, 2, 1))
            vel_rows = (rows.kind != cfg.ROW_POS) | ((rows.flags & cfg.FLAG_VEL_TARGET) != 0)
            if vel_rows.any():  # velocity targets are 0 on plain position rows: no history needed then
                self.delay_qd = wp.zeros((D + 1, R, E_pad), dtype=wp.float32, device=dev)[:, :, :E].transpose((0, 2, 1))
        # Effort readout [N·m or N].
        self.computed_effort = self.applied_effort = self.saturation_count = None
        if track_effort:
            self.computed_effort = per_env(R)
            self.applied_effort = per_env(R)
            self.saturation_count = per_env(R, wp.int32)
        self.row_accel = up(rows.accel.astype(np.int32), wp.int32)
        self.has_accel = bool(rows.accel.any())
        # The joint-space response r = (H^-1)_ii per env and row: acceleration drives and stable explicit PD need it.
        self.needs_response = self.has_accel or self.explicit_mode >= 2
        self.response = per_env(max(R, 1), fill=1.0) if self.needs_response else wp.ones((1, max(R, 1)), device=dev)
        self._jsr = None
        self._fused = None  # fused H / Cholesky kernel (wpctrl.kernels.inertia) where the articulation allows it
        self.coupled_iterations = wp.zeros(E if self.coupled else 1, dtype=wp.int32, device=dev)
        self._launch_coupled: _Launch | None = None
        if self.needs_response:
            self._init_response(model, binding)

        # State per (env, row), column-major (per_env): ManiSkill's _start_qpos, _target_qpos, _target_qvel.
        self.start_qpos = per_env(R)
        self.target_qpos = per_env(R)
        self.target_qvel = per_env(R)
        self.processed_action = per_env(self.action_dim)
        self.step = wp.zeros(E, dtype=wp.int32, device=dev)
        self.dim = E * R  # one thread per (env, row), 1-D launches
        self.dim2 = (E, R)  # the same, 2-D: wp.tid() gives (env, row)
        self.per_substep = self._needs_per_substep_work()
        # The step kernels' compile-time layout (one thread per env, rows unrolled: kernels/pd_step.py).
        self.layout = KS.StepLayout(
            kind=tuple(int(x) for x in rows.kind),
            flags=tuple(int(x) for x in rows.flags),
            act_col=tuple(int(x) for x in rows.act_col),
            vel_col=tuple(int(x) for x in rows.vel_col),
            mimic_src=tuple(int(x) for x in rows.mimic_src),
            accel=tuple(int(x) for x in rows.accel),
            q_off=tuple(int(x) for x in q_idx[0]) if strided else None,
            qd_off=tuple(int(x) for x in qd_idx[0]) if strided else None,
            action_dim=int(self.action_dim),
            clip=self.clip_targets,
            explicit=0 if self.coupled else self.explicit_mode,
            delay=self.delay is not None,
            delay_vel=self.delay_qd is not None,
            effort=self.computed_effort is not None and not self.coupled,
            yaw_row=tuple(int(x) for x in rows.yaw_row) if (rows.base_axis >= 0).any() else (),
            base_axis=tuple(int(x) for x in rows.base_axis) if (rows.base_axis >= 0).any() else (),
            bx_col=tuple(int(x) for x in rows.bx_col) if (rows.base_axis >= 0).any() else (),
            by_col=tuple(int(x) for x in rows.by_col) if (rows.base_axis >= 0).any() else (),
        )
        self.block_dim = step_block_dim(dev, E)
        # Elided substeps: the host's substep count since the last set_action, and the Control whose drive targets
        # hold the current targets (its joint_target_q/qd arrays, kept alive so that their addresses stay unique).
        self.host_substeps = 0
        self._known_control: tuple[wp.array, wp.array] | None = None
        self.step_view = wp.zeros(E, dtype=wp.int32, device=dev)
        self._launch_targets: _Launch | None = None
        self.bad_action_count = wp.zeros(E, dtype=wp.int32, device=dev)
        self.action_buffer = wp.zeros((E, self.action_dim), dtype=wp.float32, device=dev)
        self.wrappers: dict = {}  # zero-copy wp.array views of torch actions, by (address, strides)
        self._launch_set_action: _Launch | None = None
        self._launch_substep: _Launch | None = None
        self._reset_count = 0
        self.ee_parts: list = []  # wpctrl.ee.EEPart: end-effector controllers' launches (set_action, reset)

    def _needs_per_substep_work(self) -> bool:
        """Whether something must run before every solver substep: explicit torques (they depend on the measured
        state), interpolation (the target moves), a command delay (the ring buffer shifts), the effort readout (it
        reads the measured state), or a per-substep inertia update. Otherwise the drive targets are constant over the
        control step and the substep launch is elided."""
        interpolates = bool((self.rows.flags & cfg.FLAG_INTERPOLATE).any())
        inertia_per_substep = self.needs_response and self.inertia_update == "substep"
        delayed = self.delay is not None
        tracks_effort = self.computed_effort is not None
        return self.explicit or interpolates or delayed or tracks_effort or inertia_per_substep

    def _host_substeps(self) -> int:
        """The host's substep count to bake into a launch (0 when the substep kernel counts on the device)."""
        if self.per_substep:
            return 0
        return self.host_substeps

    def _init_response(self, model: newton.Model, binding: JointBinding) -> None:
        from newton.actuators import JointSpaceResponse

        art = model.joint_articulation.numpy()[binding.joint_index]  # (E, R)
        if (art < 0).any():
            raise cfg.ConfigError(
                "drive_mode: 'acceleration' and stable explicit PD need the joints to be in an articulation "
                "(ModelBuilder.add_articulation)"
            )
        art_dof0 = model.joint_qd_start.numpy()[model.articulation_start.numpy()[art]]
        local = binding.dof_index - art_dof0  # (E, R) DOF index inside its articulation
        base = art[:, 0]
        if ((art - base[:, None]) != (art[:1] - base[:1])).any() or (local != local[:1]).any():
            raise cfg.ConfigError("joint_names: the articulations are laid out differently across worlds")
        dev = self.device
        self.row_art_off = wp.array((art[0] - base[0]).astype(np.int32), dtype=wp.int32, device=dev)
        self.row_art_dof = wp.array(local[0].astype(np.int32), dtype=wp.int32, device=dev)
        self.env_art_base = wp.array(base.astype(np.int32), dtype=wp.int32, device=dev)
        layout, why = KI.chain_layout(model, binding.joint_index, binding.dof_index)
        if layout is not None:
            self._fused = KI.FusedChain(layout, model)
        elif self.coupled:
            raise cfg.ConfigError(
                f"explicit_pd: 'coupled' needs a fixed-base articulation of revolute / prismatic joints ({why}); use "
                f"explicit_pd='stable' (its per-joint response includes floating roots and multi-axis joints) or "
                f"actuation='implicit'"
            )
        else:
            self._jsr = JointSpaceResponse(model)

    def update_response(self, state) -> None:
        """Recompute r = (H^-1)_ii for the current configuration; with an implicit acceleration drive, write the
        per-env solver gains Kp / r, Kd / r into the model (and notify the solver, if one was given)."""
        if not self.needs_response:
            return
        if self._fused is not None:  # one launch: H from joint_q, its Cholesky factor, diag(H^-1) of the rows
            self._fused.launch_response(state.joint_q, self.response)
        else:
            self._jsr.refresh(state)
            self._gather_response()
        self._write_accel_gains()

    def _gather_response(self) -> None:
        wp.launch(
            K._response_kernel,
            dim=self.dim,
            inputs=[self.row_art_off, self.row_art_dof, self.env_art_base, self._jsr.inverse_blocks, self.response],
            device=self.device,
        )

    def _write_accel_gains(self) -> None:
        if self.has_accel and not self.explicit:
            m = self.model
            wp.launch(
                K._accel_gains_kernel,
                dim=self.dim,
                inputs=[
                    self.row_accel,
                    self.row_qd_off,
                    self.env_qd_base,
                    self.kp,
                    self.kd,
                    self.response,
                    m.joint_target_ke,
                    m.joint_target_kd,
                ],
                device=self.device,
            )
            if self.solver is not None:
                self.solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES)

    # -- stages ---------------------------------------------------------------------------------------------------

    def set_action(self, action: wp.array, state) -> None:
        if self.inertia_update == "control" and not self.coupled:
            self.update_response(state)
        if self._launch_set_action is None:
            self._launch_set_action = _Launch(
                KS.set_action_kernel(self.layout),
                self.num_envs,
                {
                    "row_f": self.row_f,
                    "q_idx": self.q_idx,
                    "qd_idx": self.qd_idx,
                    "q_stride": self.q_stride,
                    "qd_stride": self.qd_stride,
                    "host_substeps": 0,
                    "action_in": action,
                    "joint_q_in": state.joint_q,
                    "processed_action_out": self.processed_action,
                    "start_qpos_out": self.start_qpos,
                    "target_qpos_out": self.target_qpos,
                    "target_qvel_out": self.target_qvel,
                    "step_out": self.step,
                    "bad_action_count_out": self.bad_action_count,
                    "joint_target_q_out": None,
                    "joint_target_qd_out": None,
                },
                self.device,
                block_dim=self.block_dim,
            )
        for part in self.ee_parts:  # EE rows' targets first; the joint launch leaves them alone (act_col -1)
            part.set_action(action, state)
        ln = self._launch_set_action
        ln.bind("action_in", action)
        ln.bind("joint_q_in", state.joint_q)
        if not self.per_substep:
            # An env whose action is rejected keeps counting: it carries the substeps since the previous set_action.
            # A captured graph does not know how many substeps preceded it at replay: it assumes a full control step.
            carry = self.num_substeps if self.device.is_capturing else self.host_substeps
            ln.bind("host_substeps", carry)
            known = self._known_control
            ln.bind("joint_target_q_out", None if known is None else known[0])
            ln.bind("joint_target_qd_out", None if known is None else known[1])
            self.host_substeps = 0
        ln.launch()

    def substep(self, state: newton.State, control: newton.Control) -> None:
        if not self.per_substep:
            # The drive targets are constant over the control step: written by set_action into the known Control.
            self.host_substeps += 1
            if not self._is_known_control(control):
                self.write_targets(control)
            return
        if self.inertia_update == "substep" and not self.coupled:
            self.update_response(state)
        joint_f = control.joint_f if self.explicit else None
        if self._launch_substep is None:
            self._launch_substep = _Launch(
                KS.substep_kernel(self.layout),
                self.num_envs,
                {
                    "q_idx": self.q_idx,
                    "qd_idx": self.qd_idx,
                    "q_stride": self.q_stride,
                    "qd_stride": self.qd_stride,
                    "kp": self.kp,
                    "kd": self.kd,
                    "force_limit": self.force_limit,
                    "num_substeps": self.num_substeps,
                    "dt": self.sim_dt,
                    "max_delay": 0 if self.delay_range is None else int(self.delay_range[1]),
                    "joint_q_in": state.joint_q,
                    "joint_qd_in": state.joint_qd,
                    "response_in": self.response,
                    "start_qpos_in": self.start_qpos,
                    "target_qpos_in": self.target_qpos,
                    "target_qvel_in": self.target_qvel,
                    "delay_in": self.delay,
                    "step_out": self.step,
                    "delay_head_out": self.delay_head,
                    "delay_q_out": self.delay_q,
                    "delay_qd_out": self.delay_qd,
                    "joint_target_q_out": control.joint_target_q,
                    "joint_target_qd_out": control.joint_target_qd,
                    "joint_f_out": joint_f,
                    # the coupled drive writes the effort readout itself
                    "computed_effort_out": None if self.coupled else self.computed_effort,
                    "applied_effort_out": None if self.coupled else self.applied_effort,
                    "saturation_count_out": None if self.coupled else self.saturation_count,
                },
                self.device,
                block_dim=self.block_dim,
            )
        ln = self._launch_substep
        ln.bind("joint_q_in", state.joint_q)
        ln.bind("joint_qd_in", state.joint_qd)
        ln.bind("joint_target_q_out", control.joint_target_q)
        ln.bind("joint_target_qd_out", control.joint_target_qd)
        ln.bind("joint_f_out", joint_f)
        ln.launch()
        if self.coupled:
            self._coupled(state, control)

    def _coupled(self, state: newton.State, control: newton.Control) -> None:
        """The coupled drive's launch: reads the targets the substep kernel just wrote, writes joint_f."""
        if self._launch_coupled is None:
            fc = self._fused
            params = fc.chain_args()
            params.update(
                {
                    "row_kind": self.row_kind,
                    "row_flags": self.row_flags,
                    "row_q_off": self.row_q_off,
                    "row_qd_off": self.row_qd_off,
                    "row_accel": self.row_accel,
                    "env_q_base": self.env_q_base,
                    "env_qd_base": self.env_qd_base,
                    "kp": self.kp,
                    "kd": self.kd,
                    "force_limit": self.force_limit,
                    "dt": self.sim_dt,
                    "pgs_sweeps": KD.PGS_SWEEPS,
                    "joint_q_in": state.joint_q,
                    "joint_qd_in": state.joint_qd,
                    "joint_target_q_in": control.joint_target_q,
                    "joint_target_qd_in": control.joint_target_qd,
                    "joint_f_out": control.joint_f,
                    "response_out": self.response,
                    "iterations_out": self.coupled_iterations,
                    "computed_effort_out": self.computed_effort,
                    "applied_effort_out": self.applied_effort,
                    "saturation_count_out": self.saturation_count,
                }
            )
            self._launch_coupled = _Launch(
                KD.coupled_kernel(*fc.kernel_key()), self.num_envs, params, self.device, block_dim=PER_ENV_BLOCK_DIM
            )
        ln = self._launch_coupled
        ln.bind("joint_q_in", state.joint_q)
        ln.bind("joint_qd_in", state.joint_qd)
        ln.bind("joint_target_q_in", control.joint_target_q)
        ln.bind("joint_target_qd_in", control.joint_target_qd)
        ln.bind("joint_f_out", control.joint_f)
        ln.launch()

    # -- the Control that holds the drive targets (no per-substep work) ----------------------------------------------

    def _is_known_control(self, control) -> bool:
        known = self._known_control
        return (
            known is not None
            and known[0].ptr == control.joint_target_q.ptr
            and known[1].ptr == control.joint_target_qd.ptr
        )

    def write_targets(self, control: newton.Control) -> None:
        """Write every env's current drive targets into ``control`` (one launch) and make it the known Control."""
        if self._launch_targets is None:
            self._launch_targets = _Launch(
                K._targets_kernel,
                self.dim2,
                {
                    "row_kind": self.row_kind,
                    "row_flags": self.row_flags,
                    "q_idx": self.q_idx,
                    "qd_idx": self.qd_idx,
                    "q_stride": self.q_stride,
                    "qd_stride": self.qd_stride,
                    "target_qpos_in": self.target_qpos,
                    "target_qvel_in": self.target_qvel,
                    "joint_target_q_out": control.joint_target_q,
                    "joint_target_qd_out": control.joint_target_qd,
                },
                self.device,
            )
        ln = self._launch_targets
        ln.bind("joint_target_q_out", control.joint_target_q)
        ln.bind("joint_target_qd_out", control.joint_target_qd)
        ln.launch()
        self._known_control = (control.joint_target_q, control.joint_target_qd)

    def forget_control(self) -> None:
        """The known Control no longer holds the current targets (they were edited on the host, or the user overwrote
        the Control): the next substep writes them again."""
        self._known_control = None

    def step_counter(self) -> wp.array:
        """(num_envs,) ManiSkill's ``_step``: the live device counter, or (elided substeps) a view refreshed now."""
        if self.per_substep:
            return self.step
        wp.launch(
            K._step_view_kernel,
            dim=self.num_envs,
            inputs=[self.host_substeps, self.step, self.step_view],
            device=self.device,
        )
        return self.step_view

    def reset(self, state, env_ids, env_mask, control, first: bool) -> None:
        write_all = False
        if not self.per_substep:
            if control is None:
                # The reset envs' targets go into the known Control (if any), which then still holds every env's.
                control = None if self._known_control is None else _Targets(*self._known_control)
            elif not self._is_known_control(control):
                write_all = True  # a new Control: it gets every env's targets, not only the reset envs'
        n = 0 if env_ids is None else env_ids.shape[0]
        if (env_ids is not None and n == 0) or self.num_rows == 0:
            if write_all:
                self.write_targets(control)
            return
        wp.launch(
            K._reset_kernel,
            dim=(self.num_envs if env_ids is None else n, self.num_rows),
            inputs=[
                self.row_kind,
                self.row_flags,
                self.q_idx,
                self.qd_idx,
                self.q_stride,
                self.qd_stride,
                int(first),
                self._host_substeps(),
                0 if self.delay_range is None else int(self.delay_range[0]),
                0 if self.delay_range is None else int(self.delay_range[1]),
                self.seed,
                env_ids,
                env_mask,
                state.joint_q,
                state.joint_qd,
                self.rng_counter,
                self.start_qpos,
                self.target_qpos,
                self.target_qvel,
                self.step,
                None if control is None else control.joint_target_q,
                None if control is None else control.joint_target_qd,
                None if (control is None or not self.explicit) else control.joint_f,
                self.delay,
                self.delay_head,
                self.delay_q,
                self.delay_qd,
                self.computed_effort,
                self.applied_effort,
                self.saturation_count,
            ],
            device=self.device,
        )
        if self.delay_range is not None and self.delay_range[1] > self.delay_range[0]:
            wp.launch(KA._bump_counter_kernel, dim=1, inputs=[self.rng_counter], device=self.device)
        for part in self.ee_parts:
            part.reset(state, env_ids, env_mask)
        if write_all:
            self.write_targets(control)
