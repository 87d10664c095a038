"""Controller families: what every controller config declares once, so that a control mode is built from the
declarations alone.

A config class names its controller class (``controller_cls``, as ManiSkill's configs do) and its :class:`Family`:
the function that validates a config and turns it into joint rows (plus, for a family with launches of its own, the
spec its engine part reads) and the module of that engine part. ``build_controller`` reads nothing else: it asks each
config's family for its rows, imports the family's part module (which registers the part with the engine) and wraps
the engine in the config's controller class. Adding a controller family is one config class with these two
declarations, its part, its kernels and its controller class (docs/architecture.md, "Adding a controller family").

Host only; this module imports nothing of the package but :mod:`.errors`, so every config module can use it.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


class ControllerClass:
    """``Config.controller_cls`` of wpctrl's configs: the controller class, named by its module and class and imported
    on first read. So it is the class itself right after ``import wpctrl`` (the controllers import Newton and load
    lazily), and the config layer imports nothing of the controller layer. A subclass that assigns its own
    ``controller_cls`` (as ManiSkill's configs do) replaces it."""

    def __init__(self, module: str, name: str):
        self.module, self.name = module, name

    def __get__(self, obj, owner=None):
        return getattr(importlib.import_module(self.module), self.name)

    def __repr__(self) -> str:
        return f"ControllerClass({self.module}.{self.name})"


@dataclass(frozen=True)
class Family:
    """How the configs of one controller family become a running controller.

    ``rows(config, qlimits)`` validates a config and returns its rows (a :class:`~wpctrl.config.rows.Rows`), or,
    for a family with an engine part, ``(rows, spec)``: the spec is the validated, device-independent parameters that
    the part reads from the plan. ``qlimits`` is the (n, 2) joint limits [rad or m] of ``config.joint_names``.
    ``part`` is the module of that engine part, named (not imported: the config layer never imports the engine);
    the controller layer imports it before it plans the mode, and the module registers its part on import
    (:func:`wpctrl.engine.parts.register_part`).
    """

    rows: Callable[[Any, Any], Any]
    part: str | None = None

    def make(self, config, qlimits) -> tuple[Any, Any]:
        """``(rows, spec)`` of ``config``, validated; the spec is None for a family without a part."""
        if self.part is None:
            return self.rows(config, qlimits), None
        return self.rows(config, qlimits)

    def load_part(self) -> None:
        """Import the family's part module, so that its part is registered with the engine (no-op without one)."""
        if self.part is not None:
            importlib.import_module(self.part)


@dataclass
class ControllerConfig:
    joint_names: list[str]
    """Names of the joints this controller drives, matched against the Newton model's joint labels."""

    # Class variables (not dataclass fields): the controller class this config builds (as in ManiSkill) and the
    # family that turns the config into rows and names the engine part that runs it.
    controller_cls = None
    family = None  # a Family
