"""The device arrays of one control mode, allocated once from its :class:`~wpctrl.engine.plan.Plan`.

:class:`Alloc` is how every part allocates: per-(env, row) state is stored column-major (a transposed
``(cols, E_pad)`` buffer), so the one-thread-per-env step kernels access it coalesced while every kernel and view still
indexes it ``[env, row]``. :class:`CoreArrays` holds what every control mode has: the row and env tables, the row
float table, ManiSkill's per-env controller state (``start_qpos``, ``target_qpos``, ``target_qvel``, processed action,
substep counter) and the action buffer.

Kernel arguments are looked up by name (:meth:`Arrays.lookup`): a kernel parameter ``target_qpos_in`` or
``target_qpos_out`` takes the array named ``target_qpos``, from the core or from an active part; a parameter no
active part provides is ``None`` (the kernel variant compiled without that part never reads it).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .plan import Plan


class Alloc:
    """Allocation on one device for ``num_envs`` envs."""

    def __init__(self, device, num_envs: int):
        self.device = device
        self.num_envs = E = num_envs
        # The column stride: a multiple of 32 elements that is not a power of two (with a power-of-two stride, e.g.
        # 2^20 envs, a thread's rows fall on the same DRAM channel / L2 set and camp there).
        pad = -(-E // 32) * 32 + 32
        if pad & (pad - 1) == 0:
            pad += 32
        self.env_pad = pad

    def up(self, a, dtype) -> wp.array:
        """A host array uploaded as it is."""
        return wp.array(np.ascontiguousarray(a), dtype=dtype, device=self.device)

    def per_env(self, cols: int, dtype=wp.float32, fill=None) -> wp.array:
        """A ``(num_envs, cols)`` array stored column-major (a transposed ``(cols, E_pad)`` buffer), optionally
        filled with ``fill`` broadcast to ``(num_envs, cols)``."""
        E = self.num_envs
        if cols == 0:
            return wp.zeros((E, 0), dtype=dtype, device=self.device)
        buf = wp.zeros((cols, self.env_pad), dtype=dtype, device=self.device)
        view = buf[:, :E].transpose()
        if fill is not None:
            np_dtype = np.int32 if dtype == wp.int32 else np.float32
            view.assign(np.ascontiguousarray(np.broadcast_to(np.asarray(fill, dtype=np_dtype), (E, cols))))
        return view

    def ring(self, depth: int, cols: int) -> wp.array:
        """A ``(depth, num_envs, cols)`` history, each slot column-major."""
        E = self.num_envs
        buf = wp.zeros((depth, cols, self.env_pad), dtype=wp.float32, device=self.device)
        return buf[:, :, :E].transpose((0, 2, 1))


class CoreArrays:
    """What every control mode holds on the device (see the module docstring)."""

    def __init__(self, plan: Plan, alloc: Alloc):
        rows, b = plan.rows, plan.binding
        E, R, dev = plan.num_envs, plan.num_rows, alloc.device
        up = alloc.up
        self.row_kind = up(rows.kind, wp.int32)
        self.row_flags = up(rows.flags, wp.int32)
        self.row_accel = up(rows.accel.astype(np.int32), wp.int32)
        self.row_q_off = up(b.q_off, wp.int32)
        self.row_qd_off = up(b.qd_off, wp.int32)
        self.env_q_base = up(b.q_base, wp.int32)
        self.env_qd_base = up(b.qd_base, wp.int32)
        self.q_idx = up(plan.q_idx, wp.int32)
        self.qd_idx = up(plan.qd_idx, wp.int32)
        self.q_stride = plan.q_stride
        self.qd_stride = plan.qd_stride
        self.row_f = up(plan.row_f, wp.float32)
        # Views of its joint-limit columns, for the EE kernels (Warp cannot slice an empty dimension).
        from ..kernels.pd_step import ROW_F_QHI, ROW_F_QLO

        self.row_qlo = self.row_f[:, ROW_F_QLO] if R else wp.zeros(0, dtype=wp.float32, device=dev)
        self.row_qhi = self.row_f[:, ROW_F_QHI] if R else wp.zeros(0, dtype=wp.float32, device=dev)
        # ManiSkill's per-env controller state: _start_qpos, _target_qpos, _target_qvel, the processed action.
        self.start_qpos = alloc.per_env(R)
        self.target_qpos = alloc.per_env(R)
        self.target_qvel = alloc.per_env(R)
        self.processed_action = alloc.per_env(plan.action_dim)
        self.step = wp.zeros(E, dtype=wp.int32, device=dev)  # ManiSkill's _step (minus the host's elided substeps)
        self.step_view = wp.zeros(E, dtype=wp.int32, device=dev)
        self.bad_action_count = wp.zeros(E, dtype=wp.int32, device=dev)
        self.action_buffer = wp.zeros((E, plan.action_dim), dtype=wp.float32, device=dev)
        # The device RNG (delay draws, drive randomisation): a seed and a draw counter bumped after each draw.
        delay = plan.options.delay
        self.seed = 0 if delay is None or delay.seed is None else int(delay.seed)
        self.rng_counter = wp.zeros(1, dtype=wp.int32, device=dev)
        # r = (H^-1)_ii when a part needs it (it replaces this); a (1, rows) placeholder the kernels never read.
        self.response = wp.ones((1, max(R, 1)), dtype=wp.float32, device=dev)
        self.num_substeps = plan.options.num_substeps
        self.dt = float(plan.options.sim_dt)
        self.max_delay = self.delay_min = self.delay_max = 0  # [substeps] (the delay part overrides them)


class Arrays:
    """The core arrays and the active parts' arrays, looked up by kernel parameter name."""

    def __init__(self, core: CoreArrays, parts: list, optional: set[str]):
        self.core = core
        self.parts = parts
        self.optional = optional

    def lookup(self, param: str):
        """The value of kernel parameter ``param`` (``x_in`` / ``x_out`` / ``x``: the array named ``x``)."""
        base = param[:-3] if param.endswith("_in") else param[:-4] if param.endswith("_out") else param
        args = [part.kernel_args() for part in self.parts]
        for a in args:  # an exact parameter name first (a part may set another's output aside: coupled effort)
            if param in a:
                return a[param]
        for a in args:
            if base in a:
                return a[base]
        if hasattr(self.core, base):
            return getattr(self.core, base)
        if base in self.optional or param in self.optional:
            return None
        raise KeyError(f"no array for kernel parameter {param!r}")
