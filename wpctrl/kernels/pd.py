"""Warp kernels for ManiSkill-style PD joint control over all envs of a Newton model: the shared helpers, reset, the
Control write of a swapped Control, the step-counter view and the float64 action cast.

Private module. The per-step kernels (``set_action``, the solver substep) are in :mod:`wpctrl.kernels.pd_step`,
compiled per row layout. The kernels here run off the step's hot path (reset, a Control handed over for the first
time) and are launched over ``dim=(num_envs, rows)``, one thread per (env, row), row fastest (``wp.tid()`` gives
(env, row) without an integer division).

State arrays (``(num_envs, rows)`` unless stated): ``start_qpos`` (the measured coordinate at the last accepted
action, interpolation's start), ``target_qpos`` / ``target_qvel`` (ManiSkill's ``_target_qpos`` / ``_target_qvel``),
``step`` ((num_envs,): ManiSkill's ``_step`` minus ``host_substeps``, the substeps the host counted since the last
``set_action`` when the substep launch is elided, 0 otherwise: ``_step = step + host_substeps``).

A row's coordinate in ``joint_q``/``joint_target_q`` and its DOF in ``joint_qd``/``joint_target_qd``/``joint_f`` come
from precomputed index tables (:func:`_at`): for a replicated layout a ``(1, rows)`` table of env 0 plus
``env * stride`` (no per-env load), otherwise a flat ``(num_envs, rows)`` table. Drive properties
``kp``/``kd``/``force_limit`` are ``(num_envs, rows)`` in wpctrl; the batch rule ``env if shape[0] > 1 else 0``
(:func:`_bidx`) also accepts ``(1, rows)``. Command delay (a ring ``delay_q``/``delay_qd`` of shape
``(max_delay + 1, num_envs, rows)``, one head per row) and the effort readout are filled / zeroed by reset here.

Parameter naming follows MuJoCo Warp: row and env tables first (no suffix), then ``_in`` inputs, then ``_out``
outputs (an ``_out`` array that a kernel also reads is marked "in/out").
"""

from __future__ import annotations

import warp as wp

from ..config import rows as config_rows

wp.set_module_options({"enable_backward": False})

ROW_POS = wp.constant(config_rows.ROW_POS)
ROW_EFFORT = wp.constant(config_rows.ROW_EFFORT)
ROW_VEL = wp.constant(config_rows.ROW_VEL)
ROW_PASSIVE = wp.constant(config_rows.ROW_PASSIVE)

FLAG_VEL_TARGET = wp.constant(config_rows.FLAG_VEL_TARGET)


@wp.func
def _bidx(n: int, env: int):
    """Batch index into a ``(1 | num_envs, ...)`` parameter array."""
    if n > 1:
        return env
    return 0


@wp.func
def _at(idx: wp.array2d[wp.int32], stride: int, env: int, r: int):
    """Flat index of (env, row) in a Newton array: ``idx[env, r]`` for a ``(num_envs, rows)`` table, or
    ``idx[0, r] + env * stride`` for a ``(1, rows)`` table of a constant-stride (replicated) layout: no per-env
    load."""
    return idx[_bidx(idx.shape[0], env), r] + env * stride


@wp.func
def _scale(a: float, lo: float, hi: float, normalize: int):
    """ManiSkill's normalisation: clip to [-1, 1] first, then ``0.5(h+l) + 0.5(h-l)a`` in float32."""
    if normalize == 0:
        return a
    c = wp.clamp(a, -1.0, 1.0)
    return 0.5 * (hi + lo) + (0.5 * (hi - lo)) * c


@wp.func
def _interp(start: float, target: float, k: int, num_substeps: int):
    """Substep k (1-based, held at num_substeps) of ``start + k * (target - start) / K``, ManiSkill's rounding."""
    step_size = (target - start) / float(num_substeps)
    return start + step_size * float(wp.min(k, num_substeps))


@wp.func
def _action_finite(action_in: wp.array2d[float], env: int):
    """Whether every column of ``env``'s action is finite (the "hold the whole env" policy needs all of them)."""
    ok = int(1)
    for c in range(action_in.shape[1]):
        ok = ok & int(wp.isfinite(action_in[env, c]))
    return ok != 0


