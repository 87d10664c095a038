"""Warp kernels for ManiSkill-style PD joint control over all envs of a Newton model.

Private module. The PD kernels are launched over ``dim=(num_envs, rows)``, one thread per (env, row) where a row is one
controlled joint, with the row index fastest: a warp's loads and stores of the ``(num_envs, rows)`` buffers and of
Newton's flat arrays are contiguous, and ``wp.tid()`` gives (env, row) without an integer division. The few
cross-row dependencies are arranged so that no thread reads what another writes:

- ``set_action``: a mimic follower has no thread of its own; the thread of its source row writes it (it only reads
  its source's fresh target). An env whose action holds NaN/Inf is left untouched by all its threads; its lead row
  (the first non-follower) counts it. Without per-substep work (see ``_Engine.per_substep``) it also writes the drive
  targets into the Control, and the substep launch is elided.
- ``before_simulation_step``: an interpolating row keeps its own substep counter in ``(num_envs, rows)``; the
  per-env counter exposed as ManiSkill's ``_step`` is written by row 0 alone and read by no other thread.

The per-env ``step`` array holds ManiSkill's ``_step`` minus ``host_substeps``, the substeps the host counted since the
last ``set_action`` when the substep launch is elided (0 otherwise): ``_step = step + host_substeps``.

Row parameters are shared by all envs; gains are indexed with the batch rule ``env if shape[0] > 1 else 0``. A
row's coordinate in ``joint_q``/``joint_target_q`` and its DOF in ``joint_qd``/``joint_target_qd``/``joint_f`` come
from precomputed index tables (:func:`_at`): for a replicated layout a ``(1, rows)`` table of env 0 plus
``env * stride`` (no per-env load, no index traffic at 1M envs), otherwise a flat ``(num_envs, rows)`` table (one load
instead of a chain of table loads).

Actuation (issue 10): the drive properties ``kp``/``kd``/``force_limit`` are ``(num_envs, rows)`` in wpctrl (the
batch rule still accepts ``(1, rows)``). The three options below are off by default and then compiled out
(``wp.static`` variants of the set_action and substep kernels, all with the same parameters):

- command delay: a ring buffer ``delay_q``/``delay_qd`` of shape ``(max_delay + 1, num_envs, rows)`` written by the
  substep kernel, read ``delay[env]`` substeps back; each row keeps its own ring head (no cross-thread race);
- effort readout: ``computed_effort``/``applied_effort``/``saturation_count`` written by the substep kernel;
- target clamping: ``clip_targets`` clamps every stored position target to the joint limits in ``set_action``.

Parameter naming follows MuJoCo Warp: row and env tables first (no suffix), then ``_in`` inputs, then ``_out``
outputs (an ``_out`` array that a kernel also reads is marked "in/out").
"""

from __future__ import annotations

import warp as wp

from .. import config as _cfg

wp.set_module_options({"enable_backward": False})

ROW_POS = wp.constant(_cfg.ROW_POS)
ROW_VEL = wp.constant(_cfg.ROW_VEL)
ROW_PASSIVE = wp.constant(_cfg.ROW_PASSIVE)

FLAG_NORMALIZE = wp.constant(_cfg.FLAG_NORMALIZE)
FLAG_DELTA = wp.constant(_cfg.FLAG_DELTA)
FLAG_TARGET = wp.constant(_cfg.FLAG_TARGET)
FLAG_INTERPOLATE = wp.constant(_cfg.FLAG_INTERPOLATE)
FLAG_VEL_TARGET = wp.constant(_cfg.FLAG_VEL_TARGET)

EXPLICIT_OFF = wp.constant(0)
EXPLICIT_NAIVE = wp.constant(1)
EXPLICIT_STABLE = wp.constant(2)


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
    """Whether every column of ``env``'s action is finite (the "hold the whole env" policy needs all of them).

    Branch-free over the columns: one pass of independent loads of one contiguous action row (cached after the
    first thread of the env), no early exit that would diverge a warp."""
    ok = int(1)
    for c in range(action_in.shape[1]):
        ok = ok & int(wp.isfinite(action_in[env, c]))
    return ok != 0


