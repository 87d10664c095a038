"""An independent numpy float32 re-derivation of wpctrl's controller semantics, for the property tests.

Written from the configs and ``tests/data/maniskill-controllers.md`` (sections 1 and 3), ManiSkill-style: one
small class per config type (``reset`` / ``set_action`` / ``before_simulation_step`` / drive targets / explicit PD
torque) and a combined wrapper that slices a flat action in dict order. It shares nothing with wpctrl but the
config dataclasses it reads: no row tables, no kernels, no binding.

Where wpctrl deliberately differs from ManiSkill, this reference follows wpctrl:

1. ``reset(mask)`` re-initialises only the masked envs (the first reset: all envs). PDJointPosVel takes the measured
   velocity as its velocity target on the first reset and 0 on later ones; PDJointVel and passive joints get 0 on
   every reset. At construction every buffer holds the model's initial pose (velocity targets 0).
2. Drive targets are written at every substep; a reset with a control also writes the reset envs' targets (and zeroes
   their explicit torques). Exception, a mode without per-substep work (implicit actuation, no interpolation, no
   per-substep inertia update): the targets are constant over a control step, so they are written into the Control
   the controller knows (the last one given to a substep or a reset) when they change (set_action: accepted envs;
   reset, with or without a control: the reset envs), and a substep writes only a Control not known yet (every env).
   A reset with a Control not known yet writes every env's targets into it; set_state forgets the Control.
3. Interpolation holds at the K-th value past K: ``start + ((target - start) / K) * min(k, K)``, computed from the
   current start and target.
4. An env whose flat action holds any NaN/Inf is left completely untouched and counted.
5. ``set_state`` copies.

Actuation options (issue 10), also written from their description, not from the kernels:

6. Drive properties are per env ((N, n) arrays, the config's values at construction); ``set_drive`` overwrites the
   masked envs. Randomised values are Warp's RNG draws (:class:`WarpRand`, a numpy port of Warp's PCG hash: seed, the
   device draw counter, env and row), as ``randomize_drive_properties`` documents them: :func:`drive_draws`.
7. ``delay``: each substep's drive command (position target after interpolation, velocity target) enters a history;
   the drive (written targets and the explicit law) uses the command of ``d[env]`` substeps ago; a reset fills the
   env's history with its reset pose and velocity target. The per-env d is drawn at reset from the build's seed and
   the draw counter (:func:`delay_draws`).
8. ``track_effort``: the PD law (the explicit one, or the naive law for implicit actuation) before and after the
   clamp, and a count of substeps with |law| > limit; reset zeroes them for the reset envs.
9. ``clip_targets``: position targets set by an action are clamped to the joint limits (commanded joints first, then
   the mimic followers computed from the clamped source and clamped themselves).
10. Actuator models (``DCMotor``, ``PositionBasedEffortLimit``) replace the explicit clamp to the force limit; ``ema``
    smooths and ``binary`` picks the commanding joints' targets (``reference_actuators.py``).

Arrays are float32 throughout and every operation is written in ManiSkill's order, so results agree with wpctrl to
the last bit (up to the compiler's freedom to fuse multiply-adds).

Layout: the robot has J joints (``robot_joints``, model order); measured states and drive writes are (N, J) arrays in
that order. Drive writes are returned as ``{"target_q" | "target_qd" | "f": (written (N, J) bool, value (N, J))}``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from reference_actuators import ActuatorModel, binary, smooth

from wpctrl.config import (
    PassiveControllerConfig,
    PDJointPosControllerConfig,
    PDJointPosMimicControllerConfig,
    PDJointPosVelControllerConfig,
    PDJointVelControllerConfig,
)

F32 = np.float32
WRITE_KEYS = ("target_q", "target_qd", "f")


def _bcast(value, n: int) -> np.ndarray:
    """ManiSkill's ``np.broadcast_to(value, n)``, as float32."""
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).astype(F32)


def empty_writes(num_envs: int, num_joints: int) -> dict:
    return {k: (np.zeros((num_envs, num_joints), bool), np.zeros((num_envs, num_joints), F32)) for k in WRITE_KEYS}


def _write(writes: dict, key: str, env_mask: np.ndarray, cols: Sequence[int], values: np.ndarray) -> None:
    """``writes[key][env, cols] = values[env]`` for the envs in ``env_mask``."""
    written, out = writes[key]
    envs = np.nonzero(env_mask)[0]
    if envs.size == 0 or len(cols) == 0:
        return
    ix = np.ix_(envs, np.asarray(cols))
    written[ix] = True
    out[ix] = np.asarray(values, F32)[envs]


class RefRobot:
    """Joint names in model order and their (J, 2) float32 position limits (ManiSkill's ``get_qlimits()[0]``)."""

    def __init__(self, joint_names: Sequence[str], limits: np.ndarray):
        self.joint_names = list(joint_names)
        self.limits = np.asarray(limits, F32).reshape(len(self.joint_names), 2)

    def cols(self, names: Sequence[str]) -> list[int]:
        return [self.joint_names.index(s) for s in names]


