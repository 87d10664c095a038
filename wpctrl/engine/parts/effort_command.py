"""Commanded efforts (JointEffortController's rows) as an engine part.

:class:`EffortCommand` holds the ``(num_envs, rows)`` commanded effort of effort rows, written by ``set_action``,
read by the substep kernel (delayed like any target when a delay is on), zeroed by a reset.
"""

from __future__ import annotations

from .part import Part


class EffortCommand(Part):
    name = "effort_command"
    OPTIONAL_ARGS = ("target_effort",)

    @staticmethod
    def wanted(plan) -> bool:
        return plan.has_effort_rows

    def __init__(self, plan, alloc):
        self.target_effort = alloc.per_env(plan.num_rows)

    def kernel_args(self) -> dict:
        return {"target_effort": self.target_effort}
