"""How the tasks' contacts, friction, joint limits and drives are set up on MuJoCo-Warp so that they behave as
ManiSkill's PhysX scene does (host only).

PhysX (ManiSkill 3.0.1: TGS with 15 position iterations per 10 ms step, rigid contacts with zero rest offset, hard
articulation joint limits, implicit drives clamped at their force limit, each pair's friction the *average* of its
two materials) and MuJoCo (soft constraints, implicit damping, each pair's friction the *larger* of its two geoms')
differ where a task touches them. What :class:`TaskPhysics` sets, and why:

- **The arm's drive** (``arm_drive``): PhysX's TGS solver does not converge the arm's joint drives in its 15
  position iterations; a fast move of the Panda's coupled shoulder joints falls a quarter short of the rigid-body
  answer that MuJoCo's own drive gives. The default runs PhysX's pass itself before every MuJoCo step
  (:mod:`wpctrl.tasks.arm_drive`): the arm within 0.5-1.8 mrad of PhysX's over a policy's first five steps instead
  of 8-17, and a learned policy's ManiSkill episodes replay to their outcome 15 / 16 times instead of 13 / 16.
- **Substeps**: 16 MuJoCo steps of 0.625 ms per 100 Hz physics step, as PhysX's TGS integrates in 15
  sub-iterations. MuJoCo clamps a saturated drive's force but keeps its damping implicit (``dt * kd`` in the mass
  matrix), so a saturated arm joint moves as if damped harder than on PhysX, by an amount that grows with the step: at
  one 10 ms step the Panda's TCP lags and sags by 1-1.5 cm in a fast ``pd_ee_delta_pos`` push, and a pushed cube
  ends up centimetres off. The controller still runs at ManiSkill's rates (100 Hz drive targets, 20 Hz actions).
- **Contacts**: ``contact_solref`` (5 ms, critically damped) and ``contact_solimp`` (0.99-0.999) make contacts
  nearly rigid: with MuJoCo's defaults (20 ms, 0.9-0.95) the gripper's 30 N squeeze pushes the fingers centimetres
  into the 64 g cube and the grasp fails. Its price: a closed grasp never comes to rest. Fingers and held object
  chatter (the finger joints swing over 1.7-3.3 mm while the hand holds a cube still; PhysX's move 0.01 mm), and under
  PickCube's full-speed moves the cube slides 5-10 mm in the fingers (PhysX 0.3-0.9 mm); a carried peg walks out of
  them. Two MuJoCo steps (1.25 ms) stop most of it (0.5 mm, the cube 1.4-3.8 mm but one of six 12.5 mm) and replay
  grasps closer (PickCube's public episodes 0.49 -> 0.34 cm, StackCube's demos 0.45 -> 0.05 cm), but a cube struck by
  the fingers then leaves them otherwise than PhysX's: PushCube's ``pd_ee_delta_pos`` replays land 1.2 -> 5.5 cm off
  (32 fresh episodes: 1.2 -> 4.7 cm), so 5 ms stays (``docs/tasks.md``; measured with stiff finger contacts).
  PlaceSphere's physics halves the time constant and doubles the damping ratio (the same stiffness, twice the
  damping), so that a ball landing in its bin rests as PhysX's does (restitution 0) instead of rolling off, and gives
  the bin's walls contacts of 30 ms (``shape_solref``): PhysX takes a ball's impact on a wall's edge within one 10 ms
  step and the ball stops there, where MuJoCo's short steps let it pivot on the edge and roll back.
- **Finger contacts** (``finger_solimp``, impedance 0.7 on the finger shapes, 0.85 once MuJoCo mixes it with the
  other shape's): under load PhysX's fingertips sink into what they press, about 0.03 mm per newton (15 position
  iterations leave that overlap between a driven link and a light body), where the other shapes' impedance let a
  fingertip sink 0.15-0.3 mm at 36 N. With it a fingertip pressed on the cube's face, edge or corner sits within
  0.35 mm of PhysX's depth at every force (``tests/test_contact_probes.py``); a learned PushCube policy's fingertip on
  the cube's corner then sinks in as on PhysX, and its ManiSkill episodes replay to their outcome 9 / 10 times
  instead of 6 / 10; LiftPegUpright's peg turns in the fingers (0.43 N·m held, PhysX 0.33) and its demos replay.
  MuJoCo's regularised friction still lets a loaded fingertip creep across the cube's top where PhysX's sticks and
  then slides off the corner.
- **Friction cone** elliptic with ``impratio`` 10: a lifted cube stays in the fingers as on PhysX, and sliding friction
  is the same in every direction, as PhysX's patch friction is (SAPIEN sets no other friction type): a cube launched
  at 0.5 m/s slides 4.2 cm whichever way (PhysX 4.0 cm). MuJoCo's pyramidal cone is weaker off its axes (4.2 cm along
  them, 6.0 cm at 45 degrees; a 22.5-degree launch veers to 35) and doubles a pushed cube's replay error. The
  elliptic cone's price: a peg twisted in half-closed fingers is held harder than on PhysX (0.43 N·m with the soft
  finger contacts, 0.56 with stiff ones, PhysX 0.33; ``docs/tasks.md``).
- **Finger torsion** (``finger_torsion``, off by default): PhysX's patch friction on the fingers (ManiSkill's
  ``patch_radius`` 0.1 m) also resists a twist about the contact normal, which MuJoCo's condim-3 contacts do not;
  ``finger_torsion`` > 0 gives the finger shapes condim 4 and that torsional coefficient. PegInsertionSide's demos need
  it, and its task's physics has it (0.2 m: 3 / 4 insert, the peg within 0.3 cm of PhysX's, 0 / 4 with these
  defaults); LiftPegUpright's need the peg to turn in the fingers and replay further off with it.
- **Friction**: PhysX averages, MuJoCo takes the larger coefficient. With the scene's two materials (default 0.3,
  the Panda's finger pads 2.0), giving the finger shapes the average (1.15) reproduces every pair: finger-cube and
  finger-table 1.15, everything else 0.3 (:func:`mujoco_friction`).
- **Joint limits**: Newton imports URDF limits as force-space gains (ke 1e4, kd 10) that MuJoCo turns into time
  constants of 0.1-2.5 s with a damping ratio near 0.01: a saturated drive carries joint 4 0.24 rad past its limit.
  ``limit_solref`` (raw MuJoCo ``solreflimit``: two MuJoCo steps, critically damped, the stiffest MuJoCo integrates)
  and ``limit_solimp`` hold it to hundredths of a milliradian, as PhysX's hard limits do.

``docs/tasks.md`` has the replay results of these settings and of the alternatives tried.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

from ..config import ConfigError

__all__ = ["TaskPhysics", "mujoco_friction", "physics_fields", "physics_from"]

_INTEGRATORS = ("discrete", "implicitfast", "implicit", "euler")
_CONES = ("elliptic", "pyramidal")
ARM_DRIVES = ("physx_tgs", "mujoco")
"""``TaskPhysics.arm_drive``'s values: PhysX's TGS pass (:mod:`wpctrl.tasks.arm_drive`) or MuJoCo's own drive."""
_MIN_TORSION = 1e-4
"""The smallest torsional coefficient [m] TaskPhysics takes above 0: MuJoCo-Warp warns that a condim-4 geom's under
its ``mjMINMU`` (1e-5, compared after Newton's float32) may give NaN."""


