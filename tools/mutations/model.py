"""One mutation: an exact text replacement in one file of ``wpctrl/`` and the tests expected to notice it."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Mutation:
    name: str
    file: str
    old: str
    new: str
    what: str
    tests: tuple[str, ...] = ()
    """Tests run first (the ones expected to kill it); the rest of FAST_TESTS follows."""


M = Mutation
