"""Rows: the flat, per-joint description of a control mode that one kernel launch handles.

Validates configs (:mod:`wpctrl.config.joint`) and turns them into per-joint rows (plain numpy tables) that the
binding and the engine upload. Host only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from .actuator_models import ACT_NET, actuator_rows
from .errors import ConfigError, MimicJointError
from .joint import (
    ControllerConfig,
    JointEffortControllerConfig,
    PassiveControllerConfig,
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointPosVelControllerConfig,
    PDJointVelControllerConfig,
)
from .mobile_base import PDBaseForwardVelControllerConfig, PDBaseVelControllerConfig
from .validate import (  # noqa: F401  (_f32, _joint_names: used by the EE config and the controller layer)
    _bounds,
    _check_box,
    _drive_modes,
    _f32,
    _joint_names,
    _mimic_map,
    _name,
    _per_joint,
)

# Row kinds (one row per controlled joint).
ROW_POS = 0
"""Position-driven joint (PDJointPos, mimic, PDJointPosVel)."""
ROW_VEL = 1
"""Velocity-driven joint (PDJointVel): stiffness 0, velocity target from the action."""
ROW_PASSIVE = 2
"""Passive joint: stiffness 0, damping toward a zero velocity target, no action."""
ROW_EFFORT = 3
"""Effort-commanded joint (JointEffortController): the scaled action is the joint effort, drive off."""

# Row flag bits.
FLAG_NORMALIZE = 1
FLAG_DELTA = 2
FLAG_TARGET = 4
FLAG_INTERPOLATE = 8
FLAG_VEL_TARGET = 16
"""The row's velocity drive target comes from the action (PDJointPosVel)."""
FLAG_EMA = 32
"""The row's target is smoothed: ``alpha * target + (1 - alpha) * previous``, clamped to the joint's limits."""
FLAG_BINARY = 64
"""The row's target is ``hi`` for a non-negative action, ``lo`` for a negative one."""


@dataclass
class Rows:
    """Per-joint parameters of one controller (or a whole control mode), host numpy, in row order.

    Action columns index the flat action of that controller (or mode). ``lo``/``hi`` are the raw bounds of the
    position-or-velocity action column (what [-1, 1] maps onto), ``vlo``/``vhi`` those of the velocity column of
    a PDJointPosVel row.
    """

    joint_names: list[str]
    kind: np.ndarray  # int32
    flags: np.ndarray  # int32
    act_col: np.ndarray  # int32, -1: none
    vel_col: np.ndarray  # int32, -1: none
    lo: np.ndarray  # float32
    hi: np.ndarray
    vlo: np.ndarray
    vhi: np.ndarray
    mimic_src: np.ndarray  # int32 row index, -1: none
    mimic_mul: np.ndarray  # float32
    mimic_off: np.ndarray  # float32
    kp: np.ndarray  # float32 [N·m/rad or N/m]
    kd: np.ndarray  # float32 [N·m·s/rad or N·s/m]
    force_limit: np.ndarray  # float32 [N·m or N]
    friction: np.ndarray  # float32
    accel: np.ndarray  # bool: drive_mode == "acceleration"
    action_low: np.ndarray  # float32 (action_dim,), raw bounds before normalisation
    action_high: np.ndarray
    normalized: bool
    action_dim: int
    # Ego-centric base rows (PDBaseVel / PDBaseForwardVel): the planar velocity target of an x (axis 0) or y (axis 1)
    # row is the action's (vx, vy) rotated by the measured position of row ``yaw_row`` (its controller's third joint).
    yaw_row: np.ndarray | None = None  # int32 row index, -1: not a rotated base row
    base_axis: np.ndarray | None = None  # int32: 0 x, 1 y, -1 none
    bx_col: np.ndarray | None = None  # int32 action column of vx (-1: 0)
    by_col: np.ndarray | None = None  # int32 action column of vy (-1: 0, the forward-only base)
    # Actuator models and action smoothing (wpctrl.config.actuator_models): per-row model code and parameters, and the
    # models that carry more than numbers (position tables, networks) as (first row, rows, what).
    act_model: np.ndarray | None = None  # int32, ACT_* (0: the plain clamp to force_limit)
    sat_effort: np.ndarray | None = None  # float32 [N·m or N], DC-motor stall effort (inf: none)
    vel_limit: np.ndarray | None = None  # float32 [rad/s or m/s], DC-motor no-load speed (inf: none)
    ema_alpha: np.ndarray | None = None  # float32, the EMA weight of FLAG_EMA rows
    extras: list = field(default_factory=list)

    def __post_init__(self):
        n = len(self.joint_names)
        for k in ("yaw_row", "base_axis", "bx_col", "by_col"):
            if getattr(self, k) is None:
                setattr(self, k, np.full(n, -1, np.int32))
        defaults = {"act_model": (0, np.int32), "sat_effort": (np.inf, np.float32), "vel_limit": (np.inf, np.float32),
                    "ema_alpha": (1.0, np.float32)}  # fmt: skip
        for k, (v, dt) in defaults.items():
            if getattr(self, k) is None:
                setattr(self, k, np.full(n, v, dt))

    @property
    def count(self) -> int:
        return len(self.joint_names)

    @staticmethod
    def concat(parts: Sequence[Rows]) -> Rows:
        """Stack the rows of several controllers; action columns and mimic sources are offset."""
        col0 = 0
        row0 = 0
        arrays: dict[str, list[np.ndarray]] = {k: [] for k in _ROW_ARRAYS}
        names: list[str] = []
        extras = []
        for p in parts:
            extras += [(r + row0, n, what) for r, n, what in p.extras]
            for k in _ROW_ARRAYS:
                a = getattr(p, k).copy()
                if k in ("act_col", "vel_col", "bx_col", "by_col"):
                    a[a >= 0] += col0
                elif k in ("mimic_src", "yaw_row"):
                    a[a >= 0] += row0
                arrays[k].append(a)
            names += p.joint_names
            col0 += p.action_dim
            row0 += p.count
        cat = {k: np.concatenate(v) if v else np.zeros(0, _ROW_ARRAYS[k]) for k, v in arrays.items()}
        low = np.concatenate([p.action_low for p in parts]) if parts else np.zeros(0, np.float32)
        high = np.concatenate([p.action_high for p in parts]) if parts else np.zeros(0, np.float32)
        return Rows(
            joint_names=names,
            action_low=low.astype(np.float32),
            action_high=high.astype(np.float32),
            normalized=False,
            action_dim=col0,
            extras=extras,
            **cat,
        )


