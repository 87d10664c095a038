"""The substep kernel and an actuator network's kernel as one launch. Private module.

A mode with an actuator network normally runs two launches per substep: the substep kernel (one thread per env: the
targets, the PD rows, the other actuator models) and then the network's (one thread per network row, reading the
target the substep kernel wrote to ``joint_target_q``). At a few thousand robots both launches are short and each
costs its own place in the graph. The fused kernel runs both in one grid of ``num_envs * n + num_envs`` threads:
threads ``[0, num_envs * n)`` are the network's rows (:func:`.actuator_net_unrolled.unrolled_row`, the same code as
the unrolled kernel) and the ``num_envs`` threads after them the substep kernel's env threads: it is the substep
kernel itself, generated with the network's rows in it (:func:`.pd_step.substep_kernel` with ``net``), so both
launches have one signature and one body. (On the CPU the threads run in order, the network's first: a network
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
from . import pd_step
from .actuator_net import NetLayout
from .step_layout import StepLayout

wp.set_module_options({"enable_backward": False})

BLOCK_DIM = 64
"""CUDA threads per block (as the unrolled network kernel)."""


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
    """The substep kernel of ``step`` with the unrolled kernel of ``layout`` / ``weights`` / ``scales`` in it (the
    substep kernel's parameters, whose ``row0``, ``io`` and ``hist_out`` are then the network's). Launched over
    ``num_envs * (1 + layout.rows)`` threads with ``block_dim = BLOCK_DIM``."""
    return pd_step.substep_kernel(step, net=(layout, weights, scales))
