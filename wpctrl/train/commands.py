"""The light half of ``wpctrl export`` and ``wpctrl evaluate``: their entry points parse and check every argument
that needs no torch (a missing file, an unknown task, a device this machine cannot have, the train extra not
installed; :mod:`.command_args`) without importing torch, Warp or Newton, so that ``--help`` works on a base install
and a mistake is refused in a fraction of a second with one line, not after seconds of imports or as a traceback.
The commands themselves live in :mod:`.export` and :mod:`.evaluate`."""

from __future__ import annotations

import sys

from .command_args import (
    SIMS,
    check_evaluate_args,
    check_export_args,
    evaluate_parser,
    export_parser,
    missing_train_extra,
    refuse,
)

__all__ = [
    "SIMS",
    "check_evaluate_args",
    "check_export_args",
    "evaluate_main",
    "evaluate_parser",
    "export_main",
    "export_parser",
    "missing_train_extra",
    "refuse",
]


def export_main(argv=None) -> int:
    """``wpctrl export``: the arguments parsed (``--help`` included), torch and the run folder checked before torch
    loads. Export rebuilds the actor in plain torch (:mod:`.actor`): it needs no rsl-rl."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = export_parser().parse_args(argv)
    if hint := missing_train_extra("export", ("torch",), load=False):
        print(hint, file=sys.stderr)
        return 2
    if why := check_export_args(args):
        print(f"wpctrl export: error: {why}", file=sys.stderr)
        return 2
    if hint := missing_train_extra("export", ("torch",)):  # installed but broken: the import's own error
        print(hint, file=sys.stderr)
        return 2
    from .export import main

    return main(argv)


def evaluate_main(argv=None) -> int:
    """``wpctrl evaluate``: the arguments parsed (``--help`` included) and checked, and torch checked, before torch,
    Warp or ManiSkill loads."""
    argv = list(sys.argv[1:] if argv is None else argv)
    p = evaluate_parser()
    args = p.parse_args(argv)
    if hint := missing_train_extra("evaluate", ("torch",), load=False):
        print(hint, file=sys.stderr)
        return 2
    check_evaluate_args(p, args, argv)
    if hint := missing_train_extra("evaluate", ("torch",)):
        print(hint, file=sys.stderr)
        return 2
    from .evaluate import main

    return main(argv)
