"""``build_controller``: the controller class of each config, and the one entry point that builds a control mode.

Every config class names its controller class (``Config.controller_cls``, as in ManiSkill); this module sets them for
the joint and end-effector configs, so a mode dict mixing both builds from here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import newton

from ..config import ee as cfg_ee
from ..config import impedance as cfg_imp
from ..config import mobile_base as cfg_base
from ..config import rows as cfg
from .base_controller import BaseController, CombinedController
from .ee import PDEEPosController, PDEEPoseController
from .impedance import JointImpedanceController, OperationalSpaceController
from .joint import (
    JointEffortController,
    PassiveController,
    PDJointPosController,
    PDJointPosMimicController,
    PDJointPosVelController,
    PDJointVelController,
)
from .mobile_base import PDBaseForwardVelController, PDBaseVelController

cfg.PDJointPosControllerConfig.controller_cls = PDJointPosController
cfg.PDJointPosMimicControllerConfig.controller_cls = PDJointPosMimicController
cfg.PDJointVelControllerConfig.controller_cls = PDJointVelController
cfg.PDJointPosVelControllerConfig.controller_cls = PDJointPosVelController
cfg.PassiveControllerConfig.controller_cls = PassiveController
cfg.JointEffortControllerConfig.controller_cls = JointEffortController


cfg_base.PDBaseVelControllerConfig.controller_cls = PDBaseVelController
cfg_base.PDBaseForwardVelControllerConfig.controller_cls = PDBaseForwardVelController
cfg_ee.PDEEPosControllerConfig.controller_cls = PDEEPosController
cfg_ee.PDEEPoseControllerConfig.controller_cls = PDEEPoseController
cfg_imp.OperationalSpaceControllerConfig.controller_cls = OperationalSpaceController
cfg_imp.JointImpedanceControllerConfig.controller_cls = JointImpedanceController


def build_controller(
    config,
    model: newton.Model,
    control_freq: int = 20,
    sim_freq: int = 100,
    actuation: str = "implicit",
    *,
    solver: Any = None,
    nan_policy: str = "hold",
    explicit_pd: str = "naive",
    inertia_update: str | None = None,
    delay=None,
    track_effort: bool = False,
    clip_targets: str = "none",
    seed: int = 0,
    balance_passive_force: bool | None = None,
) -> BaseController:
    """Build the controller for one config or a ManiSkill control-mode dict ``{uid: config}``.

    Args:
        config: A controller config, or a dict of them (a combined controller with a flat action).
        model: The finalized Newton model; every world must hold the configs' joints. Drive properties are
            written into it (gains, target modes, effort limits, friction).
        control_freq: Control steps per second [Hz].
        sim_freq: Solver steps per second [Hz]; a multiple of ``control_freq``.
        actuation: ``"implicit"`` (the solver's built-in PD tracks ``Control.joint_target_q/qd``) or
            ``"explicit"`` (wpctrl's kernel writes clamped PD torques into ``Control.joint_f``; built-in drive off).
        solver: Optional solver already built on ``model``: notified of the changed drive properties.
        nan_policy: ``"hold"`` (an env whose action holds NaN/Inf keeps its previous targets; counted in
            ``bad_action_count``; graph-capturable) or ``"raise"`` (ValueError before any launch; costs a host sync).
        explicit_pd: With ``actuation="explicit"``: ``"naive"`` (``clamp(Kp (q* - q) + Kd (qd* - qd))``) or
            ``"stable"`` (the same law on the predicted end-of-substep state, solved with each joint's response
            r = (H^-1)_ii: ``(Kp (q* - q - dt qd) + Kd (qd* - qd)) / (1 + r dt (Kd + dt Kp))``, then clamped;
            stable at implicit-drive gains), or ``"coupled"`` (PhysX's articulation drive: the same law solved
            jointly for all rows with the full inverse-inertia block ``A`` of the articulation, recomputed from
            ``joint_q`` every substep, and the force limits enforced inside the solve:
            ``tau = clamp(b - diag(dt Kd + dt^2 Kp) A tau)``; one extra launch per substep; see docs/actuation.md,
            "The coupled drive").
        inertia_update: When the inertia is recomputed from ``joint_q``: ``"control"`` (once per control step) or
            ``"substep"`` (before every substep). Stable PD and acceleration drives refresh r = (H^-1)_ii (default
            ``"control"``, in ``set_action``); the coupled drive H (default ``"substep"``; ``"control"`` computes H
            at each control step's first substep and reuses it for the other K - 1: about a quarter of the drive's
            cost off at K = 5, with H lagging the configuration by up to K - 1 substeps).
        delay: Command latency [substeps]: None (off), an int, or ``(min, max)`` drawn uniformly per env at each
            reset of that env (device RNG). The drive targets (implicit: ``Control.joint_target_q/qd``; explicit:
            the PD law's targets, with the current measured state) are those of d substeps ago; a reset fills the
            env's history with the reset pose. ``ctrl.delay`` reads and writes d. Costs (max + 1) x num_envs x
            n_joints float32 (twice when a row has a velocity target).
        track_effort: Write ``computed_effort``/``applied_effort``/``saturation_count`` every substep (off: no bytes).
        clip_targets: ``"none"`` (ManiSkill) or ``"joint_limits"``: every position target (after delta, virtual
            target and mimic) is clamped to the joint's limits from the model before it is stored.
        seed: Seed of the device RNG that draws the delays.
        balance_passive_force: ManiSkill's agent-level switch: gravity does not act on the controlled robot's links
            (every body of the articulations that hold the controlled joints, in every env). None (default) takes
            the mode dict's ``"balance_passive_force"`` entry, True when absent or for a single config, as
            ManiSkill. It sets the model's per-body ``mujoco:gravcomp`` to 1 on those bodies (exact gravity removal
            in SolverMuJoCo, which must be built after the controller or notified of
            ``ModelFlags.BODY_INERTIAL_PROPERTIES``); other solvers ignore that attribute, so a solver other than
            SolverMuJoCo given here or to ``attach_solver`` is refused while it is on.
    """
    kw = dict(
        actuation=actuation,
        solver=solver,
        nan_policy=nan_policy,
        explicit_pd=explicit_pd,
        inertia_update=inertia_update,
        delay=delay,
        track_effort=track_effort,
        clip_targets=clip_targets,
        seed=seed,
        balance_passive_force=balance_passive_force,
    )
    if isinstance(config, Mapping):
        return CombinedController(config, model, control_freq, sim_freq, **kw)
    if not isinstance(config, cfg.ControllerConfig):
        raise cfg.ConfigError(f"config: expected a controller config or a dict of them, got {type(config).__name__}")
    return type(config).controller_cls(config, model, control_freq, sim_freq, **kw)
