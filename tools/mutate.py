"""Mutation check: does the test suite notice a small, deliberate bug in the kernels and the engine?

Each mutation below is one exact text replacement in one file of ``wpctrl/`` (a sign flip, an off-by-one, a dropped
term, a check that skips a case). For each one this script copies the working tree to a temporary directory, applies
the replacement there, and runs the fast tests of the copy against the copy's ``wpctrl`` (the editable install's
import hook, which maps ``wpctrl`` to this checkout, is removed from the child interpreter, and the child checks that
the module it imported holds the mutated text). ``-x`` stops at the first failing test: that test *killed* the
mutation. A mutation that passes every test it ran *survived*: a blind spot of the suite.

Not part of CI: every mutation recompiles the kernels of the mutated module (Warp caches them by source, so the
mutated kernels land next to the real ones in Warp's kernel cache; ``--warp-cache DIR`` puts them elsewhere).

    python tools/mutate.py                    # every mutation, one at a time
    python tools/mutate.py --list             # names and what each one breaks
    python tools/mutate.py -k delay -k ema    # the mutations whose name contains "delay" or "ema"
    python tools/mutate.py --baseline         # the fast tests on an unmutated copy (must pass)
    python tools/mutate.py --markdown out.md  # also write the result table

Exit status: 0 when every mutation run was killed, 1 when one survived, 2 on a stale mutation (its text is no longer
in the file exactly once) or a baseline failure.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

FAST_TESTS = (
    "tests/test_semantics.py",
    "tests/test_conformance.py",
    "tests/test_launches.py",
    "tests/test_actuation.py",
    "tests/test_base_controllers.py",
    "tests/test_errors.py",
    "tests/test_binding.py",
    "tests/test_plan.py",
    "tests/test_acceleration.py",
    "tests/test_coupled.py",
    "tests/test_ee.py",
    "tests/test_ee_conformance.py",
    "tests/test_actuator_models.py",
    "tests/test_actuator_net.py",
    "tests/test_actuator_net_fused.py",
    "tests/test_multi_axis.py",
    "tests/test_gravity.py",
    "tests/test_alloc_sync.py",
    "tests/test_properties.py",
    "tests/test_config_boundaries.py",
    "tests/test_actuator_setups.py",
    "tests/test_construction_orders.py",
    "tests/test_distributed_ranks.py",
    "tests/test_impedance.py",
    "tests/test_impedance_envs.py",
    "tests/test_second_controller.py",
)
"""The fast tests a mutation runs after its own targeted ones (a minute or less each on a 2-core CPU, warm cache)."""

PROPERTY_EXAMPLES = "60"
"""Hypothesis examples per property test in a mutant (``WPCTRL_PROPERTY_EXAMPLES``); the suite's default is larger."""


@dataclass(frozen=True)
class Mutation:
    name: str
    file: str
    old: str
    new: str
    what: str
    tests: tuple[str, ...] = ()
    """Tests run first (the ones expected to kill it); the rest of FAST_TESTS follows."""


