"""Mutations: the tasks' arm drive as PhysX's TGS solver applies it (``wpctrl/kernels/tgs_drive.py``,
``wpctrl/tasks/arm_drive.py``, its use in ``wpctrl/tasks/env.py``)."""

from .model import M

_TESTS = ("tests/test_arm_drive.py",)

MUTATIONS = [
    M(
        "tgs_limit_per_solver_step",
        "wpctrl/kernels/tgs_drive.py",
        "room = force_limit[env, r] * window",
        "room = force_limit[env, r] * h",
        "the force limit bounds each solver step's impulse instead of the physics step's",
        _TESTS,
    ),
    M(
        "tgs_rows_uncoupled",
        "wpctrl/kernels/tgs_drive.py",
        "        for c in range(r):\n",
        "        for c in range(0):\n",
        "a row does not see the velocity the rows before it changed in the same pass (Jacobi, not Gauss-Seidel)",
        _TESTS,
    ),
    M(
        "arm_drive_never_built",
        "wpctrl/tasks/env.py",
        'if physics.arm_drive == "physx_tgs":',
        'if physics.arm_drive == "none":',
        "the TGS pass is never built: MuJoCo keeps its own drive of the arm",
        _TESTS + ("tests/test_policy_replay.py",),
    ),
]
