"""The device engine of one control mode: plan → state → launches, each option a part.

:mod:`.plan` (the host-only plan: rows, index tables, options, active parts, the step kernels' layout), :mod:`.state`
(the device arrays every mode has, allocation, lookup of kernel arguments by name), :mod:`.parts` (one module per
option: drive properties, joint-space response, the coupled drive, delay, effort readout and commands, actuator models,
end effectors, gravity compensation), :mod:`.core` (:class:`_Engine`: runs the stages), :mod:`.launch` (recorded
launches).
"""

from .core import _Engine
from .plan import Options, Plan, make_plan

__all__ = ["Options", "Plan", "_Engine", "make_plan"]