# ----------------------------------------------------------------------------------------------------------------------
# Warp's random numbers (warp/native/rand.h: the PCG hash of Jarzynski and Olano), in numpy.

_M32 = 0xFFFFFFFF


def _pcg(x: int) -> int:
    b = (x * 747796405 + 2891336453) & _M32
    c = (((b >> ((b >> 28) + 4)) ^ b) * 277803737) & _M32
    return (c >> 22) ^ c


class WarpRand:
    """One Warp RNG state: ``wp.rand_init(seed, offset)``, then ``randi`` / ``randf`` draws from it."""

    def __init__(self, seed: int, offset: int):
        self.state = (int(seed) + _pcg(int(offset) & _M32)) & _M32
        self.state = _pcg(self.state)

    def _next(self) -> int:
        self.state = _pcg(self.state)
        return self.state

    def randi(self, lo: int | None = None, hi: int | None = None) -> int:
        """``wp.randi(state)`` (an int32) or ``wp.randi(state, lo, hi)`` in [lo, hi)."""
        u = self._next()
        if lo is None:
            return u - (1 << 32) if u >= (1 << 31) else u
        return u % (hi - lo) + lo

    def randf(self) -> np.float32:
        return F32((self._next() >> 8) * (1.0 / 16777216.0))


def drive_draws(seed: int, counter: int, num_envs: int, total_rows: int, row0: int, n: int) -> np.ndarray:
    """(num_envs, n, 4) uniform [0, 1) draws of ``randomize_drive_properties``: per (env, row of the mode), one
    state keyed by the seed and the draw counter, four draws (stiffness, damping, force limit, friction)."""
    key = WarpRand(seed, counter).randi()
    out = np.zeros((num_envs, n, 4), F32)
    for e in range(num_envs):
        for j in range(n):
            r = WarpRand(key & _M32, e * total_rows + row0 + j)
            out[e, j] = [r.randf() for _ in range(4)]
    return out


def param_draws(seed: int, counter: int, num_envs: int, total_rows: int, row0: int, n: int, stream: int) -> np.ndarray:
    """(num_envs, n) uniform [0, 1) draws of one actuator-model parameter (DC-motor stall effort: stream 4, no-load
    speed: stream 5) in ``randomize_drive_properties``: the drive properties' key, offset by the stream, one draw per
    (env, row of the mode)."""
    key = WarpRand(seed, counter).randi()
    out = np.zeros((num_envs, n), F32)
    for e in range(num_envs):
        for j in range(n):
            out[e, j] = WarpRand((key + stream * 7919) & _M32, e * total_rows + row0 + j).randf()
    return out


def drawn_value(u: np.ndarray, lo: float, hi: float, nominal=None) -> np.ndarray:
    """``lo + (hi - lo) u`` in float32, times the nominal value for a "scale" draw."""
    x = F32(lo) + (F32(hi) - F32(lo)) * np.asarray(u, F32)
    return x if nominal is None else np.asarray(nominal, F32) * x


def delay_draws(seed: int, counter: int, num_envs: int, lo: int, hi: int) -> np.ndarray:
    """(num_envs,) per-env delays a reset draws in [lo, hi] [substeps] (lo when the range is a single value)."""
    if hi <= lo:
        return np.full(num_envs, lo, np.int64)
    out = np.zeros(num_envs, np.int64)
    for e in range(num_envs):
        key = WarpRand(seed, counter).randi()
        out[e] = WarpRand(key & _M32, e).randi(lo, hi + 1)
    return out


# ----------------------------------------------------------------------------------------------------------------------
# The coupled drive (README "PhysX-faithful drive"), solved as the box QP it is.


