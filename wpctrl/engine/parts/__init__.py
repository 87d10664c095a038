"""The parts of a control mode's engine: each option is one part.

A part owns its device arrays (allocated once from the plan), names the kernel arguments it provides
(:meth:`Part.kernel_args`; looked up by parameter name, see :mod:`wpctrl.engine.state`), contributes its compile-time
pieces through the plan's step layout, and hooks into the stages it takes part in (:meth:`Part.build`,
:meth:`Part.before_set_action`, :meth:`Part.before_substep`, :meth:`Part.after_substep`, :meth:`Part.after_reset`).
The engine calls the hooks of its active parts in plan order; a part that is off costs nothing (no array, no launch,
and the kernel variant compiled without it).
"""

from __future__ import annotations


class Part:
    """Base class: every hook does nothing."""

    name = "part"
    OPTIONAL_ARGS: tuple[str, ...] = ()
    """Kernel argument names this part provides; ``None`` in the kernels of a mode without it."""

    @staticmethod
    def wanted(plan) -> bool:
        """Whether a mode with this plan needs the part (host only: read the plan's rows and options)."""
        return False

    def kernel_args(self) -> dict:
        return {}

    def build(self, engine, model, solver) -> None:
        """After every part is allocated: model writes, first device work."""

    def before_set_action(self, engine, action, state) -> None:
        """Before the joint set_action launch."""

    def before_substep(self, engine, state, control) -> None:
        """Before the substep launch (only with per-substep work)."""

    def after_substep(self, engine, state, control) -> None:
        """After the substep launch."""

    def after_reset(self, engine, state, env_ids, env_mask) -> None:
        """After the reset launch."""


def part_classes() -> dict[str, type[Part]]:
    """The part classes by name, in the order the engine runs their hooks. A new option is a new part: its module,
    and one entry here."""
    from .actuators import ActuatorModels, EffortCommand
    from .delay import Delay
    from .drive import DriveProperties
    from .ee import EndEffectors
    from .effort import EffortReadout
    from .gravity import BalancePassiveForce
    from .impedance import Impedance
    from .response import CoupledDrive, JointSpaceResponse

    return {
        "drive": DriveProperties,
        "response": JointSpaceResponse,
        "coupled": CoupledDrive,
        "effort_command": EffortCommand,
        "actuators": ActuatorModels,
        "delay": Delay,
        "effort": EffortReadout,
        "ee": EndEffectors,
        "impedance": Impedance,
        "gravity": BalancePassiveForce,
    }
