"""The per-step PD kernels (``set_action`` and the solver substep), specialised at compile time on the row layout.

Private module. One thread per env runs every row of the control mode, with the rows unrolled: a row's kind, flags,
action columns, mimic source, acceleration-drive flag and (for replicated worlds) its coordinate / DOF index in env 0
are compile-time constants of the kernel (:class:`StepLayout`, ``wp.static``). So a thread issues all its loads at
once (its action row, then the measured coordinates of every row, no chain of table loads), checks its action row for
NaN/Inf once, keeps a mimic source's fresh target in a register for its followers, and runs no branch on row tables.
What stays a runtime array: the per-row float bounds ``row_f`` (one ``(rows, 9)`` table read uniformly by every
thread, so configs that differ only in bounds share a kernel), the per-env drive properties and Newton's arrays.
A control mode compiles its two kernels once (Warp's kernel cache keeps them across runs); modes with the same layout
share them.

Every kernel body is written as: all loads, then the arithmetic, then the stores grouped by array. The compiler may not
move a load above a store to another array that might alias it, so interleaving them row by row would cost a memory
round trip per row (and, at 1M envs, re-fetch the sectors evicted in between). The controller's own
``(num_envs, rows)`` arrays are column-major views (``_Engine``'s ``per_env``), so a warp's access of one row is 32
consecutive values; Newton's per-world arrays are read and written where they are.

Row float table ``row_f[r]``: ``lo, hi`` (action bounds of the row's position / velocity column), ``vlo, vhi`` (the
velocity column of a position-velocity row), ``mimic_mul, mimic_off`` (a follower's coupling), ``qlo, qhi`` (joint
limits [rad or m], for ``clip_targets`` and EMA), ``alpha`` (the EMA weight).

Semantics are those of ManiSkill's controllers (:mod:`wpctrl.kernels.pd` states the state arrays' meaning):

- ``set_action``: an env whose action holds NaN/Inf is left untouched and counted; its substep counter keeps counting
  (``host_substeps`` carries the substeps the host counted for an elided substep launch). Otherwise every position
  row snapshots the measured coordinate (``start_qpos``) and computes its target (normalise, clip, absolute / delta
  from the measured coordinate / delta on the previous target, optional clamp to the joint limits); a follower takes
  ``target[source] * mul + off``; velocity columns set the velocity targets. Without per-substep work the kernel also
  writes the drive targets into the Control (``joint_target_q_out`` / ``joint_target_qd_out`` given).
- ``substep``: bumps the env's substep counter ``k`` (ManiSkill's ``_step``), interpolates ``start + k (target -
  start) / K`` (held at K) on interpolating rows, pushes / pops the command delay ring, writes the drive targets and,
  for explicit actuation, the clamped PD torque (naive, or stable: on the end-of-step state of a semi-implicit step).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .pd_set_action import _make_set_action_kernel
from .pd_substep import _make_substep_kernel
from .step_layout import ROW_F_QHI, ROW_F_QLO, StepLayout, row_float_table  # noqa: F401  (what the engine uses)

_SET_ACTION: dict[StepLayout, wp.Kernel] = {}
_SUBSTEP: dict[tuple, wp.Kernel] = {}


def set_action_kernel(layout: StepLayout) -> wp.Kernel:
    """The set_action kernel of ``layout`` (compiled once per layout and process; Warp caches it on disk);
    substep-only fields of the layout are ignored."""
    key = layout._replace(act_model=(), limit_table=())
    k = _SET_ACTION.get(key)
    if k is None:
        k = _SET_ACTION[key] = _make_set_action_kernel(key)
    return k


def substep_kernel(layout: StepLayout, net: tuple | None = None) -> wp.Kernel:
    """The substep kernel of ``layout``; set_action-only fields of the layout are ignored. ``net`` =
    ``(NetLayout, weights, scales)``: the kernel that also runs that network's rows in its launch
    (:mod:`.actuator_net_fused`)."""
    key = layout._replace(
        act_col=(), vel_col=(), mimic_src=(), action_dim=0, clip=False, yaw_row=(), base_axis=(), bx_col=(), by_col=()
    )
    if net is not None:
        weights = np.ascontiguousarray(net[1], dtype=np.float32)
        net = (net[0], weights, tuple(float(np.float32(x)) for x in net[2]))
    cache_key = (key, None if net is None else (net[0], net[1].tobytes(), net[2]))
    k = _SUBSTEP.get(cache_key)
    if k is None:
        k = _SUBSTEP[cache_key] = _make_substep_kernel(key, net)
    return k
