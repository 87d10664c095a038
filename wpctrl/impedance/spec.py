"""An impedance config validated: its joint rows and its :class:`ImpedanceSpec` (host only).

:func:`osc_rows` and :func:`joint_impedance_rows` are the families' row functions
(:class:`~wpctrl.config.family.Family`): each checks every field of its config (:mod:`.config`) and returns the
joint rows (effort rows whose torque the impedance kernel computes before every substep; no action column of their
own, the impedance kernels read the action) and the spec the engine part reads. Nothing here touches a device.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.ee import MAX_EE_DOF, POSE_FRAMES, check_pose_box, link_and_frame
from ..config.errors import ConfigError
from ..config.joint_rows import _drive_fields
from ..config.robot_description import Descriptions, descriptions_for
from ..config.rows import ROW_EFFORT, Rows
from ..config.validate import _bounds, _check_box, _joint_names

IMPEDANCE_MODES = ("fixed", "variable_kp", "variable")
NULLSPACE_MODES = ("none", "position")
MODE_FIXED = 0
MODE_VARIABLE_KP = 1
MODE_VARIABLE = 2
DECOUPLE_NONE = 0
DECOUPLE_FULL = 1
DECOUPLE_PARTIAL = 2


@dataclass
class ImpedanceSpec:
    """The validated, device-independent parameters of one impedance config (host)."""

    osc: bool  # operational space (True) or joint impedance
    num_dof: int
    task_dim: int  # 6 (OSC) or num_dof: the axes the gains act on
    mode: int  # MODE_*
    use_delta: bool
    use_target: bool
    normalize: bool
    frame_bits: int
    target_low: np.ndarray  # (task_dim,) float32 raw bounds of the target columns (pose or joint positions)
    target_high: np.ndarray
    rot_scale: np.ndarray  # (3,) float32 (OSC): the processed rotation is the norm-clipped action times this
    stiffness: np.ndarray  # (task_dim,) float32: task (OSC) or joint gains
    damping: np.ndarray
    damping_ratio: np.ndarray  # (task_dim,) float32
    stiffness_limits: tuple[float, float]
    damping_ratio_limits: tuple[float, float]
    decoupling: int  # DECOUPLE_* (OSC), or DECOUPLE_FULL / NONE for joint impedance's inertial compensation
    gravity: bool
    nullspace: bool
    nullspace_target: np.ndarray | None  # (num_dof,) float32, or None: the reset pose
    singularity_damping: float
    ee_link: str | None = None
    urdf_path: str | None = None
    root_link_name: str | None = None
    descriptions: Descriptions = Descriptions(None, ())  # for links the model lacks (see EESpec)

    @property
    def gain_columns(self) -> int:
        return self.task_dim * self.mode

    @property
    def joint_targets(self) -> bool:
        """Whether the controller has joint position targets (joint impedance; target clipping applies to them)."""
        return not self.osc


def _name(c) -> str:
    return type(c).__name__


def _bool(c, f: str) -> bool:
    v = getattr(c, f)
    if not isinstance(v, (bool, np.bool_)):
        raise ConfigError(f"{_name(c)}.{f}: expected a bool, got {v!r}")
    return bool(v)


def _axes(c, f: str, value, n: int, what: str, *, allow_none=False, positive=False, nonneg=False) -> np.ndarray:
    """A scalar or ``n`` values (one per ``what``) as a float64 (n,) array; finite (or NaN for None with
    ``allow_none``)."""
    if value is None:
        if allow_none:
            return np.full(n, np.nan)
        raise ConfigError(f"{_name(c)}.{f}: expected a number or {n} numbers (one per {what}), got None")
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf":
            raise TypeError(raw.dtype)
        a = raw.astype(np.float64)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{_name(c)}.{f}: expected a number or {n} numbers (one per {what}), got {value!r}") from e
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] not in (1, n)):
        raise ConfigError(f"{_name(c)}.{f}: expected a scalar or {n} values (one per {what}), got shape {a.shape}")
    a = np.broadcast_to(a, (n,)).astype(np.float64)
    with np.errstate(over="ignore"):
        finite = np.isfinite(a.astype(np.float32))
    if not finite.all():
        raise ConfigError(f"{_name(c)}.{f}: expected finite numbers (float32 range), got {value!r}")
    if positive and (a <= 0).any():
        raise ConfigError(f"{_name(c)}.{f}: expected values > 0, got {value!r}")
    if nonneg and (a < 0).any():
        raise ConfigError(f"{_name(c)}.{f}: expected values >= 0, got {value!r}")
    return a


def _limits(c, f: str) -> tuple[float, float]:
    v = getattr(c, f)
    try:
        items = list(v)
        if len(items) != 2 or not all(isinstance(x, (int, float, np.integer, np.floating)) for x in items):
            raise TypeError(v)
        if any(isinstance(x, (bool, np.bool_)) for x in items):
            raise TypeError(v)
        lo, hi = (float(x) for x in items)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{_name(c)}.{f}: expected a (low, high) pair of numbers, got {v!r}") from e
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi):
        raise ConfigError(f"{_name(c)}.{f}: expected finite 0 <= low <= high, got ({lo!r}, {hi!r})")
    return lo, hi


def _gains(c, n: int, what: str, kp_field: str, kd_field: str, ratio_field: str):
    """Stiffness, damping (from the ratio where None) and the ratio, (n,) float64 each."""
    kp = _axes(c, kp_field, getattr(c, kp_field), n, what, nonneg=True)
    ratio = _axes(c, ratio_field, getattr(c, ratio_field), n, what, nonneg=True)
    kd_value = getattr(c, kd_field)
    kd = 2.0 * ratio * np.sqrt(kp) if kd_value is None else _axes(c, kd_field, kd_value, n, what, nonneg=True)
    if not np.isfinite(kd.astype(np.float32)).all():
        raise ConfigError(
            f"{_name(c)}.{ratio_field}: the damping 2 {ratio_field} √{kp_field} overflows float32 "
            f"({ratio_field}={getattr(c, ratio_field)!r}, {kp_field}={getattr(c, kp_field)!r})"
        )
    return kp, kd, ratio


def _mode(c) -> int:
    if c.impedance_mode not in IMPEDANCE_MODES:
        raise ConfigError(f"{_name(c)}.impedance_mode: expected one of {IMPEDANCE_MODES}, got {c.impedance_mode!r}")
    mode = IMPEDANCE_MODES.index(c.impedance_mode)
    if mode != MODE_FIXED and c.damping is not None:
        raise ConfigError(
            f"{_name(c)}.damping: with impedance_mode={c.impedance_mode!r} the damping follows the stiffness "
            f"(2 damping_ratio √Kp); leave damping None, got {c.damping!r}"
        )
    return mode


def _task_gains(c, n: int, what: str) -> dict:
    """The spec's gain fields: the impedance mode, stiffness, damping and damping ratio of the ``n`` axes the gains act
    on (one per ``what``), and the gain actions' limits."""
    mode = _mode(c)
    kp, kd, ratio = _gains(c, n, what, "stiffness", "damping", "damping_ratio")
    return dict(
        task_dim=n,
        mode=mode,
        stiffness=kp.astype(np.float32),
        damping=kd.astype(np.float32),
        damping_ratio=ratio.astype(np.float32),
        stiffness_limits=_limits(c, "stiffness_limits"),
        damping_ratio_limits=_limits(c, "damping_ratio_limits"),
    )