_ROW_ARRAYS = {
    "kind": np.int32,
    "flags": np.int32,
    "act_col": np.int32,
    "vel_col": np.int32,
    "lo": np.float32,
    "hi": np.float32,
    "vlo": np.float32,
    "vhi": np.float32,
    "mimic_src": np.int32,
    "mimic_mul": np.float32,
    "mimic_off": np.float32,
    "kp": np.float32,
    "kd": np.float32,
    "force_limit": np.float32,
    "friction": np.float32,
    "accel": np.bool_,
    "yaw_row": np.int32,
    "base_axis": np.int32,
    "bx_col": np.int32,
    "by_col": np.int32,
    "act_model": np.int32,
    "sat_effort": np.float32,
    "vel_limit": np.float32,
    "ema_alpha": np.float32,
}


def _pos_rows(config, qlimits: np.ndarray, *, mimic: bool = False, posvel: bool = False) -> Rows:
    names = _joint_names(config)
    n = len(names)
    low, high = _bounds(config, config.lower, config.upper, qlimits)
    kp = _per_joint(config, "stiffness", config.stiffness, n, nonneg=True)
    kd = _per_joint(config, "damping", config.damping, n, nonneg=True)
    fl = _per_joint(config, "force_limit", config.force_limit, n, nonneg=True)
    fr = _per_joint(config, "friction", config.friction, n, nonneg=True)
    accel = _drive_modes(config, n)
    for f in ("use_delta", "use_target", "interpolate", "normalize_action"):
        if not isinstance(getattr(config, f), (bool, np.bool_)):
            raise ConfigError(f"{_name(config)}.{f}: expected a bool, got {getattr(config, f)!r}")
    flags = 0
    if config.normalize_action:
        flags |= FLAG_NORMALIZE
    if config.use_delta:
        flags |= FLAG_DELTA
        if config.use_target:
            flags |= FLAG_TARGET
    if config.interpolate:
        flags |= FLAG_INTERPOLATE

    act_col = np.full(n, -1, np.int32)
    vel_col = np.full(n, -1, np.int32)
    mimic_src = np.full(n, -1, np.int32)
    mul = np.ones(n, np.float32)
    off = np.zeros(n, np.float32)
    if mimic:
        mm = _mimic_map(config, names)
        followers, sources = [], []
        for m_name, entry in mm.items():
            if not isinstance(entry, Mapping) or "joint" not in entry:
                raise ConfigError(
                    f"{_name(config)}.mimic[{m_name!r}]: expected {{'joint': name, 'multiplier': m, 'offset': o}}, "
                    f"got {entry!r}"
                )
            c_name = entry["joint"]
            for role, jn in (("mimic joint", m_name), ("control joint", c_name)):
                if jn not in names:
                    raise MimicJointError(f"{_name(config)}.mimic: {role} {jn!r} is not in joint_names {names}")
            raw = (entry.get("multiplier", 1.0), entry.get("offset", 0.0))
            if any(isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating))
                   for x in raw):  # fmt: skip
                raise ConfigError(
                    f"{_name(config)}.mimic[{m_name!r}]: expected numbers for multiplier and offset, got "
                    f"{raw[0]!r}, {raw[1]!r}"
                )
            m, o = float(raw[0]), float(raw[1])
            # Finite in float32, where they are used (1e39 would become inf).
            if not all(math.isfinite(x) and abs(x) <= float(np.finfo(np.float32).max) for x in (m, o)):
                raise ConfigError(
                    f"{_name(config)}.mimic[{m_name!r}]: expected a finite multiplier and offset (within float32 "
                    f"range), got multiplier={m!r}, offset={o!r}"
                )
            if m_name == c_name:
                raise ConfigError(f"{_name(config)}.mimic[{m_name!r}]: a joint cannot mimic itself")
            i, j = names.index(m_name), names.index(c_name)
            followers.append(i)
            sources.append(j)
            mimic_src[i] = j
            mul[i] = np.float32(m)
            off[i] = np.float32(o)
        chained = sorted(set(followers) & set(sources))
        if chained:
            # Walk from a follower whose source follows too, to show the whole chain (or cycle).
            start = next(i for i in followers if mimic_src[i] in chained)
            path = [start]
            while mimic_src[path[-1]] >= 0 and path.count(path[-1]) == 1:
                path.append(int(mimic_src[path[-1]]))
            what = "cycle" if path.count(path[-1]) > 1 else "chain"
            shown = " -> ".join(repr(names[i]) for i in path)
            raise ConfigError(
                f"{_name(config)}.mimic: expected every follower to mimic a commanded joint directly, got a mimic "
                f"{what} {shown} (read 'a' -> 'b' as 'a' follows 'b'); make each follower mimic the commanded joint"
            )
        control = sorted(set(sources))  # ascending position in joint_names, as ManiSkill's torch.unique
        for c, j in enumerate(control):
            act_col[j] = c
        rows_for_action = control
    else:
        act_col[:] = np.arange(n, dtype=np.int32)
        rows_for_action = list(range(n))

    d = len(rows_for_action)
    vlo = np.zeros(n, np.float32)
    vhi = np.zeros(n, np.float32)
    a_low = low[rows_for_action]
    a_high = high[rows_for_action]
    _check_box(config, low, high, names, bool(config.normalize_action), "lower/upper")
    if posvel:
        vl = _per_joint(config, "vel_lower", config.vel_lower, n).astype(np.float32)
        vh = _per_joint(config, "vel_upper", config.vel_upper, n).astype(np.float32)
        _check_box(config, vl, vh, names, bool(config.normalize_action), "vel_lower/vel_upper")
        vlo[:], vhi[:] = vl, vh
        vel_col[:] = np.arange(n, dtype=np.int32) + n
        flags |= FLAG_VEL_TARGET
        a_low = np.concatenate([a_low, vl])
        a_high = np.concatenate([a_high, vh])
        d = 2 * n
    act = actuator_rows(config, n)
    if getattr(config, "ema", None) is not None:
        flags |= FLAG_EMA
    binary = getattr(config, "binary", False)
    if not isinstance(binary, (bool, np.bool_)):
        raise ConfigError(f"{_name(config)}.binary: expected a bool, got {binary!r}")
    if binary:
        if config.use_delta or posvel:
            what = "use_delta=True" if config.use_delta else "a position-velocity config"
            raise ConfigError(f"{_name(config)}.binary: a binary command sets absolute targets, not with {what}")
        flags |= FLAG_BINARY
    return Rows(
        joint_names=names,
        kind=np.full(n, ROW_POS, np.int32),
        flags=np.full(n, flags, np.int32),
        act_col=act_col,
        vel_col=vel_col,
        lo=low.astype(np.float32),
        hi=high.astype(np.float32),
        vlo=vlo,
        vhi=vhi,
        mimic_src=mimic_src,
        mimic_mul=mul,
        mimic_off=off,
        kp=kp.astype(np.float32),
        kd=kd.astype(np.float32),
        force_limit=fl.astype(np.float32),
        friction=fr.astype(np.float32),
        accel=accel,
        action_low=a_low.astype(np.float32),
        action_high=a_high.astype(np.float32),
        normalized=bool(config.normalize_action),
        action_dim=d,
        act_model=act["act_model"],
        sat_effort=act["sat_effort"],
        vel_limit=act["vel_limit"],
        ema_alpha=act["ema_alpha"],
        extras=act["extras"],
    )


