"""The mutation list as data: one module per area of the code, each a ``MUTATIONS`` list of :class:`Mutation`.

A new area is a module here and one name in ``AREAS``; a mutation keeps its name and its killing test.
"""

from __future__ import annotations

import importlib

from .model import M, Mutation

AREAS = (
    "response",
    "coupled_drive",
    "arm_drive",
    "set_action",
    "substep",
    "reset",
    "randomness",
    "impedance",
    "ee",
    "actuator_models",
    "actuator_networks",
    "later_controllers",
    "construction",
    "train_reach",
    "train_tasks",
    "distributed",
    "robots",
    "tasks",
    "impedance_envs",
    "second_controller",
    "first_hour",
    "task_envs",
    "lift_peg_upright",
    "stack_cube",
    "pull_cube",
    "layout",
    "peg_insertion_side",
    "finger_contacts",
    "replay_input",
    "task_randomization",
    "place_sphere",
)
"""The areas, in the order the runner takes them."""


def all_mutations() -> list[Mutation]:
    out: list[Mutation] = []
    for area in AREAS:
        out += importlib.import_module(f"{__name__}.{area}").MUTATIONS
    names = [m.name for m in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"mutation names must be unique; repeated: {dup}")
    return out


__all__ = ["AREAS", "M", "Mutation", "all_mutations"]
