"""The options of a control mode, in three groups: how the drive force is computed (:class:`Actuation`), command
latency (:class:`Delay`), and what is checked and recorded on the way (:class:`Diagnostics`).

Each group is a frozen dataclass that validates itself when it is made: a value outside its choices, or a combination
of fields that could not all take effect (an explicit PD law with implicit actuation, a seed for a delay that draws
nothing), raises :class:`~wpctrl.config.errors.ConfigError` naming the field, the expected and the received value.
What depends on the controllers' joints too (an inertia update for a mode that computes no inertia, target clipping for
a mode without position targets) is checked when the controller is built (:func:`wpctrl.engine.plan.check_options`).
Host only. ``build_controller`` takes these objects, or the plain keywords it turns into them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .errors import ConfigError

ACTUATION_MODES = ("implicit", "explicit")
EXPLICIT_PD_LAWS = ("naive", "stable", "coupled")
INERTIA_UPDATES = ("control", "substep")
NAN_POLICIES = ("hold", "raise")
CLIP_TARGETS = ("none", "joint_limits")
MAX_DELAY = 1024
"""The longest delay [substeps] (the history holds max + 1 targets per env and joint)."""


def _choice(name: str, value, choices: tuple) -> None:
    if not isinstance(value, str) or value not in choices:
        raise ConfigError(f"{name}: expected one of {choices}, got {value!r}")


def _int32(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not -(2**31) <= int(value) < 2**31:
        raise ConfigError(f"{name}: expected an int32, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class Actuation:
    """Who computes the drive force, and how (docs/actuation.md).

    Args:
        mode: ``"implicit"`` (the solver's built-in PD tracks ``Control.joint_target_q/qd``) or ``"explicit"``
            (wpctrl's kernel writes the PD torque into ``Control.joint_f``; the built-in drive off).
        explicit_pd: The explicit PD law, with ``mode="explicit"`` only (None there means ``"naive"``):
            ``"naive"`` (``clamp(Kp (q* - q) + Kd (qd* - qd))``), ``"stable"`` (the same law on the predicted
            end-of-substep state, solved per joint with its response r = (H^-1)_ii) or ``"coupled"`` (PhysX's
            articulation drive: all rows solved together with the articulation's inverse inertia, the force limits
            inside the solve; one extra launch per substep).
        inertia_update: When the inertia is recomputed from ``joint_q``, for a mode that computes it (acceleration
            drives, ``"stable"``, ``"coupled"``; None otherwise): ``"control"`` (once per control step) or
            ``"substep"`` (before every substep). None takes the drive's default: ``"substep"`` for the coupled
            drive, ``"control"`` for the others.
    """

    mode: str = "implicit"
    explicit_pd: str | None = None
    inertia_update: str | None = None

    def __post_init__(self):
        _choice("actuation.mode", self.mode, ACTUATION_MODES)
        if self.explicit_pd is not None:
            _choice("actuation.explicit_pd", self.explicit_pd, EXPLICIT_PD_LAWS)
            if self.mode != "explicit":
                raise ConfigError(
                    f"actuation.explicit_pd: expected None with mode='implicit' (the solver's built-in drive computes "
                    f"the force; an explicit law needs mode='explicit'), got {self.explicit_pd!r}"
                )
        if self.inertia_update is not None:
            _choice("actuation.inertia_update", self.inertia_update, INERTIA_UPDATES)

    @property
    def explicit(self) -> bool:
        return self.mode == "explicit"

    @property
    def law(self) -> str | None:
        """The explicit PD law that runs (``"naive"``, ``"stable"``, ``"coupled"``), or None with implicit actuation."""
        return (self.explicit_pd or "naive") if self.explicit else None

    @property
    def coupled(self) -> bool:
        return self.law == "coupled"


@dataclass(frozen=True)
class Delay:
    """Command latency [substeps, as Isaac Lab's DelayedPDActuator counts] (docs/randomisation.md).

    The drive targets (implicit: ``Control.joint_target_q/qd``; explicit: the PD law's targets, with the current
    measured state) are those of d substeps ago; a reset fills the env's history with the reset pose. Costs
    (max + 1) x num_envs x n_joints float32 (twice when a row has a velocity target).

    Args:
        substeps: d for every env, or ``(min, max)``: each env draws d uniformly in [min, max] at each of its resets
            (device RNG). 0 <= min <= max <= 1024.
        seed: The device RNG's seed for those draws (int32; None: 0). Only with a range: a fixed delay draws nothing.
    """

    substeps: int | tuple[int, int]
    seed: int | None = None

    def __post_init__(self):
        d = self.substeps
        single = isinstance(d, (int, np.integer)) and not isinstance(d, bool)
        vals = (d, d) if single else d
        ok = isinstance(vals, Sequence) and not isinstance(vals, str) and len(vals) == 2
        ok = ok and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in vals)
        if not ok:
            raise ConfigError(f"delay.substeps: expected an int or (min_substeps, max_substeps) ints, got {d!r}")
        lo, hi = int(vals[0]), int(vals[1])
        if lo < 0 or hi < lo:
            raise ConfigError(f"delay.substeps: expected 0 <= min_substeps <= max_substeps, got ({lo}, {hi})")
        if hi > MAX_DELAY:
            raise ConfigError(
                f"delay.substeps: expected at most {MAX_DELAY} substeps (the history holds max + 1 targets), got {hi}"
            )
        object.__setattr__(self, "substeps", lo if single else (lo, hi))
        if self.seed is not None:
            object.__setattr__(self, "seed", _int32("delay.seed", self.seed))
            if lo == hi:
                raise ConfigError(
                    f"delay.seed: expected None for a fixed delay of {lo} substeps (nothing is drawn), "
                    f"got {self.seed!r}"
                )

    @property
    def range(self) -> tuple[int, int]:
        """``(min, max)`` [substeps]."""
        s = self.substeps
        return (s, s) if isinstance(s, int) else s

    @property
    def min(self) -> int:
        return self.range[0]

    @property
    def max(self) -> int:
        return self.range[1]

    @property
    def drawn(self) -> bool:
        """Whether each env draws its delay at its resets (a range), rather than all sharing one."""
        return self.range[1] > self.range[0]


@dataclass(frozen=True)
class Diagnostics:
    """What is checked and recorded on the way (docs/errors.md, docs/randomisation.md).

    Args:
        track_effort: Write ``computed_effort`` / ``applied_effort`` / ``saturation_count`` every substep (off: no
            bytes, no work).
        nan_policy: ``"hold"`` (an env whose action holds NaN/Inf keeps its previous targets; counted in
            ``bad_action_count``; graph-capturable) or ``"raise"`` (ConfigError before any launch; a host sync).
        clip_targets: ``"none"`` (ManiSkill) or ``"joint_limits"``: every position target (after delta, virtual
            target and mimic) is clamped to the joint's limits from the model before it is stored; for a mode with
            position targets.
    """

    track_effort: bool = False
    nan_policy: str = "hold"
    clip_targets: str = "none"

    def __post_init__(self):
        if not isinstance(self.track_effort, (bool, np.bool_)):
            raise ConfigError(f"diagnostics.track_effort: expected a bool (True or False), got {self.track_effort!r}")
        object.__setattr__(self, "track_effort", bool(self.track_effort))
        _choice("diagnostics.nan_policy", self.nan_policy, NAN_POLICIES)
        _choice("diagnostics.clip_targets", self.clip_targets, CLIP_TARGETS)


class ControllerOptions(NamedTuple):
    """A built controller's options as they run (``ctrl.options``): every field resolved (the explicit law and the
    inertia update that run, None where nothing of the kind runs)."""

    actuation: Actuation
    delay: Delay | None
    diagnostics: Diagnostics
    balance_passive_force: bool


def grouped_options(
    actuation=None,
    delay=None,
    diagnostics=None,
    *,
    explicit_pd=None,
    inertia_update=None,
    seed=None,
    track_effort=None,
    nan_policy=None,
    clip_targets=None,
) -> tuple[Actuation, Delay | None, Diagnostics]:
    """``build_controller``'s options as the three groups: each given as its object, or as the plain keywords that
    make it (the one place they are turned into objects). A group given both ways is refused: the keyword would be
    ignored.

    Args:
        actuation: An :class:`Actuation`, ``"implicit"`` / ``"explicit"`` (its mode) or None (implicit).
        delay: A :class:`Delay`, its ``substeps`` (an int or ``(min, max)``) or None (off).
        diagnostics: A :class:`Diagnostics` or None (its defaults).
        explicit_pd, inertia_update: :class:`Actuation`'s fields, with ``actuation`` not an object.
        seed: :class:`Delay`'s field, with ``delay`` not an object.
        track_effort, nan_policy, clip_targets: :class:`Diagnostics`' fields, without ``diagnostics``.
    """
    flat = {"explicit_pd": explicit_pd, "inertia_update": inertia_update}
    if isinstance(actuation, Actuation):
        _refuse_both("actuation", actuation, flat)
    elif actuation is None or isinstance(actuation, str):
        actuation = Actuation("implicit" if actuation is None else actuation, explicit_pd, inertia_update)
    else:
        raise ConfigError(f"actuation: expected 'implicit', 'explicit' or a wpctrl.Actuation, got {actuation!r}")
    if isinstance(delay, Delay):
        _refuse_both("delay", delay, {"seed": seed})
    elif delay is not None:
        delay = Delay(delay, seed)
    elif seed is not None:
        raise ConfigError(f"seed: expected None without a delay (the seed keys the per-env delay draws), got {seed!r}")
    flat = {"track_effort": track_effort, "nan_policy": nan_policy, "clip_targets": clip_targets}
    if isinstance(diagnostics, Diagnostics):
        _refuse_both("diagnostics", diagnostics, flat)
    elif diagnostics is None:
        diagnostics = Diagnostics(**{k: v for k, v in flat.items() if v is not None})
    else:
        raise ConfigError(f"diagnostics: expected a wpctrl.Diagnostics or None, got {diagnostics!r}")
    return actuation, delay, diagnostics


def _refuse_both(group: str, obj, flat: dict) -> None:
    for name, value in flat.items():
        if value is not None:
            raise ConfigError(
                f"{name}: expected None when {group} is given as {obj!r} (set {group}.{name} there), got {value!r}"
            )
