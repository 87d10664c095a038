"""The parts of a control mode's engine: each option is one part.

A part owns its device arrays (allocated once from the plan), names the kernel arguments it provides
(:meth:`Part.kernel_args`; looked up by parameter name, see :mod:`wpctrl.engine.state`), contributes its compile-time
pieces through the plan's step layout, and hooks into the stages it takes part in (:meth:`Part.build`,
:meth:`Part.before_set_action`, :meth:`Part.before_substep`, :meth:`Part.after_substep`, :meth:`Part.after_reset`).
The engine calls the hooks of its active parts in plan order; a part that is off costs nothing (no array, no launch,
and the kernel variant compiled without it).

The parts of the options are listed here; a controller family's part (e.g. :mod:`wpctrl.impedance.engine_part`)
lives with its family and registers itself with :func:`register_part` when its module is imported, which
``build_controller`` does for a mode that uses the family (the config's ``family.part`` names the module).
"""

from __future__ import annotations

from .actuator_models import ActuatorModels
from .coupled_drive import CoupledDrive
from .delay import Delay
from .drive_properties import DriveProperties
from .ee import EndEffectors
from .effort_command import EffortCommand
from .effort_readout import EffortReadout
from .gravity import BalancePassiveForce
from .part import Part
from .response import JointSpaceResponse

PARTS: dict[str, type[Part]] = {
    cls.name: cls
    for cls in (
        DriveProperties,
        JointSpaceResponse,
        CoupledDrive,
        EffortCommand,
        ActuatorModels,
        Delay,
        EffortReadout,
        EndEffectors,
        BalancePassiveForce,
    )
}
"""The part classes by name, in the order the engine runs their hooks (a registered part after these). A new option
is a new part: its module, and one entry here."""


def register_part(cls: type[Part]) -> type[Part]:
    """Add a controller family's part to :data:`PARTS` (after the parts already there); registering the same class
    again does nothing, another class under a taken name is refused."""
    known = PARTS.get(cls.name)
    if known is not None and known is not cls:
        raise ValueError(f"engine part {cls.name!r}: already registered as {known.__module__}.{known.__qualname__}")
    PARTS[cls.name] = cls
    return cls


def part_classes() -> dict[str, type[Part]]:
    """:data:`PARTS` (the part classes by name, in hook order)."""
    return PARTS
