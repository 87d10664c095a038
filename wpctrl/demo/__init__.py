"""The demo (``python -m wpctrl demo``): N Pandas driven through a ManiSkill control mode by wpctrl inside a real Newton
solver, with a tracking report. :mod:`.cli` (options, checks, the run), :mod:`.joint_task` / :mod:`.ee_task` (the
scripted policy and tracked quantities of each mode family), :mod:`.report` (reductions over ranks, strict JSON,
table, plot, timing)."""

from .cli import (  # noqa: F401  (the demo's public face: tests and the CLI read these)
    ACTUATIONS,
    COMPILE_NOTICE,
    DEFAULT_OUT,
    SOLVERS,
    _check_extras,
    _parser,
    default_sim_freq,
    explicit_pd_choices,
    main,
    run,
    supported_combinations,
    unsupported,
)