def _vel_rows(config, bounds: tuple[np.ndarray, np.ndarray] | None = None) -> Rows:
    names = _joint_names(config)
    n = len(names)
    if bounds is None:
        lo = _per_joint(config, "lower", config.lower, n).astype(np.float32)
        hi = _per_joint(config, "upper", config.upper, n).astype(np.float32)
    else:
        lo, hi = (b.astype(np.float32) for b in bounds)
    if not isinstance(config.normalize_action, (bool, np.bool_)):
        raise ConfigError(f"{_name(config)}.normalize_action: expected a bool, got {config.normalize_action!r}")
    _check_box(config, lo, hi, names, bool(config.normalize_action), "lower/upper")
    return Rows(
        joint_names=names,
        kind=np.full(n, ROW_VEL, np.int32),
        flags=np.full(n, FLAG_NORMALIZE if config.normalize_action else 0, np.int32),
        act_col=np.arange(n, dtype=np.int32),
        vel_col=np.full(n, -1, np.int32),
        lo=lo,
        hi=hi,
        vlo=np.zeros(n, np.float32),
        vhi=np.zeros(n, np.float32),
        mimic_src=np.full(n, -1, np.int32),
        mimic_mul=np.ones(n, np.float32),
        mimic_off=np.zeros(n, np.float32),
        kp=np.zeros(n, np.float32),
        kd=_per_joint(config, "damping", config.damping, n, nonneg=True).astype(np.float32),
        force_limit=_per_joint(config, "force_limit", config.force_limit, n, nonneg=True).astype(np.float32),
        friction=_per_joint(config, "friction", config.friction, n, nonneg=True).astype(np.float32),
        accel=_drive_modes(config, n),
        action_low=lo.copy(),
        action_high=hi.copy(),
        normalized=bool(config.normalize_action),
        action_dim=n,
        **_vel_actuator(config, n),
    )


