"""Effort readout: the PD law before and after the force-limit clamp, and a per-row saturation count, written every
substep [N·m or N] (explicit: the torque itself; implicit: the same law on the substep's start state, an estimate of
what the solver's implicit drive applies). A reset zeroes the reset envs' rows."""

from __future__ import annotations

import warp as wp

from .part import Part


class EffortReadout(Part):
    name = "effort_readout"
    OPTIONAL_ARGS = ("computed_effort", "applied_effort", "saturation_count")

    @staticmethod
    def wanted(plan) -> bool:
        return plan.track_effort

    def __init__(self, plan, alloc):
        R = plan.num_rows
        self.computed_effort = alloc.per_env(R)
        self.applied_effort = alloc.per_env(R)
        self.saturation_count = alloc.per_env(R, wp.int32)

    def kernel_args(self) -> dict:
        return {
            "computed_effort": self.computed_effort,
            "applied_effort": self.applied_effort,
            "saturation_count": self.saturation_count,
        }