@dataclass(frozen=True)
class TaskPhysics:
    """MuJoCo-Warp settings of a task's scene (see the module docstring for what each one reproduces).

    ``TaskPhysics()`` is the common default. A task may depart from it where its contacts need other settings
    (``Task.physics``: PegInsertionSide-v1's grip, PlaceSphere-v1's damped impacts);
    ``wpctrl.tasks.task_physics(env_id, **changes)`` is a task's own, and what ``make`` uses when given no physics."""

    substeps: int = 16
    """MuJoCo-Warp steps per physics step (the physics step is ManiSkill's 1 / ``sim_freq`` = 10 ms)."""
    integrator: str = "implicitfast"
    cone: str = "elliptic"
    impratio: float = 10.0
    iterations: int = 100
    """MuJoCo's constraint solver iterations (its default)."""
    ls_iterations: int = 50
    contact_solref: tuple[float, float] = (0.005, 1.0)
    """MuJoCo ``solref`` of every contact: (time constant [s], damping ratio). MuJoCo raises a time constant under two
    of its steps to two steps (``refsafe``): 1.25 ms is two steps at 16 substeps and acts as 2.5 ms at 8."""
    contact_solimp: tuple[float, float, float] = (0.99, 0.999, 0.001)
    """MuJoCo ``solimp`` (dmin, dmax, width [m]) of every contact."""
    limit_solref: tuple[float, float] | None = (0.00125, 1.0)
    """MuJoCo ``solreflimit`` of every robot joint limit: (time constant [s], damping ratio); None keeps Newton's
    import (force-space gains ``joint_limit_ke/kd``, soft). 1.25 ms is two MuJoCo steps at 16 substeps, the stiffest
    limit MuJoCo integrates (it raises a shorter time constant to two steps by itself)."""
    limit_solimp: tuple[float, float, float] = (0.99, 0.999, 0.001)
    friction_combine: str = "average"
    """``"average"`` (PhysX's rule, reproduced per shape: :func:`mujoco_friction`) or ``"max"`` (MuJoCo's own, the
    materials' coefficients unchanged)."""
    contact_gap: float = 0.01
    """How far apart [m] two shapes are already handed to MuJoCo's contact solver (every shape's ``gap``). It changes
    which pairs are tracked, not the forces: a tracked pair pushes only once it touches. Newton's default, 0.1 m, tracks
    every link within 10 cm of the table, the cube or another link (about ten times the contacts of 0.01 m, and a
    step 2.3 times slower on the CPU); 1 cm is eight MuJoCo steps of a 1 m/s approach at the default substeps."""
    finger_torsion: float = 0.0
    """Torsional friction coefficient [m] of the Panda's finger shapes; 0 (the default) leaves them without any. Above 0
    the finger shapes get MuJoCo's ``condim`` 4 (friction about the contact normal too) and this coefficient, every
    other shape a torsional coefficient of 0, so every finger contact resists a twist about its normal with up to this
    coefficient times its normal force. It stands in for PhysX's torsional patch friction on ManiSkill's finger
    material (``patch_radius`` / ``min_patch_radius`` 0.1 m), which MuJoCo's elliptic cone lacks. PegInsertionSide's
    physics sets 0.2 (its demos replay 3 / 4, the peg within 0.3 cm of PhysX's, 0 / 4 without). It is not the
    default: LiftPegUpright's demos need the peg to turn in the fingers, and with it they
    replay 0 / 4 instead of 4 / 4 (``docs/tasks.md``). Values between 0 and 1e-4 are refused (MuJoCo warns of NaN
    under 1e-5)."""

    finger_solimp: tuple[float, float, float] | None = (0.7, 0.7, 0.001)
    """MuJoCo ``solimp`` (dmin, dmax, width [m]) of the Panda's finger shapes; None gives them ``contact_solimp``.
    MuJoCo mixes the two shapes' values of a pair half and half, so a finger contact's impedance is 0.85 (0.7 and
    the other shape's 0.99-0.999): a fingertip pressed on the cube sinks into it as far as PhysX's does under the
    same force (1.1-1.3 mm at 35-40 N; with ``contact_solimp`` on the fingers too, 0.15-0.3 mm). The contact
    probes in ``docs/tasks.md`` measure it."""
    finger_solref: tuple[float, float] | None = None
    """MuJoCo ``solref`` (time constant [s], damping ratio) of the Panda's finger shapes; None gives them
    ``contact_solref``. MuJoCo mixes the two shapes' values of a pair half and half."""

    arm_drive: str = "physx_tgs"
    """Who computes the arm's drive torques: ``"physx_tgs"`` (the default) runs PhysX's TGS pass over the arm's
    drive rows before every MuJoCo step (:mod:`wpctrl.tasks.arm_drive`), so that a fast move of the coupled shoulder
    joints falls as short as it does on ManiSkill's 15-iteration PhysX; ``"mujoco"`` keeps MuJoCo's built-in
    implicit drive, which gives the converged rigid-body answer. The gripper keeps MuJoCo's drive either way.
    PegInsertionSide-v1's physics keeps ``"mujoco"`` (``docs/tasks.md``)."""

    shape_solref: tuple[tuple[str, tuple[int, ...], tuple[float, float]], ...] = ()
    """MuJoCo ``solref`` (time constant [s], damping ratio) of some of a task actor's shapes: each entry is (the
    actor's name, the shapes' indices in the actor's ``shapes``, the solref); every other shape keeps
    ``contact_solref``. MuJoCo mixes the two shapes' values of a pair half and half. PlaceSphere-v1's physics gives its
    bin's walls 30 ms, so that a ball rolled or dropped onto a wall's edge stops on it as on PhysX (``docs/tasks.md``);
    the task's scene refuses an actor or index it does not have."""

    def __post_init__(self):
        _int_at_least(self, "substeps", 1)
        _int_at_least(self, "iterations", 1)
        _int_at_least(self, "ls_iterations", 1)
        _one_of(self, "integrator", _INTEGRATORS)
        _one_of(self, "cone", _CONES)
        _one_of(self, "friction_combine", ("average", "max"))
        _one_of(self, "arm_drive", ARM_DRIVES)
        if (
            isinstance(self.contact_gap, bool)
            or not isinstance(self.contact_gap, (int, float))
            or not (0.0 <= self.contact_gap < float("inf"))
        ):
            raise ConfigError(f"TaskPhysics.contact_gap: expected a finite number >= 0 [m], got {self.contact_gap!r}")
        if (
            isinstance(self.finger_torsion, bool)
            or not isinstance(self.finger_torsion, (int, float))
            or not (self.finger_torsion == 0.0 or _MIN_TORSION <= self.finger_torsion < float("inf"))
        ):
            raise ConfigError(f"TaskPhysics.finger_torsion: expected 0 (none) or a finite number >= {_MIN_TORSION} [m] "
                              f"(MuJoCo warns of NaN under 1e-5), got {self.finger_torsion!r}")  # fmt: skip
        if isinstance(self.impratio, bool) or not isinstance(self.impratio, (int, float)) or not self.impratio >= 1.0:
            raise ConfigError(f"TaskPhysics.impratio: expected a number >= 1, got {self.impratio!r}")
        for name in ("contact_solref", "limit_solref", "finger_solref"):
            v = getattr(self, name)
            if v is None and name != "contact_solref":
                continue
            if not _numbers(v, 2) or not (v[0] > 0.0 and v[1] > 0.0):
                raise ConfigError(f"TaskPhysics.{name}: expected (time constant > 0 [s], damping ratio > 0), got {v!r}")
        object.__setattr__(self, "shape_solref", _shape_solref(self.shape_solref))
        for name in ("contact_solimp", "limit_solimp", "finger_solimp"):
            v = getattr(self, name)
            if v is None and name == "finger_solimp":
                continue
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

    def constraint_rows(self, contacts_per_world: int, dofs_per_world: int) -> int:
        """MuJoCo-Warp's constraint rows per world (its ``njmax``) for ``contacts_per_world`` contacts (the collision
        pipeline's capacity) and ``dofs_per_world`` joint DOFs: every contact's rows at its cone (elliptic: its
        ``condim``, 3 or 4 with :attr:`finger_torsion`; pyramidal: 2 (condim - 1)), a limit row per DOF and room for
        the equality rows of the mimic joints. MuJoCo-Warp's own estimate counts far fewer contacts, and the rows it
        has no room for are dropped from the solve (``nefc overflow``)."""
        condim = 4 if self.finger_torsion > 0.0 else 3
        per_contact = condim if self.cone == "elliptic" else 2 * (condim - 1)
        return int(contacts_per_world) * per_contact + int(dofs_per_world) + 16

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def physics_fields() -> tuple[str, ...]:
    """The names of :class:`TaskPhysics`'s fields."""
    return tuple(f.name for f in fields(TaskPhysics))