def coupled_torques(A: np.ndarray, b: np.ndarray, d: np.ndarray, lim: np.ndarray) -> np.ndarray:
    """One env's coupled drive torques, float64: ``tau = clamp(b - D A tau, -lim, lim)`` with ``D = diag(d)``, i.e.
    the box QP ``min 1/2 tau^T (D^-1 + A) tau - (D^-1 b)^T tau  s.t. |tau| <= lim`` over the rows with ``d > 0``
    (the others apply 0). The active set comes from scipy's bounded-variable least squares on the Cholesky factor of
    ``D^-1 + A`` (``1/2 |L^T tau - L^-1 D^-1 b|^2`` is the QP's objective up to a constant); the free rows are then
    solved exactly on it, and the result is checked to satisfy the clamp equation."""
    from scipy.optimize import lsq_linear

    A, b, d, lim = (np.asarray(x, np.float64) for x in (A, b, d, lim))
    tau = np.zeros_like(b)
    act = (d > 0) & (lim > 0)  # a zero limit pins its row at 0 (out of the QP, like a passive one)
    if not act.any():
        return tau
    idx = np.nonzero(act)[0]
    M = np.diag(1.0 / d[idx]) + A[np.ix_(idx, idx)]
    c = b[idx] / d[idx]
    lo, hi = -lim[idx], lim[idx]
    x = np.linalg.solve(M, c)  # no active limit: the linear system
    if not ((x >= lo) & (x <= hi)).all():
        L = np.linalg.cholesky(M)
        x = lsq_linear(L.T, np.linalg.solve(L, c), bounds=(lo, hi), method="bvls", tol=1e-14, max_iter=1000).x
        for _ in range(len(idx) + 2):  # polish on the active set found: exact free rows, clamped ones at the bound
            clamped = (x <= lo * (1 - 1e-9)) | (x >= hi * (1 - 1e-9))
            x = np.where(clamped, np.clip(x, lo, hi), x)
            f = ~clamped
            if f.any():
                rhs = c[f] - M[np.ix_(f, ~f)] @ x[~f]
                x[f] = np.linalg.solve(M[np.ix_(f, f)], rhs)
            if ((x >= lo * (1 + 1e-9)) & (x <= hi * (1 + 1e-9))).all():
                break
    tau[idx] = x
    w = b - d * (A @ tau)
    assert np.allclose(tau[idx], np.clip(w[idx], -lim[idx], lim[idx]), rtol=1e-7, atol=1e-9 * (1 + np.abs(b).max()))
    return tau


# ----------------------------------------------------------------------------------------------------------------------
# One class per config type.


