"""``build_controller``: the one entry point that builds a control mode from a config or a mode dict.

Every config class names its controller class (``Config.controller_cls``, as in ManiSkill; resolved on first read,
:mod:`wpctrl.config.joint`); a mode dict of any configs builds one :class:`~.base_controller.CombinedController`.
The options arrive here as their groups (:mod:`wpctrl.config.options`) or as the plain keywords that make them.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import newton

from ..config.errors import ConfigError
from ..config.joint import ControllerConfig
from ..config.options import Actuation, Delay, Diagnostics, grouped_options
from .base_controller import BaseController, CombinedController
from .stability import warn_unstable_explicit_pd


def build_controller(
    config,
    model: newton.Model,
    control_freq: int = 20,
    sim_freq: int = 100,
    *,
    actuation: Actuation | str | None = None,
    delay: Delay | int | tuple[int, int] | None = None,
    diagnostics: Diagnostics | None = None,
    solver: Any = None,
    balance_passive_force: bool | None = None,
    explicit_pd: str | None = None,
    inertia_update: str | None = None,
    delay_seed: int | None = None,
    seed: int | None = None,
    track_effort: bool | None = None,
    nan_policy: str | None = None,
    clip_targets: str | None = None,
) -> BaseController:
    """Build the controller for one config or a ManiSkill control-mode dict ``{uid: config}``.

    The options come in three groups, each a frozen object that checks itself (docs/api.md, "Options"):
    :class:`wpctrl.Actuation` (who computes the drive force: mode, explicit PD law, inertia update),
    :class:`wpctrl.Delay` (command latency) and :class:`wpctrl.Diagnostics` (effort readout, NaN policy, target
    clipping). Each group may instead be given by its plain keywords (``actuation="explicit", explicit_pd="stable"``,
    ``delay=(0, 2), delay_seed=3``, ``track_effort=True``); they build the same objects. Every option is
    keyword-only, and one that this mode would ignore is refused with :class:`wpctrl.ConfigError` (an explicit law
    with implicit actuation, an inertia update for a mode that computes no inertia, a delay seed for a delay that
    draws nothing, target clipping without position targets, a group given both as an object and by its keywords).
    ``ctrl.options`` (and ``ctrl.explicit_pd``, ``ctrl.inertia_update``, ...) then tell what runs.

    Args:
        config: A controller config, or a dict of them (a combined controller with a flat action).
        model: The finalized Newton model; every world must hold the configs' joints. Drive properties are
            written into it (gains, target modes, effort limits, friction).
        control_freq: Control steps per second [Hz].
        sim_freq: Solver steps per second [Hz]; a multiple of ``control_freq``.
        actuation: A :class:`wpctrl.Actuation`, or its mode ``"implicit"`` (default: the solver's built-in PD tracks
            ``Control.joint_target_q/qd``) / ``"explicit"`` (wpctrl's kernel writes the PD torque into
            ``Control.joint_f``; the built-in drive off).
        delay: A :class:`wpctrl.Delay`, or its ``substeps``: an int, or ``(min, max)`` drawn per env at each reset of
            that env; None (default): off. ``ctrl.delay`` reads and writes each env's d.
        diagnostics: A :class:`wpctrl.Diagnostics`; None: its defaults, or those of the keywords below.
        solver: Optional solver already built on ``model``: notified of the changed drive properties.
        balance_passive_force: ManiSkill's agent-level switch: gravity does not act on the controlled robot's links
            (every body of the articulations that hold the controlled joints, in every env). None (default) takes
            the mode dict's ``"balance_passive_force"`` entry, True when absent or for a single config, as
            ManiSkill; given both ways, they must agree. It sets the model's per-body ``mujoco:gravcomp`` to 1 on
            those bodies (exact gravity removal in SolverMuJoCo, which must be built after the controller or
            notified of ``ModelFlags.BODY_INERTIAL_PROPERTIES``); other solvers ignore that attribute, so a solver
            other than SolverMuJoCo given here or to ``attach_solver`` is refused while it is on.
        explicit_pd, inertia_update: :class:`wpctrl.Actuation`'s fields, when ``actuation`` is a mode string.
        delay_seed: The seed of the per-env delay draws (:class:`wpctrl.Delay`'s ``seed``), when ``delay`` is given
            as its substeps ``(min, max)``.
        seed: Deprecated name of ``delay_seed`` (a ``DeprecationWarning``; refused together with ``delay_seed``).
        track_effort, nan_policy, clip_targets: :class:`wpctrl.Diagnostics`' fields, without ``diagnostics``.

    Explicit naive PD is checked against the stability bound of a semi-implicit Euler step (``Kp dt^2/m + 2 Kd dt/m
    < 4`` per joint, m its effective inertia at the model's initial pose: :mod:`wpctrl.controllers.stability`); the
    joints past it are named in a ``UserWarning``.
    """
    if seed is not None:
        if delay_seed is not None:
            raise ConfigError(
                f"seed: expected None when delay_seed is given (seed is the deprecated name of delay_seed), got "
                f"seed={seed!r} and delay_seed={delay_seed!r}"
            )
        warnings.warn(
            "build_controller: seed= is deprecated, use delay_seed= (the seed of the per-env delay draws)",
            DeprecationWarning,
            stacklevel=2,
        )
        delay_seed = seed
    if delay_seed is not None and (delay is None or isinstance(delay, Delay)):  # else the Delay made here checks it
        where = "without a delay" if delay is None else f"when delay is given as {delay!r} (set delay.seed there)"
        raise ConfigError(f"delay_seed: expected None {where} (it seeds the per-env delay draws), got {delay_seed!r}")
    actuation, delay, diagnostics = grouped_options(
        actuation,
        delay,
        diagnostics,
        explicit_pd=explicit_pd,
        inertia_update=inertia_update,
        seed=delay_seed,
        track_effort=track_effort,
        nan_policy=nan_policy,
        clip_targets=clip_targets,
    )
    kw = dict(
        actuation=actuation,
        delay=delay,
        diagnostics=diagnostics,
        solver=solver,
        balance_passive_force=balance_passive_force,
    )
    if isinstance(config, Mapping):
        ctrl = CombinedController(config, model, control_freq, sim_freq, **kw)
    elif isinstance(config, ControllerConfig):
        ctrl = type(config).controller_cls(config, model, control_freq, sim_freq, **kw)
    else:
        raise ConfigError(f"config: expected a controller config or a dict of them, got {type(config).__name__}")
    warn_unstable_explicit_pd(ctrl, sim_freq)
    return ctrl
