"""Host-side configs of the torque-level impedance controllers: operational-space control (OSC) of an end effector
and joint impedance, and their validation.

Neither exists in ManiSkill; both follow the conventions of its end-effector configs (:mod:`.ee`): joint names,
normalised action bounds, ``frame``, ``use_delta``, ``use_target``, ``ee_link``, ``urdf_path``, ``force_limit``,
``friction``, and mix with joint configs (a gripper) in one mode dict. Their gain options are Isaac Lab's
(``impedance_mode``, ``inertial_dynamics_decoupling``, ``gravity_compensation``, ``nullspace_control``, damping from a
damping ratio). Nothing here touches a device: :func:`impedance_rows` validates a config and returns its joint rows
(effort rows whose torque the impedance kernel computes before every substep) and an :class:`ImpedanceSpec`.

Units: positions [m], rotations [rad], task stiffness [1/s²] (with inertial decoupling: the spring acts as an
acceleration, premultiplied by the operational-space inertia) or [N/m, N·m/rad] (without), task damping [1/s] or
[N·s/m, N·m·s/rad]; joint gains likewise [1/s²] / [1/s] with inertial compensation, else [N·m/rad] / [N·m·s/rad].
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Union

import numpy as np

from . import rows as cfg
from .ee import FRAME_BODY_ROT, FRAME_BODY_TRANS, MAX_EE_DOF, POSE_FRAMES
from .errors import ConfigError
from .joint import ControllerClass, ControllerConfig

IMPEDANCE_MODES = ("fixed", "variable_kp", "variable")
NULLSPACE_MODES = ("none", "position")
MODE_FIXED = 0
MODE_VARIABLE_KP = 1
MODE_VARIABLE = 2
DECOUPLE_NONE = 0
DECOUPLE_FULL = 1
DECOUPLE_PARTIAL = 2


@dataclass
class OperationalSpaceControllerConfig(ControllerConfig):
    """Operational-space control of ``ee_link``: joint torques ``τ = Jᵀ F + N τ₀ + g`` toward a target pose.

    ``F = Λ (Kp ∘ e − Kd ∘ ẋ)`` with the pose error ``e`` (position, and the rotation vector of
    ``q_target q⁻¹``) and the EE twist ``ẋ = J q̇`` in the root frame, ``Λ = (J M⁻¹ Jᵀ)⁻¹`` the operational-space
    inertia (``M``: the controlled joints' block of the articulation's mass matrix), ``N τ₀`` a joint posture term
    projected into the task's null space, ``g`` the gravity torque. The torques go to ``Control.joint_f`` before every
    solver substep, clamped to ``force_limit``."""

    controller_cls = ControllerClass("wpctrl.controllers.impedance", "OperationalSpaceController")

    pos_lower: Union[float, Sequence[float]] = -0.1
    """Lower bound of the position action [m] (per axis or one value; a delta with ``use_delta``); None: -inf
    (unnormalised actions only)."""
    pos_upper: Union[float, Sequence[float]] = 0.1
    """Upper bound of the position action [m]."""
    rot_lower: Union[float, Sequence[float]] = -0.1
    """Lower bound of the rotation action [rad] (Euler XYZ, as the EE controllers)."""
    rot_upper: Union[float, Sequence[float]] = 0.1
    """Upper bound of the rotation action [rad]. A normalised rotation action is clipped by its norm (as ManiSkill's)
    and scaled by the half range ``(rot_upper - rot_lower) / 2`` (a positive action rotates positively)."""
    stiffness: Union[float, Sequence[float]] = 100.0
    """Task stiffness Kp per axis (x, y, z, rx, ry, rz of the root frame), one value or 6 [1/s² with inertial
    decoupling, else N/m and N·m/rad]; with ``impedance_mode`` "variable_kp" / "variable": the value before the first
    action."""
    damping: Union[None, float, Sequence[float]] = None
    """Task damping Kd per axis [1/s with decoupling, else N·s/m and N·m·s/rad]; None: ``2 damping_ratio √Kp``
    (critical damping of a unit inertia: exact with full decoupling)."""
    damping_ratio: Union[float, Sequence[float]] = 1.0
    """Damping ratio ζ of the task axes where ``damping`` is None (and the fixed ratio of "variable_kp")."""
    force_limit: Union[float, Sequence[float]] = 1e10
    """Joint effort limit [N·m or N] per joint: the torque is clamped to it (as the drives' limits)."""
    friction: Union[float, Sequence[float]] = 0.0
    """Joint friction [N·m or N], written to ``Model.joint_friction``."""
    ee_link: str = None
    """The controlled link: a body label, a site on a body, or a link of ``urdf_path`` merged into a kept body (as
    the EE controllers)."""
    urdf_path: str = None
    """Optional URDF of the robot; used only where the model lacks ``ee_link``, to find its fixed offset."""
    frame: Literal[
        "body_translation:root_aligned_body_rotation",
        "root_translation:root_aligned_body_rotation",
        "body_translation:body_aligned_body_rotation",
        "root_translation:body_aligned_body_rotation",
    ] = "root_translation:root_aligned_body_rotation"
    """Frames of a delta action's position and rotation, as the EE controllers (the gains always act along the root
    frame's axes)."""
    root_link_name: str | None = None
    """The root frame of the poses (a body label); None: the articulation root."""
    use_delta: bool = True
    """Actions are pose increments; False: absolute poses ``[x, y, z, rx, ry, rz]`` in the root frame."""
    use_target: bool = False
    """Compose increments on the last target pose instead of the measured EE pose."""
    normalize_action: bool = True
    """Actions in [-1, 1] are clipped and scaled onto the bounds (pose and gains)."""
    impedance_mode: Literal["fixed", "variable_kp", "variable"] = "fixed"
    """Isaac Lab's: "fixed" (the config's gains), "variable_kp" (6 more action columns: the stiffness, damping from
    ``damping_ratio``), "variable" (12 more: stiffness, then damping ratio)."""
    stiffness_limits: tuple[float, float] = (0.0, 1000.0)
    """The stiffness action's bounds (what [-1, 1] maps onto when normalised; the clip otherwise)."""
    damping_ratio_limits: tuple[float, float] = (0.0, 2.0)
    """The damping-ratio action's bounds ("variable")."""
    inertial_dynamics_decoupling: bool = True
    """Premultiply the task acceleration by Λ (stiffness and damping then act per unit inertia)."""
    partial_inertial_dynamics_decoupling: bool = False
    """Λ without the coupling of translation and rotation (two 3×3 blocks)."""
    gravity_compensation: bool = True
    """Add the gravity torque ``g(q)`` of the whole articulation at the controlled joints (not with
    ``balance_passive_force``, where the solver already takes gravity off the robot's links)."""
    nullspace_control: Literal["none", "position"] = "none"
    """"position": a joint posture PD ``τ₀ = [M] (Kp_n (q_n − q) − Kd_n q̇)`` projected into the task's null space
    (dynamically consistent with full decoupling, else through the pseudo-inverse); more than 6 joints."""
    nullspace_stiffness: Union[float, Sequence[float]] = 10.0
    """Posture stiffness per joint [1/s² with decoupling, else N·m/rad]; per-env in ``ctrl.stiffness``."""
    nullspace_damping: Union[None, float, Sequence[float]] = None
    """Posture damping per joint; None: ``2 nullspace_damping_ratio √Kp_n``."""
    nullspace_damping_ratio: Union[float, Sequence[float]] = 1.0
    """Posture damping ratio where ``nullspace_damping`` is None."""
    nullspace_target: Union[None, Sequence[float]] = None
    """Posture [rad or m] per joint; None: each env's joint positions at its last reset (``ctrl.target_qpos``,
    writable)."""
    singularity_damping: float = 1e-3
    """Near a singularity: when the smallest pivot of the Jacobi-scaled ``J M⁻¹ Jᵀ`` (unit diagonal) falls below
    this value ε, ``ε (1 − p/ε)²`` is added to its diagonal before it is inverted (0: off); see the docs."""


@dataclass
class JointImpedanceControllerConfig(ControllerConfig):
    """Joint impedance: ``τ = [M] (Kp (q* − q) − Kd q̇) + g`` toward joint targets, written to ``Control.joint_f``
    before every solver substep and clamped to ``force_limit`` (``M``: the controlled joints' block of the
    articulation's mass matrix, with ``inertial_compensation``; ``g``: the gravity torque)."""

    controller_cls = ControllerClass("wpctrl.controllers.impedance", "JointImpedanceController")

    lower: Union[None, float, Sequence[float]]
    """Lower action bound [rad or m] (a delta bound with ``use_delta``); None takes the joint's lower limit."""
    upper: Union[None, float, Sequence[float]]
    """Upper action bound [rad or m]; None takes the joint's upper limit."""
    stiffness: Union[float, Sequence[float]]
    """Joint stiffness Kp [1/s² with inertial compensation, else N·m/rad or N/m]; per-env in ``ctrl.stiffness``."""
    damping: Union[None, float, Sequence[float]] = None
    """Joint damping Kd [1/s with inertial compensation, else N·m·s/rad or N·s/m]; None: ``2 damping_ratio √Kp``."""
    damping_ratio: Union[float, Sequence[float]] = 1.0
    """Damping ratio where ``damping`` is None (and the fixed ratio of "variable_kp")."""
    force_limit: Union[float, Sequence[float]] = 1e10
    """Joint effort limit [N·m or N]: the torque is clamped to it."""
    friction: Union[float, Sequence[float]] = 0.0
    """Joint friction [N·m or N], written to ``Model.joint_friction``."""
    use_delta: bool = False
    """Actions are increments on the measured positions (or on the last target with ``use_target``)."""
    use_target: bool = False
    """With ``use_delta``: increments on the last target."""
    normalize_action: bool = True
    """Actions in [-1, 1] are clipped and scaled onto [lower, upper] (and the gain limits)."""
    impedance_mode: Literal["fixed", "variable_kp", "variable"] = "fixed"
    """"fixed", "variable_kp" (n more action columns: the stiffness), "variable" (2 n more: stiffness, damping
    ratio)."""
    stiffness_limits: tuple[float, float] = (0.0, 1000.0)
    """The stiffness action's bounds."""
    damping_ratio_limits: tuple[float, float] = (0.0, 2.0)
    """The damping-ratio action's bounds ("variable")."""
    inertial_compensation: bool = False
    """Premultiply the PD term by M (the gains then act per unit inertia, decoupled)."""
    gravity_compensation: bool = True
    """Add the gravity torque ``g(q)`` (not with ``balance_passive_force``: see the OSC config)."""


IMPEDANCE_CONFIGS = (OperationalSpaceControllerConfig, JointImpedanceControllerConfig)


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

    @property
    def gain_columns(self) -> int:
        return self.task_dim * self.mode


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


def _gain_bounds(c, mode: int, n: int, normalize: bool, kp_lim, ratio_lim) -> tuple[list, list]:
    """The gain columns' raw bounds (what [-1, 1] maps onto)."""
    low, high = [], []
    if mode >= MODE_VARIABLE_KP:
        low.append(np.full(n, kp_lim[0]))
        high.append(np.full(n, kp_lim[1]))
    if mode == MODE_VARIABLE:
        low.append(np.full(n, ratio_lim[0]))
        high.append(np.full(n, ratio_lim[1]))
    return low, high


def _effort_rows(c, names: list[str], kp, kd, low: np.ndarray, high: np.ndarray, normalize: bool) -> cfg.Rows:
    """Effort rows without an action column of their own (the impedance kernel writes their commanded torque)."""
    n = len(names)
    z = np.zeros(n, np.float32)
    return cfg.Rows(
        joint_names=names,
        kind=np.full(n, cfg.ROW_EFFORT, np.int32),
        flags=np.zeros(n, np.int32),
        act_col=np.full(n, -1, np.int32),
        vel_col=np.full(n, -1, np.int32),
        lo=z.copy(),
        hi=z.copy(),
        vlo=z.copy(),
        vhi=z.copy(),
        mimic_src=np.full(n, -1, np.int32),
        mimic_mul=np.ones(n, np.float32),
        mimic_off=z.copy(),
        kp=np.asarray(kp, np.float32),
        kd=np.asarray(kd, np.float32),
        force_limit=cfg._per_joint(c, "force_limit", c.force_limit, n, nonneg=True).astype(np.float32),
        friction=cfg._per_joint(c, "friction", c.friction, n, nonneg=True).astype(np.float32),
        accel=np.zeros(n, np.bool_),
        action_low=low.astype(np.float32),
        action_high=high.astype(np.float32),
        normalized=normalize,
        action_dim=int(low.shape[0]),
    )


def _osc_rows(c: OperationalSpaceControllerConfig) -> tuple[cfg.Rows, ImpedanceSpec]:
    names = cfg._joint_names(c)
    n = len(names)
    if not 1 <= n <= MAX_EE_DOF:
        raise ConfigError(f"{_name(c)}.joint_names: expected 1 to {MAX_EE_DOF} joints on the EE chain, got {n}")
    flags = {f: _bool(c, f) for f in ("use_delta", "use_target", "normalize_action", "inertial_dynamics_decoupling",
                                      "partial_inertial_dynamics_decoupling", "gravity_compensation")}  # fmt: skip
    if not isinstance(c.ee_link, str) or not c.ee_link:
        raise ConfigError(f"{_name(c)}.ee_link: expected the name of the controlled link, got {c.ee_link!r}")
    if c.urdf_path is not None and not isinstance(c.urdf_path, (str, bytes)) and not hasattr(c.urdf_path, "__fspath__"):
        raise ConfigError(f"{_name(c)}.urdf_path: expected a path or None, got {c.urdf_path!r}")
    if c.root_link_name is not None and not isinstance(c.root_link_name, str):
        raise ConfigError(f"{_name(c)}.root_link_name: expected a link name or None, got {c.root_link_name!r}")
    if c.frame not in POSE_FRAMES:
        raise ConfigError(f"{_name(c)}.frame: expected one of {POSE_FRAMES}, got {c.frame!r}")
    bits = (FRAME_BODY_TRANS if c.frame.startswith("body_translation") else 0) | (
        FRAME_BODY_ROT if c.frame.endswith("body_aligned_body_rotation") else 0
    )
    normalize = flags["normalize_action"]
    bounds = []
    for f in ("pos_lower", "pos_upper", "rot_lower", "rot_upper"):
        bounds.append(_axes(c, f, getattr(c, f), 3, "axis (x, y, z)", allow_none=not normalize))
    plo, phi, rlo, rhi = bounds
    t_low = np.nan_to_num(np.concatenate([plo, rlo]), nan=-np.inf)
    t_high = np.nan_to_num(np.concatenate([phi, rhi]), nan=np.inf)
    axes = ["x", "y", "z", "rx", "ry", "rz"]
    bad = np.nonzero(t_low > t_high)[0]
    if bad.size:
        i = int(bad[0])
        what = "pos_lower/pos_upper" if i < 3 else "rot_lower/rot_upper"
        raise ConfigError(
            f"{_name(c)}.{what}: lower must be <= upper, got lower={cfg._f32(t_low[i])} > "
            f"upper={cfg._f32(t_high[i])} for axis {axes[i]!r}"
        )
    mode = _mode(c)
    kp, kd, ratio = _gains(c, 6, "task axis (x, y, z, rx, ry, rz)", "stiffness", "damping", "damping_ratio")
    kp_lim, ratio_lim = _limits(c, "stiffness_limits"), _limits(c, "damping_ratio_limits")
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
    g_low, g_high = _gain_bounds(c, mode, 6, normalize, kp_lim, ratio_lim)
    low = np.concatenate([t_low, *g_low])
    high = np.concatenate([t_high, *g_high])
    rows = _effort_rows(c, names, nkp, nkd, low, high, normalize)
    spec = ImpedanceSpec(
        osc=True,
        num_dof=n,
        task_dim=6,
        mode=mode,
        use_delta=flags["use_delta"],
        use_target=flags["use_target"],
        normalize=normalize,
        frame_bits=bits,
        target_low=t_low.astype(np.float32),
        target_high=t_high.astype(np.float32),
        rot_scale=(0.5 * (rhi - rlo)).astype(np.float32) if normalize else np.ones(3, np.float32),
        stiffness=kp.astype(np.float32),
        damping=kd.astype(np.float32),
        damping_ratio=ratio.astype(np.float32),
        stiffness_limits=kp_lim,
        damping_ratio_limits=ratio_lim,
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
    )
    return rows, spec


def _joint_rows(c: JointImpedanceControllerConfig, qlimits: np.ndarray) -> tuple[cfg.Rows, ImpedanceSpec]:
    names = cfg._joint_names(c)
    n = len(names)
    flags = {f: _bool(c, f) for f in ("use_delta", "use_target", "normalize_action", "inertial_compensation",
                                      "gravity_compensation")}  # fmt: skip
    normalize = flags["normalize_action"]
    lo, hi = cfg._bounds(c, c.lower, c.upper, qlimits)
    cfg._check_box(c, lo, hi, names, normalize, "lower/upper")
    mode = _mode(c)
    kp, kd, ratio = _gains(c, n, "joint", "stiffness", "damping", "damping_ratio")
    kp_lim, ratio_lim = _limits(c, "stiffness_limits"), _limits(c, "damping_ratio_limits")
    g_low, g_high = _gain_bounds(c, mode, n, normalize, kp_lim, ratio_lim)
    low = np.concatenate([lo, *g_low])
    high = np.concatenate([hi, *g_high])
    rows = _effort_rows(c, names, kp, kd, low, high, normalize)
    spec = ImpedanceSpec(
        osc=False,
        num_dof=n,
        task_dim=n,
        mode=mode,
        use_delta=flags["use_delta"],
        use_target=flags["use_target"],
        normalize=normalize,
        frame_bits=0,
        target_low=lo.astype(np.float32),
        target_high=hi.astype(np.float32),
        rot_scale=np.ones(3, np.float32),
        stiffness=kp.astype(np.float32),
        damping=kd.astype(np.float32),
        damping_ratio=ratio.astype(np.float32),
        stiffness_limits=kp_lim,
        damping_ratio_limits=ratio_lim,
        decoupling=DECOUPLE_FULL if flags["inertial_compensation"] else DECOUPLE_NONE,
        gravity=flags["gravity_compensation"],
        nullspace=False,
        nullspace_target=None,
        singularity_damping=0.0,
    )
    return rows, spec


def impedance_rows(c, qlimits: np.ndarray) -> tuple[cfg.Rows, ImpedanceSpec]:
    """Validate an impedance config; return its joint rows (effort rows, no action column of their own: the
    impedance kernels read the action) and its spec.

    Args:
        c: An :class:`OperationalSpaceControllerConfig` or :class:`JointImpedanceControllerConfig`.
        qlimits: (n, 2) joint limits [rad or m] of ``c.joint_names`` (the joint-impedance bounds where None).
    """
    if isinstance(c, OperationalSpaceControllerConfig):
        return _osc_rows(c)
    return _joint_rows(c, qlimits)
