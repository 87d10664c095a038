"""Host-side configs of ManiSkill 3's end-effector controllers (PDEEPos / PDEEPose) and their validation.

Class names, field names, field order and defaults are ManiSkill 3.0.1's (``mani_skill/agents/controllers/
pd_ee_pose.py``), so a ManiSkill ``pd_ee_*`` control-mode dict ports by changing an import. Nothing here touches a
device: :func:`ee_rows` validates a config and returns the joint rows (position rows driven by the EE kernels) plus
an :class:`EESpec` with the EE-specific parameters.

Units: positions [m], rotations [rad] (Euler XYZ increments, as ManiSkill), joint quantities as in
:mod:`wpctrl.config.joint`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal, Union, get_args

import numpy as np

from .errors import ConfigError
from .family import ControllerClass, ControllerConfig, Family
from .joint import PDJointPosControllerConfig
from .joint_rows import _pos_rows
from .robot_description import Descriptions, descriptions_for
from .rows import Rows
from .validate import DriveMode, _f32, _joint_names

POS_FRAMES = ("root_translation", "body_translation")
PoseFrame = Literal[
    "body_translation:root_aligned_body_rotation",
    "root_translation:root_aligned_body_rotation",
    "body_translation:body_aligned_body_rotation",
    "root_translation:body_aligned_body_rotation",
]
"""Frames of a pose action's position (root or EE axes) and rotation (pre- or post-multiplied)."""
POSE_FRAMES = get_args(PoseFrame)
SOLVER_TYPES = ("levenberg_marquardt", "pseudo_inverse")
MAX_EE_DOF = 8
"""Most controlled joints on one EE chain (the fixed-size Jacobian of the kernels is 6 x MAX_EE_DOF)."""


def _default_solver() -> dict:
    return dict(type="levenberg_marquardt", alpha=1.0)


@dataclass
class PDEEPosControllerConfig(ControllerConfig):
    controller_cls = ControllerClass("wpctrl.controllers.ee", "PDEEPosController")
    family = Family(lambda config, qlimits: ee_rows(config, qlimits), part="wpctrl.engine.parts.ee")  # (below)

    pos_lower: Union[float, Sequence[float]]
    """Lower bound of the position action [m] (per axis or one value for x, y, z); None: unbounded (-inf)."""
    pos_upper: Union[float, Sequence[float]]
    """Upper bound of the position action [m]; None: unbounded (+inf)."""
    stiffness: Union[float, Sequence[float]]
    """Joint drive stiffness Kp [N·m/rad or N/m] of the chain's joints."""
    damping: Union[float, Sequence[float]]
    """Joint drive damping Kd [N·m·s/rad or N·s/m]."""
    force_limit: Union[float, Sequence[float]] = 1e10
    """Joint drive effort limit [N·m or N]."""
    friction: Union[float, Sequence[float]] = 0.0
    """Joint friction [N·m or N]."""
    ee_link: str = None
    """The controlled link: a body label of the Newton model (exact or its last ``/`` part), a site/shape label on
    a body, or a link of ``urdf_path`` merged into a kept ancestor body (e.g. by ``collapse_fixed_joints``)."""
    urdf_path: str = None
    """Optional URDF of the robot; used only where the model lacks ``ee_link``, to find its fixed offset."""
    frame: Literal["body_translation", "root_translation"] = "root_translation"
    """Frame of the position delta: the root link's axes or the EE's own axes."""
    root_link_name: str | None = None
    """The root frame of all EE poses (a body label); None: the articulation root (the world frame for a fixed
    base merged into the world, shifted by each env's own root placement)."""
    use_delta: bool = True
    """Actions are pose increments; False: absolute poses in the root frame."""
    use_target: bool = False
    """Compose increments on the last target pose instead of the measured EE pose."""
    interpolate: bool = False
    """Ramp the joint drive targets from the measured to the IK joint positions over the substeps."""
    normalize_action: bool = True
    """Actions in [-1, 1] are clipped and scaled onto [lower, upper]."""
    delta_solver_config: dict = field(default_factory=_default_solver)
    """``type`` ("levenberg_marquardt" | "pseudo_inverse"), ``alpha`` (step scale), and wpctrl's
    ``solver_iterations`` (default 1: ManiSkill's GPU semantics, one step per control step; more: Pinocchio-style
    CLIK as ManiSkill runs on CPU), ``tolerance`` (CLIK success threshold on ‖log6‖, default 1e-4), ``clik_dt``
    (0.1), ``clik_damping`` (1e-6), ``lm_lambda`` (1e-4) and ``rotation_sign`` ("maniskill": the rotation action is
    multiplied by ``rot_lower`` as ManiSkill does (issue #1469); "corrected": a positive action rotates positively)."""
    drive_mode: Union[Sequence[DriveMode], DriveMode] = "force"
    """"force" or "acceleration", for all joints or per joint."""


