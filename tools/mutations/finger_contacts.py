"""Mutations: the finger contacts' softness (``TaskPhysics.finger_solimp`` in ``wpctrl/tasks/physics.py`` and
``wpctrl/tasks/scene.py``) and the constraint rows MuJoCo-Warp is built with (``wpctrl/tasks/env.py``)."""

from .model import M

_PROBES = ("tests/test_contact_probes.py", "tests/test_tasks.py")

MUTATIONS = [
    M(
        "finger_contacts_stiff",
        "wpctrl/tasks/physics.py",
        "finger_solimp: tuple[float, float, float] | None = (0.7, 0.7, 0.001)",
        "finger_solimp: tuple[float, float, float] | None = None",
        "the fingers' contacts as stiff as the others' (a pressed fingertip sinks 0.2 mm where PhysX's sinks 1.2)",
        _PROBES,
    ),
    M(
        "finger_solimp_on_every_shape",
        "wpctrl/tasks/scene.py",
        "        solimp[fingers, 0:3] = physics.finger_solimp",
        "        solimp[:, 0:3] = physics.finger_solimp",
        "every shape's contacts as soft as the fingers' (the cube sinks into the table)",
        ("tests/test_tasks.py",),
    ),
    M(
        "finger_solref_on_every_shape",
        "wpctrl/tasks/scene.py",
        "        solref[fingers] = physics.finger_solref",
        "        solref[:] = physics.finger_solref",
        "finger_solref sets every shape's contact time constant, not just the fingers'",
        ("tests/test_tasks.py",),
    ),
    M(
        "constraint_rows_pyramidal_as_elliptic",
        "wpctrl/tasks/physics.py",
        'per_contact = condim if self.cone == "elliptic" else 2 * (condim - 1)',
        "per_contact = condim",
        "the pyramidal cone's contacts counted at the elliptic cone's rows (3, where it needs 4)",
        ("tests/test_tasks.py",),
    ),
    M(
        "constraint_rows_from_mujoco_warp",
        "wpctrl/tasks/env.py",
        "        if self.solver.mjw_data.njmax < rows:",
        "        if False:",
        "MuJoCo-Warp's own constraint-row estimate (about a third of the contacts' rows; the rest dropped)",
        ("tests/test_tasks.py",),
    ),
]
