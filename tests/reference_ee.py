"""The end-effector controllers' one-step semantics (ManiSkill's GPU path) in numpy, for the property tests.

Written from the configs and the README: the processed action is the position action clipped and scaled onto
[pos_lower, pos_upper] (and, for PDEEPose, the rotation action norm-clipped to 1 and multiplied by ``rot_lower``, or
by half the rotation range with ``rotation_sign="corrected"``); with ``use_delta`` (no ``use_target``, one solver
iteration) the task-space step ``dx = [dp; dr]`` (dr = 0 for PDEEPos) is solved by damped least squares at the
measured positions, ``dq = J^T (J J^T + lambda I6)^-1 dx``, and the targets are ``q + alpha dq`` (clamped to the joint
limits with ``clip_targets``). J is an input (``kinematics``): the test computes it from Newton's own forward
kinematics. Everything else (drive targets, interpolation, resets, NaN hold, delay) is a position row's.
"""

from __future__ import annotations

import numpy as np
from reference_np import F32, RefPDJointPos, _bcast

from wpctrl.config import PDEEPosControllerConfig, PDEEPoseControllerConfig

EE_CONFIGS = (PDEEPosControllerConfig, PDEEPoseControllerConfig)


class RefEE(RefPDJointPos):
    """PDEEPos / PDEEPose with ``use_delta=True``, ``use_target=False`` and one solver iteration."""

    def __init__(self, config, robot, num_envs, num_substeps, q0):
        super(RefPDJointPos, self).__init__(config, robot, num_envs, num_substeps, q0)
        c = config
        solver = dict(c.delta_solver_config or {})
        if not c.use_delta or c.use_target or solver.get("solver_iterations", 1) != 1:
            raise NotImplementedError("the reference covers one-step delta EE control only")
        if solver.get("type", "levenberg_marquardt") != "levenberg_marquardt":
            raise NotImplementedError("the reference covers the Levenberg-Marquardt step only")
        self.alpha = float(solver.get("alpha", 1.0))
        self.lam = float(solver.get("lm_lambda", 1e-4))
        self.kp = np.tile(_bcast(c.stiffness, self.n), (num_envs, 1))
        self.pose = isinstance(c, PDEEPoseControllerConfig)
        low, high = [_bcast(c.pos_lower, 3)], [_bcast(c.pos_upper, 3)]
        if self.pose:
            rlo, rhi = _bcast(c.rot_lower, 3), _bcast(c.rot_upper, 3)
            low.append(rlo)
            high.append(rhi)
            corrected = solver.get("rotation_sign", "maniskill") == "corrected"
            self.rot_scale = (F32(0.5) * (rhi - rlo)) if corrected else rlo
        self._set_bounds(np.concatenate(low), np.concatenate(high), c.normalize_action)
        self.kinematics = None

    def preprocess(self, a):
        a = np.asarray(a, F32)
        lo, hi = self.low[:3], self.high[:3]
        p = np.clip(a[:, :3], F32(-1), F32(1)) if self.normalize else a[:, :3].copy()
        if self.normalize:
            p = F32(0.5) * (hi + lo) + F32(0.5) * (hi - lo) * p
        out = [p]
        if self.pose:
            r = a[:, 3:6].copy()
            if self.normalize:
                nrm = np.sqrt(r[:, 2] * r[:, 2] + (r[:, 1] * r[:, 1] + r[:, 0] * r[:, 0]))
                with np.errstate(divide="ignore", invalid="ignore"):
                    r = np.where((nrm > 1)[:, None], r * (F32(1) / nrm)[:, None], r)
                r = r * self.rot_scale
            out.append(r)
        return np.concatenate(out, axis=1).astype(F32)

    def set_action(self, a, q, good):
        act = self.preprocess(a)
        self.processed_action[good] = act[good]
        self.step[good] = 0
        qm = q[:, self.cols]
        self.start_qpos[good] = qm[good]
        J = np.asarray(self.kinematics(q, self.names, self.config.ee_link), np.float64)  # (N, 6, n)
        dx = np.zeros((self.N, 6))
        dx[:, : act.shape[1]] = act
        dq = np.zeros((self.N, self.n))
        for e in np.nonzero(good)[0]:
            y = np.linalg.solve(J[e] @ J[e].T + self.lam * np.eye(6), dx[e])
            dq[e] = J[e].T @ y
        target = self._clamp((qm + self.alpha * dq).astype(F32))
        self.target_qpos[good] = target[good]
