"""Command line: ``python -m wpctrl <command> [options]`` (also the ``wpctrl`` console script; under
``torchrun --nproc-per-node=N -m wpctrl demo ...`` one process per rank).

The commands are argparse subcommands whose options each command's own module parses: only the chosen command's
module is imported, so ``--help`` and a refused argument cost milliseconds, not Warp's or torch's import."""

from __future__ import annotations

import argparse
import sys

COMMANDS = {
    "demo": ("wpctrl.demo", "run a ManiSkill control mode on Newton Pandas and report tracking (CPU or GPU)"),
    "train": ("wpctrl.train.cli", "train a PPO policy (rsl-rl) through wpctrl on a vectorised Newton task"),
    "replay": ("wpctrl.tasks.replay", "replay ManiSkill's recorded episodes of its table-top tasks on Newton"),
    "export": (
        "wpctrl.train.commands:export_main",
        "export a policy trained on a ManiSkill task as TorchScript (and ONNX)",
    ),
    "evaluate": (
        "wpctrl.train.commands:evaluate_main",
        "evaluate an exported policy in the real ManiSkill or on Newton",
    ),
}
"""{command: ("module" (its ``main(argv)``) or "module:function", one-line summary)}."""


def parser() -> argparse.ArgumentParser:
    """The top-level parser: the command, then its options, left to the command (``<command> --help`` lists them)."""
    listing = "\n".join(f"  {name:8s} {summary}" for name, (_, summary) in COMMANDS.items())
    p = argparse.ArgumentParser(
        prog="wpctrl",
        allow_abbrev=False,
        usage="python -m wpctrl <command> [options]",
        description=f"commands:\n{listing}",
        epilog="python -m wpctrl <command> --help lists a command's options. Every command is quiet unless given "
        "--verbose\n(then Warp prints its banner and a line per kernel module it loads).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="command", metavar="<command>", help=argparse.SUPPRESS, required=True)
    for name in COMMANDS:  # listed in the description; the options are the command's own parser's
        sub.add_parser(name, add_help=False, allow_abbrev=False)
    return p


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = parser()
    if not argv:
        p.print_help()
        return 2
    try:
        args, rest = p.parse_known_args(argv)
    except SystemExit as e:  # --help (0), an unknown command (2)
        return e.code if isinstance(e.code, int) else 1
    import importlib

    path, _, func = COMMANDS[args.command][0].partition(":")  # "module" (its main) or "module:function"
    module = importlib.import_module(path)  # light: warp and torch load once the command's arguments are checked
    try:
        return getattr(module, func or "main")(rest)
    except SystemExit as e:  # argparse and the commands' checks exit 2 with a one-line message
        return e.code if isinstance(e.code, int) else 1


if __name__ == "__main__":
    raise SystemExit(main())