M = Mutation
MUTATIONS: list[Mutation] = [
    # -- the response r = (H^-1)_ii, acceleration drives and stable PD ---------------------------------------------
    M(
        "substep_inertia_only_in_set_action",
        "wpctrl/engine/parts/response.py",
        "    def before_set_action(self, engine, action, state) -> None:\n"
        "        if not self.update_per_substep:\n"
        "            self.update(engine, state)\n\n"
        "    def before_substep(self, engine, state, control) -> None:\n"
        "        if self.update_per_substep:\n"
        "            self.update(engine, state)\n",
        "    def before_set_action(self, engine, action, state) -> None:\n"
        "        self.update(engine, state)\n\n"
        "    def before_substep(self, engine, state, control) -> None:\n"
        "        pass\n",
        'inertia_update="substep" refreshes r only in set_action',
        ("tests/test_acceleration.py",),
    ),
    M(
        "accel_gains_not_notified",
        "wpctrl/engine/parts/response.py",
        "            engine.notify_solver()\n",
        "",
        "the implicit acceleration drive does not notify the solver after writing Kp/r, Kd/r",
        ("tests/test_acceleration.py",),
    ),
    M(
        "accel_gain_times_r",
        "wpctrl/kernels/pd_substep.py",
        "                        kpr = kpr / resp[r]\n",
        "                        kpr = kpr * resp[r]\n",
        "explicit acceleration drive multiplies Kp by r instead of dividing",
        ("tests/test_acceleration.py",),
    ),
    M(
        "accel_model_kd_from_kp",
        "wpctrl/engine/parts/response.py",
        "joint_target_kd_out[di] = kd[_bidx(kd.shape[0], env), r] / resp",
        "joint_target_kd_out[di] = kp[_bidx(kp.shape[0], env), r] / resp",
        "implicit acceleration drive writes Kp/r as the solver's damping",
        ("tests/test_actuation.py",),
    ),
    M(
        "stable_pd_denominator_without_kp",
        "wpctrl/kernels/pd_substep.py",
        "1.0 + resp[r] * dt * (kdr + dt * kpr)",
        "1.0 + resp[r] * dt * kdr",
        "stable explicit PD drops the dt^2 Kp term of its denominator",
        ("tests/test_coupled.py", "tests/test_acceleration.py"),
    ),
    # -- the coupled drive ------------------------------------------------------------------------------------------
    M(
        "coupled_clamp_never_released",
        "wpctrl/kernels/coupled_drive.py",
        "if (s == 1 and w < lim[r]) or (s == -1 and w > -lim[r]):",
        "if (s == 3 and w < lim[r]) or (s == -3 and w > -lim[r]):",
        "the coupled solve never releases a clamped row",
        ("tests/test_coupled.py",),
    ),
    M(
        "coupled_d_without_dt2_kp",
        "wpctrl/kernels/coupled_drive.py",
        "d[r] = h * kde + h * h * kpe",
        "d[r] = h * kde",
        "the coupled drive's D = dt Kd + dt^2 Kp loses its Kp term",
        ("tests/test_coupled.py",),
    ),
    M(
        "coupled_h_recovery_keeps_d",
        "wpctrl/kernels/coupled_drive.py",
        "L[wp.static(ROWD[r]), wp.static(ROWD[r])] = L[wp.static(ROWD[r]), wp.static(ROWD[r])] - dprev[r]",
        "L[wp.static(ROWD[r]), wp.static(ROWD[r])] = L[wp.static(ROWD[r]), wp.static(ROWD[r])]",
        "a later active-set iteration of the coupled drive keeps the last free rows' D inside H",
        ("tests/test_coupled.py",),
    ),
    M(
        "coupled_fallback_on_the_factor",
        "wpctrl/kernels/coupled_drive.py",
        "A = inverse_block(recover(H, dprev))",
        "A = inverse_block(H)",
        "the coupled drive's fallback sweeps build A from the last factor instead of H",
        ("tests/test_coupled.py",),
    ),
    M(
        "composite_inertia_without_parallel_axis",
        "wpctrl/kernels/inertia_unrolled.py",
        "pj = pj + Iw + m * (wp.dot(rr, rr) * wp.identity(n=3, dtype=wp.float64) - wp.outer(rr, rr))",
        "pj = pj + Iw",
        "the composite form of H drops the parallel-axis term of each body's inertia about the reference point",
        ("tests/test_coupled.py",),
    ),
    # -- set_action ----------------------------------------------------------------------------------------------
    M(
        "mimic_offset_dropped",
        "wpctrl/kernels/pd_set_action.py",
        "t[r] = t[wp.static(max(SRC[r], 0))] * row_f[r, ROW_F_MUL] + row_f[r, ROW_F_OFF]",
        "t[r] = t[wp.static(max(SRC[r], 0))] * row_f[r, ROW_F_MUL]",
        "a mimic follower ignores its offset",
        ("tests/test_semantics.py",),
    ),
    M(
        "nan_check_skips_last_column",
        "wpctrl/kernels/pd_set_action.py",
        "            ok = ok & int(wp.isfinite(a[c]))\n",
        "            if c < wp.static(A - 1):\n                ok = ok & int(wp.isfinite(a[c]))\n",
        "the joint kernel's NaN/Inf check skips the last action column",
        ("tests/test_semantics.py",),
    ),
    M(
        "mimic_multiplier_dropped",
        "wpctrl/kernels/pd_set_action.py",
        "t[r] = t[wp.static(max(SRC[r], 0))] * row_f[r, ROW_F_MUL] + row_f[r, ROW_F_OFF]",
        "t[r] = t[wp.static(max(SRC[r], 0))] + row_f[r, ROW_F_OFF]",
        "a mimic follower ignores its multiplier",
        ("tests/test_semantics.py",),
    ),
    M(
        "binary_zero_closes",
        "wpctrl/kernels/pd_set_action.py",
        "                    if a[c] < 0.0:\n",
        "                    if a[c] <= 0.0:\n",
        "a binary command of exactly 0 closes (it opens: upper for a >= 0)",
        ("tests/test_actuator_models.py",),
    ),
    M(
        "base_yaw_sign_flipped",
        "wpctrl/kernels/pd_set_action.py",
        "vt[r] = cy * ax + (-sy) * ay",
        "vt[r] = cy * ax + sy * ay",
        "the ego-centric base velocity rotates vy by the wrong sign of the yaw",
        ("tests/test_base_controllers.py",),
    ),
    M(
        "ee_nan_check_own_columns",
        "wpctrl/kernels/ee.py",
        "        if not _action_finite(action_in, env):\n            return\n",
        "        bad = int(0)\n"
        "        for k in range(3 + 3 * pose):\n"
        "            if not wp.isfinite(action_in[env, col0 + k]):\n"
        "                bad = 1\n"
        "        if bad != 0:\n"
        "            return\n",
        "the EE kernel checks NaN/Inf only in its own action columns",
        ("tests/test_ee.py",),
    ),
    M(
        "ema_coefficient_swapped",
        "wpctrl/kernels/pd_set_action.py",
        "al * t[r] + (1.0 - al) * tp",
        "(1.0 - al) * t[r] + al * tp",
        "the EMA weights the previous target with alpha",
        ("tests/test_actuator_models.py",),
    ),
    M(
        "target_delta_from_measured",
        "wpctrl/kernels/pd_set_action.py",
        "                    t[r] = t[r] + x[c]\n",
        "                    t[r] = q[r] + x[c]\n",
        "use_target deltas start from the measured position",
        ("tests/test_semantics.py",),
    ),
    M(
        "normalize_without_clip",
        "wpctrl/kernels/pd.py",
        "    c = wp.clamp(a, -1.0, 1.0)\n",
        "    c = a\n",
        "normalised actions are scaled without clipping to [-1, 1]",
        ("tests/test_semantics.py",),
    ),
    M(
        "clip_targets_skips_followers",
        "wpctrl/kernels/pd_set_action.py",
        "                if wp.static(CLIP):\n"
        "                    t[r] = wp.clamp(t[r], row_f[r, ROW_F_QLO], row_f[r, ROW_F_QHI])\n",
        "                if wp.static(False):\n"
        "                    t[r] = wp.clamp(t[r], row_f[r, ROW_F_QLO], row_f[r, ROW_F_QHI])\n",
        'clip_targets="joint_limits" leaves mimic followers unclamped',
        ("tests/test_actuation.py",),
    ),
    M(
        "rejected_env_stops_counting",
        "wpctrl/kernels/pd_set_action.py",
        "step_out[env] = step_out[env] + host_substeps",
        "step_out[env] = step_out[env]",
        "an env whose action is rejected loses the substeps the host counted",
        ("tests/test_launches.py",),
    ),
    M(
        "elided_set_action_skips_control",
        "wpctrl/engine/core.py",
        'ln.bind("joint_target_q_out", None if known is None else known[0])',
        'ln.bind("joint_target_q_out", None)',
        "without per-substep work, set_action no longer writes the position targets into the known Control",
        ("tests/test_launches.py",),
    ),
    # -- substep --------------------------------------------------------------------------------------------------
    M(
        "stable_pd_on_the_start_state",
        "wpctrl/kernels/pd_substep.py",
        "u[r] = (kpr * (e - dt * qd[r]) + kdr * (tqd[r] - qd[r])) / (",
        "u[r] = (kpr * e + kdr * (tqd[r] - qd[r])) / (",
        "stable explicit PD evaluates its position error on the start state, not the predicted one",
        ("tests/test_acceleration.py",),
    ),
    M(
        "pd_damping_sign_flipped",
        "wpctrl/kernels/pd_substep.py",
        "u[r] = kpr * e + kdr * (tqd[r] - qd[r])",
        "u[r] = kpr * e + kdr * (qd[r] - tqd[r])",
        "the naive PD law's damping term has the wrong sign",
        ("tests/test_actuation.py",),
    ),
    M(
        "interpolation_off_by_one",
        "wpctrl/kernels/pd.py",
        "return start + step_size * float(wp.min(k, num_substeps))",
        "return start + step_size * float(wp.min(k - 1, num_substeps))",
        "interpolation lags one substep",
        ("tests/test_semantics.py",),
    ),
    M(
        "delay_off_by_one",
        "wpctrl/kernels/pd_substep.py",
        "d = wp.clamp(delay_in[env], 0, max_delay)",
        "d = wp.clamp(delay_in[env] + 1, 0, max_delay)",
        "the command delay is one substep longer than drawn",
        ("tests/test_actuation.py",),
    ),
    M(
        "force_limit_one_sided",
        "wpctrl/kernels/pd_substep.py",
        "f[r] = wp.clamp(u[r], -lim[r], lim[r])",
        "f[r] = wp.min(u[r], lim[r])",
        "explicit torques are clamped only from above",
        ("tests/test_actuation.py",),
    ),
    M(
        "saturation_count_inverted",
        "wpctrl/kernels/pd_substep.py",
        "if f[r] != u[r]:",
        "if f[r] == u[r]:",
        "the effort readout counts unsaturated substeps",
        ("tests/test_actuation.py",),
    ),
    # -- reset --------------------------------------------------------------------------------------------------------
    M(
        "reset_keeps_joint_f",
        "wpctrl/kernels/pd.py",
        "            joint_f_out[di] = 0.0\n",
        "            joint_f_out[di] = joint_f_out[di]\n",
        "a reset given a Control leaves the explicit joint_f of the reset envs",
        ("tests/test_semantics.py",),
    ),
    M(
        "partial_reset_ignores_mask",
        "wpctrl/kernels/pd.py",
        "        if not env_mask_in[env]:\n            return\n    if r == 0:",
        "        if not env_mask_in[env]:\n            pass\n    if r == 0:",
        "a reset with a bool mask resets every env",
        ("tests/test_semantics.py",),
    ),
    M(
        "velocity_target_kept_on_reset",
        "wpctrl/kernels/pd.py",
        "    target_qvel_out[env, r] = v\n",
        "    target_qvel_out[env, r] = target_qvel_out[env, r]\n",
        "a reset keeps the stale velocity target (ManiSkill's behaviour, not wpctrl's)",
        ("tests/test_semantics.py",),
    ),
    M(
        "posvel_first_reset_ignores_velocity",
        "wpctrl/kernels/pd.py",
        "if first != 0 and kind == ROW_POS and vel_target:",
        "if first == 2 and kind == ROW_POS and vel_target:",
        "the first reset of a PDJointPosVel does not take the measured velocity",
        ("tests/test_semantics.py",),
    ),
    M(
        "delay_history_not_refilled",
        "wpctrl/kernels/pd.py",
        "            delay_q_out[i, env, r] = held\n",
        "            delay_q_out[i, env, r] = delay_q_out[i, env, r]\n",
        "a reset leaves the previous episode's commands in the delay ring",
        ("tests/test_actuation.py",),
    ),
    M(
        "effort_count_not_zeroed_on_reset",
        "wpctrl/kernels/pd.py",
        "        saturation_count_out[env, r] = 0\n",
        "        saturation_count_out[env, r] = saturation_count_out[env, r]\n",
        "a reset keeps the saturation count",
        ("tests/test_actuation.py",),
    ),
    # -- randomness -------------------------------------------------------------------------------------------------
    M(
        "randomize_ignores_seed",
        "wpctrl/controllers/drive_properties.py",
        'drive.randomize(eng, lo, hi, enabled, mode == "abs", int(seed),',
        'drive.randomize(eng, lo, hi, enabled, mode == "abs", 0,',
        "randomize_drive_properties ignores its seed",
        ("tests/test_actuation.py",),
    ),
    M(
        "randomize_same_draw_every_env",
        "wpctrl/engine/parts/drive_properties.py",
        "state = wp.rand_init(key, env * drive.kp.shape[1] + r)",
        "state = wp.rand_init(key, r)",
        "randomize_drive_properties draws the same values for every env",
        ("tests/test_actuation.py",),
    ),
    M(
        "delay_draw_ignores_seed",
        "wpctrl/kernels/pd.py",
        "st = wp.rand_init(seed, rng_counter_in[0])",
        "st = wp.rand_init(0, rng_counter_in[0])",
        "the per-env delay draw ignores the build's seed",
        ("tests/test_actuation.py",),
    ),
    # -- impedance controllers (operational space, joint impedance) ------------------------------------------------
    M(
        "osc_without_operational_space_inertia",
        "wpctrl/kernels/impedance.py",
        "f = _task_solve(lam_inv, a, eps)",
        "f = a",
        "OSC with decoupling applies the task acceleration without Λ",
        ("tests/test_impedance.py",),
    ),
    M(
        "osc_partial_decoupling_keeps_the_coupling",
        "wpctrl/kernels/impedance.py",
        "if decoupling == 1 or wp.static((k < 3) == (m < 3)):",
        "if decoupling != 0:",
        "partial decoupling keeps the translation-rotation blocks of Λ⁻¹",
        ("tests/test_impedance.py",),
    ),
    M(
        "osc_nullspace_not_projected",
        "wpctrl/kernels/impedance.py",
        "tau = tau + t0 - wp.transpose(J) * y",
        "tau = tau + t0",
        "the posture torque is added without the null-space projection",
        ("tests/test_impedance.py",),
    ),
    M(
        "osc_nullspace_always_kinematic",
        "wpctrl/kernels/impedance.py",
        "if decoupling == 1:  # dynamically consistent",
        "if decoupling == 3:  # dynamically consistent",
        "full decoupling uses the kinematic (J Jᵀ) projector, not the dynamically consistent one",
        ("tests/test_impedance.py",),
    ),
    M(
        "impedance_gravity_sign",
        "wpctrl/kernels/impedance.py",
        "tau = tau + g",
        "tau = tau - g",
        "the gravity torque is subtracted",
        ("tests/test_impedance.py",),
    ),
    M(
        "osc_damping_sign",
        "wpctrl/kernels/impedance.py",
        "- wp.float64(task_kd[env, k]) * xd[k]",
        "+ wp.float64(task_kd[env, k]) * xd[k]",
        "the task damping pushes along the TCP's velocity",
        ("tests/test_impedance.py",),
    ),
    M(
        "osc_rotation_error_in_the_body_frame",
        "wpctrl/kernels/impedance.py",
        "dr = _log3(wp.transform_get_rotation(tgt) * wp.quat_inverse(wp.transform_get_rotation(t_ee)))",
        "dr = _log3(wp.quat_inverse(wp.transform_get_rotation(t_ee)) * wp.transform_get_rotation(tgt))",
        "the orientation error is taken in the EE frame instead of the root frame",
        ("tests/test_impedance.py",),
    ),
    M(
        "osc_singularity_damping_off",
        "wpctrl/kernels/impedance.py",
        "    if pmin < eps:",
        "    if pmin < wp.float64(0.0):",
        "the singularity damping never acts",
        ("tests/test_impedance.py",),
    ),
    M(
        "joint_impedance_inertia_ignored",
        "wpctrl/kernels/impedance.py",
        "                tau = M * a",
        "                tau = a",
        "joint impedance's inertial compensation is dropped",
        ("tests/test_impedance.py",),
    ),
    M(
        "variable_impedance_damping_not_doubled",
        "wpctrl/kernels/impedance.py",
        "kd_out[env, gain_off + k] = 2.0 * ratio[k] * wp.sqrt(kp[k])",
        "kd_out[env, gain_off + k] = ratio[k] * wp.sqrt(kp[k])",
        "variable impedance's damping is ζ √Kp instead of 2 ζ √Kp",
        ("tests/test_impedance.py",),
    ),
    M(
        "joint_impedance_use_target_ignored",
        "wpctrl/kernels/impedance.py",
        "t = target_qpos_out[env, row0 + c] + x",
        "t = joint_q_in[qb + row_q_off[c]] + x",
        "joint impedance's use_target adds the increment to the measured position",
        ("tests/test_impedance.py",),
    ),
    M(
        "osc_fixed_posture_ignored",
        "wpctrl/kernels/impedance.py",
        "qn = posture[c]",
        "qn = target_qpos_in[env, row0 + c]",
        "nullspace_target is ignored (the reset pose stays the posture)",
        ("tests/test_impedance.py",),
    ),
    M(
        "impedance_gravity_twice_with_balance",
        "wpctrl/engine/parts/impedance.py",
        "self.gravity_on = bool(spec.gravity and not plan.options.balance_passive_force)",
        "self.gravity_on = bool(spec.gravity)",
        "the controller adds gravity although the solver already takes it off the robot",
        ("tests/test_impedance.py",),
    ),
    M(
        "osc_reset_keeps_the_old_target",
        "wpctrl/engine/parts/impedance.py",
        "EEPart.reset(self, state, env_ids, env_mask, use_target=True)",
        "EEPart.reset(self, state, env_ids, env_mask, use_target=False)",
        "an OSC reset leaves the target pose where it was",
        ("tests/test_impedance.py",),
    ),
    M(
        "impedance_default_damping_not_critical",
        "wpctrl/config/impedance.py",
        "kd = 2.0 * ratio * np.sqrt(kp) if kd_value is None",
        "kd = ratio * np.sqrt(kp) if kd_value is None",
        "damping=None gives ζ √Kp instead of critical damping",
        ("tests/test_impedance.py",),
    ),
    M(
        "osc_task_gain_scale_ignores_the_config",
        "wpctrl/engine/parts/impedance.py",
        "                x = nominal_in[p, k] * x\n",
        "                x = x\n",
        "randomize_task_impedance's 'scale' mode draws the factor itself, not the config's gain times it",
        ("tests/test_impedance.py",),
    ),
    M(
        "fused_gravity_composite_sign",
        "wpctrl/kernels/inertia_unrolled.py",
        "G[i] = G[i] - wp.dot(gv, pl)",
        "G[i] = G[i] + wp.dot(gv, pl)",
        "the unrolled composite gravity torque adds the subtree's end term",
        ("tests/test_impedance.py",),
    ),
    M(
        "fused_gravity_runtime_dropped",
        "wpctrl/kernels/inertia.py",
        "G[i] = G[i] - m * wp.dot(gv, jv[i])",
        "G[i] = G[i] - wp.float64(0.5) * m * wp.dot(gv, jv[i])",
        "the runtime-loop gravity torque counts half of each body's weight",
        ("tests/test_impedance.py",),
    ),
    # -- end effector, state ---------------------------------------------------------------------------------------
    M(
        "ee_rotation_not_norm_clipped",
        "wpctrl/kernels/ee_math.py",
        "            if nrm > 1.0:\n",
        "            if nrm > 10.0:\n",
        "the EE rotation action is not clipped to norm 1",
        ("tests/test_ee.py",),
    ),
    M(
        "ee_use_target_ignored",
        "wpctrl/kernels/ee.py",
        "                prev = _read_pose(target_pose_out, env)\n",
        "                prev = t_ee\n",
        "EE use_target composes on the measured pose",
        ("tests/test_ee.py",),
    ),
    M(
        "set_state_keeps_control",
        "wpctrl/controllers/base_controller.py",
        "        eng.forget_control()  # the Control's drive targets are now stale: the next substep rewrites them\n",
        "",
        "set_state leaves the known Control's stale drive targets",
        ("tests/test_launches.py",),
    ),
    # -- actuator models: per-env parameters, tables on later controllers, validation at the boundary --------------
    M(
        "dc_velocity_limit_of_env_0",
        "wpctrl/kernels/pd_substep.py",
        "vlim[r] = vel_limit[env, r]",
        "vlim[r] = vel_limit[0, r]",
        "DCMotor: every env uses env 0's no-load speed (per-env velocity_limit ignored)",
        ("tests/test_actuator_setups.py",),
    ),
    M(
        "dc_saturation_of_env_0",
        "wpctrl/kernels/pd_substep.py",
        "sate[r] = sat_effort[env, r]",
        "sate[r] = sat_effort[0, r]",
        "DCMotor: every env uses env 0's stall effort (per-env saturation_effort ignored)",
        ("tests/test_actuator_setups.py",),
    ),
    M(
        "dc_lower_bound_sign",
        "wpctrl/kernels/actuator_models.py",
        "lo = wp.clamp(sat * (-1.0 - s), -lim, lim)",
        "lo = wp.clamp(sat * (-1.0 + s), -lim, lim)",
        "DCMotor: the lower envelope falls with the speed instead of rising",
        ("tests/test_actuator_models.py",),
    ),
    M(
        "dc_envelope_past_force_limit",
        "wpctrl/kernels/actuator_models.py",
        "hi = wp.clamp(sat * (1.0 - s), -lim, lim)",
        "hi = sat * (1.0 - s)",
        "DCMotor: the upper envelope is not capped by force_limit",
        ("tests/test_actuator_models.py",),
    ),
    M(
        "extras_not_offset_in_a_mode",
        "wpctrl/config/rows.py",
        "extras += [(r + row0, n, what) for r, n, what in p.extras]",
        "extras += [(r, n, what) for r, n, what in p.extras]",
        "a position table / network on a later controller of a mode lands on the first controller's rows",
        ("tests/test_actuator_setups.py",),
    ),
    M(
        "table_not_capped_by_force_limit",
        "wpctrl/kernels/pd_substep.py",
        "                        fl = wp.min(fl, lim[r])\n",
        "",
        "PositionBasedEffortLimit: the table's limit is not capped by force_limit",
        ("tests/test_actuator_setups.py", "tests/test_actuator_models.py"),
    ),
    M(
        "table_first_value_not_held",
        "wpctrl/kernels/pd_substep.py",
        "                        fl = wp.where(q[r] <= wp.static(TAB[r][0]), wp.static(TAB[r][1]), fl)\n",
        "",
        "PositionBasedEffortLimit: below the first position the first piece is extrapolated instead of held",
        ("tests/test_actuator_models.py", "tests/test_actuator_setups.py"),
    ),
    M(
        "ema_zero_accepted",
        "wpctrl/config/actuator_models.py",
        "not (0.0 < _f32(ema) <= 1.0)",
        "not (0.0 <= _f32(ema) <= 1.0)",
        "ema=0 (targets that never move) is accepted",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "ema_one_refused",
        "wpctrl/config/actuator_models.py",
        "not (0.0 < _f32(ema) <= 1.0)",
        "not (0.0 < _f32(ema) < 1.0)",
        "ema=1 (no smoothing, the boundary inside the range) is refused",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "mimic_list_accepted",
        "wpctrl/config/validate.py",
        "if not isinstance(mimic, Mapping):",
        "if not isinstance(mimic, (Mapping, list)):",
        "a mimic map that is a list of pairs, not a dict, is accepted",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "table_decreasing_positions_accepted",
        "wpctrl/config/actuator_models.py",
        "(np.diff(pos) < 0).any()",
        "(np.diff(pos) < -1e-3).any()",
        "PositionBasedEffortLimit: slightly decreasing positions are accepted",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "dc_velocity_limit_zero_accepted",
        "wpctrl/config/actuator_models.py",
        "if (v <= 0).any():",
        "if (v < 0).any():",
        "DCMotor / ActuatorNet: velocity_limit=0 (a division by zero) is accepted",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "net_input_idx_64_accepted",
        "wpctrl/config/actuator_models.py",
        "not 0 <= i <= 63",
        "not 0 <= i <= 64",
        "ActuatorNet: a history tap of 64 substeps (past the kernel's bound) is accepted",
        ("tests/test_config_boundaries.py",),
    ),
    # -- actuator networks ------------------------------------------------------------------------------------------
    M(
        "net_lstm_pos_scale_ignored",
        "wpctrl/kernels/actuator_net_unrolled.py",
        "                x[0] = _scaled(err, wp.static(PS))\n",
        "                x[0] = err\n",
        "an LSTM actuator (input order pos_vel) ignores pos_scale",
        ("tests/test_actuator_setups.py",),
    ),
    M(
        "net_mlp_vel_scale_ignored",
        "wpctrl/kernels/actuator_net_unrolled.py",
        "x[wp.static(VEL_AT[t])] = _scaled(hv[wp.static(TAPS[t])], wp.static(VS))",
        "x[wp.static(VEL_AT[t])] = hv[wp.static(TAPS[t])]",
        "an MLP actuator ignores vel_scale",
        ("tests/test_actuator_net.py", "tests/test_actuator_setups.py"),
    ),
    M(
        "net_torque_scale_ignored",
        "wpctrl/kernels/actuator_net_unrolled.py",
        "write_effort(_scaled(x[0], wp.static(TS)), qd,",
        "write_effort(x[0], qd,",
        "an actuator network's output is not multiplied by torque_scale",
        ("tests/test_actuator_net.py", "tests/test_actuator_setups.py"),
    ),
    M(
        "net_rows_from_zero",
        "wpctrl/kernels/actuator_net_unrolled.py",
        "        r = row0 + j\n",
        "        r = j\n",
        "a network on a later controller of a mode reads and writes the first controller's rows",
        ("tests/test_actuator_setups.py",),
    ),
    M(
        "net_input_order_ignored",
        "wpctrl/engine/parts/actuator_models.py",
        'pos_first=spec.input_order == "pos_vel"',
        "pos_first=True",
        'ActuatorNet(input_order="vel_pos") feeds the position errors first',
        ("tests/test_actuator_net.py", "tests/test_actuator_setups.py"),
    ),
    M(
        "net_history_not_shifted",
        "wpctrl/kernels/actuator_net_unrolled.py",
        "            new[k] = hp[k]\n",
        "            new[k] = hp[k + 1]\n",
        "an MLP actuator's position-error history does not shift by one substep",
        ("tests/test_actuator_net.py", "tests/test_actuator_setups.py"),
    ),
    M(
        "mma_weight_pair_swapped",
        "wpctrl/kernels/actuator_net_mma.py",
        "np.stack([hi[rows, c0], hi[rows, c0 + 1], lo[rows, c0], lo[rows, c0 + 1]], -1)",
        "np.stack([hi[rows, c0 + 1], hi[rows, c0], lo[rows, c0], lo[rows, c0 + 1]], -1)",
        "the tensor-core kernel's packed weights give a lane's two inputs each other's weights",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "mma_weight_remainder_dropped",
        "wpctrl/kernels/actuator_net_mma.py",
        "hi[rows, c0 + 1], lo[rows, c0], lo[rows, c0 + 1]], -1)",
        "hi[rows, c0 + 1], 0 * lo[rows, c0], 0 * lo[rows, c0 + 1]], -1)",
        "the tensor-core kernel keeps only the TF32 part of each weight (10 mantissa bits)",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "mma_bias_pair_swapped",
        "wpctrl/kernels/actuator_net_mma.py",
        "bf.append(np.stack([bp[u], bp[u + 1]], -1))",
        "bf.append(np.stack([bp[u + 1], bp[u]], -1))",
        "the tensor-core kernel's packed biases swap units 2t and 2t + 1",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "mma_small_product_dropped",
        "wpctrl/kernels/actuator_net_mma.py",
        '"    acc += l0 * w.c[0]; acc += h0 * w.c[2]; acc += h0 * w.c[0];",',
        '"    acc += h0 * w.c[2]; acc += h0 * w.c[0];",',
        "the tensor-core kernel drops an activation's remainder times the weight (two products of three)",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "mma_auto_needs_newer_gpu",
        "wpctrl/kernels/actuator_net.py",
        "cuda_arch >= MMA_MIN_SM and",
        "cuda_arch > MMA_MIN_SM and",
        'kernel="auto" keeps a large MLP off the tensor cores of an sm_80 GPU',
        ("tests/test_actuator_net.py",),
    ),
    M(
        "mma_width_limit_off_by_8",
        "wpctrl/kernels/actuator_net.py",
        "if widest > MMA_MAX_WIDTH:",
        "if widest >= MMA_MAX_WIDTH:",
        "the tensor-core kernel refuses a layer exactly 128 wide",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "mma_takes_lstm",
        "wpctrl/kernels/actuator_net.py",
        '        return "an LSTM (this kernel runs MLPs)"\n',
        "        pass\n",
        'kernel="3xtf32" (and "auto" past the unrolled size on a GPU) takes an LSTM it cannot run',
        ("tests/test_actuator_net.py",),
    ),
    M(
        "net_reset_keeps_history",
        "wpctrl/kernels/actuator_net.py",
        "        hist_out[s, k] = 0.0\n",
        "        hist_out[s, k] = hist_out[s, k]\n",
        "a reset leaves the network's position-error history of the reset envs",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "net_lstm_gates_swapped",
        "wpctrl/kernels/actuator_net.py",
        "c_new = sigmoid(fg) * c + sigmoid(ig) * tanh(cg)",
        "c_new = sigmoid(ig) * c + sigmoid(fg) * tanh(cg)",
        "the LSTM reads its forget gate as the input gate (PyTorch's order: input, forget, cell, output)",
        ("tests/test_actuator_net.py", "tests/test_actuator_setups.py"),
    ),
    M(
        "net_without_dc_envelope",
        "wpctrl/kernels/actuator_net.py",
        "f = dc_motor_clamp(u, qd, sat, vl, lim)",
        "f = wp.clamp(u, -lim, lim)",
        "an actuator network's output skips its DC-motor envelope (saturation_effort / velocity_limit)",
        ("tests/test_actuator_setups.py", "tests/test_actuator_net.py"),
    ),
    M(
        "net_split_total_without_last_warp",
        "wpctrl/kernels/actuator_net_split.py",
        "        for q in range(1, wp.static(S)):\n",
        "        for q in range(1, wp.static(S) - 1):\n",
        "the split kernel's output sums the partial sums of every warp but the last",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "net_split_hidden_gather_own_slice",
        "wpctrl/kernels/actuator_net_split.py",
        "v = sh[q, t]\n                        for k in range(wp.static(SLICE[DOUT[li]]",
        "v = sh[lane, t]\n                        for k in range(wp.static(SLICE[DOUT[li]]",
        "the split kernel's hidden layers read their own warp's slice in place of every other warp's",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "net_split_lstm_c_of_first_warp",
        "wpctrl/kernels/actuator_net_split.py",
        "io.lstm_c[wp.static(li * H) + lane * wp.static(MH) + k, s]\n",
        "io.lstm_c[wp.static(li * H) + k, s]\n",
        "every warp of the split LSTM reads the first warp's units' cell state",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "net_split_lstm_last_layer_h_everywhere",
        "wpctrl/kernels/actuator_net_split.py",
        "s] = ho[wp.static(li * MH) + k]\n",
        "s] = own[k]\n",
        "the split LSTM stores its last layer's new h as every layer's",
        ("tests/test_actuator_net.py",),
    ),
    M(
        "net_fused_rows_from_zero",
        "wpctrl/kernels/actuator_net_fused.py",
        "            r = row0 + j\n",
        "            r = j\n",
        "a network run in the substep's launch, on a later controller, reads and writes the first controller's rows",
        ("tests/test_actuator_net_fused.py",),
    ),
    M(
        "net_fused_target_of_first_rows",
        "wpctrl/kernels/actuator_net_fused.py",
        "    return di, target_qpos_in[env, r] - q, qd, lim, sat, vl\n",
        "    return di, target_qpos_in[env, j] - q, qd, lim, sat, vl\n",
        "a network run in the substep's launch reads its targets from the mode's first rows",
        ("tests/test_actuator_net_fused.py",),
    ),
    M(
        "net_auto_never_in_the_substeps_launch",
        "wpctrl/engine/parts/actuator_models.py",
        "        if why is None:\n            self.fused = self.nets[0]\n",
        "        if why is None and asked == ['fused']:\n            self.fused = self.nets[0]\n",
        'ActuatorNet(launch="auto") (the default) runs the network in a launch of its own even where the mode allows '
        "the substep's launch",
        ("tests/test_actuator_net_fused.py",),
    ),
    M(
        "net_fused_despite_delay",
        "wpctrl/kernels/actuator_net_fused.py",
        "    if step.delay:\n",
        "    if False:\n",
        "a network behind a command delay runs in the substep's launch (it would read the undelayed command)",
        ("tests/test_actuator_net_fused.py", "tests/test_actuator_setups.py"),
    ),
    M(
        "net_fused_despite_interpolation",
        "wpctrl/kernels/actuator_net_fused.py",
        "    if any(int(f) & FLAG_INTERPOLATE for f in step.flags[row0 : row0 + n]):\n",
        "    if False:\n",
        "a network with interpolated targets runs in the substep's launch (it would read the end of the interpolation)",
        ("tests/test_actuator_net_fused.py",),
    ),
    # -- smoothing, effort readout, bases and DOF indices on later controllers / other models ----------------------
    M(
        "ema_alpha_of_row_0",
        "wpctrl/kernels/pd_set_action.py",
        "al = row_f[r, ROW_F_ALPHA]",
        "al = row_f[0, ROW_F_ALPHA]",
        "every smoothed joint uses the first row's EMA weight (one alpha per mode, not per controller)",
        ("tests/test_actuator_setups.py",),
    ),
    M(
        "effort_limit_of_env_0",
        "wpctrl/kernels/pd_substep.py",
        "lim[r] = force_limit[lb, r]",
        "lim[r] = force_limit[0, r]",
        "the explicit clamp and the effort readout use env 0's force limit",
        ("tests/test_actuator_setups.py", "tests/test_actuation.py"),
    ),
    M(
        "base_yaw_row_not_offset",
        "wpctrl/config/rows.py",
        'elif k in ("mimic_src", "yaw_row"):',
        'elif k in ("mimic_src",):',
        "a mobile base after another controller rotates by the yaw of a row of that controller",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "substep_dofs_at_coordinate_stride",
        "wpctrl/kernels/step_layout.py",
        "di[r] = env * qd_stride + wp.static(QDOFF[r])",
        "di[r] = env * q_stride + wp.static(QDOFF[r])",
        "replicated envs with more coordinates than DOFs (floating bases): env e's DOFs at the coordinate stride",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "set_action_velocity_target_at_coordinate",
        "wpctrl/kernels/pd_set_action.py",
        "                    joint_target_qd_out[di[r]] = vt[r]\n",
        "                    joint_target_qd_out[qi[r]] = vt[r]\n",
        "set_action writes velocity targets at the coordinate index (wrong on floating bases)",
        ("tests/test_construction_orders.py",),
    ),
    # -- the solver built before the controller; end effectors of envs placed apart ----------------------------------
    M(
        "given_solver_not_told_of_gravity",
        "wpctrl/engine/core.py",
        "flags |= newton.ModelFlags.BODY_INERTIAL_PROPERTIES",
        "flags |= newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES",
        "a solver built before the controller is not told of the gravity compensation (mujoco:gravcomp)",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "given_solver_not_notified",
        "wpctrl/engine/core.py",
        "            if solver is not None:\n                solver.notify_model_changed(self.model_flags())\n",
        "",
        "a solver given as solver= is not notified of the drive properties and gravity at build",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "attach_solver_not_notified",
        "wpctrl/engine/core.py",
        "        self.solver = solver\n        solver.notify_model_changed(self.model_flags())\n",
        "        self.solver = solver\n",
        "attach_solver keeps the solver for later notices but does not notify it now",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "ee_root_is_env_0_world",
        "wpctrl/engine/parts/ee.py",
        "x0 = _design_frame(spec, _short(jlabels[table[0, 0]]))",
        "x0 = None",
        "EE poses of a world-merged fixed base are in env 0's world frame (replicate's centred grid moves env 0)",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "ee_env_placement_ignored",
        "wpctrl/engine/parts/ee.py",
        "                root[e] = np.array([*r.p, *r.q], np.float32)\n",
        "                pass\n",
        "EE poses of envs placed apart are not moved into each env's base frame",
        ("tests/test_construction_orders.py",),
    ),
    # -- training: the reach task ------------------------------------------------------------------------------------
    M(
        "reach_success_inverted",
        "wpctrl/train/task_kernels.py",
        "if d < success_radius:",
        "if d > success_radius:",
        "the reach task counts an episode as a success when the TCP ends outside the radius",
        ("tests/test_reach_success.py",),
    ),
    M(
        "reach_success_radius_doubled",
        "wpctrl/train/task_kernels.py",
        "if d < success_radius:",
        "if d < 2.0 * success_radius:",
        "the reach task's success radius is twice the configured one",
        ("tests/test_reach_success.py",),
    ),
    M(
        "reach_episode_one_step_long",
        "wpctrl/train/task_kernels.py",
        "end = n >= max_steps",
        "end = n > max_steps",
        "a reach episode lasts episode_steps + 1 control steps",
        ("tests/test_reach_success.py", "tests/test_train.py"),
    ),
    M(
        "reach_start_noise_ignored",
        "wpctrl/train/task_kernels.py",
        "q = q + noise * (2.0 * wp.randf(rng) - 1.0)",
        "q = q",
        "reach episodes start exactly at the rest pose whatever start_noise says",
        ("tests/test_reach_success.py",),
    ),
    M(
        "reach_seed_ignored",
        "wpctrl/train/task_kernels.py",
        "rng = wp.rand_init(seed, counter[0] * 1000003 + e)",
        "rng = wp.rand_init(0, counter[0] * 1000003 + e)",
        "the reach task's start poses and goals ignore the env's seed",
        ("tests/test_reach_success.py",),
    ),
    M(
        "evaluate_success_unweighted",
        "wpctrl/train/cli.py",
        'successes += (s["success_rate"] or 0.0) * s["episodes"]',
        'successes += s["success_rate"] or 0.0',
        "the evaluation averages the success rates of its rounds without their episode counts",
        ("tests/test_reach_success.py",),
    ),
    M(
        "coupled_beside_effort_rows_accepted",
        "wpctrl/engine/plan.py",
        "    if a.coupled and (rows.kind == ROW_EFFORT).any():\n",
        "    if a.coupled and False:\n",
        "the coupled drive is accepted beside an effort controller, whose torques it then overwrites",
        ("tests/test_options.py::test_an_effort_controller_beside_an_explicit_drive_keeps_its_torque",),
    ),
    # -- PPO on the ManiSkill tasks, export, evaluate -----------------------------------------------------------------
    M(
        "rollout_bootstraps_the_next_episode",
        "wpctrl/train/task_ppo.py",
        'final = TensorDict({"policy": extras["final_observations"]}, batch_size=[env.num_envs])',
        'final = TensorDict({"policy": obs}, batch_size=[env.num_envs])',
        "an episode end is bootstrapped with the value of the next episode's first observation, not its final one",
        (
            "tests/test_train_tasks.py::test_rollout_bootstraps_every_episode_end_with_the_critics_value_of_its_final_observation",
        ),
    ),
    M(
        "rollout_bootstraps_only_time_outs",
        "wpctrl/train/task_ppo.py",
        "rewards = rewards + alg.gamma * value * dones.to(value.dtype)",
        'rewards = rewards + alg.gamma * value * extras["truncated"].to(value.dtype)',
        "a successful episode's end is not bootstrapped (ManiSkill's PPO bootstraps every end under partial resets)",
        (
            "tests/test_train_tasks.py::test_rollout_bootstraps_every_episode_end_with_the_critics_value_of_its_final_observation",
        ),
    ),
    M(
        "captured_update_skips_advantage_normalisation",
        "wpctrl/train/ppo_update.py",
        "if alg.normalize_advantage_per_mini_batch:",
        "if False:",
        "the captured PPO step skips the per-mini-batch advantage normalisation rsl-rl's update does",
        ("tests/test_ppo_update.py::test_eager_update_is_rsl_rls_on_the_cpu",),
    ),
    M(
        "captured_update_clips_the_actor_only",
        "wpctrl/train/ppo_update.py",
        "torch.nn.utils.clip_grad_norm_(alg.critic.parameters(), alg.max_grad_norm)",
        "pass",
        "the captured PPO step leaves the critic's gradient norm unclipped",
        ("tests/test_ppo_update.py::test_eager_update_is_rsl_rls_on_the_cpu",),
    ),
    M(
        "sync_free_sampling_ignores_the_std",
        "wpctrl/train/sampling.py",
        "t.actions = (mean + actor.distribution.std * torch.randn_like(mean)).detach()",
        "t.actions = (mean + torch.randn_like(mean)).detach()",
        "the sync-free sampler draws with unit standard deviation instead of the policy's",
        ("tests/test_sampling.py::test_act_stores_rsl_rls_transition",),
    ),
    M(
        "sync_free_sampling_log_prob_of_the_mean",
        "wpctrl/train/sampling.py",
        "t.actions_log_prob = actor.get_output_log_prob(t.actions).detach()",
        "t.actions_log_prob = actor.get_output_log_prob(mean).detach()",
        "the sync-free sampler stores the log-probability of the mean, not of the sampled action",
        ("tests/test_sampling.py::test_act_stores_rsl_rls_transition",),
    ),
    M(
        "collector_always_uses_rsl_rl_sampling",
        "wpctrl/train/task_ppo.py",
        'self._act = (lambda obs: act(alg, obs)) if sampling == "sync-free" else alg.act',
        "self._act = alg.act",
        "the rollout ignores sync-free sampling and keeps rsl-rl's act (a host sync per step on CUDA)",
        ("tests/test_sampling.py::test_sync_free_rollout_never_calls_torch_normal",),
    ),
    M(
        "task_ppo_normalises_observations_by_default",
        "wpctrl/train/task_ppo.py",
        'obs_normalization=args.obs_normalization == "on"',
        'obs_normalization=args.obs_normalization != "off"',
        "the ManiSkill tasks' PPO normalises observations by default (ManiSkill's PPO reads them raw)",
        ("tests/test_train_tasks.py::test_ppo_learns_pushcube_on_the_cpu",),
    ),
    M(
        "task_evaluation_success_at_end_as_once",
        "wpctrl/train/task_ppo.py",
        "once += float(hit[:m].float().sum())",
        'once += float(info["success"][:m].float().sum())',
        "a task evaluation's success rate counts success at the last step, not success at any step",
        ("tests/test_train_tasks.py::test_evaluation_counts_success_at_any_step_and_at_the_last_separately",),
    ),
    # -- distributed -------------------------------------------------------------------------------------------------
    M(
        "device_from_global_rank",
        "wpctrl/distributed.py",
        "dev = _resolve_device(device, local_rank, local_world)",
        "dev = _resolve_device(device, rank, local_world)",
        "a rank on a second node picks its GPU by its global rank (cuda:RANK, not cuda:LOCAL_RANK)",
        ("tests/test_distributed_ranks.py",),
    ),
    M(
        "seed_from_local_rank",
        "wpctrl/distributed.py",
        "seed=rank_seed(seed, rank),",
        "seed=rank_seed(seed, local_rank),",
        "ranks with the same local rank on different nodes draw the same seed",
        ("tests/test_distributed_ranks.py",),
    ),
    M(
        "main_process_by_local_rank",
        "wpctrl/distributed.py",
        "        return self.rank == 0\n",
        "        return self.local_rank == 0\n",
        "the first rank of every node acts as the main process (prints, writes files)",
        ("tests/test_distributed_ranks.py",),
    ),
    M(
        "rank_seed_additive",
        "wpctrl/distributed.py",
        "return int(np.random.SeedSequence([int(seed), int(rank)]).generate_state(1)[0])",
        "return int(seed) + int(rank)",
        "rank seeds are seed + rank (run 0's rank 1 repeats run 1's rank 0)",
        ("tests/test_distributed.py",),
    ),
    # -- ManiSkill robots --------------------------------------------------------------------------------------------
    M(
        "load_robot_root_pose_ignored",
        "wpctrl/maniskill/__init__.py",
        "pose = root_pose if root_pose is not None else (kf.pose if kf else None)",
        "pose = kf.pose if kf else None",
        "load_robot ignores root_pose",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_keyframe_always_first",
        "wpctrl/maniskill/__init__.py",
        'chosen = (next(iter(keyframes), None) if keyframe == "default" else keyframe) if keyframes else None',
        "chosen = next(iter(keyframes), None) if keyframes else None",
        "load_robot starts at the first keyframe whatever keyframe= names (None included)",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_collapse_ignored",
        "wpctrl/maniskill/__init__.py",
        "collapse_fixed_joints=collapse_fixed_joints, **importer_kwargs,",
        "collapse_fixed_joints=False, **importer_kwargs,",
        "load_robot ignores collapse_fixed_joints",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_keyframe_qpos_dropped",
        "wpctrl/maniskill/__init__.py",
        "missing = set_joint_positions(builder, kf.qpos)",
        "missing = []",
        "load_robot leaves the joints at zero instead of the keyframe's qpos",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_floating_pose_dropped",
        "wpctrl/maniskill/__init__.py",
        "    if not fix_root and pose is not None:\n        set_root_pose(builder, pose)\n",
        "",
        "a floating robot's root stays at the origin instead of the keyframe's (or the given) pose",
        ("tests/test_maniskill_options.py",),
    ),
    M(
        "load_robot_self_collisions_on",
        "wpctrl/maniskill/__init__.py",
        'not bool(getattr(cls, "disable_self_collisions", False)))',
        "True)",
        "load_robot ignores the agent's disable_self_collisions",
        ("tests/test_maniskill_robot.py",),
    ),
    # -- ManiSkill's tasks on Newton ---------------------------------------------------------------------------------
    M(
        "tasks_push_success_height",
        "wpctrl/tasks/kernels.py",
        "cube_p[2] < P.half_size + 5.0e-3",
        "cube_p[2] < P.half_size + 5.0e-2",
        "PushCube's success accepts a cube 5 cm above the table",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_pick_success_without_static",
        "wpctrl/tasks/kernels.py",
        "        ok = placed and static\n",
        "        ok = placed\n",
        "PickCube's success ignores is_robot_static",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_push_reached_radius",
        "wpctrl/tasks/kernels.py",
        "        if d < 0.01:\n",
        "        if d < 0.1:\n",
        "PushCube's place reward starts 10 cm from the push point",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_pick_grasp_reward_without_place",
        "wpctrl/tasks/kernels.py",
        "            r = r + 1.0 + (1.0 - wp.tanh(5.0 * wp.length(goal - cube_p)))\n",
        "            r = r + 1.0\n",
        "PickCube's dense reward drops the grasped place term",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_right_finger_direction",
        "wpctrl/tasks/kernels.py",
        "rflag = _grasping(finger_force[2 * e + 1, 0], -wp.quat_rotate(",
        "rflag = _grasping(finger_force[2 * e + 1, 0], wp.quat_rotate(",
        "is_grasped tests the right finger's force against +y instead of its opening direction -y",
        ("tests/test_tasks.py", "tests/test_tasks_replay.py"),
    ),
    M(
        "tasks_obs_quaternion_xyzw",
        "wpctrl/tasks/kernels.py",
        "    return wp.vec4(q[3], q[0], q[1], q[2])\n",
        "    return wp.vec4(q[0], q[1], q[2], q[3])\n",
        "observed quaternions leave in Warp's xyzw order",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_reset_noise_scale",
        "wpctrl/tasks/kernels.py",
        "rest_qpos[j] + P.qpos_noise * wp.randn(rng)",
        "rest_qpos[j] + 2.0 * P.qpos_noise * wp.randn(rng)",
        "the robot's init noise is twice ManiSkill's",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_push_goal_offset",
        "wpctrl/tasks/kernels.py",
        "goal_pos[e] = wp.vec3(x + P.push_goal_offset, y, 1.0e-3)",
        "goal_pos[e] = wp.vec3(x + 0.5 * P.push_goal_offset, y, 1.0e-3)",
        "PushCube's goal 10 cm in front of the cube instead of 20",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_truncation_off_by_one",
        "wpctrl/tasks/kernels.py",
        "    trunc = n >= max_steps\n",
        "    trunc = n > max_steps\n",
        "episodes truncate after 51 steps",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_ignore_terminations_ignored",
        "wpctrl/tasks/kernels.py",
        "    term = success[e] and ignore_terminations == 0\n",
        "    term = success[e]\n",
        "ignore_terminations has no effect",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_normalized_reward_not_divided",
        "wpctrl/tasks/kernels.py",
        "        r = r / max_reward\n",
        "        r = r\n",
        "normalized_dense returns the dense reward",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_friction_rule_max",
        "wpctrl/tasks/physics.py",
        "    return {name: (0.5 * (lo + hi) if mu == hi else mu) for name, mu in materials.items()}",
        "    return dict(materials)",
        "PhysX's average friction rule is not reproduced (MuJoCo's max applies)",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_state_dict_quaternion_order",
        "wpctrl/tasks/state_dict.py",
        "        q[idx, c + 3 : c + 6] = cube[:, 4:7]\n        q[idx, c + 6] = cube[:, 3]\n",
        "        q[idx, c + 3 : c + 7] = cube[:, 3:7]\n",
        "set_state_dict writes ManiSkill's wxyz quaternion as xyzw",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_state_dict_forces_not_zeroed",
        "wpctrl/tasks/env.py",
        "        wp.launch(_zero_forces, dim=self.num_envs, inputs=[mask, self._sensor.force_matrix], "
        "device=self.wp_device)\n",
        "",
        "a state just set keeps the previous contact forces (stale is_grasped)",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_limits_not_applied",
        "wpctrl/tasks/scene.py",
        "    if physics.limit_solref is None:\n        return\n",
        "    return\n",
        "the stiff joint limits are never applied (Newton's soft import stays)",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_auto_reset_always",
        "wpctrl/tasks/env.py",
        "        if self.auto_reset:\n            self._reset_envs(self.done)\n",
        "        self._reset_envs(self.done)\n",
        "finished envs are reset even with auto_reset off",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_partial_reset_all",
        "wpctrl/tasks/env.py",
        '            mask = env_mask(options["env_idx"], self.num_envs, self.wp_device)\n',
        "            pass\n",
        "reset(options={'env_idx': ...}) resets every env",
        ("tests/test_tasks.py",),
    ),
    M(
        "tasks_contact_gap_ignored",
        "wpctrl/tasks/scene.py",
        "    env.rigid_gap = float(physics.contact_gap)\n",
        "",
        "TaskPhysics.contact_gap does not reach the table and the cube (Newton's 10 cm envelope stays there)",
        ("tests/test_tasks.py::test_contact_gap_changes_which_pairs_are_tracked_not_the_motion",),
    ),
    M(
        "tasks_replay_agreement_all_episodes",
        "wpctrl/tasks/replay.py",
        "        ok = [e for e in self.episodes if e.success_at_end_recorded]\n",
        "        ok = self.episodes\n",
        "the replay's success agreement counts ManiSkill's failed episodes too",
        ("tests/test_tasks.py", "tests/test_tasks_replay.py"),
    ),
    # -- envs, worlds and controllers that differ: operational-space and joint impedance --
    M(
        "envs_joint_impedance_variable_gains_into_the_first_rows",
        "wpctrl/engine/parts/impedance.py",
        "        return drive.kp, drive.kd, self.row0",
        "        return drive.kp, drive.kd, 0",
        "a later joint-impedance controller's variable gains are written to the mode's first rows",
        ("tests/test_impedance_envs.py::test_second_joint_impedance_controller_takes_its_own_variable_gains",),
    ),
    M(
        "envs_joint_impedance_variable_gains_from_the_first_columns",
        "wpctrl/engine/parts/impedance.py",
        "gain_col0=self.col0 + s.task_dim,",
        "gain_col0=s.task_dim,",
        "a later impedance controller reads its gain columns from the action's start",
        ("tests/test_impedance_envs.py::test_second_joint_impedance_controller_takes_its_own_variable_gains",),
    ),
    M(
        "envs_osc_nullspace_gains_from_env0",
        "wpctrl/kernels/impedance.py",
        "a0 = VecN()\n                kb = _bidx(kp.shape[0], env)",
        "a0 = VecN()\n                kb = _bidx(kp.shape[0], 0)",
        "OSC's null-space (posture) gains are read from env 0 for every env",
        ("tests/test_impedance_envs.py::test_osc_per_env_gains_states_and_gravity_equal_newtons_controller",),
    ),
    M(
        "envs_osc_task_gains_from_env0",
        "wpctrl/kernels/impedance.py",
        "wp.float64(task_kp[env, k]) * e[k]",
        "wp.float64(task_kp[0, k]) * e[k]",
        "OSC's task stiffness is read from env 0 for every env",
        ("tests/test_impedance_envs.py::test_osc_per_env_gains_states_and_gravity_equal_newtons_controller",),
    ),
    M(
        "envs_joint_impedance_gains_from_env0",
        "wpctrl/kernels/impedance.py",
        "kb = _bidx(kp.shape[0], env)\n            a = VecN()",
        "kb = _bidx(kp.shape[0], 0)\n            a = VecN()",
        "joint impedance's per-env stiffness and damping are read from env 0",
        (
            "tests/test_impedance_envs.py::test_joint_impedance_per_env_gains_and_gravity_equal_newtons_controller",
            "tests/test_impedance_envs.py::test_second_joint_impedance_controller_clips_to_its_own_joints_limits",
        ),
    ),
    M(
        "envs_impedance_gravity_from_env0",
        "wpctrl/kernels/impedance.py",
        "gv = gravity_in[env_world[env]]",
        "gv = gravity_in[env_world[0]]",
        "the gravity compensation of every env uses env 0's world gravity",
        (
            "tests/test_impedance_envs.py::test_joint_impedance_per_env_gains_and_gravity_equal_newtons_controller",
            "tests/test_impedance_envs.py::test_osc_per_env_gains_states_and_gravity_equal_newtons_controller",
        ),
    ),
    M(
        "envs_impedance_world_gravity_ignored",
        "wpctrl/engine/parts/impedance.py",
        "self.env_world = up(np.where(w < 0, gworld - 1, np.minimum(w, gworld - 1)))",
        "self.env_world = up(np.full(E, gworld - 1))",
        "the gravity compensation uses the model's global gravity, not each env's world gravity",
        (
            "tests/test_impedance_envs.py::test_joint_impedance_per_env_gains_and_gravity_equal_newtons_controller",
            "tests/test_impedance_envs.py::test_osc_per_env_gains_states_and_gravity_equal_newtons_controller",
        ),
    ),
    M(
        "envs_joint_impedance_clip_first_controllers_limits",
        "wpctrl/kernels/impedance.py",
        "t = wp.clamp(t, p.row_qlo[row0 + c], p.row_qhi[row0 + c])",
        "t = wp.clamp(t, p.row_qlo[c], p.row_qhi[c])",
        "joint-impedance clip_targets clamps to the mode's first joints' limits, not its own joints'",
        ("tests/test_impedance_envs.py::test_second_joint_impedance_controller_clips_to_its_own_joints_limits",),
    ),
    M(
        "envs_joint_impedance_torque_first_controllers_targets",
        "wpctrl/kernels/impedance.py",
        "wp.float64(kp[kb, row0 + c]) * (wp.float64(target_qpos_in[env, row0 + c]) - q[c])",
        "wp.float64(kp[kb, row0 + c]) * (wp.float64(target_qpos_in[env, c]) - q[c])",
        "joint impedance's torque reads the mode's first rows' targets",
        ("tests/test_impedance_envs.py::test_second_joint_impedance_controller_clips_to_its_own_joints_limits",),
    ),
    M(
        "envs_joint_impedance_action_first_columns",
        "wpctrl/kernels/impedance.py",
        "x = _scale(action_in[env, col0 + c], target_lo[c], target_hi[c], normalize)",
        "x = _scale(action_in[env, c], target_lo[c], target_hi[c], normalize)",
        "a later joint-impedance controller reads the action's first columns",
        ("tests/test_impedance_envs.py::test_second_joint_impedance_controller_clips_to_its_own_joints_limits",),
    ),
    M(
        "envs_impedance_q_offsets_of_the_first_rows",
        "wpctrl/engine/parts/impedance.py",
        "self.row_q_off = up(b.q_off[row0 : row0 + n])",
        "self.row_q_off = up(b.q_off[0:n])",
        "an impedance controller measures the positions of the mode's first joints, not its own",
        ("tests/test_impedance_envs.py::test_second_joint_impedance_controller_clips_to_its_own_joints_limits",),
    ),
    M(
        "envs_osc_rotation_action_scaled_twice",
        "wpctrl/kernels/impedance.py",
        "act = _pose_action(action_in, env, col0, 1, normalize, lo, hi, p.rot_scale)",
        "act = _pose_action(action_in, env, col0, 1, normalize, lo, hi, wp.cw_mul(p.rot_scale, p.rot_scale))",
        "the rotation part of a normalised OSC action is scaled twice",
        ("tests/test_impedance_envs.py::test_osc_target_pose_from_the_action_in_every_frame_and_option",),
    ),
    M(
        "envs_osc_body_translation_ignored",
        "wpctrl/config/impedance.py",
        'bits = (FRAME_BODY_TRANS if c.frame.startswith("body_translation") else 0) | (',
        'bits = (FRAME_BODY_TRANS if c.frame.endswith("body_translation") else 0) | (',
        "OSC's body_translation frame is ignored (delta positions along the root axes)",
        ("tests/test_impedance_envs.py::test_osc_target_pose_from_the_action_in_every_frame_and_option",),
    ),
    M(
        "envs_osc_use_target_ignored",
        "wpctrl/kernels/impedance.py",
        "            if use_target != 0:\n                prev = _read_pose(target_pose_out, env)",
        "            if use_target != 0:\n                prev = t_ee",
        "OSC's use_target composes the increment on the measured pose, not the last target",
        ("tests/test_impedance_envs.py::test_osc_target_pose_from_the_action_in_every_frame_and_option",),
    ),
    M(
        "envs_osc_rotation_scale_full_range",
        "wpctrl/config/impedance.py",
        "rot_scale=(0.5 * (rhi - rlo)).astype(np.float32) if normalize",
        "rot_scale=(rhi - rlo).astype(np.float32) if normalize",
        "a normalised OSC rotation is scaled by the full range instead of the half range",
        ("tests/test_impedance_envs.py::test_osc_target_pose_from_the_action_in_every_frame_and_option",),
    ),
    # -- a second controller, a floating base: actuator networks and the elided-substep targets; option ranges --
    M(
        "net_dofs_at_coordinate_stride",
        "wpctrl/kernels/actuator_net.py",
        "    di = qd_lin + j + env * io.qd_stride\n",
        "    di = qd_lin + j + env * io.q_stride\n",
        "a network on consecutive joints of a floating base indexes env e's DOFs by the coordinate stride",
        ("tests/test_second_controller.py",),
    ),
    M(
        "net_table_dofs_at_coordinate_stride",
        "wpctrl/kernels/actuator_net.py",
        "di = _at(io.qd_idx, io.qd_stride, env, r)",
        "di = _at(io.qd_idx, io.q_stride, env, r)",
        "a network on joints out of the model's order (index tables) on a floating base: DOFs at the coordinate stride",
        ("tests/test_second_controller.py",),
    ),
    M(
        "net_velocity_at_coordinate",
        "wpctrl/kernels/actuator_net.py",
        "return qi, di, joint_q_in[qi], joint_qd_in[di],",
        "return qi, di, joint_q_in[qi], joint_qd_in[qi],",
        "an actuator network reads its joint's velocity at the coordinate index (wrong past a free joint)",
        ("tests/test_second_controller.py",),
    ),
    M(
        "elided_position_target_at_dof",
        "wpctrl/kernels/pd_set_action.py",
        "                    joint_target_q_out[qi[r]] = t[r]\n",
        "                    joint_target_q_out[di[r]] = t[r]\n",
        "with the substep launch elided, set_action writes position targets at the DOF index (wrong on floating bases)",
        ("tests/test_second_controller.py",),
    ),
    M(
        "targets_into_new_control_at_dof_stride",
        "wpctrl/kernels/pd.py",
        "joint_target_q_out[_at(q_idx, q_stride, env, r)] = target_qpos_in[env, r]",
        "joint_target_q_out[_at(q_idx, qd_stride, env, r)] = target_qpos_in[env, r]",
        "a Control handed in with the substep launch elided gets env e's position targets at the DOF stride",
        ("tests/test_second_controller.py",),
    ),
    M(
        "delay_max_checks_min",
        "wpctrl/config/options.py",
        "        if hi > MAX_DELAY:\n",
        "        if lo > MAX_DELAY:\n",
        "Delay's upper bound checks the minimum: a range (0, 1025) is accepted",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "delay_range_order_unchecked",
        "wpctrl/config/options.py",
        "        if lo < 0 or hi < lo:\n",
        "        if lo < 0 or hi < 0:\n",
        "Delay accepts a range whose max is below its min",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "delay_fixed_seed_accepted",
        "wpctrl/config/options.py",
        "            if lo == hi:\n",
        "            if single:\n",
        "Delay((d, d), seed=s) (a range of one value: nothing drawn) takes the seed",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "actuator_envelope_checked_in_float64",
        "wpctrl/config/actuator_models.py",
        "            s, v = s.astype(np.float32), v.astype(np.float32)\n",
        "            s, v = s.astype(np.float64), v.astype(np.float64)\n",
        "a DC envelope beyond float32 passes its checks (stall effort 1e39: inf in the kernel, NaN torques at v_max)",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "position_table_checked_in_float64",
        "wpctrl/config/actuator_models.py",
        "            pos, eff = pos.astype(np.float32), eff.astype(np.float32)\n",
        "            pos, eff = pos.astype(np.float64), eff.astype(np.float64)\n",
        "a position table beyond float32 passes its checks (a position of -1e39: a NaN piece in the kernel)",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "net_scales_checked_in_float64",
        "wpctrl/config/actuator_models.py",
        "not math.isfinite(_f32(v)):",
        "not math.isfinite(v):",
        "an actuator network's scale of 1e39 (inf in the kernel) passes its check",
        ("tests/test_config_boundaries.py",),
    ),
    M(
        "ema_checked_in_float64",
        "wpctrl/config/actuator_models.py",
        "not (0.0 < _f32(ema) <= 1.0):",
        "not (0.0 < float(ema) <= 1.0):",
        "an EMA weight of 1e-46 (0 in float32: the target never moves) passes its check",
        ("tests/test_config_boundaries.py",),
    ),
    # -- the first hour: refusals, the stability warning, resume and the learning curve --
    M(
        "papercut_unknown_reset_option_accepted",
        "wpctrl/tasks/_validate.py",
        "    if unknown:\n        raise ConfigError(f\"reset: unknown options key(s)",
        "    if False:\n        raise ConfigError(f\"reset: unknown options key(s)",
        "reset(options=...) drops unknown keys silently",
        ("tests/test_papercuts.py::test_task_env_repr_names_the_task_and_reset_refuses_unknown_options",),
    ),
    M(
        "papercut_batch_rule_off_by_one",
        "wpctrl/train/ppo_config.py",
        "    if per >= min_samples:\n",
        "    if per >= min_samples - 1:\n",
        "a mini-batch of one sample (an undefined advantage std) passes the batch check",
        ("tests/test_papercuts.py::test_batch_too_small_for_the_minibatches_is_refused_before_building",),
    ),
    M(
        "stability_damping_term_single",
        "wpctrl/controllers/stability.py",
        "    bad = np.flatnonzero(a + 2.0 * b >= STABILITY_BOUND)\n",
        "    bad = np.flatnonzero(a + b >= STABILITY_BOUND)\n",
        "the explicit-PD stability bound counts the damping term once (Kp dt^2/m + Kd dt/m < 4)",
        ("tests/test_papercuts.py::test_one_dof_diverges_just_past_the_bound_and_not_below",),
    ),
    M(
        "delay_seed_alias_dropped",
        "wpctrl/controllers/build.py",
        "        delay_seed = seed\n",
        "        pass\n",
        "the deprecated seed= no longer seeds the delay draws",
        ("tests/test_papercuts.py::test_delay_seed_names_the_delay_and_seed_is_its_deprecated_alias",),
    ),
    M(
        "resume_conflicting_flag_accepted",
        "wpctrl/train/resume.py",
        "        if name in given and mine != value:\n",
        "        if name in given and mine != value and name == \"task\":\n",
        "--resume takes a conflicting --envs or --control-mode silently",
        ("tests/test_train_outputs.py::test_resume_refuses_flags_that_contradict_the_run",),
    ),
    M(
        "curve_smoothing_unweighted",
        "wpctrl/train/outputs.py",
        "            w = min(n, need)\n",
        "            w = min(1, need)\n",
        "the learning curve weighs every iteration alike, not by its finished episodes",
        ("tests/test_train_outputs.py::test_success_smoothing_weighs_iterations_by_their_finished_episodes",),
    ),
    # -- tasks, evaluation rounds, the gymnasium API and the tasks' range edges --
    M(
        "tasks_reset_same_draw_every_env",
        "wpctrl/tasks/kernels.py",
        "    rng = wp.rand_init(seed[0], e + n * reset_count[e])\n",
        "    rng = wp.rand_init(seed[0], n * reset_count[e])\n",
        "every env of a reset draws the same episode (the RNG's offset forgets the env)",
        ("tests/test_tasks_envs.py::test_every_env_of_a_reset_draws_its_own_episode_from_maniskills_distribution",),
    ),
    M(
        "tasks_set_state_dict_resets_every_env",
        "wpctrl/tasks/state_dict.py",
        "        self._after_state_write(mask)\n",
        "        self._after_state_write(self._all)\n",
        "set_state_dict(env_idx=...) resets the drive targets, contact forces and observations of every env",
        ("tests/test_tasks_envs.py::test_partial_set_state_dict_leaves_the_other_envs_exactly_as_they_were",),
    ),
    M(
        "tasks_final_info_misses_success",
        "wpctrl/tasks/env.py",
        '            done = t["terminated"] | t["truncated"]\n',
        '            done = t["truncated"].clone()\n',
        "the final-info mask misses the envs whose episode ended by success",
        ("tests/test_tasks_envs.py::test_an_episode_ended_by_success_is_in_the_final_info_and_restarts_inside_the_step",),
    ),
    M(
        "tasks_pick_static_six_joints",
        "wpctrl/tasks/kernels.py",
        "    for j in range(7):\n        if wp.abs(joint_qd[qd0 + j]) > P.static_threshold:\n",
        "    for j in range(6):\n        if wp.abs(joint_qd[qd0 + j]) > P.static_threshold:\n",
        "PickCube's robot-static test ignores the 7th arm joint",
        ("tests/test_tasks_envs.py::test_pick_robot_static_checks_every_arm_joint_at_the_threshold",),
    ),
    M(
        "tasks_static_threshold_exclusive",
        "wpctrl/tasks/kernels.py",
        "        if wp.abs(joint_qd[qd0 + j]) > P.static_threshold:\n",
        "        if wp.abs(joint_qd[qd0 + j]) >= P.static_threshold:\n",
        "a joint at exactly 0.2 rad/s counts as moving (ManiSkill: max |qvel| <= 0.2 is static)",
        ("tests/test_tasks_envs.py::test_pick_robot_static_checks_every_arm_joint_at_the_threshold",),
    ),
    M(
        "tasks_grasp_angle_in_radians",
        "wpctrl/tasks/env.py",
        "math.cos(math.radians(spec.grasp_max_angle))",
        "math.cos(spec.grasp_max_angle)",
        "the grasp cone's 85 degrees taken as radians",
        ("tests/test_tasks_envs.py::test_pick_grasp_cone_and_force_limit_at_their_edges",),
    ),
    M(
        "tasks_pick_goal_radius_shrunk",
        "wpctrl/tasks/kernels.py",
        "        placed = wp.length(goal - cube_p) <= P.goal_radius\n",
        "        placed = wp.length(goal - cube_p) < P.goal_radius - 1.0e-3\n",
        "PickCube's goal radius (0.025 m, inclusive) shrunk by a millimetre",
        ("tests/test_tasks_envs.py::test_goal_radius_and_height_edges",),
    ),
    M(
        "train_eval_rounds_one_seed",
        "wpctrl/train/task_ppo.py",
        "seed=None if seed is None else seed + rounds",
        "seed=seed",
        "every evaluation round replays the first round's episodes (one seed)",
        ("tests/test_train_tasks.py::test_evaluation_over_several_rounds_draws_new_episodes_and_counts_each_once",),
    ),
    M(
        "train_eval_success_once_kept",
        "wpctrl/train/task_ppo.py",
        "            hit = torch.zeros(n, dtype=torch.bool, device=env.device)\n",
        "            hit = hit if rounds > 1 else torch.zeros(n, dtype=torch.bool, device=env.device)\n",
        "an evaluation round keeps the last round's success_once",
        ("tests/test_train_tasks.py::test_evaluation_over_several_rounds_draws_new_episodes_and_counts_each_once",),
    ),
    M(
        "train_stats_success_once_kept",
        "wpctrl/train/task_env.py",
        "        self._success_once.masked_fill_(dones, False)\n",
        "",
        "the training statistics' success_once is not cleared when an episode ends",
        ("tests/test_train_tasks.py::test_adapter_statistics_count_success_once_per_episode",),
    ),
    M(
        "train_stats_return_kept",
        "wpctrl/train/task_env.py",
        "        self._return.masked_fill_(dones, 0.0)\n",
        "",
        "an episode's return in the training statistics carries the last episode's rewards",
        ("tests/test_train_tasks.py::test_adapter_statistics_count_success_once_per_episode",),
    ),
]


