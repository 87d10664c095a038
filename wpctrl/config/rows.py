"""Rows: the flat, per-joint description of a control mode that one kernel launch handles.

A config becomes rows through its family (:mod:`wpctrl.config.family`: each config class declares how); this module
holds the table itself (:class:`Rows`, one row per controlled joint: kind, flags, action columns, bounds, gains...),
the row kinds and flags the kernels branch on, and the checks of a whole control-mode dict. Plain numpy tables that
the binding and the engine upload. Host only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from .errors import ConfigError
from .family import ControllerConfig
from .validate import _joint_names

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

    @classmethod
    def of(cls, names: Sequence[str], kind: int, *, action_low=None, action_high=None, normalized=False,
           action_dim: int | None = None, **fields) -> Rows:  # fmt: skip
        """Rows of the joints ``names``, all of ``kind``; a per-row field not given takes its neutral value (no flag,
        no action or velocity column, zero bounds, gains and limits, no mimic source, a force drive). ``action_low``
        / ``action_high``: the raw bounds of the action (none by default); ``action_dim`` their length unless given."""
        n = len(names)
        zero = lambda: np.zeros(n, np.float32)  # noqa: E731
        neutral = {
            "flags": np.zeros(n, np.int32),
            "act_col": np.full(n, -1, np.int32),
            "vel_col": np.full(n, -1, np.int32),
            "lo": zero(), "hi": zero(), "vlo": zero(), "vhi": zero(),
            "mimic_src": np.full(n, -1, np.int32),
            "mimic_mul": np.ones(n, np.float32),
            "mimic_off": zero(),
            "kp": zero(), "kd": zero(), "force_limit": zero(), "friction": zero(),
            "accel": np.zeros(n, np.bool_),
        }  # fmt: skip
        neutral.update(fields)
        low = np.zeros(0, np.float32) if action_low is None else np.asarray(action_low, np.float32)
        high = np.zeros(0, np.float32) if action_high is None else np.asarray(action_high, np.float32)
        return cls(
            joint_names=list(names),
            kind=np.full(n, kind, np.int32),
            action_low=low,
            action_high=high,
            normalized=bool(normalized),
            action_dim=int(low.shape[0]) if action_dim is None else int(action_dim),
            **neutral,
        )

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


def controller_rows(config: ControllerConfig, qlimits: np.ndarray) -> tuple[Rows, object]:
    """Validate one config through its family; return its rows and its spec (None for a family without a part).

    Args:
        config: A controller config (its class declares ``family``).
        qlimits: (n, 2) float joint limits [rad or m] of ``config.joint_names``, in that order.
    """
    family = type(config).family if isinstance(config, ControllerConfig) else None
    if family is None:
        what = type(config).__name__
        raise ConfigError(f"config: expected a wpctrl controller config (PDJointPosControllerConfig, ...), got {what}")
    return family.make(config, qlimits)


def config_rows(config: ControllerConfig, qlimits: np.ndarray) -> Rows:
    """Validate one config and return its rows (:func:`controller_rows` without the spec)."""
    return controller_rows(config, qlimits)[0]


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
