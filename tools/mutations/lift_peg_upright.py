"""Mutations: LiftPegUpright-v1 (``wpctrl/tasks/lift_peg_upright.py``)."""

from .model import M

_TESTS = ("tests/test_task_lift_peg_upright.py",)

MUTATIONS = [
    M(
        "lift_peg_upright_tolerance",
        "wpctrl/tasks/lift_peg_upright.py",
        "wp.abs(wp.abs(euler_z) - wp.pi / 2.0) < UPRIGHT_TOL",
        "wp.abs(wp.abs(euler_z) - wp.pi / 2.0) < 2.0 * UPRIGHT_TOL",
        "LiftPegUpright's success accepts a peg 0.16 rad off upright",
        _TESTS,
    ),
    M(
        "lift_peg_height_tolerance",
        "wpctrl/tasks/lift_peg_upright.py",
        "actor_pos(s, e, PEG)[2] - PEG_HALF_LENGTH) < HEIGHT_TOL",
        "actor_pos(s, e, PEG)[2] - PEG_HALF_LENGTH) < 2.0 * HEIGHT_TOL",
        "LiftPegUpright's success accepts a centre 1 cm off 0.12 m",
        _TESTS,
    ),
    M(
        "lift_peg_reach_weight",
        "wpctrl/tasks/lift_peg_upright.py",
        "    return r + reach / 5.0\n",
        "    return r + reach\n",
        "LiftPegUpright's reaching reward at full weight instead of a fifth",
        _TESTS,
    ),
    M(
        "lift_peg_laid_along_y",
        "wpctrl/tasks/lift_peg_upright.py",
        "wp.quat(_LIE_X, 0.0, 0.0, _LIE_W)",
        "wp.quat(0.0, 0.0, _LIE_X, _LIE_W)",
        "the peg starts turned a quarter about z (lying along y) instead of about its own axis",
        _TESTS,
    ),
]