def _make_set_action_kernel(CLIP: bool):
    """The set_action kernel, specialised at compile time on ``clip_targets`` (the default runs no clamp)."""

    def _set_action_kernel(
        # Rows:
        row_kind: wp.array[wp.int32],
        row_flags: wp.array[wp.int32],
        row_act_col: wp.array[wp.int32],
        row_vel_col: wp.array[wp.int32],
        row_lo: wp.array[float],
        row_hi: wp.array[float],
        row_vlo: wp.array[float],
        row_vhi: wp.array[float],
        row_mimic_src: wp.array[wp.int32],
        row_follow_start: wp.array[wp.int32],
        row_follow: wp.array[wp.int32],
        row_mimic_mul: wp.array[float],
        row_mimic_off: wp.array[float],
        row_qlo: wp.array[float],
        row_qhi: wp.array[float],
        lead_row: int,
        clip_targets: int,
        # Envs x rows:
        q_idx: wp.array2d[wp.int32],
        qd_idx: wp.array2d[wp.int32],
        q_stride: int,
        qd_stride: int,
        host_substeps: int,
        # In:
        action_in: wp.array2d[float],
        joint_q_in: wp.array[float],
        # Out:
        processed_action_out: wp.array2d[float],
        start_qpos_out: wp.array2d[float],
        target_qpos_out: wp.array2d[float],  # in/out: the previous (virtual) target
        target_qvel_out: wp.array2d[float],
        step_out: wp.array[wp.int32],  # in/out (held envs)
        row_step_out: wp.array2d[wp.int32],
        bad_action_count_out: wp.array[wp.int32],  # in/out
        joint_target_q_out: wp.array[float],  # optional: the drive targets, when no substep launch writes them
        joint_target_qd_out: wp.array[float],  # optional
    ):
        env, r = wp.tid()
        if row_mimic_src[r] >= 0:
            return  # a follower: written by its source row's thread

        # A non-finite action leaves the whole env untouched (targets hold) and is counted once; its substep counter
        # keeps counting from its last accepted action.
        if not _action_finite(action_in, env):
            if r == lead_row:
                bad_action_count_out[env] = bad_action_count_out[env] + 1
                step_out[env] = step_out[env] + host_substeps
            return

        if r == lead_row:
            step_out[env] = 0
        kind = row_kind[r]
        flags = row_flags[r]
        if flags & FLAG_INTERPOLATE:
            row_step_out[env, r] = 0
        norm = flags & FLAG_NORMALIZE
        col = row_act_col[r]
        if kind == ROW_POS:
            qi = _at(q_idx, q_stride, env, r)
            q = joint_q_in[qi]
            start_qpos_out[env, r] = q
            t = target_qpos_out[env, r]  # a joint outside the mimic map keeps its target
            if col >= 0:
                a = _scale(action_in[env, col], row_lo[r], row_hi[r], norm)
                processed_action_out[env, col] = a
                t = a
                if flags & FLAG_DELTA:
                    if flags & FLAG_TARGET:
                        t = target_qpos_out[env, r] + a
                    else:
                        t = q + a
                if wp.static(CLIP):  # the joint's limits [rad or m]: a virtual target cannot run past them
                    t = wp.clamp(t, row_qlo[r], row_qhi[r])
                target_qpos_out[env, r] = t
            if joint_target_q_out:
                joint_target_q_out[qi] = t
            vcol = row_vel_col[r]
            if vcol >= 0:
                v = _scale(action_in[env, vcol], row_vlo[r], row_vhi[r], norm)
                processed_action_out[env, vcol] = v
                target_qvel_out[env, r] = v
                if joint_target_qd_out:
                    joint_target_qd_out[_at(qd_idx, qd_stride, env, r)] = v
            # Followers: target[m] = target[source] * multiplier + offset.
            for i in range(row_follow_start[r], row_follow_start[r + 1]):
                m = row_follow[i]
                mi = _at(q_idx, q_stride, env, m)
                start_qpos_out[env, m] = joint_q_in[mi]
                tm = t * row_mimic_mul[m] + row_mimic_off[m]
                if wp.static(CLIP):
                    tm = wp.clamp(tm, row_qlo[m], row_qhi[m])
                target_qpos_out[env, m] = tm
                if row_flags[m] & FLAG_INTERPOLATE:
                    row_step_out[env, m] = 0
                if joint_target_q_out:
                    joint_target_q_out[mi] = tm
        elif kind == ROW_VEL:
            v = _scale(action_in[env, col], row_lo[r], row_hi[r], norm)
            processed_action_out[env, col] = v
            target_qvel_out[env, r] = v
            if joint_target_qd_out:
                joint_target_qd_out[_at(qd_idx, qd_stride, env, r)] = v

    return wp.kernel(_set_action_kernel, name=f"_set_action_kernel_clip{int(CLIP)}")


_SET_ACTION_KERNELS = {c: _make_set_action_kernel(c) for c in (False, True)}