# ----------------------------------------------------------------------------------------------------------------------
# Running one mutation in a copy.

_CHILD = textwrap.dedent(
    """
    import importlib, json, sys, time
    root, out, mod, new = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
    # The editable install's finder maps 'wpctrl' to the original checkout: drop it, import the copy's.
    sys.meta_path[:] = [f for f in sys.meta_path if '__editable__' not in getattr(f, '__module__', '')]
    sys.path_hooks[:] = [h for h in sys.path_hooks if '__editable__' not in getattr(h, '__module__', '')]
    sys.path_importer_cache.clear()
    sys.path.insert(0, root)
    import wpctrl
    assert wpctrl.__file__.startswith(root), ('wpctrl imported from', wpctrl.__file__)
    if mod:
        m = importlib.import_module(mod)
        with open(m.__file__) as f:
            src = f.read()
        assert m.__file__.startswith(root) and new in src, ('mutation not active in', m.__file__)
    import pytest

    class Recorder:
        def __init__(self):
            self.failed, self.ran = [], 0

        def pytest_runtest_logreport(self, report):
            if report.when == 'call':
                self.ran += 1
            if report.failed and report.nodeid not in self.failed:
                self.failed.append(report.nodeid)

        def pytest_collectreport(self, report):
            if report.failed:
                self.failed.append(report.nodeid or 'collection')

    rec = Recorder()
    t0 = time.time()
    code = pytest.main(sys.argv[5:], plugins=[rec])
    with open(out, 'w') as f:
        json.dump({'exit': int(code), 'failed': rec.failed, 'ran': rec.ran, 'seconds': time.time() - t0}, f)
    """
)


