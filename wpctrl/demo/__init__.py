"""The demo (``python -m wpctrl demo``): N Pandas driven through a ManiSkill control mode by wpctrl inside a real Newton
solver, with a tracking report.

:mod:`.arguments` (command-line options and their checks), :mod:`.run` (one run), :mod:`.cli` (the command),
:mod:`.joint_task` / :mod:`.ee_task` (the scripted policy and tracked quantities of each mode family), :mod:`.notice`
(the compile notice), :mod:`.report` (reductions over ranks, strict JSON, table, plot, timing)."""

from .arguments import (  # noqa: F401  (the demo's command-line options and checks: tests and the CLI read these)
    ACTUATIONS,
    DEFAULT_OUT,
    PANDA_MODES,
    ROBOT_MODES,
    ROBOT_MODES_REFUSED,
    SOLVERS,
    _check_extras,
    _parser,
    compile_what,
    default_sim_freq,
    explicit_pd_choices,
    supported_combinations,
    unsupported,
)
from .cli import main  # noqa: F401
from .run import run  # noqa: F401