def _rows_and_spec(c, names, gains: dict, kp, kd, normalize: bool, **fields) -> tuple[Rows, ImpedanceSpec]:
    """The joint rows (effort rows with gains ``kp`` / ``kd``, no action column of their own: the impedance kernels
    read the action) and the spec; the action is the target columns, then the gain columns of a variable mode."""
    n_task, mode = gains["task_dim"], gains["mode"]
    low, high = [fields["target_low"]], [fields["target_high"]]
    kp_lim, ratio_lim = gains["stiffness_limits"], gains["damping_ratio_limits"]
    if mode >= MODE_VARIABLE_KP:
        low.append(np.full(n_task, kp_lim[0]))
        high.append(np.full(n_task, kp_lim[1]))
    if mode == MODE_VARIABLE:
        low.append(np.full(n_task, ratio_lim[0]))
        high.append(np.full(n_task, ratio_lim[1]))
    rows = Rows.of(
        names,
        ROW_EFFORT,
        kp=np.asarray(kp, np.float32),
        kd=np.asarray(kd, np.float32),
        **_drive_fields(c, len(names), damping=False),
        action_low=np.concatenate(low),
        action_high=np.concatenate(high),
        normalized=normalize,
    )
    target = {k: fields.pop(k).astype(np.float32) for k in ("target_low", "target_high")}
    return rows, ImpedanceSpec(num_dof=len(names), normalize=normalize, **gains, **target, **fields)