def physics_from(settings, where: str) -> TaskPhysics:
    """``TaskPhysics(**settings)``, refusing with a :class:`ConfigError` prefixed by ``where``: a ``settings`` that
    is not a mapping, a field TaskPhysics does not have (named, with the fields it has), a value out of its range."""
    if not isinstance(settings, Mapping):
        raise ConfigError(f"{where} expected a mapping of TaskPhysics fields to values, got {settings!r}")
    unknown = sorted(set(settings) - set(physics_fields()))
    if unknown:
        raise ConfigError(f"{where}: {unknown} are not TaskPhysics fields (expected some of {list(physics_fields())})")
    try:
        return TaskPhysics(**settings)
    except ConfigError as e:
        raise ConfigError(f"{where}: {e}") from e


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


def _shape_solref(v) -> tuple:
    """``TaskPhysics.shape_solref`` checked and made tuples (a JSON record gives lists)."""
    expected = "a sequence of (actor name, (shape index >= 0, ...), (time constant > 0 [s], damping ratio > 0))"
    if not isinstance(v, (tuple, list)):
        raise ConfigError(f"TaskPhysics.shape_solref: expected {expected}, got {v!r}")
    out = []
    for i, entry in enumerate(v):
        ok = isinstance(entry, (tuple, list)) and len(entry) == 3 and isinstance(entry[0], str) and entry[0]
        index = entry[1] if ok else None
        ok = ok and isinstance(index, (tuple, list)) and len(index) > 0
        ok = ok and all(isinstance(k, int) and not isinstance(k, bool) and k >= 0 for k in index)
        ok = ok and _numbers(entry[2], 2) and entry[2][0] > 0.0 and entry[2][1] > 0.0
        if not ok:
            raise ConfigError(f"TaskPhysics.shape_solref[{i}]: expected (actor name, (shape index >= 0, ...), "
                              f"(time constant > 0 [s], damping ratio > 0)), got {entry!r}")  # fmt: skip
        out.append((entry[0], tuple(int(k) for k in index), (float(entry[2][0]), float(entry[2][1]))))
    return tuple(out)
