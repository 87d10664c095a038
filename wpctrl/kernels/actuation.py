"""Warp kernels for per-env drive properties: set, randomise, and mirror them into the Newton model.

Private module. One thread per (selected env, row of the controller or child), row index fastest, as in ``pd.py``.
The four drive properties are handled together, indexed ``p`` = 0 stiffness [N·m/rad or N/m], 1 damping
[N·m·s/rad or N·s/m], 2 force limit [N·m or N], 3 friction [N·m or N]; ``enabled[p]`` selects which are written.

Randomness: ``wp.rand_init(seed, counter)`` keyed by a device-side draw counter, so that a captured graph draws new
values on every replay. The counter is read here and incremented by :func:`_bump_counter_kernel` in a separate
launch after the draw (reading and incrementing it in one launch would race between threads).
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

MODE_SCALE = wp.constant(0)
MODE_ABS = wp.constant(1)


@wp.func
def _select(tid: int, num_rows: int, env_ids_in: wp.array[wp.int32], env_mask_in: wp.array[wp.bool], n: int):
    """(env, local row, selection index) of thread ``tid``; env = -1 when the env is not selected."""
    i = tid // num_rows
    rl = tid - i * num_rows
    env = i
    if env_ids_in:
        env = env_ids_in[i]
        if env < 0 or env >= n:
            env = -1
    if env >= 0 and env_mask_in:
        if not env_mask_in[env]:
            env = -1
    return env, rl, i


@wp.func
def _store(
    env: int,
    r: int,
    p: int,
    value: float,
    kp_out: wp.array2d[float],
    kd_out: wp.array2d[float],
    force_limit_out: wp.array2d[float],
    friction_out: wp.array2d[float],
    row_accel: wp.array[wp.int32],
    row_qd_off: wp.array[wp.int32],
    env_qd_base: wp.array[wp.int32],
    response_in: wp.array2d[float],
    joint_target_ke_out: wp.array[float],
    joint_target_kd_out: wp.array[float],
    joint_effort_limit_out: wp.array[float],
    joint_friction_out: wp.array[float],
):
    """Write one property of (env, row) into its per-env array and mirror it into Newton's per-DOF model array.
    Gains reach the model only with implicit actuation (the ke/kd outputs are None otherwise); an acceleration row
    hands the solver Kp / r, Kd / r."""
    if p == 0:
        kp_out[env, r] = value
    elif p == 1:
        kd_out[env, r] = value
    elif p == 2:
        force_limit_out[env, r] = value
    else:
        friction_out[env, r] = value
    di = env_qd_base[env] + row_qd_off[r]
    if p < 2:
        if joint_target_ke_out:
            g = value
            if row_accel[r] != 0:
                g = value / response_in[wp.min(env, response_in.shape[0] - 1), r]
            if p == 0:
                joint_target_ke_out[di] = g
            else:
                joint_target_kd_out[di] = g
    elif p == 2:
        joint_effort_limit_out[di] = value
    else:
        joint_friction_out[di] = value


@wp.kernel
def _randomize_drive_kernel(
    # Rows:
    row_accel: wp.array[wp.int32],
    row_qd_off: wp.array[wp.int32],
    row0: int,
    num_rows: int,
    # Envs:
    env_qd_base: wp.array[wp.int32],
    # Draw:
    seed: int,
    mode: int,
    enabled: wp.vec4i,
    lo: wp.vec4,
    hi: wp.vec4,
    # In:
    env_ids_in: wp.array[wp.int32],  # optional: thread block i draws for env env_ids_in[i]
    env_mask_in: wp.array[wp.bool],  # optional: only where True
    nominal_in: wp.array2d[float],  # (4, rows) the config's values
    rng_counter_in: wp.array[wp.int32],  # (1,)
    response_in: wp.array2d[float],  # (num_envs, rows) r, for acceleration rows
    # Out:
    kp_out: wp.array2d[float],  # (num_envs, rows)
    kd_out: wp.array2d[float],
    force_limit_out: wp.array2d[float],
    friction_out: wp.array2d[float],
    joint_target_ke_out: wp.array[float],  # optional (implicit actuation)
    joint_target_kd_out: wp.array[float],  # optional
    joint_effort_limit_out: wp.array[float],
    joint_friction_out: wp.array[float],
):
    """value = nominal * U(lo, hi) ("scale") or U(lo, hi) ("abs"); lo == hi gives exactly nominal * lo (no rounding
    of the draw can enter: (hi - lo) * u == 0)."""
    tid = wp.tid()
    env, rl, i = _select(tid, num_rows, env_ids_in, env_mask_in, kp_out.shape[0])
    if env < 0:
        return
    r = row0 + rl
    key = wp.randi(wp.rand_init(seed, rng_counter_in[0]))
    state = wp.rand_init(key, env * kp_out.shape[1] + r)
    for p in range(4):
        u = wp.randf(state)  # drawn for every p, so a property's values do not depend on which others are enabled
        if enabled[p] != 0:
            x = lo[p] + (hi[p] - lo[p]) * u
            if mode == MODE_SCALE:
                x = nominal_in[p, r] * x
            _store(
                env,
                r,
                p,
                x,
                kp_out,
                kd_out,
                force_limit_out,
                friction_out,
                row_accel,
                row_qd_off,
                env_qd_base,
                response_in,
                joint_target_ke_out,
                joint_target_kd_out,
                joint_effort_limit_out,
                joint_friction_out,
            )


@wp.kernel
def _set_drive_kernel(
    # Rows:
    row_accel: wp.array[wp.int32],
    row_qd_off: wp.array[wp.int32],
    row0: int,
    num_rows: int,
    # Envs:
    env_qd_base: wp.array[wp.int32],
    enabled: wp.vec4i,
    # In:
    env_ids_in: wp.array[wp.int32],  # optional
    env_mask_in: wp.array[wp.bool],  # optional
    values_in: wp.array3d[float],  # (4, 1 | len(env_ids) | num_envs, num_rows): row 0 broadcasts
    response_in: wp.array2d[float],
    # Out:
    kp_out: wp.array2d[float],
    kd_out: wp.array2d[float],
    force_limit_out: wp.array2d[float],
    friction_out: wp.array2d[float],
    joint_target_ke_out: wp.array[float],  # optional (implicit actuation)
    joint_target_kd_out: wp.array[float],  # optional
    joint_effort_limit_out: wp.array[float],
    joint_friction_out: wp.array[float],
):
    """Copy given values into the per-env drive arrays (and the model) for the selected envs."""
    tid = wp.tid()
    env, rl, i = _select(tid, num_rows, env_ids_in, env_mask_in, kp_out.shape[0])
    if env < 0:
        return
    r = row0 + rl
    b = 0
    if values_in.shape[1] > 1:
        b = i
        if env_mask_in:
            b = env  # a mask selects from values of shape (num_envs, n)
    for p in range(4):
        if enabled[p] != 0:
            x = values_in[p, b, rl]
            _store(
                env,
                r,
                p,
                x,
                kp_out,
                kd_out,
                force_limit_out,
                friction_out,
                row_accel,
                row_qd_off,
                env_qd_base,
                response_in,
                joint_target_ke_out,
                joint_target_kd_out,
                joint_effort_limit_out,
                joint_friction_out,
            )


@wp.kernel
def _bump_counter_kernel(
    # Out:
    counter_out: wp.array[wp.int32],  # in/out (1,)
):
    """One more draw: launched after each kernel that read the counter."""
    counter_out[0] = counter_out[0] + 1


@wp.kernel
def _set_rows_kernel(
    row0: int,
    num_rows: int,
    env_ids_in: wp.array[wp.int32],  # optional
    env_mask_in: wp.array[wp.bool],  # optional
    values_in: wp.array2d[float],  # (1 | len(env_ids) | num_envs, num_rows): row 0 broadcasts
    # Out:
    param_out: wp.array2d[float],  # (num_envs, rows) a per-env parameter without a model mirror
):
    """Copy given values into a per-env parameter (an actuator model's) for the selected envs."""
    tid = wp.tid()
    env, rl, i = _select(tid, num_rows, env_ids_in, env_mask_in, param_out.shape[0])
    if env < 0:
        return
    b = 0
    if values_in.shape[0] > 1:
        b = i
        if env_mask_in:
            b = env
    param_out[env, row0 + rl] = values_in[b, rl]


@wp.kernel
def _randomize_rows_kernel(
    row0: int,
    num_rows: int,
    seed: int,
    stream: int,  # a stream per parameter: its draws do not depend on which others are drawn
    mode: int,
    lo: float,
    hi: float,
    env_ids_in: wp.array[wp.int32],  # optional
    env_mask_in: wp.array[wp.bool],  # optional
    nominal_in: wp.array[float],  # (rows,) the config's values
    rng_counter_in: wp.array[wp.int32],  # (1,)
    # Out:
    param_out: wp.array2d[float],  # (num_envs, rows)
):
    """value = nominal * U(lo, hi) ("scale") or U(lo, hi) ("abs"), as :func:`_randomize_drive_kernel`."""
    tid = wp.tid()
    env, rl, i = _select(tid, num_rows, env_ids_in, env_mask_in, param_out.shape[0])
    if env < 0:
        return
    r = row0 + rl
    key = wp.randi(wp.rand_init(seed, rng_counter_in[0]))
    state = wp.rand_init(key + stream * 7919, env * param_out.shape[1] + r)
    x = lo + (hi - lo) * wp.randf(state)
    if mode == MODE_SCALE:
        x = nominal_in[r] * x
    param_out[env, r] = x