def set_action_kernel(clip_targets: bool):
    """The set_action kernel variant (same parameters in both; ``clip_targets`` is also passed as an int)."""
    return _SET_ACTION_KERNELS[bool(clip_targets)]


_set_action_kernel = _SET_ACTION_KERNELS[False]


def _make_substep_kernel(DELAY: bool, EFFORT: bool):
    """The substep kernel, specialised at compile time on whether a delay and the effort readout are on, so that the
    default build runs none of their branches (on the CPU backend a null-array check per thread cost ~30 %)."""

    def _substep_kernel(
        # Rows:
        row_kind: wp.array[wp.int32],
        row_flags: wp.array[wp.int32],
        # Envs x rows:
        q_idx: wp.array2d[wp.int32],
        qd_idx: wp.array2d[wp.int32],
        q_stride: int,
        qd_stride: int,
        # Gains (1 | num_envs, rows):
        kp: wp.array2d[float],
        kd: wp.array2d[float],
        force_limit: wp.array2d[float],
        row_accel: wp.array[wp.int32],
        num_substeps: int,
        explicit_pd: int,
        dt: float,
        max_delay: int,
        # In:
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        response_in: wp.array2d[float],
        start_qpos_in: wp.array2d[float],
        target_qpos_in: wp.array2d[float],
        target_qvel_in: wp.array2d[float],
        delay_in: wp.array[wp.int32],  # optional (num_envs,) [substeps]; None: no delay
        # Out:
        step_out: wp.array[wp.int32],  # in/out
        row_step_out: wp.array2d[wp.int32],  # in/out
        delay_head_out: wp.array2d[wp.int32],  # in/out, with delay_in: each row's ring-buffer slot
        delay_q_out: wp.array3d[float],  # in/out, with delay_in: (max_delay + 1, num_envs, rows) position targets
        delay_qd_out: wp.array3d[float],  # in/out, optional: velocity targets (only when a row has one)
        joint_target_q_out: wp.array[float],
        joint_target_qd_out: wp.array[float],
        joint_f_out: wp.array[float],
        computed_effort_out: wp.array2d[float],  # optional [N·m or N]: PD law before the clamp
        applied_effort_out: wp.array2d[float],  # optional [N·m or N]: after the clamp
        saturation_count_out: wp.array2d[wp.int32],  # optional, in/out: substeps with |computed| > force limit
    ):
        env, r = wp.tid()
        if r == 0:
            step_out[env] = step_out[env] + 1
        kind = row_kind[r]
        flags = row_flags[r]
        qi = _at(q_idx, q_stride, env, r)
        di = _at(qd_idx, qd_stride, env, r)
        vel_target = kind != ROW_POS or (flags & FLAG_VEL_TARGET) != 0
        tq = float(0.0)
        tqd = float(0.0)
        if vel_target:
            tqd = target_qvel_in[env, r]
        if kind == ROW_POS:
            tq = target_qpos_in[env, r]
            if flags & FLAG_INTERPOLATE:
                k = row_step_out[env, r] + 1
                row_step_out[env, r] = k
                tq = _interp(start_qpos_in[env, r], tq, k, num_substeps)
        if wp.static(DELAY):
            # Push this substep's command, pop the one from delay[env] substeps ago (a reset filled the ring).
            h = delay_head_out[env, r] + 1
            if h > max_delay:
                h = 0
            delay_head_out[env, r] = h
            delay_q_out[h, env, r] = tq
            if delay_qd_out:
                delay_qd_out[h, env, r] = tqd
            s = h - wp.clamp(delay_in[env], 0, max_delay)
            if s < 0:
                s = s + max_delay + 1
            tq = delay_q_out[s, env, r]
            if delay_qd_out:
                tqd = delay_qd_out[s, env, r]
        if vel_target:
            joint_target_qd_out[di] = tqd
        if kind == ROW_POS:
            joint_target_q_out[qi] = tq
        if explicit_pd != 0 or wp.static(EFFORT):
            qd = joint_qd_in[di]
            kpe = float(0.0)
            e = float(0.0)
            if kind == ROW_POS:
                kpe = kp[_bidx(kp.shape[0], env), r]
                e = tq - joint_q_in[qi]
            kde = kd[_bidx(kd.shape[0], env), r]
            resp = float(1.0)
            if explicit_pd == EXPLICIT_STABLE or row_accel[r] != 0:
                resp = response_in[_bidx(response_in.shape[0], env), r]
            if row_accel[r] != 0:  # acceleration drive: gains times the effective inertia 1/r
                kpe = kpe / resp
                kde = kde / resp
            u = float(0.0)
            if explicit_pd == EXPLICIT_STABLE:
                # PD on the end-of-step state of a semi-implicit Euler step, solved with the joint's response r:
                # u = Kp (q* - q - dt qd) + Kd (qd* - qd) over 1 + r dt (Kd + dt Kp)
                u = (kpe * (e - dt * qd) + kde * (tqd - qd)) / (1.0 + resp * dt * (kde + dt * kpe))
            else:
                u = kpe * e + kde * (tqd - qd)
            lim = force_limit[_bidx(force_limit.shape[0], env), r]
            f = wp.clamp(u, -lim, lim)
            if explicit_pd != 0:
                joint_f_out[di] = f
            if wp.static(EFFORT):
                computed_effort_out[env, r] = u
                applied_effort_out[env, r] = f
                if wp.abs(u) > lim:
                    saturation_count_out[env, r] = saturation_count_out[env, r] + 1

    return wp.kernel(_substep_kernel, name=f"_substep_kernel_delay{int(DELAY)}_effort{int(EFFORT)}")