class RefController:
    """Shared state of every controller: (N, n) buffers over the config's joints, a per-env substep counter."""

    has_qpos = False  # has a position target (start/target buffers are meaningful)
    has_vel_target = False  # writes a velocity drive target

    def __init__(self, config, robot: RefRobot, num_envs: int, num_substeps: int, q0: np.ndarray):
        self.config = config
        self.names = list(config.joint_names)
        self.cols = robot.cols(self.names)
        self.qlimits = robot.limits[self.cols].copy()
        self.clip = False
        self.n = len(self.names)
        self.N = num_envs
        self.K = num_substeps
        q0 = np.asarray(q0, F32)[:, self.cols]
        self.start_qpos = q0.copy()
        self.target_qpos = q0.copy()
        self.target_qvel = np.zeros((num_envs, self.n), F32)
        self.step = np.zeros(num_envs, np.int64)
        n = self.n
        self.kp = np.zeros((num_envs, n), F32)
        self.kd = np.tile(_bcast(config.damping, n), (num_envs, 1))
        self.force_limit = np.tile(_bcast(config.force_limit, n), (num_envs, 1))
        self.friction = np.tile(_bcast(config.friction, n), (num_envs, 1))
        self.computed_effort = np.zeros((num_envs, n), F32)
        self.applied_effort = np.zeros((num_envs, n), F32)
        self.saturation_count = np.zeros((num_envs, n), np.int64)
        self.sat_margin = np.zeros((num_envs, n), np.int64)  # coupled drive: substeps within 1e-5 of the limit
        mode = getattr(config, "drive_mode", "force")  # ManiSkill's passive drive is always "force"
        modes = [mode] * n if isinstance(mode, str) else list(mode)
        self.accel = np.array([m == "acceleration" for m in modes], bool)
        self.actuator = ActuatorModel(config, num_envs, n)  # DC motor, position table, or ManiSkill's clamp
        self.low = np.zeros(0, F32)
        self.high = np.zeros(0, F32)
        self.normalize = False
        self.processed_action = np.zeros((num_envs, 0), F32)

    @property
    def action_dim(self) -> int:
        return self.low.shape[0]

    def _set_bounds(self, low, high, normalize: bool) -> None:
        self.low = np.asarray(low, F32)
        self.high = np.asarray(high, F32)
        self.normalize = bool(normalize)
        self.processed_action = np.zeros((self.N, self.low.shape[0]), F32)

    def preprocess(self, a: np.ndarray) -> np.ndarray:
        """ManiSkill's ``clip_and_scale_action``: clip first, then ``0.5(h+l) + 0.5(h-l)a``, float32."""
        a = np.asarray(a, F32)
        if not self.normalize:
            return a.copy()
        a = np.clip(a, F32(-1), F32(1))
        return F32(0.5) * (self.high + self.low) + F32(0.5) * (self.high - self.low) * a

    # -- stages -----------------------------------------------------------------------------------------------------

    def set_drive(self, name: str, values: np.ndarray, mask: np.ndarray) -> None:
        """Per-env drive property ``name`` (stiffness, damping, force_limit, friction) of the masked envs."""
        if name in ("saturation_effort", "velocity_limit"):
            target = self.actuator.sat_effort if name == "saturation_effort" else self.actuator.vel_limit
        else:
            target = getattr(self, {"stiffness": "kp", "damping": "kd"}.get(name, name))
        target[mask] = np.asarray(values, F32)[mask]

    def reset(self, q: np.ndarray, qd: np.ndarray, mask: np.ndarray, first: bool) -> None:
        q = q[:, self.cols]
        self.computed_effort[mask] = 0
        self.applied_effort[mask] = 0
        self.saturation_count[mask] = 0
        self.sat_margin[mask] = 0
        self.step[mask] = 0
        self.start_qpos[mask] = q[mask]
        self.target_qpos[mask] = q[mask]
        self.target_qvel[mask] = 0

    def set_action(self, a: np.ndarray, q: np.ndarray, good: np.ndarray) -> None:
        self.step[good] = 0

    def drive_target_q(self) -> np.ndarray | None:
        """(N, n) position drive target at the current substep counter, or None (no position drive)."""
        return None

    def drive_writes(self, mask: np.ndarray, writes: dict) -> None:
        """The drive targets a substep writes (position and velocity targets, no torque), for the envs in ``mask``."""
        tq = self.drive_target_q()
        if tq is not None:
            _write(writes, "target_q", mask, self.cols, tq)
        if self.has_vel_target:
            _write(writes, "target_qd", mask, self.cols, self.target_qvel)

    def drive_command(self) -> tuple[np.ndarray | None, np.ndarray]:
        """This substep's undelayed command: (position target or None, velocity target (zeros without one))."""
        tqd = self.target_qvel.copy() if self.has_vel_target else np.zeros((self.N, self.n), F32)
        return self.drive_target_q(), tqd

    def before_simulation_step(
        self, q, qd, response, explicit_pd: str | None, dt, writes: dict, command=None, track_effort=False
    ) -> None:
        """One substep: count it, write the drive targets and, with explicit actuation, the clamped PD torque.

        ``response``: (N, n) joint-space response r = (H^-1)_ii (an input, as the physics is); acceleration drives
        scale both gains by 1/r; the "stable" law is ``(Kp (e - dt qd) + Kd (qd* - qd)) / (1 + r dt (Kd + dt Kp))``.
        ``command``: None, or a function mapping this substep's command to the (delayed) one to drive with.
        "coupled": the torques of all children are solved together (:meth:`RefCombined.coupled_step`); this keeps
        the command it wrote in ``self.command``.
        """
        self.step += 1
        everyone = np.ones(self.N, bool)
        tq, tqd = self.drive_command()
        if command is not None:
            tq, tqd = command(tq, tqd)
        if tq is not None:
            _write(writes, "target_q", everyone, self.cols, tq)
        if self.has_vel_target:
            _write(writes, "target_qd", everyone, self.cols, tqd)
        self.command = (tq, tqd)
        if explicit_pd == "coupled" or (explicit_pd is None and not track_effort):
            return
        qm, qdm = q[:, self.cols], qd[:, self.cols]
        r = np.asarray(response, F32)
        kp = np.broadcast_to(self.kp, (self.N, self.n))
        kd = np.broadcast_to(self.kd, (self.N, self.n))
        e = np.zeros((self.N, self.n), F32)
        if tq is None:
            kp = np.zeros_like(kp)
        else:
            e = tq - qm
        kp = np.where(self.accel, kp / r, kp)
        kd = np.where(self.accel, kd / r, kd)
        if explicit_pd == "stable":
            u = (kp * (e - dt * qdm) + kd * (tqd - qdm)) / (F32(1) + r * dt * (kd + dt * kp))
        else:
            u = kp * e + kd * (tqd - qdm)
        f, near = self.actuator.apply(u, qm, qdm, self.force_limit)  # ManiSkill's clamp, or the actuator model
        if explicit_pd is not None:
            _write(writes, "f", everyone, self.cols, f)
        if track_effort:
            self.computed_effort = u.astype(F32)
            self.applied_effort = f.astype(F32)
            self.saturation_count += (f != u) & ~near
            self.sat_margin += near

    def reset_writes(self, q: np.ndarray, mask: np.ndarray, explicit: bool, writes: dict) -> None:
        """What ``reset(..., control=c)`` writes for the reset envs."""
        if self.has_qpos:
            _write(writes, "target_q", mask, self.cols, q[:, self.cols])
        if self.has_vel_target:
            _write(writes, "target_qd", mask, self.cols, self.target_qvel)
        if explicit:
            _write(writes, "f", mask, self.cols, np.zeros((self.N, self.n), F32))

    # -- model drive properties -------------------------------------------------------------------------------------

    def drive_properties(self, explicit: bool, response=None) -> dict[str, np.ndarray]:
        """(N, n) stiffness, damping, force limit, friction and the Newton target-mode name the model must hold.

        Implicit acceleration drives hand the solver per-env gains Kp / r and Kd / r (``response``: (N, n) r)."""
        if self.has_qpos:
            mode = "POSITION_VELOCITY" if self.has_vel_target else "POSITION"
        else:
            mode = "VELOCITY"
        shape = (self.N, self.n)
        r = np.ones(shape, F32) if response is None else np.asarray(response, F32)
        zero = np.zeros(shape, F32)
        ke = np.broadcast_to(self.kp, shape)
        kd = np.broadcast_to(self.kd, shape)
        return {
            "ke": zero if explicit else np.where(self.accel, ke / r, ke),
            "kd": zero if explicit else np.where(self.accel, kd / r, kd),
            "effort": np.broadcast_to(self.force_limit, shape),
            "friction": np.broadcast_to(self.friction, shape),
            "mode": np.broadcast_to(np.array(["EFFORT" if explicit else mode] * self.n), shape),
        }

    # -- state ------------------------------------------------------------------------------------------------------

    @property
    def uses_target(self) -> bool:
        return bool(getattr(self.config, "use_delta", False) and getattr(self.config, "use_target", False))

    def get_state(self) -> dict:
        return {"target_qpos": self.target_qpos.copy()} if self.uses_target else {}

    def set_state(self, state) -> None:
        if state and self.uses_target:
            self.target_qpos[...] = np.asarray(state["target_qpos"], F32)


