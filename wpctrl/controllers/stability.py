"""The stability check of explicit naive PD: a ``UserWarning`` at ``build_controller`` time for the joints whose PD
spring-damper the simulation step cannot integrate stably (their state turns NaN within a second, silently).

The bound. One solver step per simulation step (``dt = 1 / sim_freq``) integrates the joint with semi-implicit
(symplectic) Euler, as MuJoCo's and Featherstone's integrators do with a torque in ``Control.joint_f``. For one joint
of effective inertia m, position error x and velocity v, with the torque ``-Kp x - Kd v`` read at the start of the
step::

    v+ = v - dt (Kp x + Kd v) / m,    x+ = x + dt v+

With ``y = dt v``, ``a = Kp dt^2 / m`` and ``b = Kd dt / m`` the step is the linear map (x, y) -> (x+, y+) of matrix
``[[1 - a, 1 - b], [-a, 1 - b]]``: trace ``T = 2 - a - b``, determinant ``D = 1 - b``. Both roots of
``z^2 - T z + D`` lie inside the unit circle (Jury's test) if and only if ``|D| < 1``, ``1 - T + D = a > 0`` and
``1 + T + D = 4 - a - 2 b > 0``; for a > 0 the last implies the first. So the step is stable if and only if::

    Kp dt^2 / m + 2 Kd dt / m < 4

(a = 0, a pure damper: ``b < 2``, the same bound). m is the joint's effective inertia ``1 / (H^-1)_ii`` at the model's
initial pose (the response the stable and coupled laws use, :mod:`wpctrl.kernels.inertia`); for an acceleration
drive the law divides by ``(H^-1)_ii`` itself, so a and b take m = 1. The joint's own number is a lower bound for the
articulation's: with diagonal gains the largest eigenvalue of ``H^-1 Kp`` is at least each ``Kp_i (H^-1)_ii``
(Rayleigh quotient), and with proportional damping (``Kd = c Kp``, as ManiSkill's gains) every mode meets the same
bound with that eigenvalue in place of ``Kp_i / m_i``: a joint past the bound means a diverging mode.
"""

from __future__ import annotations

import warnings

import numpy as np
import warp as wp

from ..config.rows import ROW_POS, ROW_VEL
from ..kernels import inertia

__all__ = ["STABILITY_BOUND", "explicit_pd_numbers", "warn_unstable_explicit_pd"]

STABILITY_BOUND = 4.0
"""Semi-implicit Euler integrates a PD spring-damper stably while ``Kp dt^2 / m + 2 Kd dt / m`` stays below this."""


def effective_inertia(model, binding) -> np.ndarray | None:
    """(rows,) float64: each bound joint's effective inertia ``1 / (H^-1)_ii`` [kg m^2 or kg] in env 0 at the model's
    initial pose (``Model.joint_q``); None when the joints are not in articulations (nothing to read it from)."""
    art = model.joint_articulation.numpy()[binding.joint_index[:1]]  # (1, R)
    if (art < 0).any():
        return None
    layout, _ = inertia.chain_layout(model, binding.joint_index, binding.dof_index)
    if layout is not None:  # the fused kernel of the stable law: H, its Cholesky factor, diag(H^-1) of the rows
        out = wp.zeros((binding.joint_index.shape[0], binding.joint_index.shape[1]), dtype=float, device=model.device)
        inertia.FusedChain(layout, model).launch_response(model.joint_q, out)
        response = out.numpy()[0].astype(np.float64)
    else:  # Newton's per-articulation inverse, the stable law's fallback
        from newton.actuators import JointSpaceResponse

        jsr = JointSpaceResponse(model)
        state = model.state()
        jsr.refresh(state)
        art_dof0 = model.joint_qd_start.numpy()[model.articulation_start.numpy()[art[0]]]
        local = binding.dof_index[0] - art_dof0
        response = jsr.inverse_blocks.numpy()[art[0], local, local].astype(np.float64)
    with np.errstate(divide="ignore"):
        return np.where(response > 0.0, 1.0 / response, np.inf)


def explicit_pd_numbers(rows, mass: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Per row, ``(Kp dt^2 / m, Kd dt / m)`` of the naive PD law (velocity rows: Kp = 0; acceleration drives: m = 1;
    other rows: 0)."""
    pd = (rows.kind == ROW_POS) | (rows.kind == ROW_VEL)
    kp = np.where(rows.kind == ROW_POS, rows.kp, 0.0).astype(np.float64)
    kd = np.where(pd, rows.kd, 0.0).astype(np.float64)
    m = np.where(rows.accel, 1.0, mass)
    return kp * dt * dt / m, kd * dt / m


def warn_unstable_explicit_pd(ctrl, sim_freq: float) -> None:
    """Warn (``UserWarning``) when ``ctrl`` runs explicit naive PD and some joint's ``Kp dt^2/m + 2 Kd dt/m`` is at or
    past :data:`STABILITY_BOUND` (see the module docstring); the message names those joints, their numbers and the
    fixes."""
    if ctrl.explicit_pd != "naive":
        return
    engine = ctrl._engine
    rows = engine.plan.rows
    mass = effective_inertia(engine.model, engine.plan.binding)
    if mass is None:
        return
    dt = 1.0 / float(sim_freq)
    a, b = explicit_pd_numbers(rows, mass, dt)
    bad = np.flatnonzero(a + 2.0 * b >= STABILITY_BOUND)
    if bad.size == 0:
        return
    joints = ", ".join(
        f"{rows.joint_names[i]} (Kp*dt^2/m = {a[i]:.3g}, Kd*dt/m = {b[i]:.3g}, m = {mass[i]:.3g})" for i in bad
    )
    warnings.warn(
        f"build_controller: actuation='explicit' with explicit_pd='naive' at sim_freq {sim_freq:g} Hz (dt = {dt:g} s) "
        f"is unstable for {bad.size} joint(s): {joints}. A semi-implicit Euler step integrates a PD spring-damper "
        f"stably only while Kp*dt^2/m + 2*Kd*dt/m < {STABILITY_BOUND:g} (m: the joint's effective inertia at the "
        "model's initial pose); past it the joint's state grows into NaN. Use explicit_pd='stable' or "
        "explicit_pd='coupled' (PD on the predicted end-of-step state, stable at these gains), "
        "actuation='implicit', a higher sim_freq or lower gains.",
        UserWarning,
        stacklevel=3,
    )