def _vel_actuator(config, n: int) -> dict:
    act = actuator_rows(config, n)
    if (act["act_model"] == ACT_NET).any():
        raise ConfigError(
            f"{_name(config)}.actuator: an ActuatorNet drives position rows (it reads position errors); use DCMotor "
            f"or PositionBasedEffortLimit on a velocity controller"
        )
    return {k: act[k] for k in ("act_model", "sat_effort", "vel_limit", "extras")}


def _effort_rows(config) -> Rows:
    """Rows of a JointEffortController: the scaled action is the joint effort [N·m or N] (no drive, no target)."""
    names = _joint_names(config)
    n = len(names)
    lo = _per_joint(config, "lower", config.lower, n).astype(np.float32)
    hi = _per_joint(config, "upper", config.upper, n).astype(np.float32)
    if not isinstance(config.normalize_action, (bool, np.bool_)):
        raise ConfigError(f"{_name(config)}.normalize_action: expected a bool, got {config.normalize_action!r}")
    _check_box(config, lo, hi, names, bool(config.normalize_action), "lower/upper")
    z = np.zeros(n, np.float32)
    return Rows(
        joint_names=names,
        kind=np.full(n, ROW_EFFORT, np.int32),
        flags=np.full(n, FLAG_NORMALIZE if config.normalize_action else 0, np.int32),
        act_col=np.arange(n, dtype=np.int32),
        vel_col=np.full(n, -1, np.int32),
        lo=lo,
        hi=hi,
        vlo=z.copy(),
        vhi=z.copy(),
        mimic_src=np.full(n, -1, np.int32),
        mimic_mul=np.ones(n, np.float32),
        mimic_off=z.copy(),
        kp=z.copy(),
        kd=z.copy(),
        force_limit=_per_joint(config, "force_limit", config.force_limit, n, nonneg=True).astype(np.float32),
        friction=_per_joint(config, "friction", config.friction, n, nonneg=True).astype(np.float32),
        accel=np.zeros(n, np.bool_),
        action_low=lo.copy(),
        action_high=hi.copy(),
        normalized=bool(config.normalize_action),
        action_dim=n,
    )