class RefPDJointPos(RefController):
    """§1.1: absolute, delta from the measured position, or delta on the virtual target; optional interpolation."""

    has_qpos = True

    def __init__(self, config, robot, num_envs, num_substeps, q0):
        super().__init__(config, robot, num_envs, num_substeps, q0)
        self.kp = np.tile(_bcast(config.stiffness, self.n), (num_envs, 1))
        lim = robot.limits[self.cols].copy()  # float32 (n, 2)
        if config.lower is not None:
            lim[:, 0] = config.lower
        if config.upper is not None:
            lim[:, 1] = config.upper
        self.pos_low, self.pos_high = lim[:, 0].copy(), lim[:, 1].copy()
        self._set_bounds(self.pos_low, self.pos_high, config.normalize_action)

    def _new_target(self, a: np.ndarray, q: np.ndarray) -> np.ndarray:
        c = self.config
        if c.use_delta:
            if c.use_target:
                return self.target_qpos + a
            return q + a
        return a

    def set_action(self, a, q, good):
        sign = binary(self.config, a, self.low, self.high)
        a = self.preprocess(a) if sign is None else sign
        self.processed_action[good] = a[good]
        self.step[good] = 0
        qm = q[:, self.cols]
        self.start_qpos[good] = qm[good]
        self._set_pos_targets(a[:, : self._pos_dim], qm, good)

    @property
    def _pos_dim(self) -> int:
        return self.n

    def _clamp(self, t, idx=slice(None)):
        if not self.clip:
            return t
        return np.clip(t, self.qlimits[idx, 0], self.qlimits[idx, 1]).astype(F32)

    def _set_pos_targets(self, a, qm, good):
        target = smooth(self.config, self._new_target(a, qm), self.target_qpos, self.qlimits)
        target = self._clamp(target)
        self.target_qpos[good] = target[good]

    def drive_target_q(self):
        if not self.config.interpolate:
            return self.target_qpos.copy()
        step_size = (self.target_qpos - self.start_qpos) / F32(self.K)
        k = np.minimum(self.step, self.K).astype(F32)[:, None]
        return self.start_qpos + step_size * k


class RefPDJointPosMimic(RefPDJointPos):
    """§1.2: the action commands the control joints (ascending position in joint_names); mimics follow."""

    def __init__(self, config, robot, num_envs, num_substeps, q0):
        super().__init__(config, robot, num_envs, num_substeps, q0)
        mimic = dict(config.mimic or {})
        if not mimic and self.n == 2:
            mimic = {self.names[0]: {"joint": self.names[1]}}  # ManiSkill's default (without mutating the config)
        self.mimic_idx = np.array([self.names.index(k) for k in mimic], np.int64)
        self.mimic_src = np.array([self.names.index(v["joint"]) for v in mimic.values()], np.int64)
        self.mul = np.array([v.get("multiplier", 1.0) for v in mimic.values()], F32)
        self.off = np.array([v.get("offset", 0.0) for v in mimic.values()], F32)
        self.control_idx = np.unique(self.mimic_src)  # sorted, as torch.unique
        self._set_bounds(self.pos_low[self.control_idx], self.pos_high[self.control_idx], config.normalize_action)

    @property
    def _pos_dim(self) -> int:
        return len(self.control_idx)

    def _set_pos_targets(self, a, qm, good):
        c = self.config
        C = self.control_idx
        target = self.target_qpos.copy()
        if c.use_delta:
            if c.use_target:
                target[:, C] = target[:, C] + a
            else:
                target[:, C] = qm[:, C] + a
        else:
            target[:, C] = a
        target[:, C] = smooth(c, target[:, C], self.target_qpos[:, C], self.qlimits[C])
        target[:, C] = self._clamp(target[:, C], C)
        M = self.mimic_idx
        target[:, M] = self._clamp(target[:, self.mimic_src] * self.mul + self.off, M)
        self.target_qpos[good] = target[good]