@dataclass
class PDEEPoseControllerConfig(PDEEPosControllerConfig):
    controller_cls = ControllerClass("wpctrl.controllers.ee", "PDEEPoseController")

    rot_lower: Union[float, Sequence[float]] = None
    """Lower bound of the rotation action [rad]; ManiSkill scales the clipped rotation by this value (see
    ``delta_solver_config["rotation_sign"]``)."""
    rot_upper: Union[float, Sequence[float]] = None
    """Upper bound of the rotation action [rad] (only the action space uses it, as ManiSkill)."""
    stiffness: Union[float, Sequence[float]] = None
    damping: Union[float, Sequence[float]] = None
    force_limit: Union[float, Sequence[float]] = 1e10
    friction: Union[float, Sequence[float]] = 0.0
    frame: PoseFrame = "root_translation:root_aligned_body_rotation"
    """Frames of the position delta (root or EE axes) and of the rotation delta (pre- or post-multiplied)."""


EE_CONFIGS = (PDEEPosControllerConfig, PDEEPoseControllerConfig)

# Solver kinds and frame bits (shared with the kernels).
SOLVER_LM = 0
SOLVER_PINV = 1
FRAME_BODY_TRANS = 1
FRAME_BODY_ROT = 2


@dataclass
class EESpec:
    """The EE-specific, validated parameters of one config (host)."""

    pose: bool  # PDEEPose (6 action columns) or PDEEPos (3)
    frame_bits: int
    use_delta: bool
    use_target: bool
    normalize: bool
    solver: int
    alpha: float
    iterations: int
    tolerance: float
    clik_dt: float
    clik_damping: float
    lm_lambda: float
    rot_scale: np.ndarray  # (3,) float32: the processed rotation is r_clipped * rot_scale
    ee_link: str
    urdf_path: str | None
    root_link_name: str | None
    descriptions: Descriptions  # urdf_path's joints, else the registered robots': for links the model lacks

    joint_targets = True  # its solve writes the rows' joint position targets (target clipping applies)


def _name(c) -> str:
    return type(c).__name__


def _vec3(c, fname: str, value, allow_none: bool) -> np.ndarray:
    if value is None:
        if allow_none:
            return np.full(3, np.nan)
        raise ConfigError(f"{_name(c)}.{fname}: expected a number or 3 numbers, got None")
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf":  # strings ("0.1" would parse), bools, objects
            raise TypeError(f"dtype {raw.dtype}")
        a = raw.astype(np.float64)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{_name(c)}.{fname}: expected a number or 3 numbers, got {value!r}") from e
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] not in (1, 3)):
        raise ConfigError(
            f"{_name(c)}.{fname}: expected a scalar or 3 values (x, y, z), got shape {a.shape}: {value!r}"
        )
    a = np.broadcast_to(a, (3,)).astype(np.float64)
    if np.isnan(a).any():
        raise ConfigError(f"{_name(c)}.{fname}: expected finite numbers, got {value!r}")
    return a


