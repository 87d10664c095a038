"""Actuator models beyond ManiSkill's PD law, for explicit actuation: what limits (or replaces) the PD torque.

Attach one to a joint config's trailing ``actuator`` field, e.g.
``PDJointPosControllerConfig(..., actuator=wpctrl.DCMotor(saturation_effort=120.0, velocity_limit=7.5))``. The
parameters broadcast over the config's joints (a number, or one value per joint). Host only; every value is
validated here, before anything reaches a device.

- :class:`DCMotor`: the four-quadrant torque-speed envelope of a DC motor (Isaac Lab's ``DCMotor``, Newton's
  ``ClampingDCMotor``).
- :class:`PositionBasedEffortLimit`: an effort limit interpolated from a table over the joint position (Isaac Lab's
  ``RemotizedPDActuator``, Newton's ``ClampingPositionBased``).
- :class:`ActuatorNet`: a learned actuator (MLP over a history of position errors and velocities, or an LSTM),
  loaded from TorchScript as Isaac Lab's ``ActuatorNetMLP`` / ``ActuatorNetLSTM``, evaluated in a Warp kernel.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, Union

import numpy as np

from .errors import ConfigError
from .validate import _name, _per_joint

Number = Union[float, Sequence[float]]


@dataclass(frozen=True)
class DCMotor:
    """DC motor torque-speed envelope: ``tau = clip(tau_PD, max(s (-1 - v / v_max), -L), min(s (1 - v / v_max), L))``
    with ``s`` the stall (saturation) effort, ``v_max`` the no-load speed, ``L`` the config's ``force_limit`` and
    ``v`` the measured joint velocity clipped to the corner velocities ``±v_max (1 + L / s)`` (where the envelope
    meets ``±L``), as Isaac Lab and Newton do. Per env: ``ctrl.saturation_effort`` / ``ctrl.velocity_limit``,
    randomisable with ``randomize_drive_properties``."""

    saturation_effort: Number
    """Stall effort s [N·m or N] (>= 0)."""
    velocity_limit: Number
    """No-load speed v_max [rad/s or m/s] (> 0)."""


@dataclass(frozen=True)
class PositionBasedEffortLimit:
    """``|tau| <= f(q)``, ``f`` the linear interpolation of ``(positions, efforts)`` at the measured position (end
    values held outside the table), and ``<= force_limit``. One table for all the config's joints."""

    positions: Sequence[float]
    """Sample positions [rad or m], non-decreasing."""
    efforts: Sequence[float]
    """Effort limits at those positions [N·m or N], >= 0."""