_SUBSTEP_KERNELS = {(d, e): _make_substep_kernel(d, e) for d in (False, True) for e in (False, True)}


def substep_kernel(delay: bool, effort: bool):
    """The substep kernel variant for these options (same parameters in all four)."""
    return _SUBSTEP_KERNELS[(bool(delay), bool(effort))]


_substep_kernel = _SUBSTEP_KERNELS[(False, False)]


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
    step_out: wp.array[wp.int32],
    row_step_out: wp.array2d[wp.int32],
    joint_target_q_out: wp.array[float],  # optional (no Control given)
    joint_target_qd_out: wp.array[float],  # optional
    joint_f_out: wp.array[float],  # optional (explicit actuation only)
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
    row_step_out[env, r] = 0
    kind = row_kind[r]
    qi = _at(q_idx, q_stride, env, r)
    di = _at(qd_idx, qd_stride, env, r)
    q = joint_q_in[qi]
    start_qpos_out[env, r] = q
    target_qpos_out[env, r] = q
    vel_target = kind != ROW_POS or (row_flags[r] & FLAG_VEL_TARGET) != 0
    v = float(0.0)
    if first != 0 and kind == ROW_POS and vel_target:
        v = joint_qd_in[di]  # ManiSkill's first reset of a PDJointPosVel takes the measured velocity
    target_qvel_out[env, r] = v
    if joint_target_q_out and kind == ROW_POS:
        joint_target_q_out[qi] = q
    if joint_target_qd_out and vel_target:
        joint_target_qd_out[di] = v
    if joint_f_out:
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
        for i in range(delay_q_out.shape[0]):
            delay_q_out[i, env, r] = q
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
    if kind != ROW_POS or (row_flags[r] & FLAG_VEL_TARGET) != 0:
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
def _response_kernel(
    # Rows:
    row_art_off: wp.array[wp.int32],
    row_art_dof: wp.array[wp.int32],
    # Envs:
    env_art_base: wp.array[wp.int32],
    # In:
    inverse_blocks_in: wp.array3d[float],
    # Out:
    response_out: wp.array2d[float],
):
    """Each row's joint-space response r = (H^-1)_ii [1/(kg m^2) or 1/kg] from the articulation's inverse block."""
    tid = wp.tid()
    num_rows = row_art_off.shape[0]
    env = tid // num_rows
    r = tid - env * num_rows
    i = row_art_dof[r]
    response_out[env, r] = inverse_blocks_in[env_art_base[env] + row_art_off[r], i, i]


@wp.kernel
def _accel_gains_kernel(
    # Rows:
    row_accel: wp.array[wp.int32],
    row_qd_off: wp.array[wp.int32],
    # Envs:
    env_qd_base: wp.array[wp.int32],
    # Gains (1 | num_envs, rows):
    kp: wp.array2d[float],
    kd: wp.array2d[float],
    # In:
    response_in: wp.array2d[float],
    # Out:
    joint_target_ke_out: wp.array[float],
    joint_target_kd_out: wp.array[float],
):
    """Implicit acceleration drive: the solver's per-env gains are Kp / r and Kd / r (r: the joint's response)."""
    tid = wp.tid()
    num_rows = row_accel.shape[0]
    env = tid // num_rows
    r = tid - env * num_rows
    if row_accel[r] != 0:
        di = env_qd_base[env] + row_qd_off[r]
        resp = response_in[env, r]
        joint_target_ke_out[di] = kp[_bidx(kp.shape[0], env), r] / resp
        joint_target_kd_out[di] = kd[_bidx(kd.shape[0], env), r] / resp


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