def _solver(c) -> dict:
    d = c.delta_solver_config
    if d is None:
        d = _default_solver()
    if not isinstance(d, Mapping):
        raise ConfigError(f"{_name(c)}.delta_solver_config: expected a dict like {_default_solver()}, got {d!r}")
    known = {"type", "alpha", "solver_iterations", "tolerance", "clik_dt", "clik_damping", "lm_lambda", "rotation_sign"}
    extra = sorted(set(d) - known)
    if extra:
        raise ConfigError(f"{_name(c)}.delta_solver_config: unknown keys {extra}; expected keys among {sorted(known)}")
    t = d.get("type", "levenberg_marquardt")
    if t not in SOLVER_TYPES:
        raise ConfigError(f"{_name(c)}.delta_solver_config['type']: expected one of {SOLVER_TYPES}, got {t!r}")
    out = {"type": t}
    for key, default, lo in (
        ("alpha", 1.0, None),
        ("tolerance", 1e-4, 0.0),
        ("clik_dt", 0.1, 0.0),
        ("clik_damping", 1e-6, 0.0),
        ("lm_lambda", 1e-4, 0.0),
    ):
        v = d.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
            raise ConfigError(f"{_name(c)}.delta_solver_config[{key!r}]: expected a finite number, got {v!r}")
        if lo is not None and not v > lo:
            raise ConfigError(f"{_name(c)}.delta_solver_config[{key!r}]: expected a number > {lo}, got {v!r}")
        out[key] = float(v)
    it = d.get("solver_iterations", 1)
    if isinstance(it, bool) or not isinstance(it, (int, np.integer)) or not 1 <= it <= 10000:
        raise ConfigError(
            f"{_name(c)}.delta_solver_config['solver_iterations']: expected an int in [1, 10000], got {it!r}"
        )
    out["solver_iterations"] = int(it)
    sign = d.get("rotation_sign", "maniskill")
    if sign not in ("maniskill", "corrected"):
        raise ConfigError(
            f"{_name(c)}.delta_solver_config['rotation_sign']: expected 'maniskill' or 'corrected', got {sign!r}"
        )
    out["rotation_sign"] = sign
    return out


def link_and_frame(c, frames: tuple[str, ...]) -> int:
    """Check an end-effector config's ``ee_link``, ``urdf_path``, ``root_link_name`` and ``frame`` (one of
    ``frames``); return the frame's bits (``FRAME_BODY_TRANS``, ``FRAME_BODY_ROT``)."""
    if not isinstance(c.ee_link, str) or not c.ee_link:
        raise ConfigError(f"{_name(c)}.ee_link: expected the name of the controlled link, got {c.ee_link!r}")
    if c.urdf_path is not None and not isinstance(c.urdf_path, (str, bytes)) and not hasattr(c.urdf_path, "__fspath__"):
        raise ConfigError(f"{_name(c)}.urdf_path: expected a path or None, got {c.urdf_path!r}")
    if c.root_link_name is not None and not isinstance(c.root_link_name, str):
        raise ConfigError(f"{_name(c)}.root_link_name: expected a link name or None, got {c.root_link_name!r}")
    if c.frame not in frames:
        raise ConfigError(f"{_name(c)}.frame: expected one of {frames}, got {c.frame!r}")
    return (FRAME_BODY_TRANS if c.frame.startswith("body_translation") else 0) | (
        FRAME_BODY_ROT if c.frame.endswith("body_aligned_body_rotation") else 0
    )


def check_pose_box(c, low: np.ndarray, high: np.ndarray) -> None:
    """Each axis of a pose action's bounds (x, y, z, then rx, ry, rz) ordered: lower <= upper."""
    axes = ["x", "y", "z", "rx", "ry", "rz"]
    bad = np.nonzero(low > high)[0]
    if bad.size:
        i = int(bad[0])
        what = "pos_lower/pos_upper" if i < 3 else "rot_lower/rot_upper"
        raise ConfigError(
            f"{_name(c)}.{what}: lower must be <= upper, got lower={_f32(low[i])} > "
            f"upper={_f32(high[i])} for axis {axes[i]!r}"
        )