class RefPDJointPosVel(RefPDJointPos):
    """§1.4: PDJointPos on the first half of the action, velocity targets from the second half (not interpolated)."""

    has_vel_target = True

    def __init__(self, config, robot, num_envs, num_substeps, q0):
        super().__init__(config, robot, num_envs, num_substeps, q0)
        vl, vh = _bcast(config.vel_lower, self.n), _bcast(config.vel_upper, self.n)
        self._set_bounds(
            np.concatenate([self.pos_low, vl]), np.concatenate([self.pos_high, vh]), config.normalize_action
        )

    def set_action(self, a, q, good):
        super().set_action(a, q, good)
        v = self.preprocess(a)[:, self.n :]
        self.target_qvel[good] = v[good]

    def reset(self, q, qd, mask, first):
        super().reset(q, qd, mask, first)
        if first:
            self.target_qvel[mask] = qd[:, self.cols][mask]


class RefPDJointVel(RefController):
    """§1.3: velocity targets = the (clipped, scaled) action; stiffness 0."""

    has_vel_target = True

    def __init__(self, config, robot, num_envs, num_substeps, q0):
        super().__init__(config, robot, num_envs, num_substeps, q0)
        self._set_bounds(_bcast(config.lower, self.n), _bcast(config.upper, self.n), config.normalize_action)

    def set_action(self, a, q, good):
        v = self.preprocess(a)
        self.processed_action[good] = v[good]
        self.target_qvel[good] = v[good]
        self.step[good] = 0


class RefPassive(RefController):
    """§1.5: no action; damping toward a zero velocity target."""

    has_vel_target = True


def ref_controller_cls(config):
    from reference_ee import EE_CONFIGS, RefEE

    if isinstance(config, EE_CONFIGS):
        return RefEE
    for cls, ref in (
        (PDJointPosMimicControllerConfig, RefPDJointPosMimic),
        (PDJointPosVelControllerConfig, RefPDJointPosVel),
        (PDJointPosControllerConfig, RefPDJointPos),
        (PDJointVelControllerConfig, RefPDJointVel),
        (PassiveControllerConfig, RefPassive),
    ):
        if isinstance(config, cls):
            return ref
    raise TypeError(type(config).__name__)


# ----------------------------------------------------------------------------------------------------------------------
# The combined controller (a single config is a one-child dict with uid "").


def env_mask(env_ids, num_envs: int) -> np.ndarray:
    """A (num_envs,) bool mask from None, an int, a sequence of ints or a bool mask (numpy, torch or wp)."""
    if env_ids is None:
        return np.ones(num_envs, bool)
    if hasattr(env_ids, "numpy"):
        env_ids = env_ids.numpy() if not hasattr(env_ids, "detach") else env_ids.detach().cpu().numpy()
    a = np.asarray(env_ids)
    if a.dtype == np.bool_:
        return a.reshape(num_envs).copy()
    m = np.zeros(num_envs, bool)
    m[a.reshape(-1).astype(np.int64)] = True
    return m


