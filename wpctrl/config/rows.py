"""Rows: the flat, per-joint description of a control mode that one kernel launch handles.

Validates configs (:mod:`wpctrl.config.joint`) and turns them into per-joint rows (plain numpy tables) that the
binding and the engine upload. Host only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .base import PDBaseForwardVelControllerConfig, PDBaseVelControllerConfig
from .joint import (
    _DRIVE_MODES,
    ConfigError,
    ControllerConfig,
    MimicJointError,
    PassiveControllerConfig,
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointPosVelControllerConfig,
    PDJointVelControllerConfig,
    logger,
)

# Row kinds (one row per controlled joint).
ROW_POS = 0
"""Position-driven joint (PDJointPos, mimic, PDJointPosVel)."""
ROW_VEL = 1
"""Velocity-driven joint (PDJointVel): stiffness 0, velocity target from the action."""
ROW_PASSIVE = 2
"""Passive joint: stiffness 0, damping toward a zero velocity target, no action."""

# Row flag bits.
FLAG_NORMALIZE = 1
FLAG_DELTA = 2
FLAG_TARGET = 4
FLAG_INTERPOLATE = 8
FLAG_VEL_TARGET = 16
"""The row's velocity drive target comes from the action (PDJointPosVel)."""


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

    def __post_init__(self):
        n = len(self.joint_names)
        for k in ("yaw_row", "base_axis", "bx_col", "by_col"):
            if getattr(self, k) is None:
                setattr(self, k, np.full(n, -1, np.int32))

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
        for p in parts:
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
}


def _name(config) -> str:
    return type(config).__name__


def _per_joint(config, field_name: str, value, n: int, *, allow_none: bool = False, nonneg: bool = False):
    """Broadcast a scalar or length-n sequence to a float64 (n,) array, as ManiSkill's np.broadcast_to does."""
    if value is None:
        if allow_none:
            return None
        raise ConfigError(f"{_name(config)}.{field_name}: expected a number or a sequence of {n} numbers, got None")
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf":  # strings ("1e3" would parse), bools, None, objects
            raise TypeError(f"dtype {raw.dtype}")
        arr = raw.astype(np.float64)
    except (TypeError, ValueError) as e:
        raise ConfigError(
            f"{_name(config)}.{field_name}: expected a number or a sequence of {n} numbers, got {value!r} "
            f"({type(value).__name__})"
        ) from e
    if arr.ndim > 1 or (arr.ndim == 1 and arr.shape[0] not in (1, n)):
        raise ConfigError(
            f"{_name(config)}.{field_name}: expected a scalar or {n} values (one per joint in joint_names), "
            f"got shape {arr.shape}: {value!r}"
        )
    arr = np.broadcast_to(arr, (n,)).astype(np.float64)

    def bad(mask, expected: str):
        i = int(np.nonzero(mask)[0][0])
        names = getattr(config, "joint_names", None)
        joint = f" for joint {names[i]!r}" if isinstance(names, Sequence) and i < len(names) else ""
        where = f" (in {value!r})" if arr.shape[0] > 1 and np.ndim(value) else ""
        raise ConfigError(f"{_name(config)}.{field_name}: expected {expected}, got {float(arr[i])!r}{joint}{where}")

    if np.isnan(arr).any():
        bad(np.isnan(arr), "finite numbers")
    if nonneg:
        if field_name == "force_limit":  # an infinite force limit means no limit (also beyond float32's range)
            arr = np.where(arr > float(np.finfo(np.float32).max), np.inf, arr)
        else:
            # Values are used in float32: 1e39 would become inf there (and inf * 0 = NaN torques).
            with np.errstate(over="ignore"):
                bad_inf = ~np.isfinite(arr.astype(np.float32))
            if bad_inf.any():
                bad(bad_inf, "finite numbers >= 0 (within float32 range, |x| <= 3.4e38)")
        if (arr < 0).any():
            bad(arr < 0, "values >= 0")
    return arr


