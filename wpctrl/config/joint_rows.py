"""The rows of the joint-space families: position (with mimic and position-velocity variants), velocity, effort and
passive joints (ManiSkill's ``pd_joint_*`` configs, :mod:`wpctrl.config.joint`), and the velocity rows the mobile
bases build on (:mod:`wpctrl.config.mobile_base`). Each function validates a config and returns its
:class:`~wpctrl.config.rows.Rows`. Host only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from . import rows
from .actuator_models import ACT_NET, actuator_rows
from .errors import ConfigError, MimicJointError
from .validate import _bounds, _check_box, _drive_modes, _joint_names, _mimic_map, _name, _per_joint


def _pos_rows(config, qlimits: np.ndarray, *, mimic: bool = False, posvel: bool = False) -> rows.Rows:
    names = _joint_names(config)
    n = len(names)
    low, high = _bounds(config, config.lower, config.upper, qlimits)
    kp = _per_joint(config, "stiffness", config.stiffness, n, nonneg=True).astype(np.float32)
    drive = _drive_fields(config, n, damping=True)  # kd, force_limit, friction
    accel = _drive_modes(config, n)
    for f in ("use_delta", "use_target", "interpolate", "normalize_action"):
        if not isinstance(getattr(config, f), (bool, np.bool_)):
            raise ConfigError(f"{_name(config)}.{f}: expected a bool, got {getattr(config, f)!r}")
    flags = 0
    if config.normalize_action:
        flags |= rows.FLAG_NORMALIZE
    if config.use_delta:
        flags |= rows.FLAG_DELTA
        if config.use_target:
            flags |= rows.FLAG_TARGET
    if config.interpolate:
        flags |= rows.FLAG_INTERPOLATE

    vel_col = np.full(n, -1, np.int32)
    if mimic:
        act_col, mimic_src, mul, off, rows_for_action = _mimic(config, names)
    else:
        act_col = np.arange(n, dtype=np.int32)
        mimic_src, mul, off = np.full(n, -1, np.int32), np.ones(n, np.float32), np.zeros(n, np.float32)
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
        flags |= rows.FLAG_VEL_TARGET
        a_low = np.concatenate([a_low, vl])
        a_high = np.concatenate([a_high, vh])
        d = 2 * n
    act = actuator_rows(config, n)
    if getattr(config, "ema", None) is not None:
        flags |= rows.FLAG_EMA
    binary = getattr(config, "binary", False)
    if not isinstance(binary, (bool, np.bool_)):
        raise ConfigError(f"{_name(config)}.binary: expected a bool, got {binary!r}")
    if binary:
        if config.use_delta or posvel:
            what = "use_delta=True" if config.use_delta else "a position-velocity config"
            raise ConfigError(f"{_name(config)}.binary: a binary command sets absolute targets, not with {what}")
        flags |= rows.FLAG_BINARY
    return rows.Rows.of(
        names,
        rows.ROW_POS,
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
        kp=kp,
        **drive,
        accel=accel,
        action_low=a_low,
        action_high=a_high,
        normalized=config.normalize_action,
        action_dim=d,
        **act,  # act_model, sat_effort, vel_limit, ema_alpha, extras
    )


def _mimic(config, names: list[str]):
    """A mimic config's coupling: each row's action column (-1 for a follower), mimic source row, multiplier and
    offset, and the rows that take an action column (the commanded joints, ascending)."""
    n = len(names)
    act_col = np.full(n, -1, np.int32)
    mimic_src = np.full(n, -1, np.int32)
    mul = np.ones(n, np.float32)
    off = np.zeros(n, np.float32)
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
    return act_col, mimic_src, mul, off, control


def _action_box(config, n: int, labels) -> tuple[np.ndarray, np.ndarray]:
    """``lower`` / ``upper`` broadcast to ``n`` action bounds (float32), each pair ordered (named by ``labels`` in the
    error) and finite for a normalised action."""
    lo = _per_joint(config, "lower", config.lower, n).astype(np.float32)
    hi = _per_joint(config, "upper", config.upper, n).astype(np.float32)
    if not isinstance(config.normalize_action, (bool, np.bool_)):
        raise ConfigError(f"{_name(config)}.normalize_action: expected a bool, got {config.normalize_action!r}")
    _check_box(config, lo, hi, labels, bool(config.normalize_action), "lower/upper")
    return lo, hi


def _commanded_rows(config, kind: int, lo: np.ndarray, hi: np.ndarray, **fields) -> rows.Rows:
    """rows.Rows whose action column ``i`` commands row ``i`` (a velocity or an effort), within ``[lo, hi]``."""
    names = _joint_names(config)
    n = len(names)
    return rows.Rows.of(
        names,
        kind,
        flags=np.full(n, rows.FLAG_NORMALIZE if config.normalize_action else 0, np.int32),
        act_col=np.arange(n, dtype=np.int32),
        lo=lo,
        hi=hi,
        action_low=lo.copy(),
        action_high=hi.copy(),
        normalized=config.normalize_action,
        **fields,
    )


def _vel_rows(config, bounds: tuple[np.ndarray, np.ndarray] | None = None) -> rows.Rows:
    """Velocity rows; ``bounds``: the rows' bounds when the action is not one column per joint (already checked)."""
    names = _joint_names(config)
    n = len(names)
    lo, hi = _action_box(config, n, names) if bounds is None else (b.astype(np.float32) for b in bounds)
    return _commanded_rows(
        config,
        rows.ROW_VEL,
        lo,
        hi,
        **_drive_fields(config, n, damping=True),
        accel=_drive_modes(config, n),
        **_vel_actuator(config, n),
    )