class RefCombined:
    """One control mode: a config or a ``{uid: config}`` dict, with a flat action in dict insertion order."""

    def __init__(
        self,
        config,
        robot: RefRobot,
        num_envs: int,
        num_substeps: int,
        q0: np.ndarray,
        actuation: str = "implicit",
        explicit_pd: str = "naive",
        sim_dt: float = 0.01,
        inertia_update: str = "control",
        delay: tuple[int, int] | None = None,
        track_effort: bool = False,
        clip_targets: str = "none",
        kinematics=None,
    ):
        """``kinematics(q, joint_names, ee_link) -> (N, 6, n)``: the geometric Jacobian of an EE chain at the measured
        positions (an input for end-effector children, as the response is for acceleration drives)."""
        configs = dict(config) if isinstance(config, Mapping) else {"": config}
        configs.pop("balance_passive_force", None)
        self.robot = robot
        self.N = num_envs
        self.K = num_substeps
        self.explicit = actuation == "explicit"
        self.explicit_pd = explicit_pd if self.explicit else None
        self.coupled = self.explicit_pd == "coupled"
        self.dt = F32(sim_dt)
        self.children: dict[str, RefController] = {}
        self.action_mapping: dict[str, tuple[int, int]] = {}
        col = 0
        for uid, c in configs.items():
            ch = ref_controller_cls(c)(c, robot, num_envs, num_substeps, q0)
            ch.kinematics = kinematics
            ch.clip = clip_targets == "joint_limits"
            self.children[uid] = ch
            self.action_mapping[uid] = (col, col + ch.action_dim)
            col += ch.action_dim
        self.action_dim = col
        self.bad_action_count = np.zeros(num_envs, np.int64)
        self.num_resets = 0
        self.track_effort = bool(track_effort)
        self.delay_range = delay
        self.delay = np.zeros(num_envs, np.int64) if delay is None else np.full(num_envs, delay[0], np.int64)
        # Command history per child: a list (oldest first) of (position or None, velocity) (N, n) commands.
        self.history: dict[str, list] = {}
        if delay is not None:
            everyone = np.ones(num_envs, bool)
            for uid, ch in self.children.items():
                self.history[uid] = []
                self._fill_history(uid, ch, everyone)
        # Per-substep work: explicit torques, interpolation, a command delay, the effort readout, or r = (H^-1)_ii
        # refreshed every substep for an acceleration drive. Without it, drive targets are written when they change,
        # into the known Control.
        kids = self.children.values()
        interpolates = any(getattr(c.config, "interpolate", False) for c in kids)
        accel_per_substep = inertia_update == "substep" and any(c.accel.any() for c in kids)
        self.per_substep = self.explicit or interpolates or accel_per_substep or delay is not None or track_effort
        self.knows_control = False

    def _delayer(self, uid: str, ch: RefController):
        """Push a substep's command into the history; return the one of delay[env] substeps ago, per env."""

        def delayed(tq, tqd):
            hist = self.history[uid]
            hist.append((np.zeros((self.N, ch.n), F32) if tq is None else tq.copy(), tqd.copy()))
            del hist[0]
            back = np.minimum(self.delay, self.delay_range[1])  # hist[-1] is this substep's command
            cq = np.stack([hist[len(hist) - 1 - int(back[e])][0][e] for e in range(self.N)])
            cqd = np.stack([hist[len(hist) - 1 - int(back[e])][1][e] for e in range(self.N)])
            return (None if tq is None else cq), cqd

        return delayed

    def _fill_history(self, uid: str, ch: RefController, mask: np.ndarray) -> None:
        """The masked envs' whole history becomes the reset pose and velocity target."""
        size = self.delay_range[1] + 1
        hist = self.history[uid]
        while len(hist) < size:
            hist.append((np.zeros((self.N, ch.n), F32), np.zeros((self.N, ch.n), F32)))
        for tq, tqd in hist:
            tq[mask] = ch.start_qpos[mask]  # the reset pose (start = target = q after a reset)
            tqd[mask] = ch.target_qvel[mask]

    @property
    def action_low(self) -> np.ndarray:
        """Flat single-action-space bounds: [-1, 1] for normalising children, raw bounds otherwise."""
        return np.concatenate([-np.ones_like(c.low) if c.normalize else c.low for c in self.children.values()])

    @property
    def action_high(self) -> np.ndarray:
        return np.concatenate([np.ones_like(c.high) if c.normalize else c.high for c in self.children.values()])

    @property
    def step_counter(self) -> np.ndarray:
        steps = [c.step for c in self.children.values()]
        for s in steps[1:]:
            assert np.array_equal(s, steps[0])
        return steps[0]

    def reset(self, q, qd, env_ids=None, with_control: bool = False) -> dict:
        """Returns the drive writes made when a control is passed (empty writes otherwise)."""
        first = self.num_resets == 0
        self.num_resets += 1
        mask = np.ones(self.N, bool) if first else env_mask(env_ids, self.N)
        q, qd = np.asarray(q, F32), np.asarray(qd, F32)
        writes = empty_writes(self.N, len(self.robot.joint_names))
        for uid, ch in self.children.items():
            ch.reset(q, qd, mask, first)
            if with_control or (not self.per_substep and self.knows_control):
                ch.reset_writes(q, mask, self.explicit, writes)
            if self.delay_range is not None:
                self._fill_history(uid, ch, mask)
            if with_control and not self.per_substep and not self.knows_control:
                ch.drive_writes(np.ones(self.N, bool), writes)
        if with_control and not self.per_substep:
            self.knows_control = True
        return writes

    def set_action(self, action, q) -> dict:
        """Returns the drive writes (none, unless a mode without per-substep work knows a Control). End-effector
        children read the Jacobian at ``q`` from ``kinematics``."""
        a = np.asarray(action).astype(F32).reshape(self.N, self.action_dim)
        good = np.isfinite(a).all(axis=1)
        self.bad_action_count[~good] += 1
        q = np.asarray(q, F32)
        writes = empty_writes(self.N, len(self.robot.joint_names))
        with np.errstate(invalid="ignore", over="ignore"):  # rejected envs are computed, then dropped
            for uid, ch in self.children.items():
                s, e = self.action_mapping[uid]
                ch.set_action(a[:, s:e], q, good)
                if not self.per_substep and self.knows_control:
                    ch.drive_writes(good, writes)
        return writes

    def before_simulation_step(self, q, qd, response: Mapping | None = None, inverse=None) -> dict:
        """``response``: {uid: (N, n) r} for children with acceleration drives or under stable explicit PD.
        ``inverse``: (N, J, J) H^-1 over the robot's joints at ``q`` (float64), for the coupled drive."""
        q, qd = np.asarray(q, F32), np.asarray(qd, F32)
        writes = empty_writes(self.N, len(self.robot.joint_names))
        unchanged = not self.per_substep and self.knows_control  # the known Control already holds the targets
        for uid, ch in self.children.items():
            r = (response or {}).get(uid)
            r = np.ones((self.N, ch.n), F32) if r is None else r
            command = None
            if self.delay_range is not None:
                command = self._delayer(uid, ch)
            ch.before_simulation_step(q, qd, r, self.explicit_pd, self.dt, writes, command, self.track_effort)
        if self.coupled:
            self.coupled_step(q, qd, inverse, writes)
        self.knows_control = True
        return empty_writes(self.N, len(self.robot.joint_names)) if unchanged else writes

    def coupled_step(self, q, qd, inverse, writes) -> None:
        """The coupled drive (README, "PhysX-faithful drive"), float64, over every row of the mode at once:
        ``b = Kp (q* - q - dt qd) + Kd (qd* - qd)`` (Kp = 0 without a position target, qd* = 0 without a velocity
        target), ``d = dt Kd + dt^2 Kp``, acceleration rows scale Kp, Kd by 1 / A_ii, and ``tau`` solves the box QP
        (:func:`coupled_torques`) with A the rows' block of H^-1. Effort readout: the law at the predicted state
        ``b - d (A tau)`` and tau; a row counts as saturated when that law exceeds its limit (``sat_margin``: the
        substeps where it was within 1e-5 of the limit, either way)."""
        kids = list(self.children.values())
        cols = np.concatenate([ch.cols for ch in kids])
        h = float(self.dt)
        qm = np.asarray(q, np.float64)[:, cols]
        qdm = np.asarray(qd, np.float64)[:, cols]
        kp, kd, lim, accel, e, tqd = [], [], [], [], [], []
        for ch in kids:
            tq, cqd = ch.command
            has_q = tq is not None
            kp.append(np.asarray(ch.kp if has_q else np.zeros((self.N, ch.n)), np.float64))
            kd.append(np.asarray(ch.kd, np.float64))
            lim.append(np.asarray(ch.force_limit, np.float64))
            accel.append(np.broadcast_to(ch.accel, (self.N, ch.n)))
            e.append(np.asarray(tq, np.float64) if has_q else np.zeros((self.N, ch.n)))
            tqd.append(np.asarray(cqd, np.float64) if ch.has_vel_target else np.zeros((self.N, ch.n)))
        kp, kd, lim, accel, tq, tqd = (np.concatenate(x, axis=1) for x in (kp, kd, lim, accel, e, tqd))
        e = np.where(kp > 0, tq - qm, 0.0)
        tau = np.zeros_like(qm)
        w = np.zeros_like(qm)
        scale = np.zeros_like(qm)  # |b| + D |A| |tau|: what the law's rounding is relative to
        for env in range(self.N):
            A = np.asarray(inverse[env], np.float64)[np.ix_(cols, cols)]
            diag = np.diag(A)
            kpe = np.where(accel[env], kp[env] / diag, kp[env])
            kde = np.where(accel[env], kd[env] / diag, kd[env])
            b = kpe * (e[env] - h * qdm[env]) + kde * (tqd[env] - qdm[env])
            d = h * kde + h * h * kpe
            tau[env] = coupled_torques(A, b, d, lim[env])
            w[env] = np.where(d > 0, b - d * (A @ tau[env]), 0.0)
            scale[env] = np.abs(b) + d * (np.abs(A) @ np.abs(tau[env]))
        everyone = np.ones(self.N, bool)
        _write(writes, "f", everyone, cols, tau.astype(F32))
        self.coupled_scale = (cols, scale)
        if self.track_effort:
            c0 = 0
            for ch in kids:
                sl = slice(c0, c0 + ch.n)
                ch.computed_effort = w[:, sl].astype(F32)
                ch.effort_scale = scale[:, sl]
                ch.applied_effort = tau[:, sl].astype(F32)
                near = np.abs(np.abs(w[:, sl]) - lim[:, sl]) <= 1e-5 * np.maximum(lim[:, sl], 1.0)
                ch.saturation_count += (np.abs(w[:, sl]) > lim[:, sl]) & ~near
                ch.sat_margin += near
                c0 += ch.n

    def initial_control_targets(self, q0) -> dict:
        """Drive targets of a ``Model.control()`` made after construction: the initial pose on position joints, 0 on
        the coordinates of joints without a position drive, 0 velocity targets."""
        writes = empty_writes(self.N, len(self.robot.joint_names))
        everyone = np.ones(self.N, bool)
        for ch in self.children.values():
            if ch.has_qpos:
                _write(writes, "target_q", everyone, ch.cols, np.asarray(q0, F32)[:, ch.cols])
            else:
                _write(writes, "target_q", everyone, ch.cols, np.zeros((self.N, ch.n), F32))
            if ch.has_vel_target:
                _write(writes, "target_qd", everyone, ch.cols, np.zeros((self.N, ch.n), F32))
        return writes

    def get_state(self, single: bool) -> dict:
        if single:
            return self.children[""].get_state()
        return {uid: s for uid, ch in self.children.items() if (s := ch.get_state())}

    def set_state(self, state, single: bool) -> None:
        self.knows_control = False
        if single:
            self.children[""].set_state(state)
            return
        state = state or {}
        for uid, ch in self.children.items():
            ch.set_state(state.get(uid))
