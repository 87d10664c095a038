"""The base class of an engine part: what a part provides and the stages it may hook (each hook does nothing here).

See :mod:`wpctrl.engine.parts` for how the engine uses the parts.
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