def ee_rows(c: PDEEPosControllerConfig, qlimits: np.ndarray) -> tuple[Rows, EESpec]:
    """Validate an EE config; return its joint rows (position rows, no action column of their own) and its spec.

    Args:
        c: A :class:`PDEEPosControllerConfig` or :class:`PDEEPoseControllerConfig`.
        qlimits: (n, 2) joint limits [rad or m] of ``c.joint_names`` (only their count is used).
    """
    pose = isinstance(c, PDEEPoseControllerConfig)
    names = _joint_names(c)
    n = len(names)
    if not 1 <= n <= MAX_EE_DOF:
        raise ConfigError(f"{_name(c)}.joint_names: expected 1 to {MAX_EE_DOF} joints on the EE chain, got {n}")
    for f in ("use_delta", "use_target", "interpolate", "normalize_action"):
        if not isinstance(getattr(c, f), (bool, np.bool_)):
            raise ConfigError(f"{_name(c)}.{f}: expected a bool, got {getattr(c, f)!r}")
    bits = link_and_frame(c, POSE_FRAMES if pose else POS_FRAMES)
    s = _solver(c)

    normalize = bool(c.normalize_action)
    plo = _vec3(c, "pos_lower", c.pos_lower, allow_none=not normalize)
    phi = _vec3(c, "pos_upper", c.pos_upper, allow_none=not normalize)
    low, high = [np.nan_to_num(plo, nan=-np.inf)], [np.nan_to_num(phi, nan=np.inf)]
    rot_scale = np.ones(3, np.float32)
    if pose:
        rlo = _vec3(c, "rot_lower", c.rot_lower, allow_none=not normalize)
        rhi = _vec3(c, "rot_upper", c.rot_upper, allow_none=not normalize)
        low.append(np.nan_to_num(rlo, nan=-np.inf))
        high.append(np.nan_to_num(rhi, nan=np.inf))
        if normalize:
            # ManiSkill multiplies the norm-clipped rotation by rot_lower (#1469); "corrected" uses the half range.
            rot_scale = (rlo if s["rotation_sign"] == "maniskill" else 0.5 * (rhi - rlo)).astype(np.float32)
    a_low = np.concatenate(low).astype(np.float32)
    a_high = np.concatenate(high).astype(np.float32)
    check_pose_box(c, a_low, a_high)

    # Joint rows: position rows (drive, interpolation, NaN hold, reset as any joint controller) whose targets the
    # EE kernel writes; act_col -1 tells the joint kernel to keep them.
    base = PDJointPosControllerConfig(
        names,
        None,
        None,
        c.stiffness,
        c.damping,
        c.force_limit,
        c.friction,
        interpolate=c.interpolate,
        normalize_action=False,
        drive_mode=c.drive_mode,
    )
    try:
        rows = _pos_rows(base, np.full((n, 2), [-np.inf, np.inf], np.float32))
    except ConfigError as e:
        raise ConfigError(str(e).replace("PDJointPosControllerConfig", _name(c))) from None
    rows.act_col[:] = -1
    rows.action_low = a_low
    rows.action_high = a_high
    rows.action_dim = 6 if pose else 3
    rows.normalized = normalize
    spec = EESpec(
        pose=pose,
        frame_bits=bits,
        use_delta=bool(c.use_delta),
        use_target=bool(c.use_target),
        normalize=normalize,
        solver=SOLVER_LM if s["type"] == "levenberg_marquardt" else SOLVER_PINV,
        alpha=s["alpha"],
        iterations=s["solver_iterations"],
        tolerance=s["tolerance"],
        clik_dt=s["clik_dt"],
        clik_damping=s["clik_damping"],
        lm_lambda=s["lm_lambda"],
        rot_scale=rot_scale,
        ee_link=c.ee_link,
        urdf_path=None if c.urdf_path is None else str(c.urdf_path),
        root_link_name=c.root_link_name,
        descriptions=descriptions_for(None if c.urdf_path is None else str(c.urdf_path)),
    )
    return rows, spec