def osc_rows(c, qlimits: np.ndarray) -> tuple[Rows, ImpedanceSpec]:
    """Validate an :class:`~.config.OperationalSpaceControllerConfig`; its rows and spec (``qlimits`` unused)."""
    names = _joint_names(c)
    n = len(names)
    if not 1 <= n <= MAX_EE_DOF:
        raise ConfigError(f"{_name(c)}.joint_names: expected 1 to {MAX_EE_DOF} joints on the EE chain, got {n}")
    flags = {f: _bool(c, f) for f in ("use_delta", "use_target", "normalize_action", "inertial_dynamics_decoupling",
                                      "partial_inertial_dynamics_decoupling", "gravity_compensation")}  # fmt: skip
    bits = link_and_frame(c, POSE_FRAMES)
    normalize = flags["normalize_action"]
    bounds = []
    for f in ("pos_lower", "pos_upper", "rot_lower", "rot_upper"):
        bounds.append(_axes(c, f, getattr(c, f), 3, "axis (x, y, z)", allow_none=not normalize))
    plo, phi, rlo, rhi = bounds
    t_low = np.nan_to_num(np.concatenate([plo, rlo]), nan=-np.inf)
    t_high = np.nan_to_num(np.concatenate([phi, rhi]), nan=np.inf)
    check_pose_box(c, t_low, t_high)
    gains = _task_gains(c, 6, "task axis (x, y, z, rx, ry, rz)")
    if c.nullspace_control not in NULLSPACE_MODES:
        raise ConfigError(
            f"{_name(c)}.nullspace_control: expected one of {NULLSPACE_MODES}, got {c.nullspace_control!r}"
        )
    nullspace = c.nullspace_control == "position"
    decouple = flags["inertial_dynamics_decoupling"]
    if flags["partial_inertial_dynamics_decoupling"] and not decouple:
        raise ConfigError(
            f"{_name(c)}.partial_inertial_dynamics_decoupling: needs inertial_dynamics_decoupling=True (it chooses how "
            f"the operational-space inertia is formed)"
        )
    if decouple and n < 6:
        raise ConfigError(
            f"{_name(c)}.inertial_dynamics_decoupling: the operational-space inertia of a 6-D task needs at least 6 "
            f"joints, got {n} (J M⁻¹ Jᵀ is singular); use inertial_dynamics_decoupling=False"
        )
    if nullspace and n <= 6:
        raise ConfigError(
            f"{_name(c)}.nullspace_control: a posture in the task's null space needs more than 6 joints, got {n}"
        )
    nkp, nkd, _ = _gains(c, n, "joint", "nullspace_stiffness", "nullspace_damping", "nullspace_damping_ratio")
    if not nullspace:
        nkp, nkd = np.zeros(n), np.zeros(n)
    target = None
    if c.nullspace_target is not None:
        target = _axes(c, "nullspace_target", c.nullspace_target, n, "joint").astype(np.float32)
    sd = c.singularity_damping
    if isinstance(sd, bool) or not isinstance(sd, (int, float, np.floating, np.integer)) or not 0.0 <= sd < 1.0:
        raise ConfigError(f"{_name(c)}.singularity_damping: expected a number in [0, 1), got {sd!r}")
    return _rows_and_spec(
        c,
        names,
        gains,
        nkp,
        nkd,
        normalize,
        osc=True,
        use_delta=flags["use_delta"],
        use_target=flags["use_target"],
        frame_bits=bits,
        target_low=t_low,
        target_high=t_high,
        rot_scale=(0.5 * (rhi - rlo)).astype(np.float32) if normalize else np.ones(3, np.float32),
        decoupling=(DECOUPLE_PARTIAL if flags["partial_inertial_dynamics_decoupling"] else DECOUPLE_FULL)
        if decouple
        else DECOUPLE_NONE,
        gravity=flags["gravity_compensation"],
        nullspace=nullspace,
        nullspace_target=target,
        singularity_damping=float(sd),
        ee_link=c.ee_link,
        urdf_path=None if c.urdf_path is None else str(c.urdf_path),
        root_link_name=c.root_link_name,
        descriptions=descriptions_for(None if c.urdf_path is None else str(c.urdf_path)),
    )


def joint_impedance_rows(c, qlimits: np.ndarray) -> tuple[Rows, ImpedanceSpec]:
    """Validate a :class:`~.config.JointImpedanceControllerConfig`; its rows and spec (``qlimits``: the (n, 2) joint
    limits [rad or m] of ``c.joint_names``, the bounds where ``lower`` / ``upper`` are None)."""
    names = _joint_names(c)
    flags = {f: _bool(c, f) for f in ("use_delta", "use_target", "normalize_action", "inertial_compensation",
                                      "gravity_compensation")}  # fmt: skip
    normalize = flags["normalize_action"]
    lo, hi = _bounds(c, c.lower, c.upper, qlimits)
    _check_box(c, lo, hi, names, normalize, "lower/upper")
    gains = _task_gains(c, len(names), "joint")
    return _rows_and_spec(
        c,
        names,
        gains,
        gains["stiffness"],
        gains["damping"],
        normalize,
        osc=False,
        use_delta=flags["use_delta"],
        use_target=flags["use_target"],
        frame_bits=0,
        target_low=lo,
        target_high=hi,
        rot_scale=np.ones(3, np.float32),
        decoupling=DECOUPLE_FULL if flags["inertial_compensation"] else DECOUPLE_NONE,
        gravity=flags["gravity_compensation"],
        nullspace=False,
        nullspace_target=None,
        singularity_damping=0.0,
    )


def impedance_rows(c, qlimits: np.ndarray) -> tuple[Rows, ImpedanceSpec]:
    """Validate an impedance config through its family; return its joint rows and its spec.

    Args:
        c: An :class:`~.config.OperationalSpaceControllerConfig` or :class:`~.config.JointImpedanceControllerConfig`.
        qlimits: (n, 2) joint limits [rad or m] of ``c.joint_names`` (the joint-impedance bounds where None).
    """
    return type(c).family.make(c, qlimits)
