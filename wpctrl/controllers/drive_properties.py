"""Per-env drive properties on top of the ManiSkill controllers: set, randomise, read; and the per-env views of the
command delay and the effort readout (the device side: :mod:`wpctrl.engine.parts.drive_properties`,
:mod:`wpctrl.engine.parts.actuator_models`, :mod:`wpctrl.engine.parts.delay`,
:mod:`wpctrl.engine.parts.effort_readout`).

:class:`DrivePropertiesMixin` is a base of :class:`wpctrl.BaseController`; a child controller (``ctrl["arm"]``) works
on its own joints (columns). Host-side checks only read host values (and the metadata of device inputs), so
:meth:`DrivePropertiesMixin.randomize_drive_properties` with a device env selection is graph-capturable.

Solvers and the model mirror: with implicit actuation the solver's built-in drive uses Newton's per-DOF
``Model.joint_target_ke/kd`` (and ``joint_effort_limit``, ``joint_friction`` in both actuations), which the same kernel
writes for the selected envs. ``SolverMuJoCo`` copies them into MuJoCo-Warp's per-world model
(``actuator_gainprm/biasprm``, ``jnt_actfrcrange``, ``dof_frictionloss``: batched per world when the model has several
worlds) only on ``notify_model_changed(ModelFlags.JOINT_DOF_FORCE_PROPERTIES)``, which wpctrl sends to the solver given
as ``solver=`` or :meth:`~wpctrl.BaseController.attach_solver`. That notice is a handful of kernel launches with no host
sync on MuJoCo-Warp (``tests/test_actuation.py`` captures it in a graph and checks per-world gains after replay); with
``use_mujoco_cpu=True`` it copies to the host and is eager only. XPBD, Featherstone and SemiImplicit read Newton's
arrays every step and need no notice; Steel and Kamino are notified the same way.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..config.errors import ConfigError
from ..engine.parts.actuator_models import ACTUATOR_FIELDS
from ..engine.parts.drive_properties import DRIVE_FIELDS
from .inputs import _env_selection, _is_torch

_RAND_MODES = ("scale", "abs")
_F32_MAX = float(np.finfo(np.float32).max)


def _host_values(name: str, value, shape_ok, n: int) -> np.ndarray:
    """``value`` as a float64 host array; finite (force_limit may be +inf), >= 0, within float32 range."""
    if _is_torch(value):
        value = value.detach().cpu().numpy()
    elif isinstance(value, wp.array):
        value = value.numpy()
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{name}: expected numbers, got {value!r}") from e
    if not shape_ok(a.shape):
        raise ConfigError(f"{name}: expected shape ({n},) or {shape_ok.expected}, got {a.shape}")
    bad = np.isnan(a) | (a < 0)
    if name.endswith("force_limit"):
        a = np.where(a > _F32_MAX, np.inf, a)  # an infinite force limit means no limit
    else:
        bad |= ~np.isfinite(a) | (a > _F32_MAX)
    if bad.any():
        i = tuple(int(x[0]) for x in np.nonzero(bad))
        raise ConfigError(f"{name}: expected finite values >= 0 (float32 range), got {a[i]!r} at index {list(i)}")
    return a


def _ranges(fields, ranges, mode: str):
    """``(lo, hi, enabled)`` lists of the given ``(lo, hi)`` ranges (None: not drawn), validated."""
    lo, hi, enabled = [0.0] * len(fields), [0.0] * len(fields), [0] * len(fields)
    for p, (k, rng) in enumerate(zip(fields, ranges)):
        if rng is None:
            continue
        name = f"randomize_drive_properties.{k}"
        try:
            a, b = (float(x) for x in rng)
        except (TypeError, ValueError) as e:
            raise ConfigError(f"{name}: expected a (lo, hi) pair of numbers, got {rng!r}") from e
        if not (np.isfinite(a) and np.isfinite(b) and 0.0 <= a <= b <= _F32_MAX):
            raise ConfigError(f"{name}: expected finite 0 <= lo <= hi ({mode} range), got ({a!r}, {b!r})")
        lo[p], hi[p], enabled[p] = a, b, 1
    return lo, hi, enabled


def _given_values(fields, given, sel: int, n: int):
    """The given (not None) values of ``fields`` as one float32 ``(len(fields), batch, n)`` host array and the
    per-field enabled flags, or None when none is given (each validated by :func:`_host_values`)."""
    arrays = {
        k: _host_values(f"set_drive_properties.{k}", v, _Shape(sel, n), n)
        for k, v in zip(fields, given)
        if v is not None
    }
    if not arrays:
        return None
    batch = max(a.shape[0] if a.ndim == 2 else 1 for a in arrays.values())
    values = np.zeros((len(fields), batch, n), np.float32)
    for p, k in enumerate(fields):
        if k in arrays:
            values[p] = np.broadcast_to(arrays[k].astype(np.float32), (batch, n))
    return values, [int(k in arrays) for k in fields]


class _Shape:
    def __init__(self, rows: int, n: int):
        self.rows, self.n = rows, n
        self.expected = f"({rows}, {n})"

    def __call__(self, shape) -> bool:
        return tuple(shape) in ((self.n,), (self.rows, self.n))


class DrivePropertiesMixin:
    """Per-env drive properties, their randomisation, delay and effort readout (see the module docstring)."""

    # -- per-env drive properties ---------------------------------------------------------------------------------

    @property
    def stiffness(self) -> wp.array:
        """(num_envs, n_joints) drive stiffness Kp [N·m/rad or N/m] per env (live; initialised from the config)."""
        return self._view(self._engine.kp)

    @property
    def damping(self) -> wp.array:
        """(num_envs, n_joints) drive damping Kd [N·m·s/rad or N·s/m] per env (live)."""
        return self._view(self._engine.kd)

    @property
    def force_limit(self) -> wp.array:
        """(num_envs, n_joints) effort limit [N·m or N] per env (live)."""
        return self._view(self._engine.force_limit)

    @property
    def friction(self) -> wp.array:
        """(num_envs, n_joints) joint friction [N·m or N] per env (live; the solver applies it from
        ``Model.joint_friction``)."""
        return self._view(self._engine.friction)

    @property
    def saturation_effort(self) -> wp.array | None:
        """(num_envs, n_joints) DC-motor stall effort [N·m or N] per env (live; inf where no envelope), or None
        without actuator models."""
        part = self._engine.part("actuator_models")
        return None if part is None else self._view(part.sat_effort)

    @property
    def velocity_limit(self) -> wp.array | None:
        """(num_envs, n_joints) DC-motor no-load speed [rad/s or m/s] per env (live), or None without actuator
        models."""
        part = self._engine.part("actuator_models")
        return None if part is None else self._view(part.vel_limit)

    def _selection(self, env_ids):
        eng = self._engine
        return _env_selection(env_ids, eng.num_envs, eng.device)

    def set_drive_properties(
        self,
        env_ids=None,
        *,
        stiffness=None,
        damping=None,
        force_limit=None,
        friction=None,
        saturation_effort=None,
        velocity_limit=None,
    ):
        """Set drive properties of ``env_ids`` (None: all envs) for this controller's joints.

        ``env_ids`` as in :meth:`~wpctrl.BaseController.reset`; every value by keyword: shape (n_joints,) (broadcast
        to every selected env) or (len(env_ids) | num_envs for a bool mask, n_joints), torch / numpy / wp; finite and
        >= 0 (force_limit may be inf). ``saturation_effort`` and ``velocity_limit`` (> 0) set the DC-motor envelope
        of controllers built with actuator models. Written to the per-env arrays, to Newton's per-DOF model arrays
        of those envs (gains with implicit actuation; effort limit and friction always) and the attached solver is
        notified. Validation reads the values on the host (a sync for device input): call it outside captured
        graphs; use :meth:`randomize_drive_properties` inside them. With per-id values, list each env once (a
        repeated id takes one of its rows, unspecified which). A bad value raises :class:`wpctrl.ConfigError`.
        """
        eng = self._engine
        drive = (stiffness, damping, force_limit, friction)
        motor = (saturation_effort, velocity_limit)
        if any(v is not None for v in motor):
            self._actuators("set_drive_properties")
        ids, mask = self._selection(env_ids)
        n = self._rows.stop - self._rows.start
        sel = eng.num_envs if ids is None else ids.shape[0]  # a bool mask takes (num_envs, n) values
        motor_values = _given_values(ACTUATOR_FIELDS, motor, sel, n)  # every value checked before any is written
        drive_values = _given_values(DRIVE_FIELDS, drive, sel, n)
        if motor_values is not None and motor_values[1][1] and (motor_values[0][1] <= 0).any():
            raise ConfigError(f"set_drive_properties.velocity_limit: expected values > 0, got {velocity_limit!r}")
        if motor_values is not None:
            eng.part("actuator_models").set(eng, *motor_values, ids, mask, self._rows.start, n)
        if drive_values is not None:
            values, enabled = drive_values
            dev_values = wp.array(values, dtype=wp.float32, device=eng.device)
            eng.part("drive_properties").set(eng, dev_values, enabled, ids, mask, self._rows.start, n)

    def _actuators(self, what: str):
        part = self._engine.part("actuator_models")
        if part is None:
            raise ConfigError(
                f"{what}: saturation_effort / velocity_limit: expected None, this controller was built without "
                f"actuator models (no DC-motor envelope)"
            )
        return part

    def randomize_drive_properties(
        self,
        env_ids=None,
        *,
        stiffness=None,
        damping=None,
        force_limit=None,
        friction=None,
        saturation_effort=None,
        velocity_limit=None,
        mode="scale",
        seed=0,
    ):
        """Draw drive properties uniformly on the device for ``env_ids`` (None: all envs) and this controller's joints.

        ``env_ids`` as in :meth:`~wpctrl.BaseController.reset` (a device bool mask or int array keeps the call
        capturable); every other argument by keyword. Each of stiffness/damping/force_limit/friction: None
        (untouched) or ``(lo, hi)``; ``mode="scale"`` multiplies the config's nominal value by U(lo, hi) (``(1, 1)``
        leaves it bit-identical), ``"abs"`` sets U(lo, hi) in the property's units. Each joint and env draws
        independently from Warp's RNG keyed by ``seed`` and a device-side counter bumped after every call: a captured
        graph draws new values on each replay. Mirrored into the model and notified to the attached solver like
        :meth:`set_drive_properties`. ``saturation_effort`` / ``velocity_limit`` draw the DC-motor envelope of
        controllers built with actuator models the same way (streams of their own). A bad value raises
        :class:`wpctrl.ConfigError`.
        """
        if mode not in _RAND_MODES:
            raise ConfigError(f"randomize_drive_properties.mode: expected one of {_RAND_MODES}, got {mode!r}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not -(2**31) <= int(seed) < 2**31:
            raise ConfigError(f"randomize_drive_properties.seed: expected an int32, got {seed!r}")
        lo, hi, enabled = _ranges(DRIVE_FIELDS, (stiffness, damping, force_limit, friction), mode)
        alo, ahi, aen = _ranges(ACTUATOR_FIELDS, (saturation_effort, velocity_limit), mode)
        if any(aen) and alo[1] <= 0.0 and aen[1]:
            raise ConfigError(f"randomize_drive_properties.velocity_limit: expected lo > 0, got {velocity_limit!r}")
        if any(aen):
            self._actuators("randomize_drive_properties")
        if not any(enabled) and not any(aen):
            return
        eng = self._engine
        ids, mask = self._selection(env_ids)
        n = self._rows.stop - self._rows.start
        if any(aen):
            part = eng.part("actuator_models")
            part.randomize(eng, alo, ahi, aen, mode == "abs", int(seed), ids, mask, self._rows.start, n)
        if not any(enabled):
            return
        drive = eng.part("drive_properties")
        drive.randomize(eng, lo, hi, enabled, mode == "abs", int(seed), ids, mask, self._rows.start, n)

    # -- delay ----------------------------------------------------------------------------------------------------

    @property
    def delay(self) -> wp.array | None:
        """(num_envs,) int32 command delay [substeps] per env, drawn at each reset of the env from the build's
        ``delay`` range (live, writable: assign values in [0, max]); None without ``delay``."""
        return self._engine.delay

    @delay.setter
    def delay(self, value) -> None:
        eng = self._engine
        if eng.delay is None:
            raise ConfigError("delay: this controller was built without delay= (no history buffer)")
        if _is_torch(value):
            value = value.detach().cpu().numpy()
        elif isinstance(value, wp.array):
            value = value.numpy()
        a = np.broadcast_to(np.asarray(value), (eng.num_envs,)) if np.ndim(value) == 0 else np.asarray(value)
        hi = eng.delay_range[1]
        if a.shape != (eng.num_envs,) or a.dtype.kind not in "iu" or (a < 0).any() or (a > hi).any():
            raise ConfigError(
                f"delay: expected {eng.num_envs} ints in [0, {hi}] (max_delay of the build), got {np.asarray(value)!r}"
            )
        eng.delay.assign(a.astype(np.int32))

    # -- effort readout -------------------------------------------------------------------------------------------

    @property
    def computed_effort(self) -> wp.array | None:
        """(num_envs, n_joints) PD effort [N·m or N] before the force-limit clamp, written every substep with
        ``track_effort=True`` (else None). Explicit actuation: the torque law itself. Implicit: the same law on the
        substep's start state and delayed targets, an *estimate* of what the solver's implicit drive applies."""
        a = self._engine.computed_effort
        return None if a is None else self._view(a)

    @property
    def applied_effort(self) -> wp.array | None:
        """(num_envs, n_joints) effort after the clamp to ``force_limit`` [N·m or N] (implicit: an estimate)."""
        a = self._engine.applied_effort
        return None if a is None else self._view(a)

    @property
    def saturation_count(self) -> wp.array | None:
        """(num_envs, n_joints) int32: substeps in which ``abs(computed_effort)`` exceeded the force limit; zeroed by
        ``reset`` for the reset envs."""
        a = self._engine.saturation_count
        return None if a is None else self._view(a)