@wp.kernel
def _reset_kernel(
    # Rows:
    row_kind: wp.array[wp.int32],
    row_flags: wp.array[wp.int32],
    # Envs x rows:
    q_idx: wp.array2d[wp.int32],
    qd_idx: wp.array2d[wp.int32],
    q_stride: int,
    qd_stride: int,
    first: int,
    explicit_on: int,
    host_substeps: int,
    delay_min: int,
    delay_max: int,
    seed: int,
    # In:
    env_ids_in: wp.array[wp.int32],  # optional: thread row i resets env env_ids_in[i]
    env_mask_in: wp.array[wp.bool],  # optional: reset only where True
    joint_q_in: wp.array[float],
    joint_qd_in: wp.array[float],
    rng_counter_in: wp.array[wp.int32],  # (1,) draws so far; bumped by a separate launch after this one
    # Out:
    start_qpos_out: wp.array2d[float],
    target_qpos_out: wp.array2d[float],
    target_qvel_out: wp.array2d[float],
    target_effort_out: wp.array2d[float],  # optional (effort rows): zeroed
    step_out: wp.array[wp.int32],
    joint_target_q_out: wp.array[float],  # optional (no Control given)
    joint_target_qd_out: wp.array[float],  # optional
    joint_f_out: wp.array[float],  # optional (explicit actuation or effort rows): zeroed on torque rows
    delay_out: wp.array[wp.int32],  # optional (delay on): (num_envs,) drawn in [delay_min, delay_max] [substeps]
    delay_head_out: wp.array2d[wp.int32],  # optional (delay on)
    delay_q_out: wp.array3d[float],  # optional (delay on): the env's history, filled with the reset pose
    delay_qd_out: wp.array3d[float],  # optional
    computed_effort_out: wp.array2d[float],  # optional (effort tracking): zeroed
    applied_effort_out: wp.array2d[float],  # optional: zeroed
    saturation_count_out: wp.array2d[wp.int32],  # optional: zeroed
):
    env, r = wp.tid()
    if env_ids_in:
        env = env_ids_in[env]
        if env < 0 or env >= step_out.shape[0]:
            return
    if env_mask_in:
        if not env_mask_in[env]:
            return
    if r == 0:
        step_out[env] = -host_substeps  # ManiSkill's _step = 0
    kind = row_kind[r]
    qi = _at(q_idx, q_stride, env, r)
    di = _at(qd_idx, qd_stride, env, r)
    q = joint_q_in[qi]
    start_qpos_out[env, r] = q
    target_qpos_out[env, r] = q
    vel_target = kind == ROW_VEL or kind == ROW_PASSIVE or (kind == ROW_POS and (row_flags[r] & FLAG_VEL_TARGET) != 0)
    v = float(0.0)
    if first != 0 and kind == ROW_POS and vel_target:
        v = joint_qd_in[di]  # ManiSkill's first reset of a PDJointPosVel takes the measured velocity
    target_qvel_out[env, r] = v
    if joint_target_q_out and kind == ROW_POS:
        joint_target_q_out[qi] = q
    if joint_target_qd_out and vel_target:
        joint_target_qd_out[di] = v
    if target_effort_out:
        target_effort_out[env, r] = 0.0
    if joint_f_out:
        if explicit_on != 0 or kind == ROW_EFFORT:
            joint_f_out[di] = 0.0
    if delay_q_out:
        if r == 0:  # one draw per env, by its row-0 thread (no other thread reads delay_out here)
            d = delay_min
            if delay_max > delay_min:
                st = wp.rand_init(seed, rng_counter_in[0])
                st = wp.rand_init(wp.randi(st), env)
                d = wp.randi(st, delay_min, delay_max + 1)
            delay_out[env] = d
        delay_head_out[env, r] = 0
        held = q  # the ring holds targets: the reset pose, or a zero effort on effort rows
        if kind == ROW_EFFORT:
            held = 0.0
        for i in range(delay_q_out.shape[0]):
            delay_q_out[i, env, r] = held
            if delay_qd_out:
                delay_qd_out[i, env, r] = v
    if computed_effort_out:
        computed_effort_out[env, r] = 0.0
        applied_effort_out[env, r] = 0.0
        saturation_count_out[env, r] = 0


@wp.kernel
def _targets_kernel(
    # Rows:
    row_kind: wp.array[wp.int32],
    row_flags: wp.array[wp.int32],
    # Envs x rows:
    q_idx: wp.array2d[wp.int32],
    qd_idx: wp.array2d[wp.int32],
    q_stride: int,
    qd_stride: int,
    # In:
    target_qpos_in: wp.array2d[float],
    target_qvel_in: wp.array2d[float],
    # Out:
    joint_target_q_out: wp.array[float],
    joint_target_qd_out: wp.array[float],
):
    """The current drive targets [rad, m; rad/s, m/s] of every env into a Control that does not hold them yet (no
    per-substep work: the first Control seen, or a swapped one). Writes what the substep kernel would write."""
    env, r = wp.tid()
    kind = row_kind[r]
    if kind == ROW_VEL or kind == ROW_PASSIVE or (kind == ROW_POS and (row_flags[r] & FLAG_VEL_TARGET) != 0):
        joint_target_qd_out[_at(qd_idx, qd_stride, env, r)] = target_qvel_in[env, r]
    if kind == ROW_POS:
        joint_target_q_out[_at(q_idx, q_stride, env, r)] = target_qpos_in[env, r]


@wp.kernel
def _step_view_kernel(
    host_substeps: int,
    # In:
    step_in: wp.array[wp.int32],
    # Out:
    step_out: wp.array[wp.int32],
):
    """ManiSkill's ``_step`` per env: the device part plus the substeps the host counted since the last set_action."""
    env = wp.tid()
    step_out[env] = step_in[env] + host_substeps


@wp.kernel
def _cast_f64_kernel(
    # In:
    src_in: wp.array2d[wp.float64],
    # Out:
    dst_out: wp.array2d[float],
):
    """A float64 action copied into the controller's float32 action buffer."""
    i, j = wp.tid()
    dst_out[i, j] = float(src_in[i, j])
