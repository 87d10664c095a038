"""How the tasks' contacts, friction and joint limits are set up on MuJoCo-Warp so that they behave as ManiSkill's
PhysX scene does (host only).

PhysX (ManiSkill 3.0.1: TGS, 15 position iterations, rigid contacts with zero rest offset, hard articulation joint
limits, each pair's friction the *average* of its two materials) and MuJoCo (soft constraints, each pair's friction the
*larger* of its two geoms') differ where a task touches them. What :class:`TaskPhysics` sets, and why:

- **Integrator** ``"discrete"``: MuJoCo-Warp's discrete step map solves the constraints for the end of the step, so a
  contact that appears within one step is resolved without the spring overshoot of the continuous reference
  acceleration: with ``implicitfast`` a cube struck by the closed fingers at 0.7 m/s leaves them at 1.2 m/s (an
  elastic-looking bounce) and slides ~10 cm further than on PhysX.
- **Friction cone** elliptic with ``impratio`` 10: a grasp holds as PhysX's does (pyramidal cones with impratio 1
  let a lifted cube creep out of the fingers).
- **Friction**: MuJoCo takes the larger of the two coefficients, PhysX their average. With the scene's two materials
  (default 0.3, the Panda's finger pads 2.0) giving the finger shapes the average (1.15) reproduces every pair:
  finger-cube and finger-table 1.15, everything else 0.3. :func:`mujoco_friction` computes it.
- **Contact softness**: ``contact_solref`` / ``contact_solimp`` on every shape of the scene; MuJoCo's defaults.
- **Joint limits**: Newton imports URDF limits as force-space gains (ke 1e4, kd 10) that MuJoCo turns into time
  constants of 0.1-2.5 s with a damping ratio near 0.01: a driven Panda then overshoots joint 4's limit by tenths of a
  radian. PhysX's limits are hard; ``limit_solref`` (raw MuJoCo ``solreflimit``, default (0.02, 1), a critically
  damped limit) and ``limit_solimp`` hold them to a few milliradians.
- **Substeps**: MuJoCo steps per 100 Hz physics step (ManiSkill's ``sim_freq``); 1 is ManiSkill's own step and the
  cheapest.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..config import ConfigError

__all__ = ["TaskPhysics", "mujoco_friction"]

_INTEGRATORS = ("discrete", "implicitfast", "implicit", "euler")
_CONES = ("elliptic", "pyramidal")


@dataclass(frozen=True)
class TaskPhysics:
    """MuJoCo-Warp settings of a task's scene (see the module docstring for what each one reproduces)."""

    substeps: int = 4
    """MuJoCo-Warp steps per physics step (the physics step is ManiSkill's 1 / ``sim_freq`` = 10 ms)."""
    integrator: str = "implicitfast"
    cone: str = "elliptic"
    impratio: float = 10.0
    iterations: int = 100
    """MuJoCo's constraint solver iterations (its default)."""
    ls_iterations: int = 50
    contact_solref: tuple[float, float] = (0.005, 1.0)
    """MuJoCo ``solref`` of every contact: (time constant [s], damping ratio)."""
    contact_solimp: tuple[float, float, float] = (0.99, 0.999, 0.001)
    """MuJoCo ``solimp`` (dmin, dmax, width [m]) of every contact."""
    limit_solref: tuple[float, float] = (0.02, 1.0)
    """MuJoCo ``solreflimit`` of every robot joint limit: (time constant [s], damping ratio)."""
    limit_solimp: tuple[float, float, float] = (0.95, 0.99, 0.001)
    friction_combine: str = "average"
    """``"average"`` (PhysX's rule, reproduced per shape: :func:`mujoco_friction`) or ``"max"`` (MuJoCo's own, the
    materials' coefficients unchanged)."""

    def __post_init__(self):
        _int_at_least(self, "substeps", 1)
        _int_at_least(self, "iterations", 1)
        _int_at_least(self, "ls_iterations", 1)
        _one_of(self, "integrator", _INTEGRATORS)
        _one_of(self, "cone", _CONES)
        _one_of(self, "friction_combine", ("average", "max"))
        if isinstance(self.impratio, bool) or not isinstance(self.impratio, (int, float)) or not self.impratio >= 1.0:
            raise ConfigError(f"TaskPhysics.impratio: expected a number >= 1, got {self.impratio!r}")
        for name in ("contact_solref", "limit_solref"):
            v = getattr(self, name)
            if not _numbers(v, 2) or not (v[0] > 0.0 and v[1] > 0.0):
                raise ConfigError(f"TaskPhysics.{name}: expected (time constant > 0 [s], damping ratio > 0), got {v!r}")
        for name in ("contact_solimp", "limit_solimp"):
            v = getattr(self, name)
            if not _numbers(v, 3) or not (0.0 < v[0] <= v[1] < 1.0 and v[2] > 0.0):
                raise ConfigError(f"TaskPhysics.{name}: expected (dmin, dmax, width) with 0 < dmin <= dmax < 1 and "
                                  f"width > 0 [m], got {v!r}")  # fmt: skip

    def solver_kwargs(self) -> dict:
        """``newton.solvers.SolverMuJoCo`` keywords for these settings."""
        return dict(
            integrator=self.integrator,
            cone=self.cone,
            impratio=float(self.impratio),
            iterations=int(self.iterations),
            ls_iterations=int(self.ls_iterations),
        )

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def mujoco_friction(materials: dict[str, float], rule: str = "average") -> dict[str, float]:
    """Per-material MuJoCo coefficients whose pairwise maximum equals PhysX's pairwise average.

    ``materials`` maps a material name to its PhysX static friction. With at most two distinct coefficients
    ``lo < hi`` (the tasks' scene: 0.3 and the fingers' 2.0), every shape of ``hi`` gets ``(lo + hi) / 2`` and MuJoCo's
    max rule then gives ``(lo + hi) / 2`` for a lo-hi pair and ``lo`` for a lo-lo pair, as PhysX's average does (a
    hi-hi pair gets ``(lo + hi) / 2`` instead of ``hi``: no such pair exists in the scene). ``rule="max"`` returns the
    coefficients unchanged.
    """
    if rule == "max":
        return dict(materials)
    values = sorted(set(materials.values()))
    if len(values) > 2:
        raise ConfigError(
            f"mujoco_friction: PhysX's average rule is reproduced for at most two distinct coefficients, got {values}"
        )
    if len(values) < 2:
        return dict(materials)
    lo, hi = values
    return {name: (0.5 * (lo + hi) if mu == hi else mu) for name, mu in materials.items()}


def _numbers(v, n: int) -> bool:
    return (
        isinstance(v, (tuple, list))
        and len(v) == n
        and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
    )


def _int_at_least(obj, name: str, low: int) -> None:
    v = getattr(obj, name)
    if isinstance(v, bool) or not isinstance(v, int) or v < low:
        raise ConfigError(f"TaskPhysics.{name}: expected an integer >= {low}, got {v!r}")


def _one_of(obj, name: str, allowed: tuple[str, ...]) -> None:
    v = getattr(obj, name)
    if v not in allowed:
        raise ConfigError(f"TaskPhysics.{name}: expected one of {allowed}, got {v!r}")