def _base_rows(config, forward: bool) -> Rows:
    """Rows of a mobile base: velocity rows whose x / y targets are the planar action rotated by the measured yaw."""
    names = _joint_names(config)
    n = len(names)
    if n < 3 or (forward and n != 3):
        want = "exactly 3 joints" if forward else "at least 3 joints"
        raise ConfigError(
            f"{_name(config)}.joint_names: expected {want} (the base's x, y and yaw joints, in that order), got {n}: "
            f"{names}"
        )
    if forward:
        # ManiSkill's forward base: action [v, w], bounds broadcast to 2 (not one per joint).
        a_lo = _per_joint(config, "lower", config.lower, 2).astype(np.float32)
        a_hi = _per_joint(config, "upper", config.upper, 2).astype(np.float32)
        if not isinstance(config.normalize_action, (bool, np.bool_)):
            raise ConfigError(f"{_name(config)}.normalize_action: expected a bool, got {config.normalize_action!r}")
        _check_box(config, a_lo, a_hi, ["forward velocity", "yaw rate"], bool(config.normalize_action), "lower/upper")
        rows = _vel_rows(config, bounds=(np.array([a_lo[0], 0, a_lo[1]]), np.array([a_hi[0], 0, a_hi[1]])))
        rows.act_col[:] = [0, -1, 1]
        rows.action_low, rows.action_high, rows.action_dim = a_lo, a_hi, 2
        rows.bx_col[:2] = 0
    else:
        rows = _vel_rows(config)
        rows.bx_col[:2] = 0
        rows.by_col[:2] = 1
    rows.yaw_row[:2] = 2
    rows.base_axis[:2] = [0, 1]
    return rows


def _passive_rows(config) -> Rows:
    names = _joint_names(config)
    n = len(names)
    z = np.zeros(n, np.float32)
    return Rows(
        joint_names=names,
        kind=np.full(n, ROW_PASSIVE, np.int32),
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
        kp=z.copy(),
        kd=_per_joint(config, "damping", config.damping, n, nonneg=True).astype(np.float32),
        force_limit=_per_joint(config, "force_limit", config.force_limit, n, nonneg=True).astype(np.float32),
        friction=_per_joint(config, "friction", config.friction, n, nonneg=True).astype(np.float32),
        accel=np.zeros(n, np.bool_),  # ManiSkill's passive drive is always "force"
        action_low=np.zeros(0, np.float32),
        action_high=np.zeros(0, np.float32),
        normalized=False,
        action_dim=0,
    )


def config_rows(config: ControllerConfig, qlimits: np.ndarray) -> Rows:
    """Validate one config and return its rows.

    Args:
        config: One of this module's config dataclasses.
        qlimits: (n, 2) float joint limits [rad or m] of ``config.joint_names``, in that order.
    """
    # Most derived first: the mimic and pos-vel configs subclass the position config.
    if isinstance(config, PDJointPosMimicControllerConfig):
        return _pos_rows(config, qlimits, mimic=True)
    if isinstance(config, PDJointPosVelControllerConfig):
        return _pos_rows(config, qlimits, posvel=True)
    if isinstance(config, PDJointPosControllerConfig):
        return _pos_rows(config, qlimits)
    if isinstance(config, PDBaseForwardVelControllerConfig):
        return _base_rows(config, forward=True)
    if isinstance(config, PDBaseVelControllerConfig):
        return _base_rows(config, forward=False)
    if isinstance(config, PDJointVelControllerConfig):
        return _vel_rows(config)
    if isinstance(config, JointEffortControllerConfig):
        return _effort_rows(config)
    if isinstance(config, PassiveControllerConfig):
        return _passive_rows(config)
    raise ConfigError(
        f"config: expected a wpctrl controller config (PDJointPosControllerConfig, ...), got {type(config).__name__}"
    )


def check_mode_dict(configs: Mapping[str, ControllerConfig]) -> None:
    """Validate a control-mode dict ``{uid: config}``: string keys, config values, no joint shared by two children."""
    if len(configs) == 0:
        raise ConfigError("control mode: expected at least one {uid: config} entry, got an empty dict")
    owner: dict[str, str] = {}
    for uid, cfg in configs.items():
        if not isinstance(uid, str):
            raise ConfigError(f"control mode: keys must be strings (controller uids), got {uid!r}")
        if not isinstance(cfg, ControllerConfig):
            raise ConfigError(f"control mode[{uid!r}]: expected a controller config, got {type(cfg).__name__}")
        for jn in _joint_names(cfg):
            if jn in owner:
                raise ConfigError(
                    f"control mode: joint {jn!r} is controlled by both {owner[jn]!r} and {uid!r}; each joint may "
                    f"belong to one controller"
                )
            owner[jn] = uid
