"""Command delay: per-env latency d in [min, max] substeps, a ring of the last ``max + 1`` commands.

The drive targets (implicit: ``Control.joint_target_q/qd``; explicit: the PD law's targets, with the current measured
state) are those of d substeps ago. A reset draws d for the reset envs (device RNG) and fills their history with the
reset pose. The substep kernel compiled with the delay pushes this substep's command and pops the delayed one.
"""

from __future__ import annotations

import warp as wp

from ...config.rows import FLAG_VEL_TARGET, ROW_POS
from ...kernels.env_selection import _bump_counter_kernel
from .part import Part


class Delay(Part):
    name = "delay"
    OPTIONAL_ARGS = ("delay", "delay_head", "delay_q", "delay_qd")

    @staticmethod
    def wanted(plan) -> bool:
        return plan.options.delay is not None

    def __init__(self, plan, alloc):
        lo, hi = plan.delay_range
        rows = plan.rows
        self.range = (int(lo), int(hi))
        self.delay = wp.full(plan.num_envs, int(lo), dtype=wp.int32, device=alloc.device)
        self.delay_head = alloc.per_env(plan.num_rows, wp.int32)
        self.delay_q = alloc.ring(hi + 1, plan.num_rows)
        vel_rows = (rows.kind != ROW_POS) | ((rows.flags & FLAG_VEL_TARGET) != 0)
        # Velocity targets are 0 on plain position rows: no history needed then.
        self.delay_qd = alloc.ring(hi + 1, plan.num_rows) if vel_rows.any() else None

    def kernel_args(self) -> dict:
        return {
            "delay": self.delay,
            "delay_head": self.delay_head,
            "delay_q": self.delay_q,
            "delay_qd": self.delay_qd,
            "max_delay": self.range[1],
            "delay_min": self.range[0],
            "delay_max": self.range[1],
        }

    def after_reset(self, engine, state, env_ids, env_mask) -> None:
        if self.range[1] > self.range[0]:  # the reset drew delays: the next draw uses the next counter value
            wp.launch(_bump_counter_kernel, dim=1, inputs=[engine.core.rng_counter], device=engine.device)
