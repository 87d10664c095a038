"""The substep kernel and an actuator network's kernel as one launch. Private module.

A mode with an actuator network normally runs two launches per substep: the substep kernel (one thread per env: the
targets, the PD rows, the other actuator models) and then the network's (one thread per network row, reading the
target the substep kernel wrote to ``joint_target_q``). At a few thousand robots both launches are short and each
costs its own place in the graph. The fused kernel runs both in one grid of ``num_envs * n + num_envs`` threads:
threads ``[0, num_envs * n)`` are the network's rows (:func:`.actuator_net_unrolled.unrolled_row`, the same code as
the unrolled kernel) and the ``num_envs`` threads after them the substep kernel's env threads
(:func:`.pd_step.substep_func`, the same code). (On the CPU the threads run in order, the network's first: a network
row that read what the substep kernel writes in this launch would see the previous substep's values, which the tests
would catch.)

The two sets of threads write disjoint memory (the substep kernel does not write a network row's ``joint_f`` or effort
readout; the network writes nothing the substep kernel reads), so nothing has to wait for anything inside the launch,
with one exception: the network's position target. The substep kernel writes it to ``joint_target_q`` in this very
launch, so a network row cannot read it from there; it reads the mode's target table (``target_qpos``) instead,
which is the same value when the network's rows are neither interpolated nor delayed. :func:`fusable` says whether
a mode's layout allows it; the engine fuses only then (``ActuatorNet.launch``: by default wherever allowed), with
bit-identical results to the two launches on the CPU.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..config.actuator_models import ACT_NET
from ..config.rows import FLAG_INTERPOLATE
from .actuator_net import NetIO, NetLayout, net_kernel, read_row
from .actuator_net_unrolled import unrolled_row
from .pd_step import substep_func
from .pd_substep import SubstepArrays
from .step_layout import StepLayout

wp.set_module_options({"enable_backward": False})

BLOCK_DIM = 64
"""CUDA threads per block (as the unrolled network kernel)."""

_KERNELS: dict[tuple, wp.Kernel] = {}


def fusable(step: StepLayout, row0: int, n: int) -> str | None:
    """Why the network's rows ``row0 .. row0 + n`` of ``step`` cannot run in the substep's launch, or None when they
    can: their target must be the target table's value (no interpolation, no delay) and the substep kernel must leave
    their torque to the network (explicit actuation)."""
    if step.delay:
        return "a command delay (the network's target comes from the delay ring the substep kernel advances)"
    if any(int(f) & FLAG_INTERPOLATE for f in step.flags[row0 : row0 + n]):
        return "interpolated targets (the network's target depends on the substep counter the substep kernel bumps)"
    if not step.explicit or any(int(a) != ACT_NET for a in step.act_model[row0 : row0 + n]):
        return "the rows are not an explicit actuator network's"
    return None


def fused_kernel(
    step: StepLayout, layout: NetLayout, weights: np.ndarray, scales: tuple[float, float, float]
) -> wp.Kernel:
    """The substep kernel of ``step`` and the unrolled kernel of ``layout`` / ``weights`` / ``scales`` in one kernel:
    the substep kernel's parameters, then ``row0``, ``io`` and ``hist_out`` of the network's. Launched over
    ``num_envs * (1 + layout.rows)`` threads with ``block_dim = BLOCK_DIM``."""
    w = np.ascontiguousarray(weights, dtype=np.float32)
    key = (step, layout, w.tobytes(), tuple(float(np.float32(x)) for x in scales))
    k = _KERNELS.get(key)
    if k is None:
        k = _KERNELS[key] = _make(step, layout, w, scales)
    return k


def _make(step: StepLayout, L: NetLayout, weights: np.ndarray, scales: tuple[float, float, float]) -> wp.Kernel:
    substep = substep_func(step)
    row = unrolled_row(L, weights, scales)
    N = L.rows
    vec_p = wp.types.vector(length=max(2 * L.past, 1), dtype=wp.float32)

    def fused(
        # The substep kernel's (wpctrl.kernels.pd_substep):
        substep_arrays: SubstepArrays,
        joint_q_in: wp.array[float],
        joint_qd_in: wp.array[float],
        joint_target_q_out: wp.array[float],
        joint_target_qd_out: wp.array[float],
        joint_f_out: wp.array[float],
        # The network's (wpctrl.kernels.actuator_net_unrolled):
        row0: int,
        io: NetIO,
        hist_out: wp.array[vec_p],
    ):
        i = wp.tid()
        num_envs = substep_arrays.step_out.shape[0]
        if i < num_envs * wp.static(N):
            env = i // wp.static(N)
            j = i - env * wp.static(N)
            r = row0 + j
            qi, di, q, qd, lim, sat, vl = read_row(io, wp.static(L.q_lin), wp.static(L.qd_lin), env, r, j,
                                                     joint_q_in, joint_qd_in)  # fmt: skip
            # the target from the mode's table: what the substep threads write to joint_target_q in this launch
            err = substep_arrays.target_qpos_in[env, r] - q
            row(i, env, r, di, err, qd, lim, sat, vl, io, hist_out, joint_f_out)
        else:
            substep(i - num_envs * wp.static(N), substep_arrays, joint_q_in, joint_qd_in, joint_target_q_out,
                    joint_target_qd_out, joint_f_out)  # fmt: skip

    fused.__annotations__["hist_out"] = wp.array[vec_p]  # (the body does not name vec_p: no closure variable)
    return net_kernel(fused, "wpctrl_substep_actuator_net")