def _drive_fields(config, n: int, damping: bool) -> dict:
    """The config's damping (a velocity or passive drive), force limit and friction, per row, validated."""
    out = {f: _per_joint(config, f, getattr(config, f), n, nonneg=True).astype(np.float32)
           for f in (("damping",) if damping else ()) + ("force_limit", "friction")}  # fmt: skip
    if damping:
        out["kd"] = out.pop("damping")
    return out


def _vel_actuator(config, n: int) -> dict:
    act = actuator_rows(config, n)
    if (act["act_model"] == ACT_NET).any():
        raise ConfigError(
            f"{_name(config)}.actuator: an ActuatorNet drives position rows (it reads position errors); use DCMotor "
            f"or PositionBasedEffortLimit on a velocity controller"
        )
    return {k: act[k] for k in ("act_model", "sat_effort", "vel_limit", "extras")}


# The families' row functions: (config, qlimits) -> rows.Rows.


def position_rows(config, qlimits: np.ndarray) -> rows.Rows:
    """PDJointPos: position rows, one action column per joint."""
    return _pos_rows(config, qlimits)


def mimic_rows(config, qlimits: np.ndarray) -> rows.Rows:
    """PDJointPosMimic: position rows whose followers take their target from a commanded joint."""
    return _pos_rows(config, qlimits, mimic=True)


def pos_vel_rows(config, qlimits: np.ndarray) -> rows.Rows:
    """PDJointPosVel: position rows with a velocity target column each."""
    return _pos_rows(config, qlimits, posvel=True)


def velocity_rows(config, qlimits: np.ndarray) -> rows.Rows:
    """PDJointVel: velocity rows (stiffness 0)."""
    return _vel_rows(config)


def effort_rows(config, qlimits: np.ndarray) -> rows.Rows:
    """JointEffort: the scaled action is the joint effort [N·m or N] (no drive, no target)."""
    names = _joint_names(config)
    lo, hi = _action_box(config, len(names), names)
    return _commanded_rows(config, rows.ROW_EFFORT, lo, hi, **_drive_fields(config, len(names), damping=False))


def passive_rows(config, qlimits: np.ndarray) -> rows.Rows:
    """Passive joints: damping toward a zero velocity target, no action (ManiSkill's passive drive is "force")."""
    names = _joint_names(config)
    return rows.Rows.of(names, rows.ROW_PASSIVE, **_drive_fields(config, len(names), damping=True))
