"""Validation helpers of the config layer: per-joint broadcasting, bounds, joint names, drive modes, mimic maps.

Every error is a :class:`~wpctrl.config.errors.ConfigError` naming the config class, the field and the expected vs.
received value. Host only.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import Literal, get_args

import numpy as np

from .errors import ConfigError

logger = logging.getLogger("wpctrl")

DriveMode = Literal["force", "acceleration"]
_DRIVE_MODES = get_args(DriveMode)


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
    if not isinstance(mode, (str, Sequence)):
        raise ConfigError(
            f"{_name(config)}.drive_mode: expected 'force', 'acceleration' or a sequence of {n} of them, got {mode!r}"
        )
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