@dataclass(frozen=True)
class ActuatorNet:
    """A learned actuator: a network maps a joint's position error and velocity to its torque, per env and joint.

    ``network`` is a TorchScript file (what Isaac Lab loads) or a ``torch.nn.Module``: an ``nn.Sequential`` of
    ``Linear`` layers and elementwise activations (MLP), or a module holding an ``nn.LSTM`` followed by ``Linear``
    / activation layers (LSTM; called once per substep with the per-env, per-joint hidden and cell state). Torch is
    needed only to read the weights; the network runs in a Warp kernel (CPU and CUDA, graph-capturable).

    MLP input (Isaac Lab's ``ActuatorNetMLP``): the position errors ``q* - q`` at ``input_idx`` substeps ago times
    ``pos_scale`` and the velocities at the same substeps times ``vel_scale``, concatenated in ``input_order``; the
    output times ``torque_scale`` is the computed effort. LSTM input (``ActuatorNetLSTM``): ``[q* - q, qd]`` (scaled
    the same way). A reset zeroes the reset envs' history (and hidden state). The computed effort is then clipped
    by the DC-motor envelope of ``saturation_effort`` / ``velocity_limit`` (Isaac Lab's actuator nets are DC
    motors; inf: no envelope) and by ``force_limit``.
    """

    network: Any
    """TorchScript path (str / PathLike) or a torch module."""
    input_idx: Sequence[int] = (0, 1, 2)
    """MLP: which past substeps feed the network (0: the current one)."""
    pos_scale: float = 1.0
    vel_scale: float = 1.0
    torque_scale: float = 1.0
    input_order: Literal["pos_vel", "vel_pos"] = "pos_vel"
    saturation_effort: Number = math.inf
    """DC-motor stall effort [N·m or N] of the envelope applied to the network's output (inf: none)."""
    velocity_limit: Number = math.inf
    """DC-motor no-load speed [rad/s or m/s] (inf: none)."""
    kind: Literal["auto", "mlp", "lstm"] = "auto"
    """``"auto"``: an LSTM if the module holds one, else an MLP."""
    kernel: Literal["auto", "unrolled", "3xtf32", "tiled"] = "auto"
    """How the network runs on the device. ``"unrolled"``: its weights compiled into the kernel as instruction
    operands, one thread per (env, joint), no loads of weights (the fastest for actuator-sized networks; one compile
    per network). ``"3xtf32"``: an MLP's layers as warp-wide matrix products on the tensor cores at float32
    accuracy (each product three TF32 ones, CUTLASS's 3xTF32), 32 rows per warp, the weights as data (one compile per
    network shape); CUDA sm_80 or later, and the CPU (where it emulates the same rounding, for tests). ``"tiled"``:
    the weights staged in shared memory once per block, rows batched into tiles and each layer a tiled matrix product
    (one compile per network shape; for networks of up to 16,384 weights: the one kernel for an LSTM or a wide MLP
    too large to compile in, and on GPUs without TF32 tensor cores).
    ``"auto"``: unrolled up to 4,096 multiply-adds per row; past that ``"3xtf32"`` for an MLP of layers up to 128
    wide on CUDA sm_80 or later, else tiled."""
    launch: Literal["auto", "fused", "separate"] = "auto"
    """Where the network runs in each substep. ``"fused"``: in the substep kernel's launch (one launch per substep:
    the network's rows are threads of the same grid as the per-env substep threads); it needs the unrolled kernel, the
    only network of the mode, targets that are neither delayed (``delay``) nor interpolated (``interpolate``) and no
    other launch after the substep's, and is refused with the reason otherwise. ``"separate"``: a launch of its own
    after the substep kernel's (two launches per substep). ``"auto"``: fused wherever that is allowed, else separate.
    The results are the same (bit for bit on the CPU; on CUDA to float32 rounding: the fused kernel compiles the
    substep's code with the network's fast math). Fused measured never slower on an H200, and at 4,096 envs a control
    step about a sixth shorter."""


ACTUATOR_TYPES = (DCMotor, PositionBasedEffortLimit, ActuatorNet)

NET_KERNELS = ("auto", "unrolled", "3xtf32", "tiled")
"""The accepted values of ``ActuatorNet.kernel``."""


def _f32(x) -> float:
    """``x`` as the kernels read it: a float32 (inf beyond its range, 0 below its smallest subnormal)."""
    with np.errstate(over="ignore"):
        return float(np.float32(x))


# Row codes of the actuator model (the step kernels specialise on them).
ACT_NONE = 0
ACT_DC_MOTOR = 1
ACT_POSITION_LIMIT = 2
ACT_NET = 3


