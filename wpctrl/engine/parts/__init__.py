"""The parts of a control mode's engine: each option is one part.

A part owns its device arrays (allocated once from the plan), names the kernel arguments it provides
(:meth:`Part.kernel_args`; looked up by parameter name, see :mod:`wpctrl.engine.state`), contributes its compile-time
pieces through the plan's step layout, and hooks into the stages it takes part in (:meth:`Part.build`,
:meth:`Part.before_set_action`, :meth:`Part.before_substep`, :meth:`Part.after_substep`, :meth:`Part.after_reset`).
The engine calls the hooks of its active parts in plan order; a part that is off costs nothing (no array, no launch,
and the kernel variant compiled without it).
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
from .impedance import Impedance
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
        Impedance,
        BalancePassiveForce,
    )
}
"""The part classes by name, in the order the engine runs their hooks. A new option is a new part: its module, and
one entry here."""


def part_classes() -> dict[str, type[Part]]:
    """:data:`PARTS` (the part classes by name, in hook order)."""
    return PARTS
