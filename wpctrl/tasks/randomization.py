"""Per-env physics drawn at every reset, for policies that must not lean on one simulator's exact contacts.

A policy trained on one set of contact parameters can come to rely on them: how far a fingertip sinks, how fast a
pushed cube slides, how heavy the cube is. :class:`TaskRandomization` (``make(..., randomization=...)``; off by
default) gives every env, at each of its resets, its own scale factors drawn uniformly from the given ranges:

- ``friction``: every contact of the env has its sliding friction times the factor (MuJoCo takes a pair's larger
  coefficient, so scaling every shape's scales every pair's);
- ``contact_time``: every contact of the env has its ``solref`` time constant times the factor: larger is softer
  (MuJoCo mixes a pair's two time constants, so scaling both scales the mix; a resting contact sinks as the square of
  it);
- ``mass``: the task's free objects (the cube, the peg, ...) have their mass and inertia times the factor.

The factors are written into MuJoCo-Warp's per-world model arrays by one kernel (:mod:`.randomizer`) inside the
env's reset, so the auto reset of a captured step draws them too (no host work); each env draws from its own episode
seed and episode count, as its initial state does. ``TaskEnv.randomization_factors`` holds the factors of the
running episodes. They act on the solver's model only (Newton's ``Model`` keeps its values). The mass factor also
scales what MuJoCo derived from the objects' mass (their inverse weights, used to soften their contacts, and the
subtree masses): exact for a free body without children, as every task's objects are, and the same values Newton's
``notify_model_changed`` computes (``tests/test_task_randomization.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..config import ConfigError

__all__ = ["TRAINING_RANGES", "TaskRandomization"]


@dataclass(frozen=True)
class TaskRandomization:
    """Ranges ``(low, high)`` of the scale factors each env draws at every reset (None: that quantity is left as
    is). See the module docstring for what each one scales."""

    friction: tuple[float, float] | None = None
    contact_time: tuple[float, float] | None = None
    mass: tuple[float, float] | None = None

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None:
                continue
            numbers = all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
            ok = isinstance(v, (tuple, list)) and len(v) == 2 and numbers
            if not ok or not 0.0 < v[0] <= v[1]:
                raise ConfigError(f"TaskRandomization.{f.name}: expected a range (low, high) of scale factors with "
                                  f"0 < low <= high, got {v!r}")  # fmt: skip

    def ranges(self) -> np.ndarray:
        """(3, 2): friction, contact time, mass; (1, 1) where not drawn."""
        return np.array([getattr(self, f.name) or (1.0, 1.0) for f in fields(self)], np.float32)

    def contact_time_problem(self, shortest: float, dt: float) -> str | None:
        """Why ``contact_time`` cannot be drawn in a scene whose shortest contact time constant is ``shortest`` [s]
        with MuJoCo steps of ``dt`` [s] (MuJoCo raises a time constant under two steps to two steps, so a factor that
        takes one there would not act as drawn), or None."""
        low = 2.0 * dt / shortest
        if self.contact_time is None or self.contact_time[0] >= low * (1.0 - 1e-6):
            return None
        return (f"TaskRandomization.contact_time: expected low >= {low:.3g} (MuJoCo raises a time constant under two "
                f"of its steps, {2e3 * dt:.3g} ms, to two steps, so a shorter one would not be drawn; the scene's "
                f"shortest is {shortest * 1e3:.3g} ms), got {self.contact_time!r}")  # fmt: skip


TRAINING_RANGES = {"friction": (0.7, 1.3), "contact_time": (1.0, 2.0), "mass": (0.5, 1.5)}
"""``from_spec("on")``'s ranges: friction within 30 %, contacts up to twice as soft (a time constant under the scene's
would be raised to two solver steps at 8 substeps), the objects' mass within 50 %."""


def from_spec(spec: str) -> TaskRandomization | None:
    """``"off"`` (None), ``"on"`` (:data:`TRAINING_RANGES`) or ``"name=low:high,..."`` with the names of
    :class:`TaskRandomization`'s fields (``"friction=0.5:1.5,mass=0.8:1.2"``): the command line's form."""
    if spec == "off":
        return None
    if spec == "on":
        return TaskRandomization(**TRAINING_RANGES)
    names = [f.name for f in fields(TaskRandomization)]
    ranges = {}
    for item in spec.split(","):
        name, _, value = item.partition("=")
        low, _, high = value.partition(":")
        if name.strip() not in names:
            raise ConfigError(f"randomize: expected 'off', 'on' or name=low:high,... with names {names}, got "
                              f"{item!r} in {spec!r}")  # fmt: skip
        try:
            ranges[name.strip()] = (float(low), float(high))
        except ValueError:
            raise ConfigError(f"randomize: {name.strip()}: expected low:high (two numbers), got {value!r}") from None
    return TaskRandomization(**ranges)
