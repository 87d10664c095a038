"""What the per-env property kernels share: which (env, row) a thread writes, the draw modes, the RNG counter.

Private module. The kernels that set or randomise per-env properties (the drive properties:
:mod:`wpctrl.engine.parts.drive_properties`; the DC-motor envelope: :mod:`wpctrl.engine.parts.actuator_models`) run
one thread per (selected env, row of the controller or child), row index fastest; :func:`_select` maps a thread to
its env (an ``env_ids`` selection or a bool mask, as :func:`wpctrl.controllers.inputs._env_selection` makes them).

Randomness: ``wp.rand_init(seed, counter)`` keyed by a device-side draw counter, so that a captured graph draws new
values on every replay. The counter is read by the draw and incremented by :func:`_bump_counter_kernel` in a separate
launch after it (reading and incrementing it in one launch would race between threads).
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


@wp.kernel
def _bump_counter_kernel(
    # Out:
    counter_out: wp.array[wp.int32],  # in/out (1,)
):
    """One more draw: launched after each kernel that read the counter."""
    counter_out[0] = counter_out[0] + 1