def tree_files(root: Path) -> list[str]:
    """Tracked and untracked, not ignored files of the working tree."""
    out = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=root, check=True, capture_output=True
    ).stdout.decode()
    return [p for p in out.split("\0") if p and (root / p).is_file()]


def make_copy(root: Path, files: list[str]) -> Path:
    dst = Path(tempfile.mkdtemp(prefix="wpctrl-mutant-"))
    for rel in files:
        target = dst / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / rel, target)
    return dst


def apply(copy: Path, m: Mutation) -> None:
    path = copy / m.file
    text = path.read_text()
    n = text.count(m.old)
    if n != 1:
        raise LookupError(f"{m.name}: its text occurs {n} times in {m.file} (expected once): update the mutation")
    path.write_text(text.replace(m.old, m.new))


def module_name(file: str) -> str:
    return file[:-3].replace("/", ".") if file.startswith("wpctrl/") and file.endswith(".py") else ""


def run_tests(copy: Path, tests: list[str], mod: str, marker: str, args) -> dict:
    out = copy / "mutate-result.json"
    env = dict(os.environ)
    env["PYTHONPATH"] = str(copy)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    env.setdefault("WPCTRL_PROPERTY_EXAMPLES", PROPERTY_EXAMPLES)
    if args.warp_cache:
        env["WARP_CACHE_PATH"] = args.warp_cache
    cmd = [sys.executable, "-c", _CHILD, str(copy), str(out), mod, marker]
    cmd += ["-x", "-q", "-p", "no:cacheprovider", "--no-header", "--no-cov", "-m", "slow or not slow", *tests]
    # no coverage in a mutant; every test it names runs, the slow ones too
    t0 = time.time()
    try:
        proc = subprocess.run(cmd, cwd=copy, env=env, capture_output=True, text=True, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        return {"exit": -1, "failed": [], "ran": 0, "seconds": time.time() - t0, "log": "timeout"}
    if not out.exists():
        log = proc.stderr[-3000:]
        return {"exit": proc.returncode, "failed": [], "ran": 0, "seconds": time.time() - t0, "log": log}
    res = json.loads(out.read_text())
    res["seconds"] = time.time() - t0
    res["log"] = (proc.stdout + proc.stderr)[-3000:]
    return res


def test_list(m: Mutation | None, copy: Path) -> list[str]:
    first = list(m.tests) if m else []
    # a file of FAST_TESTS that a targeted test id is in is left out: pytest would merge the id into that file's run,
    # at the file's place in the list, and the targeted test would no longer run first
    named = {t.split("::")[0] for t in first}
    rest = [t for t in FAST_TESTS if t not in first and t not in named]
    tests = [t for t in first + rest if (copy / t.split("::")[0]).exists()]
    if not tests:
        raise LookupError("no test to run (the listed test files are missing)")
    return tests


def run_one(m: Mutation | None, files: list[str], args) -> dict:
    copy = make_copy(ROOT, files)
    try:
        if m is not None:
            apply(copy, m)
        res = run_tests(copy, test_list(m, copy), module_name(m.file) if m else "", m.new if m else "", args)
    finally:
        if not args.keep:
            shutil.rmtree(copy, ignore_errors=True)
    if res["exit"] == -1:
        res["status"] = "timeout"
    elif res["failed"]:
        res["status"] = "killed"
    elif res["exit"] == 0:
        res["status"] = "survived"
    else:
        res["status"] = "error"
    return res


def markdown(rows: list[tuple[Mutation, dict]]) -> str:
    lines = ["| mutation | what it breaks | result | killed by | time [s] |", "|---|---|---|---|---|"]
    for m, r in rows:
        killer = r["failed"][0] if r["failed"] else "—"
        lines.append(f"| `{m.name}` | {m.what} | {r['status']} | `{killer}` | {r['seconds']:.0f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-k", action="append", default=[], help="run only mutations whose name contains this")
    ap.add_argument("--list", action="store_true", help="list the mutations and exit")
    ap.add_argument("--baseline", action="store_true", help="run the fast tests on an unmutated copy")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per mutation")
    ap.add_argument("--warp-cache", default=None, help="Warp kernel cache for the mutants (default: Warp's own)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary copies")
    ap.add_argument("--markdown", default=None, help="write the result table to this file")
    ap.add_argument("--json", default=None, help="write the raw results to this file")
    args = ap.parse_args(argv)

    chosen = [m for m in MUTATIONS if not args.k or any(k in m.name for k in args.k)]
    if args.list:
        for m in chosen:
            print(f"{m.name:40s} {m.file:36s} {m.what}")
        return 0
    files = tree_files(ROOT)
    if args.baseline:
        r = run_one(None, files, args)
        print(f"baseline: {r['status']} ({r['ran']} tests, {r['seconds']:.0f} s) {r['failed'][:3]}")
        return 0 if r["status"] == "survived" else 2
    stale = []
    for m in chosen:
        text = (ROOT / m.file).read_text()
        if text.count(m.old) != 1:
            stale.append(m.name)
    if stale:
        print("stale mutations (their text is not in the file exactly once):", ", ".join(stale))
        return 2
    rows = []
    for i, m in enumerate(chosen):
        print(f"[{i + 1}/{len(chosen)}] {m.name} ...", end="", flush=True)
        r = run_one(m, files, args)
        rows.append((m, r))
        killer = r["failed"][0] if r["failed"] else ""
        print(f" {r['status']} in {r['seconds']:.0f} s ({r['ran']} tests) {killer}", flush=True)
        if r["status"] in ("error", "timeout"):
            print(textwrap.indent(r.get("log", ""), "    "))
    table = markdown(rows)
    print()
    print(table)
    if args.markdown:
        Path(args.markdown).write_text(table + "\n")
    if args.json:
        Path(args.json).write_text(json.dumps([{"name": m.name, **r} for m, r in rows], indent=1))
    survived = [m.name for m, r in rows if r["status"] != "killed"]
    if survived:
        print("\nnot killed:", ", ".join(survived))
    return 1 if survived else 0


if __name__ == "__main__":
    sys.exit(main())
