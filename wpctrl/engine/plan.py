"""The plan of one control mode: everything the engine decides on the host before it allocates a byte on the device.

Plain data (numpy tables, tuples, ints): rows, index tables, the options, which parts are on, and the compile-time
layout of the step kernels. Printable (``print(ctrl.describe())``) and testable without a device. The engine's
other two stages follow it in one direction: :mod:`.state` allocates the device arrays the plan needs, and
:mod:`.core` records the launches over them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..binding import JointBinding
from ..config import ConfigError
from ..config.actuator_models import ACT_DC_MOTOR, ACT_NET, ACT_NONE, ACT_POSITION_LIMIT
from ..config.ee import EESpec
from ..config.options import Actuation, ControllerOptions, Delay, Diagnostics
from ..config.rows import FLAG_INTERPOLATE, FLAG_VEL_TARGET, ROW_EFFORT, ROW_PASSIVE, ROW_POS, ROW_VEL, Rows
from ..kernels import actuator_models, pd_step
from .launch import _index_table

EXPLICIT_MODES = {"naive": 1, "stable": 2, "coupled": 3}


@dataclass(frozen=True)
class Options:
    """A control mode's options as the engine takes them: the substep count and length, and ``build_controller``'s
    option groups (each validated on its own when it was made; :func:`make_plan` checks them against the rows)."""

    num_substeps: int
    sim_dt: float = 0.01
    actuation: Actuation = Actuation()
    delay: Delay | None = None
    diagnostics: Diagnostics = Diagnostics()
    balance_passive_force: bool = False


@dataclass
class Plan:
    """What one control mode runs: its rows, where they live in the model, its options and active parts."""

    rows: Rows
    binding: JointBinding
    options: Options
    # First row of each controller whose family has a part of its own (end effector, impedance) -> (first action
    # column, rows, the family's spec); the part reads its specs from here.
    ee_specs: dict[int, tuple[int, int, EESpec | Any]] = field(default_factory=dict)
    # Index tables: the coordinate / DOF index of (env, row) is table[env or 0, row] + env * stride.
    q_idx: np.ndarray = None
    qd_idx: np.ndarray = None
    q_stride: int = 0
    qd_stride: int = 0
    row_f: np.ndarray = None  # (rows, ROW_F_WIDTH = 9) float32: bounds, mimic coupling, joint limits, EMA weight
    layout: pd_step.StepLayout = None
    parts: tuple[str, ...] = ()

    # -- derived --------------------------------------------------------------------------------------------------

    @property
    def num_envs(self) -> int:
        return self.binding.num_envs

    @property
    def num_rows(self) -> int:
        return self.rows.count

    @property
    def action_dim(self) -> int:
        return self.rows.action_dim

    @property
    def explicit(self) -> bool:
        return self.options.actuation.explicit

    @property
    def explicit_mode(self) -> int:
        """0 implicit, 1 naive, 2 stable, 3 coupled explicit PD."""
        return EXPLICIT_MODES[self.options.actuation.law] if self.explicit else 0

    @property
    def coupled(self) -> bool:
        return self.explicit_mode == 3

    @property
    def has_accel(self) -> bool:
        return bool(self.rows.accel.any())

    @property
    def needs_response(self) -> bool:
        """Acceleration drives and stable explicit PD use the joint-space response r = (H^-1)_ii (the coupled drive
        solves with H itself and computes r only for acceleration drives)."""
        return self.has_accel or self.explicit_mode == 2

    @property
    def computes_inertia(self) -> bool:
        """Whether the mode computes the articulation's inertia at all (r for acceleration drives and stable PD, H for
        the coupled drive)."""
        return self.needs_response or self.coupled

    @property
    def inertia_update(self) -> str | None:
        """When the inertia is recomputed (``"control"`` / ``"substep"``: the option, else the drive's default), or
        None for a mode that computes none."""
        if not self.computes_inertia:
            return None
        return self.options.actuation.inertia_update or ("substep" if self.coupled else "control")

    @property
    def delay_range(self) -> tuple[int, int] | None:
        d = self.options.delay
        return None if d is None else d.range

    @property
    def track_effort(self) -> bool:
        return self.options.diagnostics.track_effort

    @property
    def clip_targets(self) -> bool:
        return self.options.diagnostics.clip_targets == "joint_limits"

    @property
    def resolved_options(self) -> ControllerOptions:
        """The options as they run (the explicit law and inertia update resolved, None where none runs)."""
        o = self.options
        law = o.actuation.law
        actuation = Actuation(o.actuation.mode, law, self.inertia_update)
        return ControllerOptions(actuation, o.delay, o.diagnostics, o.balance_passive_force)

    @property
    def has_effort_rows(self) -> bool:
        return bool((self.rows.kind == ROW_EFFORT).any())

    @property
    def has_actuator_models(self) -> bool:
        return bool((self.rows.act_model != ACT_NONE).any())

    @property
    def writes_joint_f(self) -> bool:
        """Whether the substep writes ``Control.joint_f`` (explicit actuation, or effort rows)."""
        return self.explicit or self.has_effort_rows

    @property
    def strided(self) -> bool:
        return self.q_idx.shape[0] == 1

    @property
    def per_substep(self) -> bool:
        """Whether something must run before every solver substep: explicit torques (they depend on the measured
        state), interpolation (the target moves), a command delay (the ring buffer shifts), the effort readout (it
        reads the measured state), or a per-substep inertia update. Otherwise the drive targets are constant over the
        control step and the substep launch is elided."""
        interpolates = bool((self.rows.flags & FLAG_INTERPOLATE).any())
        inertia_per_substep = self.needs_response and self.inertia_update == "substep"
        return (
            self.explicit
            or self.has_effort_rows
            or interpolates
            or self.options.delay is not None
            or self.track_effort
            or inertia_per_substep
        )

    def __str__(self) -> str:
        r = self.rows
        kinds = {ROW_POS: "pos", ROW_VEL: "vel", ROW_PASSIVE: "passive", ROW_EFFORT: "effort"}
        lines = [
            f"Plan: {self.num_envs} envs x {self.num_rows} rows, action_dim {self.action_dim}, "
            f"K = {self.options.num_substeps}, {self.options.actuation.mode}"
            + (f" ({self.options.actuation.law})" if self.explicit else ""),
            f"  layout: {'replicated (stride ' + str(self.q_stride) + ')' if self.strided else 'per-env tables'}; "
            f"per-substep launch: {'yes' if self.per_substep else 'no (elided)'}",
            f"  parts: {', '.join(self.parts) or '-'}",
        ]
        ee_rows = {r: c0 for r0, (c0, n, _) in self.ee_specs.items() for r in range(r0, r0 + n)}
        for i, name in enumerate(r.joint_names):
            extra = [f"end effector (cols from {ee_rows[i]})"] if i in ee_rows else []
            if r.act_col[i] >= 0:
                extra.append(f"col {r.act_col[i]}")
            if r.mimic_src[i] >= 0:
                extra.append(f"mimics row {r.mimic_src[i]}")
            if r.base_axis[i] >= 0:
                extra.append(f"base {'xy'[r.base_axis[i]]} (yaw row {r.yaw_row[i]})")
            if r.act_model[i]:
                extra.append(["", "DC motor", "position-based limit", "actuator net"][int(r.act_model[i])])
            lines.append(f"  row {i:2d} {name:24s} {kinds[int(r.kind[i])]:7s} {', '.join(extra)}")
        return "\n".join(lines)


def make_plan(rows: Rows, binding: JointBinding, options: Options, ee_specs: dict | None = None) -> Plan:
    """The plan of ``rows`` bound by ``binding`` (host only).

    Raises:
        ConfigError: an option these rows would ignore or cannot honour (:func:`check_options`).
    """
    E, R = binding.num_envs, rows.count
    check_options(rows, options, ee_specs)
    # Coordinate / DOF index of every (env, row): env 0's row plus env * stride for a replicated layout, else a flat
    # (num_envs, rows) table; either way no chain of table loads in the kernels.
    q_idx, q_stride = _index_table(binding.coord_index.reshape(E, R))
    qd_idx, qd_stride = _index_table(binding.dof_index.reshape(E, R))
    if not (q_idx.shape[0] == 1 and qd_idx.shape[0] == 1):  # both flat, so that a step kernel indexes either by env
        q_idx, q_stride = binding.coord_index.reshape(E, R).astype(np.int32), 0
        qd_idx, qd_stride = binding.dof_index.reshape(E, R).astype(np.int32), 0
    plan = Plan(
        rows=rows,
        binding=binding,
        options=options,
        ee_specs=dict(ee_specs or {}),
        q_idx=q_idx,
        qd_idx=qd_idx,
        q_stride=q_stride,
        qd_stride=qd_stride,
        row_f=pd_step.row_float_table(rows, binding.qlimits.astype(np.float32).reshape(R, 2)),
    )
    plan.parts = _active_parts(plan)
    plan.layout = _layout(plan)
    return plan


def check_options(rows: Rows, options: Options, ee_specs: dict | None = None) -> None:
    """Refuse an option that the mode's rows would silently ignore, or cannot honour (host only).

    Each option group checked itself when it was made; what is left depends on the joints: an inertia update for a
    mode that computes no inertia, target clipping without position targets, a delay or the NaN check of a mode that
    takes no action, an actuator model that the actuation cannot apply.
    """
    a, d = options.actuation, options.diagnostics
    models = rows.act_model[rows.act_model != ACT_NONE]
    if models.size and (not a.explicit or a.coupled):
        name = {ACT_DC_MOTOR: "DCMotor", ACT_POSITION_LIMIT: "PositionBasedEffortLimit", ACT_NET: "ActuatorNet"}
        what = name[int(models[0])]
        why = (
            "the solver's implicit drive cannot apply it (it computes its own PD force inside the solve)"
            if not a.explicit
            else "explicit_pd='coupled' solves the force limits itself"
        )
        raise ConfigError(f"actuator: {what} needs actuation='explicit' with explicit_pd='naive' or 'stable'; {why}")
    if a.coupled and (rows.kind == ROW_EFFORT).any():
        raise ConfigError(
            "explicit_pd: 'coupled' solves every row's drive torque and would overwrite the torques of this mode's "
            "effort rows (a JointEffortControllerConfig, an impedance controller); use explicit_pd='naive' or "
            "'stable' (or actuation='implicit') for the drives"
        )
    accel = bool(rows.accel.any())
    if a.inertia_update is not None and not (accel or a.law in ("stable", "coupled")):
        raise ConfigError(
            f"actuation.inertia_update: expected None: this mode computes no inertia (no joint has drive_mode "
            f"'acceleration' and the explicit law is {a.law!r}, not 'stable' or 'coupled'), got {a.inertia_update!r}"
        )
    joint_targets = any(s.joint_targets for _, _, s in (ee_specs or {}).values())
    if d.clip_targets != "none" and not ((rows.kind == ROW_POS).any() or joint_targets):
        raise ConfigError(
            f"diagnostics.clip_targets: expected 'none': no joint of this mode has a position target (velocity, "
            f"effort and passive joints only), got {d.clip_targets!r}"
        )
    if rows.action_dim == 0:
        if options.delay is not None:
            raise ConfigError(
                f"delay: expected None: this mode takes no action (passive joints only), nothing to delay; got "
                f"{options.delay!r}"
            )
        if d.nan_policy != "hold":
            raise ConfigError(
                f"diagnostics.nan_policy: expected 'hold': this mode takes no action (passive joints only), nothing "
                f"to check; got {d.nan_policy!r}"
            )


def _active_parts(plan: Plan) -> tuple[str, ...]:
    """The names of the parts the plan needs, in the engine's order (each part decides from the plan)."""
    from .parts import part_classes

    return tuple(name for name, cls in part_classes().items() if cls.wanted(plan))


def _layout(plan: Plan) -> pd_step.StepLayout:
    """The step kernels' compile-time layout (one thread per env, rows unrolled: :mod:`wpctrl.kernels.pd_step`)."""
    rows = plan.rows
    o = plan.options
    base = bool((rows.base_axis >= 0).any())

    def ints(a) -> tuple:
        return tuple(int(x) for x in a)

    vel_rows = (rows.kind != ROW_POS) | ((rows.flags & FLAG_VEL_TARGET) != 0)
    return pd_step.StepLayout(
        kind=ints(rows.kind),
        flags=ints(rows.flags),
        act_col=ints(rows.act_col),
        vel_col=ints(rows.vel_col),
        mimic_src=ints(rows.mimic_src),
        accel=ints(rows.accel),
        q_off=ints(plan.q_idx[0]) if plan.strided else None,
        qd_off=ints(plan.qd_idx[0]) if plan.strided else None,
        action_dim=int(rows.action_dim),
        clip=plan.clip_targets,
        explicit=0 if plan.coupled else plan.explicit_mode,
        delay=o.delay is not None,
        delay_vel=o.delay is not None and bool(vel_rows.any()),
        effort=plan.track_effort and not plan.coupled,
        yaw_row=ints(rows.yaw_row) if base else (),
        base_axis=ints(rows.base_axis) if base else (),
        bx_col=ints(rows.bx_col) if base else (),
        by_col=ints(rows.by_col) if base else (),
        act_model=ints(rows.act_model) if plan.has_actuator_models else (),
        limit_table=_limit_tables(rows) if plan.has_actuator_models else (),
    )


def _limit_tables(rows: Rows) -> tuple:
    """Each row's position table as the substep kernel's constants (``()``: no table)."""
    t = [()] * rows.count
    for r0, count, what in rows.extras:
        if isinstance(what, tuple):  # (positions, efforts)
            for r in range(r0, r0 + count):
                t[r] = actuator_models.table_constants(*what)
    return tuple(t)
