"""Controller objects: own the device arrays of a control mode and launch its kernels.

One control mode (a single config or a ManiSkill ``{uid: config}`` dict) is one set of *rows* (controlled joints)
handled by one kernel launch per stage: ``set_action`` (1 launch), ``before_simulation_step`` (1 launch per
substep) and ``reset`` (1 launch). Child controllers of a dict are views into the parent's arrays.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import newton
import numpy as np
import warp as wp

from . import config as cfg
from .binding import JointBinding, bind_joints
from .kernels import pd as K

_ACTUATIONS = ("implicit", "explicit")
_NAN_POLICIES = ("hold", "raise")
_EXPLICIT_PD = ("naive", "stable")
_INERTIA_UPDATES = ("control", "substep")


def _torch():
    try:
        import torch
    except ImportError:  # torch is optional
        return None
    return torch


def _is_torch(x) -> bool:
    torch = _torch()
    return torch is not None and isinstance(x, torch.Tensor)


class _Launch:
    """A recorded ``wp.launch`` whose parameters are re-bound (by name) only when they change."""

    def __init__(self, kernel, dim, params: dict, device):
        names = [a.label for a in kernel.adj.args]
        assert list(params) == names, f"{kernel.key}: parameters {list(params)} != {names}"
        self._cmd = wp.launch(kernel, dim=dim, inputs=list(params.values()), device=device, record_cmd=True)
        self._index = {n: i for i, n in enumerate(names)}
        self._keys = [_key(v) for v in params.values()]

    def bind(self, name: str, value) -> None:
        i = self._index[name]
        k = _key(value)
        if self._keys[i] != k:
            self._cmd.set_param_at_index(i, value)
            self._keys[i] = k

    def launch(self) -> None:
        self._cmd.launch()


def _key(v):
    if isinstance(v, wp.array):
        return (v.ptr, v.shape, v.strides)
    return v


class _Engine:
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
        self.explicit_mode = 0 if not self.explicit else (2 if explicit_pd == "stable" else 1)
        self.sim_dt = float(sim_dt)
        self.inertia_update = inertia_update
        self.solver = None  # notified after per-env gain edits (implicit acceleration drive)
        dev = self.device
        E, R = self.num_envs, self.num_rows

        def up(a, dtype):
            return wp.array(np.ascontiguousarray(a), dtype=dtype, device=dev)

        self.row_kind = up(rows.kind, wp.int32)
        self.row_flags = up(rows.flags, wp.int32)
        self.row_act_col = up(rows.act_col, wp.int32)
        self.row_vel_col = up(rows.vel_col, wp.int32)
        self.row_lo = up(rows.lo, wp.float32)
        self.row_hi = up(rows.hi, wp.float32)
        self.row_vlo = up(rows.vlo, wp.float32)
        self.row_vhi = up(rows.vhi, wp.float32)
        self.row_mimic_src = up(rows.mimic_src, wp.int32)
        # Followers of each row (CSR): set_action's source-row thread writes them.
        order = np.argsort(rows.mimic_src, kind="stable")
        order = order[rows.mimic_src[order] >= 0]
        counts = np.bincount(rows.mimic_src[order], minlength=R) if R else np.zeros(0, np.int64)
        self.row_follow_start = up(np.concatenate([[0], np.cumsum(counts)]).astype(np.int32), wp.int32)
        self.row_follow = up(order.astype(np.int32) if order.size else np.zeros(1, np.int32), wp.int32)
        leads = np.nonzero(rows.mimic_src < 0)[0]
        self.lead_row = int(leads[0]) if leads.size else 0
        self.row_mimic_mul = up(rows.mimic_mul, wp.float32)
        self.row_mimic_off = up(rows.mimic_off, wp.float32)
        self.row_q_off = up(binding.q_off, wp.int32)
        self.row_qd_off = up(binding.qd_off, wp.int32)
        self.env_q_base = up(binding.q_base, wp.int32)
        self.env_qd_base = up(binding.qd_base, wp.int32)
        self.kp = up(rows.kp[None, :], wp.float32)
        self.kd = up(rows.kd[None, :], wp.float32)
        self.force_limit = up(rows.force_limit[None, :], wp.float32)
        self.row_accel = up(rows.accel.astype(np.int32), wp.int32)
        self.has_accel = bool(rows.accel.any())
        # The joint-space response r = (H^-1)_ii per env and row: acceleration drives and stable explicit PD need it.
        self.needs_response = self.has_accel or self.explicit_mode == 2
        self.response = wp.ones((E if self.needs_response else 1, max(R, 1)), dtype=wp.float32, device=dev)
        self._jsr = None
        if self.needs_response:
            self._init_response(model, binding)

        self.start_qpos = wp.zeros((E, R), dtype=wp.float32, device=dev)
        self.target_qpos = wp.zeros((E, R), dtype=wp.float32, device=dev)
        self.target_qvel = wp.zeros((E, R), dtype=wp.float32, device=dev)
        self.processed_action = wp.zeros((E, self.action_dim), dtype=wp.float32, device=dev)
        self.step = wp.zeros(E, dtype=wp.int32, device=dev)
        self.row_step = wp.zeros((E, R), dtype=wp.int32, device=dev)
        self.dim = E * R  # one thread per (env, row)
        self.bad_action_count = wp.zeros(E, dtype=wp.int32, device=dev)
        self.action_buffer = wp.zeros((E, self.action_dim), dtype=wp.float32, device=dev)
        self.wrappers: dict = {}  # zero-copy wp.array views of torch actions, by (address, strides)
        self._launch_set_action: _Launch | None = None
        self._launch_substep: _Launch | None = None
        self._reset_count = 0

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
        self._jsr = JointSpaceResponse(model)

    def update_response(self, state) -> None:
        """Recompute r = (H^-1)_ii for the current configuration; with an implicit acceleration drive, write the
        per-env solver gains Kp / r, Kd / r into the model (and notify the solver, if one was given)."""
        if not self.needs_response:
            return
        self._jsr.refresh(state)
        wp.launch(
            K._response_kernel,
            dim=self.dim,
            inputs=[self.row_art_off, self.row_art_dof, self.env_art_base, self._jsr.inverse_blocks, self.response],
            device=self.device,
        )
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
        if self.inertia_update == "control":
            self.update_response(state)
        if self._launch_set_action is None:
            self._launch_set_action = _Launch(
                K._set_action_kernel,
                self.dim,
                {
                    "row_kind": self.row_kind,
                    "row_flags": self.row_flags,
                    "row_act_col": self.row_act_col,
                    "row_vel_col": self.row_vel_col,
                    "row_lo": self.row_lo,
                    "row_hi": self.row_hi,
                    "row_vlo": self.row_vlo,
                    "row_vhi": self.row_vhi,
                    "row_mimic_src": self.row_mimic_src,
                    "row_follow_start": self.row_follow_start,
                    "row_follow": self.row_follow,
                    "row_mimic_mul": self.row_mimic_mul,
                    "row_mimic_off": self.row_mimic_off,
                    "row_q_off": self.row_q_off,
                    "lead_row": self.lead_row,
                    "env_q_base": self.env_q_base,
                    "action_in": action,
                    "joint_q_in": state.joint_q,
                    "processed_action_out": self.processed_action,
                    "start_qpos_out": self.start_qpos,
                    "target_qpos_out": self.target_qpos,
                    "target_qvel_out": self.target_qvel,
                    "step_out": self.step,
                    "row_step_out": self.row_step,
                    "bad_action_count_out": self.bad_action_count,
                },
                self.device,
            )
        ln = self._launch_set_action
        ln.bind("action_in", action)
        ln.bind("joint_q_in", state.joint_q)
        ln.launch()

    def substep(self, state: newton.State, control: newton.Control) -> None:
        if self.inertia_update == "substep":
            self.update_response(state)
        joint_f = control.joint_f if self.explicit else None
        if self._launch_substep is None:
            self._launch_substep = _Launch(
                K._substep_kernel,
                self.dim,
                {
                    "row_kind": self.row_kind,
                    "row_flags": self.row_flags,
                    "row_q_off": self.row_q_off,
                    "row_qd_off": self.row_qd_off,
                    "env_q_base": self.env_q_base,
                    "env_qd_base": self.env_qd_base,
                    "kp": self.kp,
                    "kd": self.kd,
                    "force_limit": self.force_limit,
                    "row_accel": self.row_accel,
                    "num_substeps": self.num_substeps,
                    "explicit_pd": self.explicit_mode,
                    "dt": self.sim_dt,
                    "joint_q_in": state.joint_q,
                    "joint_qd_in": state.joint_qd,
                    "response_in": self.response,
                    "start_qpos_in": self.start_qpos,
                    "target_qpos_in": self.target_qpos,
                    "target_qvel_in": self.target_qvel,
                    "step_out": self.step,
                    "row_step_out": self.row_step,
                    "joint_target_q_out": control.joint_target_q,
                    "joint_target_qd_out": control.joint_target_qd,
                    "joint_f_out": joint_f,
                },
                self.device,
            )
        ln = self._launch_substep
        ln.bind("joint_q_in", state.joint_q)
        ln.bind("joint_qd_in", state.joint_qd)
        ln.bind("joint_target_q_out", control.joint_target_q)
        ln.bind("joint_target_qd_out", control.joint_target_qd)
        ln.bind("joint_f_out", joint_f)
        ln.launch()

    def reset(self, state, env_ids, env_mask, control, first: bool) -> None:
        dim = (self.num_envs if env_ids is None else env_ids.shape[0]) * self.num_rows
        if dim == 0:
            return
        wp.launch(
            K._reset_kernel,
            dim=dim,
            inputs=[
                self.row_kind,
                self.row_flags,
                self.row_q_off,
                self.row_qd_off,
                self.env_q_base,
                self.env_qd_base,
                int(first),
                env_ids,
                env_mask,
                state.joint_q,
                state.joint_qd,
                self.start_qpos,
                self.target_qpos,
                self.target_qvel,
                self.step,
                self.row_step,
                None if control is None else control.joint_target_q,
                None if control is None else control.joint_target_qd,
                None if (control is None or not self.explicit) else control.joint_f,
            ],
            device=self.device,
        )

    # -- model drive properties -----------------------------------------------------------------------------------

    def apply_drive_properties(self) -> bool:
        """Write gains, target modes, effort limits and friction into the model (as ManiSkill's set_drive_property).

        Returns:
            Whether any ``joint_target_mode`` changed (solvers such as MuJoCo fix actuators at construction).
        """
        m = self.model
        rows = self.rows
        dof = self.binding.dof_index  # (E, R)
        coord = self.binding.coord_index
        ke = m.joint_target_ke.numpy()
        kd = m.joint_target_kd.numpy()
        mode = m.joint_target_mode.numpy()
        eff = m.joint_effort_limit.numpy()
        fric = m.joint_friction.numpy()
        old_mode = mode.copy()
        vel_target = (rows.kind != cfg.ROW_POS) | ((rows.flags & cfg.FLAG_VEL_TARGET) != 0)
        if self.explicit:
            row_mode = np.full(self.num_rows, int(newton.JointTargetMode.EFFORT), np.int32)
            ke[dof] = 0.0
            kd[dof] = 0.0
        else:
            row_mode = np.where(
                rows.kind == cfg.ROW_POS,
                np.where(
                    vel_target, int(newton.JointTargetMode.POSITION_VELOCITY), int(newton.JointTargetMode.POSITION)
                ),
                int(newton.JointTargetMode.VELOCITY),
            ).astype(np.int32)
            ke[dof] = rows.kp[None, :]
            kd[dof] = rows.kd[None, :]
        mode[dof] = row_mode[None, :]
        eff[dof] = rows.force_limit[None, :]
        fric[dof] = rows.friction[None, :]
        m.joint_target_ke.assign(ke)
        m.joint_target_kd.assign(kd)
        m.joint_target_mode.assign(mode)
        m.joint_effort_limit.assign(eff)
        m.joint_friction.assign(fric)
        # Initial targets of Model.control(): position rows hold the model's initial pose; rows without a position
        # drive (stiffness 0) get 0, PhysX's default target, as in ManiSkill; velocity targets are 0.
        tq = m.joint_target_q.numpy()
        tqd = m.joint_target_qd.numpy()
        q0 = m.joint_q.numpy()
        pos = rows.kind == cfg.ROW_POS
        tq[coord[:, pos]] = q0[coord[:, pos]]
        tq[coord[:, ~pos]] = 0.0
        tqd[dof[:, vel_target]] = 0.0
        m.joint_target_q.assign(tq)
        m.joint_target_qd.assign(tqd)
        return bool((old_mode != mode).any())


# ------------------------------------------------------------------------------------------------------------------
# Input conversion (host checks only: shapes, dtypes and devices are metadata, nothing is read back).


def _check_shape(name: str, shape: tuple, num_envs: int, dim: int) -> None:
    if tuple(shape) != (num_envs, dim):
        raise ValueError(f"{name}: expected shape ({num_envs}, {dim}) (num_envs, action_dim), got {tuple(shape)}")


def _action_array(action, num_envs: int, dim: int, device, buffer: wp.array, cache: dict | None = None) -> wp.array:
    """Return ``action`` as a float32 (num_envs, dim) wp.array on ``device``, zero-copy where possible.

    A float32 torch tensor is wrapped in place (wrappers are cached by address, shape and strides: torch's caching
    allocator hands the same memory back step after step). Anything that needs a conversion (float64, a layout
    Warp cannot index) is copied into the controller's own ``buffer``, never into a temporary that could be freed
    before the kernel runs.
    """
    if _is_torch(action):
        torch = _torch()
        t = action.detach()
        if t.dim() == 1 and num_envs == 1:
            t = t.unsqueeze(0)
        _check_shape("action", tuple(t.shape), num_envs, dim)
        if t.dtype not in (torch.float32, torch.float64):
            raise TypeError(f"action: expected a float32 (or float64) tensor, got dtype {t.dtype}")
        if wp.device_from_torch(t.device) != device:
            raise ValueError(f"action: expected a tensor on {device}, got one on {t.device}")
        if dim == 0:
            return buffer
        if t.dtype != torch.float32:
            wp.to_torch(buffer).copy_(t)
            return buffer
        key = (t.data_ptr(), t.stride(0), t.stride(1))
        if cache is not None and key in cache:
            return cache[key]
        a = wp.array(
            ptr=t.data_ptr(),
            dtype=wp.float32,
            shape=tuple(t.shape),
            strides=(t.stride(0) * 4, t.stride(1) * 4),
            device=device,
        )
        if cache is not None:
            if len(cache) >= 16:
                cache.clear()
            cache[key] = a
        return a
    if isinstance(action, wp.array):
        a = action
        if a.ndim == 1 and num_envs == 1:
            a = a.reshape((1, a.shape[0]))
        _check_shape("action", a.shape, num_envs, dim)
        if a.device != device:
            raise ValueError(f"action: expected a wp.array on {device}, got one on {a.device}")
        if a.dtype == wp.float32:
            return a
        if a.dtype == wp.float64:
            if dim:
                wp.launch(K._cast_f64_kernel, dim=a.shape, inputs=[a, buffer], device=device)
            return buffer
        raise TypeError(f"action: expected a float32 (or float64) wp.array, got dtype {wp.types.type_repr(a.dtype)}")
    a = np.asarray(action)
    if a.ndim == 1 and num_envs == 1:
        a = a[None, :]
    _check_shape("action", a.shape, num_envs, dim)
    if a.dtype.kind != "f":
        raise TypeError(
            f"action: expected a float32 (or float64) array, got dtype {a.dtype} (integer actions are not truncated "
            f"silently: convert them explicitly)"
        )
    if a.dtype == np.float32 and device.is_cpu and a.flags.c_contiguous:
        return wp.array(a, dtype=wp.float32, device=device, copy=False)
    buffer.assign(np.ascontiguousarray(a, dtype=np.float32))
    return buffer


def _raise_on_nonfinite(a: wp.array) -> None:
    """nan_policy="raise": a host check (a device-to-host copy and a sync; not graph-capturable)."""
    host = a.numpy()
    bad = ~np.isfinite(host)
    if bad.any():
        envs = np.nonzero(bad.any(axis=1))[0]
        e = int(envs[0])
        raise ValueError(
            f"action: non-finite values in {envs.size} env(s), e.g. env {e}: {host[e].tolist()} "
            f"(nan_policy='raise'; the default 'hold' keeps those envs' targets and counts them)"
        )


def _env_selection(env_ids, num_envs: int, device):
    """Return (ids, mask) device arrays for ``reset``; exactly one may be non-None, both None means all envs."""
    if env_ids is None:
        return None, None
    if isinstance(env_ids, (int, np.integer)) and not isinstance(env_ids, bool):
        env_ids = [int(env_ids)]
    if _is_torch(env_ids):
        torch = _torch()
        t = env_ids.detach()
        if wp.device_from_torch(t.device) != device:
            raise ValueError(f"env_ids: expected a tensor on {device}, got one on {t.device}")
        if t.dtype == torch.bool:
            if tuple(t.shape) != (num_envs,):
                raise ValueError(f"env_ids: a bool mask must have shape ({num_envs},), got {tuple(t.shape)}")
            return None, wp.from_torch(t.contiguous(), dtype=wp.bool)
        if t.dtype in (torch.int32, torch.int64, torch.int16, torch.uint8, torch.int8):
            t = t.reshape(-1)
            if t.device.type == "cpu" and t.numel() and (int(t.min()) < 0 or int(t.max()) >= num_envs):
                raise ValueError(f"env_ids: expected indices in [0, {num_envs}), got {t.tolist()}")
            return wp.from_torch(t.to(torch.int32).contiguous(), dtype=wp.int32), None
        raise TypeError(f"env_ids: expected an int or bool tensor, got dtype {t.dtype}")
    if isinstance(env_ids, wp.array):
        if env_ids.device != device:
            raise ValueError(f"env_ids: expected a wp.array on {device}, got one on {env_ids.device}")
        if env_ids.dtype == wp.bool:
            if env_ids.shape != (num_envs,):
                raise ValueError(f"env_ids: a bool mask must have shape ({num_envs},), got {env_ids.shape}")
            return None, env_ids
        if env_ids.dtype == wp.int32:
            return env_ids.flatten(), None
        raise TypeError(f"env_ids: expected an int32 or bool wp.array, got {wp.types.type_repr(env_ids.dtype)}")
    a = np.asarray(env_ids)
    if a.dtype == np.bool_:
        if a.shape != (num_envs,):
            raise ValueError(f"env_ids: a bool mask must have shape ({num_envs},), got {a.shape}")
        return None, wp.array(a, dtype=wp.bool, device=device)
    if a.size == 0:
        a = a.astype(np.int32)
    if a.dtype.kind not in "iu":
        raise TypeError(f"env_ids: expected env indices (ints) or a bool mask, got dtype {a.dtype}")
    a = a.reshape(-1)
    if a.size and (a.min() < 0 or a.max() >= num_envs):
        raise ValueError(f"env_ids: expected indices in [0, {num_envs}), got {a.tolist()}")
    return wp.array(a.astype(np.int32), dtype=wp.int32, device=device), None


def _as_rows_array(name: str, value, shape: tuple) -> np.ndarray:
    if _is_torch(value):
        value = value.detach().cpu().numpy()
    elif isinstance(value, wp.array):
        value = value.numpy()
    a = np.asarray(value, dtype=np.float32)
    if a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    return a


# ------------------------------------------------------------------------------------------------------------------
# Controllers


class BaseController:
    """A ManiSkill-style joint controller over all envs of a Newton model.

    Build it with :func:`wpctrl.build_controller` (or ``Config.controller_cls(config, model, ...)``). Per control
    step call :meth:`set_action` once, then :meth:`before_simulation_step` before every solver substep. Drive
    targets are written into the ``Control`` in :meth:`before_simulation_step` (implicit actuation:
    ``joint_target_q``/``joint_target_qd``, the solver's built-in PD acts); explicit actuation also writes
    ``joint_f = clamp(Kp (q* - q) + Kd (qd* - qd), -force_limit, force_limit)`` [N·m or N].
    """

    sets_target_qpos = False
    sets_target_qvel = False

    def __init__(
        self,
        config,
        model: newton.Model,
        control_freq: int = 20,
        sim_freq: int = 100,
        *,
        actuation: str = "implicit",
        solver: Any = None,
        nan_policy: str = "hold",
        explicit_pd: str = "naive",
        inertia_update: str = "control",
    ):
        self.config = config
        self.control_freq = control_freq
        self.sim_freq = sim_freq
        num_substeps = _num_substeps(control_freq, sim_freq)
        if actuation not in _ACTUATIONS:
            raise ValueError(f"actuation: expected one of {_ACTUATIONS}, got {actuation!r}")
        self.actuation = actuation
        if nan_policy not in _NAN_POLICIES:
            raise ValueError(f"nan_policy: expected one of {_NAN_POLICIES}, got {nan_policy!r}")
        self.nan_policy = nan_policy
        if explicit_pd not in _EXPLICIT_PD:
            raise ValueError(f"explicit_pd: expected one of {_EXPLICIT_PD}, got {explicit_pd!r}")
        if inertia_update not in _INERTIA_UPDATES:
            raise ValueError(f"inertia_update: expected one of {_INERTIA_UPDATES}, got {inertia_update!r}")
        self.explicit_pd = explicit_pd
        if isinstance(config, Mapping):
            configs = dict(config)
            configs.pop("balance_passive_force", None)  # a ManiSkill agent option, not a controller
            cfg.check_mode_dict(configs)
        else:
            configs = {"": config}
        names: list[str] = []
        for c in configs.values():
            if not isinstance(c, cfg.ControllerConfig):
                raise cfg.ConfigError(f"config: expected a controller config, got {type(c).__name__}")
            names += cfg._joint_names(c)
        binding = bind_joints(model, names)  # once for the whole mode
        parts: list[tuple[str, Any, cfg.Rows]] = []
        r0 = 0
        for uid, c in configs.items():
            n = len(c.joint_names)
            parts.append((uid, c, cfg.config_rows(c, binding.qlimits[r0 : r0 + n])))
            r0 += n
        all_rows = cfg.Rows.concat([p[2] for p in parts])
        self._engine = _Engine(
            all_rows,
            binding,
            model,
            num_substeps,
            actuation,
            explicit_pd=explicit_pd,
            inertia_update=inertia_update,
            sim_dt=1.0 / sim_freq,
        )
        self._rows = slice(0, all_rows.count)
        self._cols = slice(0, all_rows.action_dim)
        self._owner = True
        self.children: dict[str, BaseController] = {}
        if isinstance(config, Mapping):
            r0 = c0 = 0
            for uid, c, rows in parts:
                child_cls = type(c).controller_cls
                child = child_cls.__new__(child_cls)
                child._init_view(c, self, slice(r0, r0 + rows.count), slice(c0, c0 + rows.action_dim), rows)
                self.children[uid] = child
                r0 += rows.count
                c0 += rows.action_dim
            self.single_action_space = _flat_space([ch.single_action_space for ch in self.children.values()])
            self.action_mapping = {uid: (ch._cols.start, ch._cols.stop) for uid, ch in self.children.items()}
            self.sets_target_qpos = any(ch.sets_target_qpos for ch in self.children.values())
            self.sets_target_qvel = any(ch.sets_target_qvel for ch in self.children.values())
        else:
            self._set_spaces(parts[0][2])
        self.action_space = _batched(self.single_action_space, self.num_envs)

        changed = self._engine.apply_drive_properties()
        model_state = _ModelState(model)
        self._engine.update_response(model_state)  # per-env gains of implicit acceleration drives
        self._engine.solver = solver
        if solver is not None:
            solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES)
            if changed and type(solver).__name__ == "SolverMuJoCo":
                warnings.warn(
                    "wpctrl changed Model.joint_target_mode after the MuJoCo solver was built; MuJoCo creates its "
                    "actuators at construction, so build the controller before the solver",
                    stacklevel=2,
                )
        # Targets start at the model's initial pose (the first reset() re-initialises every env from the state).
        self._engine.reset(model_state, None, None, None, first=False)

    def _init_view(self, config, parent: BaseController, rows_slice: slice, cols_slice: slice, rows: cfg.Rows):
        self.config = config
        self.control_freq = parent.control_freq
        self.sim_freq = parent.sim_freq
        self.actuation = parent.actuation
        self.nan_policy = parent.nan_policy
        self.explicit_pd = parent.explicit_pd
        self._engine = parent._engine
        self._rows = rows_slice
        self._cols = cols_slice
        self._owner = False
        self.children = {}
        self._set_spaces(rows)
        self.action_space = _batched(self.single_action_space, self.num_envs)

    def _set_spaces(self, rows: cfg.Rows) -> None:
        raw = gym.spaces.Box(rows.action_low, rows.action_high, shape=(rows.action_dim,), dtype=np.float32)
        if rows.normalized:
            self._original_single_action_space = raw
            self.single_action_space = gym.spaces.Box(-1.0, 1.0, shape=(rows.action_dim,), dtype=np.float32)
        else:
            self._original_single_action_space = None
            self.single_action_space = raw

    # -- metadata -------------------------------------------------------------------------------------------------

    @property
    def num_envs(self) -> int:
        return self._engine.num_envs

    @property
    def device(self):
        return self._engine.device

    @property
    def joint_names(self) -> list[str]:
        return self._engine.rows.joint_names[self._rows]

    @property
    def action_dim(self) -> int:
        return self._cols.stop - self._cols.start

    @property
    def num_substeps(self) -> int:
        """K = sim_freq // control_freq: solver substeps per control step."""
        return self._engine.num_substeps

    @property
    def is_graphable(self) -> bool:
        """Every per-step call (set_action, before_simulation_step, reset with device env ids) can be captured."""
        return True

    def __getitem__(self, uid: str) -> BaseController:
        try:
            return self.children[uid]
        except KeyError:
            raise KeyError(f"no child controller {uid!r}; known: {list(self.children)}") from None

    # -- device views ---------------------------------------------------------------------------------------------

    def _view(self, arr: wp.array) -> wp.array:
        if self._owner:
            return arr
        return arr[:, self._rows.start : self._rows.stop]

    @property
    def target_qpos(self) -> wp.array:
        """(num_envs, n_joints) position targets [rad or m] at the end of the control step (live view)."""
        return self._view(self._engine.target_qpos)

    @property
    def target_qvel(self) -> wp.array:
        """(num_envs, n_joints) velocity targets [rad/s or m/s] (live view)."""
        return self._view(self._engine.target_qvel)

    @property
    def start_qpos(self) -> wp.array:
        """(num_envs, n_joints) measured positions at the last set_action or reset [rad or m] (live view)."""
        return self._view(self._engine.start_qpos)

    @property
    def processed_action(self) -> wp.array:
        """(num_envs, action_dim) last action after clip and scale (raw units) (live view)."""
        arr = self._engine.processed_action
        if self._owner:
            return arr
        if self._cols.start == self._cols.stop:  # a child without action columns (passive)
            return wp.zeros((self.num_envs, 0), dtype=wp.float32, device=self.device)
        return arr[:, self._cols.start : self._cols.stop]

    @property
    def step_counter(self) -> wp.array:
        """(num_envs,) int32 substeps since the last set_action or reset (ManiSkill's ``_step``, per env)."""
        return self._engine.step

    @property
    def bad_action_count(self) -> wp.array:
        """(num_envs,) int32 count of actions rejected for NaN/Inf; those envs kept their previous targets."""
        return self._engine.bad_action_count

    def attach_solver(self, solver) -> None:
        """Notify ``solver`` of the drive properties now, and after every per-env gain update (implicit acceleration
        drives). Use it when the solver is built after the controller (as MuJoCo requires)."""
        self._require_owner("attach_solver")
        self._engine.solver = solver
        solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES)

    @property
    def response(self) -> wp.array | None:
        """(num_envs, n_joints) joint-space response r = (H^-1)_ii [1/(kg m^2) or 1/kg] of the last update (1/r is
        the effective inertia), when acceleration drives or stable explicit PD use it; otherwise None."""
        if not self._engine.needs_response:
            return None
        return self._view(self._engine.response)

    # -- per-step API ---------------------------------------------------------------------------------------------

    def _require_owner(self, what: str) -> None:
        if not self._owner:
            raise RuntimeError(f"{what}: this is a child of a combined controller; call it on the parent")

    def _check_state(self, state, what: str) -> None:
        eng = self._engine
        if state is None or not hasattr(state, "joint_q"):
            raise TypeError(f"{what}: expected a newton.State, got {type(state).__name__}")
        if state.joint_q.device != eng.device:
            raise ValueError(f"{what}: state is on {state.joint_q.device}, the controller on {eng.device}")
        if (
            state.joint_q.shape[0] != eng.model.joint_coord_count
            or state.joint_qd.shape[0] != eng.model.joint_dof_count
        ):
            raise ValueError(
                f"{what}: state has {state.joint_q.shape[0]} coordinates / {state.joint_qd.shape[0]} DOFs, the "
                f"controller's model {eng.model.joint_coord_count} / {eng.model.joint_dof_count}: another model?"
            )

    def _check_control(self, control, what: str) -> None:
        eng = self._engine
        if control is None or not hasattr(control, "joint_target_q"):
            raise TypeError(f"{what}: expected a newton.Control, got {type(control).__name__}")
        if control.joint_target_q is None or control.joint_target_q.device != eng.device:
            raise ValueError(f"{what}: control is not on the controller's device {eng.device}")
        if control.joint_target_qd.shape[0] != eng.model.joint_dof_count:
            raise ValueError(
                f"{what}: control has {control.joint_target_qd.shape[0]} DOFs, the controller's model "
                f"{eng.model.joint_dof_count}: another model?"
            )

    def set_action(self, action, state: newton.State) -> None:
        """Set this control step's targets from ``action`` (num_envs, action_dim) and the measured ``state``.

        ``action`` may be a torch tensor (used zero-copy when float32), a numpy array or a wp.array on the
        controller's device. An env whose action holds NaN/Inf keeps its previous targets and its
        :attr:`bad_action_count` grows. One kernel launch; no allocation or host sync for float32 device input.
        """
        self._require_owner("set_action")
        self._check_state(state, "set_action")
        eng = self._engine
        a = _action_array(action, eng.num_envs, eng.action_dim, eng.device, eng.action_buffer, eng.wrappers)
        if self.nan_policy == "raise":
            _raise_on_nonfinite(a)
        eng.set_action(a, state)

    def before_simulation_step(self, state: newton.State, control: newton.Control) -> None:
        """Call once before every solver substep: writes the (interpolated) drive targets and, for explicit
        actuation, the PD torques into ``control``. One kernel launch."""
        self._require_owner("before_simulation_step")
        self._check_state(state, "before_simulation_step")
        self._check_control(control, "before_simulation_step")
        self._engine.substep(state, control)

    def reset(self, state: newton.State, env_ids=None, control: newton.Control | None = None) -> None:
        """Re-initialise the targets of ``env_ids`` (None: all) from the measured ``state``: start = target = q.

        Unlike ManiSkill, only the given envs are touched. The first call initialises every env, as ManiSkill's
        first reset does (PDJointPosVel then takes the measured velocity as its velocity target; later resets set
        it to 0). With ``control``, the reset envs' drive targets are written at once (and explicit torques zeroed);
        otherwise the next :meth:`before_simulation_step` writes them. ``env_ids``: None, an int, a sequence of ints,
        a bool mask of shape (num_envs,), or a torch/numpy/wp array of either (device arrays: graph-capturable).
        """
        self._require_owner("reset")
        self._check_state(state, "reset")
        if control is not None:
            self._check_control(control, "reset")
        eng = self._engine
        first = eng._reset_count == 0
        ids, mask = _env_selection(env_ids, eng.num_envs, eng.device)  # validated on every call
        if first:
            ids = mask = None  # the first reset initialises every env, as ManiSkill's
        eng.reset(state, ids, mask, control, first=first)
        eng._reset_count += 1

    # -- state ----------------------------------------------------------------------------------------------------

    @property
    def _uses_target(self) -> bool:
        return bool(getattr(self.config, "use_delta", False) and getattr(self.config, "use_target", False))

    def get_state(self) -> dict:
        """``{"target_qpos": wp.array}`` (a live view) for a ``use_target`` controller, ``{}`` otherwise; a combined
        controller returns ``{uid: state}`` for its children with a state."""
        if self.children:
            return {uid: s for uid, ch in self.children.items() if (s := ch.get_state())}
        if self._uses_target:
            return {"target_qpos": self.target_qpos}
        return {}

    def set_state(self, state: dict | None) -> None:
        """Restore :meth:`get_state`'s result (values are copied into the controller's arrays)."""
        if self.children:
            state = state or {}
            for uid, ch in self.children.items():
                ch.set_state(state.get(uid))
            return
        if not state or not self._uses_target:
            return
        eng = self._engine
        new = _as_rows_array("target_qpos", state["target_qpos"], (eng.num_envs, self._rows.stop - self._rows.start))
        full = eng.target_qpos.numpy()
        full[:, self._rows] = new
        eng.target_qpos.assign(full)

    def __repr__(self) -> str:
        inner = ", ".join(self.joint_names)
        return f"{type(self).__name__}(dof={self.action_dim}, num_envs={self.num_envs}, joints=({inner}))"


class _ModelState:
    """The model's initial joint state, shaped like a State for the construction-time reset."""

    def __init__(self, model: newton.Model):
        self.joint_q = model.joint_q
        self.joint_qd = model.joint_qd


def _num_substeps(control_freq, sim_freq) -> int:
    for name, v in (("control_freq", control_freq), ("sim_freq", sim_freq)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
            raise cfg.ConfigError(f"{name}: expected a positive int [Hz], got {v!r}")
    if sim_freq % control_freq != 0:
        raise cfg.ConfigError(
            f"sim_freq: expected a multiple of control_freq={control_freq} so that each control step spans whole "
            f"substeps, got sim_freq={sim_freq} (ManiSkill's env asserts this too)"
        )
    return int(sim_freq // control_freq)


def _flat_space(spaces: Sequence[gym.spaces.Box]) -> gym.spaces.Box:
    low = np.concatenate([s.low for s in spaces]).astype(np.float32) if spaces else np.zeros(0, np.float32)
    high = np.concatenate([s.high for s in spaces]).astype(np.float32) if spaces else np.zeros(0, np.float32)
    return gym.spaces.Box(low, high, shape=low.shape, dtype=np.float32)


def _batched(space: gym.spaces.Box, num_envs: int) -> gym.spaces.Box:
    if num_envs > 1:
        return gym.vector.utils.batch_space(space, num_envs)
    return space


class PDJointPosController(BaseController):
    """Position targets: absolute, delta from the measured position, or delta on a virtual target."""

    sets_target_qpos = True


class PDJointPosMimicController(PDJointPosController):
    """PDJointPos whose mimic joints follow ``target[control] * multiplier + offset``."""


class PDJointVelController(BaseController):
    """Velocity targets (stiffness 0): ``qd* = action`` once per control step."""

    sets_target_qvel = True

    @property
    def target_qpos(self):
        """A velocity controller has no position target (None)."""
        return None


class PDJointPosVelController(PDJointPosController):
    """Position targets as PDJointPos plus velocity targets from the second half of the action (never
    interpolated)."""

    sets_target_qvel = True


class PassiveController(BaseController):
    """No action: damping toward zero velocity (stiffness 0) and joint friction."""


class CombinedController(BaseController):
    """A control mode ``{uid: config}``: one flat action in dict insertion order, see :attr:`action_mapping`."""


cfg.PDJointPosControllerConfig.controller_cls = PDJointPosController
cfg.PDJointPosMimicControllerConfig.controller_cls = PDJointPosMimicController
cfg.PDJointVelControllerConfig.controller_cls = PDJointVelController
cfg.PDJointPosVelControllerConfig.controller_cls = PDJointPosVelController
cfg.PassiveControllerConfig.controller_cls = PassiveController


def build_controller(
    config,
    model: newton.Model,
    control_freq: int = 20,
    sim_freq: int = 100,
    actuation: str = "implicit",
    *,
    solver: Any = None,
    nan_policy: str = "hold",
    explicit_pd: str = "naive",
    inertia_update: str = "control",
) -> BaseController:
    """Build the controller for one config or a ManiSkill control-mode dict ``{uid: config}``.

    Args:
        config: A controller config, or a dict of them (a combined controller with a flat action).
        model: The finalized Newton model; every world must hold the configs' joints. Drive properties are
            written into it (gains, target modes, effort limits, friction).
        control_freq: Control steps per second [Hz].
        sim_freq: Solver steps per second [Hz]; a multiple of ``control_freq``.
        actuation: ``"implicit"`` (the solver's built-in PD tracks ``Control.joint_target_q/qd``) or
            ``"explicit"`` (wpctrl's kernel writes clamped PD torques into ``Control.joint_f``; built-in drive off).
        solver: Optional solver already built on ``model``: notified of the changed drive properties.
        nan_policy: ``"hold"`` (an env whose action holds NaN/Inf keeps its previous targets; counted in
            ``bad_action_count``; graph-capturable) or ``"raise"`` (ValueError before any launch; costs a host sync).
        explicit_pd: With ``actuation="explicit"``: ``"naive"`` (``clamp(Kp (q* - q) + Kd (qd* - qd))``) or
            ``"stable"`` (the same law on the predicted end-of-substep state, solved with each joint's response
            r = (H^-1)_ii: ``(Kp (q* - q - dt qd) + Kd (qd* - qd)) / (1 + r dt (Kd + dt Kp))``, then clamped;
            stable at implicit-drive gains).
        inertia_update: When r = (H^-1)_ii is recomputed (acceleration drives, stable PD): once per control step
            in ``set_action`` (``"control"``) or before every substep (``"substep"``).
    """
    kw = dict(
        actuation=actuation,
        solver=solver,
        nan_policy=nan_policy,
        explicit_pd=explicit_pd,
        inertia_update=inertia_update,
    )
    if isinstance(config, Mapping):
        return CombinedController(config, model, control_freq, sim_freq, **kw)
    if not isinstance(config, cfg.ControllerConfig):
        raise cfg.ConfigError(f"config: expected a controller config or a dict of them, got {type(config).__name__}")
    return type(config).controller_cls(config, model, control_freq, sim_freq, **kw)