def actuator_rows(config, n: int) -> dict:
    """Validate ``config.actuator`` (and ``ema`` / ``binary``) for ``n`` joints; the per-row arrays they add.

    Returns ``{"act_model", "sat_effort", "vel_limit", "ema_alpha", "extras"}``: per-row int32 / float32 arrays, and
    ``extras`` as ``[(first row, rows, actuator)]`` for models that carry more than per-row numbers (tables, nets).
    """
    act = getattr(config, "actuator", None)
    out = {
        "act_model": np.zeros(n, np.int32),
        "sat_effort": np.full(n, np.inf, np.float32),
        "vel_limit": np.full(n, np.inf, np.float32),
        "ema_alpha": np.ones(n, np.float32),
        "extras": [],
    }
    ema = getattr(config, "ema", None)
    if ema is not None:
        if isinstance(ema, bool) or not isinstance(ema, (int, float)) or not (0.0 < _f32(ema) <= 1.0):
            raise ConfigError(f"{_name(config)}.ema: expected a number 0 < alpha <= 1 (or None), got {ema!r}")
        out["ema_alpha"][:] = float(ema)
    if act is None:
        return out
    if not isinstance(act, ACTUATOR_TYPES):
        raise ConfigError(
            f"{_name(config)}.actuator: expected wpctrl.DCMotor, wpctrl.PositionBasedEffortLimit, wpctrl.ActuatorNet "
            f"or None, got {type(act).__name__}"
        )
    where = f"{_name(config)}.actuator"

    def envelope(sat, vlim, allow_inf: bool):
        s = _per_joint(config, "actuator.saturation_effort", sat, n)
        v = _per_joint(config, "actuator.velocity_limit", vlim, n)
        with np.errstate(over="ignore"):  # checked as the kernels read them: 1e39 is inf in float32, 1e-46 is 0
            s, v = s.astype(np.float32), v.astype(np.float32)
        if (s < 0).any():
            raise ConfigError(f"{where}.saturation_effort: expected values >= 0, got {sat!r}")
        if (v <= 0).any():
            raise ConfigError(f"{where}.velocity_limit: expected values > 0, got {vlim!r}")
        if not allow_inf and (not np.isfinite(s).all() or not np.isfinite(v).all()):
            raise ConfigError(f"{where}: expected finite saturation_effort and velocity_limit, got {sat!r}, {vlim!r}")
        if (np.isinf(s) & np.isfinite(v)).any():  # s (1 - v/v_max) is inf * 0 = NaN at v = v_max
            raise ConfigError(f"{where}.saturation_effort: must be finite where velocity_limit is, got {sat!r}")
        out["sat_effort"][:] = s.astype(np.float32)
        out["vel_limit"][:] = v.astype(np.float32)

    if isinstance(act, DCMotor):
        envelope(act.saturation_effort, act.velocity_limit, allow_inf=False)
        out["act_model"][:] = ACT_DC_MOTOR
    elif isinstance(act, PositionBasedEffortLimit):
        try:
            pos = np.asarray(act.positions, dtype=np.float64).reshape(-1)
            eff = np.asarray(act.efforts, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as e:
            raise ConfigError(f"{where}: expected numeric positions and efforts, got {act!r}") from e
        with np.errstate(over="ignore"):  # checked as the kernel reads them: 1e39 is inf in float32
            pos, eff = pos.astype(np.float32), eff.astype(np.float32)
        if pos.size == 0 or pos.size != eff.size:
            raise ConfigError(
                f"{where}: expected positions and efforts of the same non-zero length, got {pos.size} and {eff.size}"
            )
        if not (np.isfinite(pos).all() and np.isfinite(eff).all()) or (eff < 0).any():
            raise ConfigError(f"{where}: expected finite positions and efforts >= 0, got {act!r}")
        if (np.diff(pos) < 0).any():
            raise ConfigError(f"{where}.positions: expected non-decreasing positions, got {list(act.positions)}")
        if pos.size > 64:
            raise ConfigError(f"{where}.positions: expected at most 64 table entries, got {pos.size}")
        out["act_model"][:] = ACT_POSITION_LIMIT
        out["extras"].append((0, n, (pos.astype(np.float32), eff.astype(np.float32))))
    else:
        envelope(act.saturation_effort, act.velocity_limit, allow_inf=True)
        if act.input_order not in ("pos_vel", "vel_pos"):
            raise ConfigError(f"{where}.input_order: expected 'pos_vel' or 'vel_pos', got {act.input_order!r}")
        idx = list(act.input_idx)
        if not idx or any(isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= i <= 63 for i in idx):
            raise ConfigError(f"{where}.input_idx: expected substep indices in [0, 63], got {act.input_idx!r}")
        for f in ("pos_scale", "vel_scale", "torque_scale"):
            v = getattr(act, f)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(_f32(v)):
                raise ConfigError(f"{where}.{f}: expected a finite number (within float32 range), got {v!r}")
        if act.kernel not in NET_KERNELS:
            kernels = ", ".join(repr(k) for k in NET_KERNELS[:-1]) + f" or {NET_KERNELS[-1]!r}"
            raise ConfigError(f"{where}.kernel: expected {kernels}, got {act.kernel!r}")
        if act.launch not in ("auto", "fused", "separate"):
            raise ConfigError(f"{where}.launch: expected 'auto', 'fused' or 'separate', got {act.launch!r}")
        out["act_model"][:] = ACT_NET
        out["extras"].append((0, n, act))
    return out