def _drive_modes(config, n: int) -> np.ndarray:
    mode = getattr(config, "drive_mode", "force")
    modes = [mode] * n if isinstance(mode, str) else list(mode)
    if len(modes) != n:
        raise ConfigError(
            f"{_name(config)}.drive_mode: expected 'force', 'acceleration' or a sequence of {n} of them, "
            f"got {len(modes)} values: {mode!r}"
        )
    for m in modes:
        if m not in _DRIVE_MODES:
            raise ConfigError(f"{_name(config)}.drive_mode: expected one of {_DRIVE_MODES}, got {m!r}")
    return np.array([m == "acceleration" for m in modes], dtype=np.bool_)


def _joint_names(config) -> list[str]:
    names = config.joint_names
    if isinstance(names, str) or not isinstance(names, Sequence) or not all(isinstance(s, str) for s in names):
        raise ConfigError(f"{_name(config)}.joint_names: expected a sequence of joint-name strings, got {names!r}")
    names = list(names)
    dup = sorted({s for s in names if names.count(s) > 1})
    if dup:
        raise ConfigError(f"{_name(config)}.joint_names: each joint may appear once, got duplicates {dup}")
    return names


def _bounds(config, lower, upper, qlimits: np.ndarray, fields=("lower", "upper")):
    """Position bounds as ManiSkill builds them: the joint limits, each column overwritten independently."""
    n = qlimits.shape[0]
    lim = np.array(qlimits, dtype=np.float32, copy=True)
    lo = _per_joint(config, fields[0], lower, n, allow_none=True)
    hi = _per_joint(config, fields[1], upper, n, allow_none=True)
    if lo is not None:
        lim[:, 0] = lo
    if hi is not None:
        lim[:, 1] = hi
    return lim[:, 0].copy(), lim[:, 1].copy()


def _f32(x) -> str:
    """The shortest repr of a float32 value (-1.7628, not -1.7627999782562256)."""
    return str(np.float32(x))


def _check_box(config, low: np.ndarray, high: np.ndarray, names: Sequence[str], normalized: bool, what: str):
    bad = np.nonzero(low > high)[0]
    if bad.size:
        i = int(bad[0])
        raise ConfigError(
            f"{_name(config)}.{what}: lower must be <= upper, got lower={_f32(low[i])} > upper={_f32(high[i])} "
            f"for joint {names[i]!r}"
        )
    if normalized:
        inf = np.nonzero(~np.isfinite(low) | ~np.isfinite(high))[0]
        if inf.size:
            i = int(inf[0])
            raise ConfigError(
                f"{_name(config)}.{what}: normalize_action needs finite bounds, got "
                f"[{_f32(low[i])}, {_f32(high[i])}] for joint {names[i]!r} (an unlimited joint: set lower/upper in "
                f"the config)"
            )


def _mimic_map(config, names: list[str]) -> dict[str, dict[str, float]]:
    mimic = config.mimic if config.mimic is not None else {}
    if not isinstance(mimic, Mapping):
        raise ConfigError(f"{_name(config)}.mimic: expected a dict {{mimic_joint: {{'joint': name}}}}, got {mimic!r}")
    if len(mimic) == 0:
        if len(names) == 2:
            logger.warning(
                "%s.mimic is empty: %r follows %r (the second joint is commanded, as in ManiSkill)",
                _name(config),
                names[0],
                names[1],
            )
            return {names[0]: {"joint": names[1]}}
        raise ConfigError(
            f"{_name(config)}.mimic: an empty mimic map is only allowed with exactly 2 joints, got {len(names)} "
            f"joints {names}"
        )
    return dict(mimic)


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
            try:
                m = float(entry.get("multiplier", 1.0))
                o = float(entry.get("offset", 0.0))
            except (TypeError, ValueError) as e:
                raise ConfigError(
                    f"{_name(config)}.mimic[{m_name!r}]: expected numbers for multiplier and offset, got "
                    f"{entry.get('multiplier', 1.0)!r}, {entry.get('offset', 0.0)!r}"
                ) from e
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
