"""Command line: ``python -m wpctrl <command> [options]`` (also the ``wpctrl`` console script; under
``torchrun --nproc-per-node=N -m wpctrl demo ...`` one process per rank)."""

from __future__ import annotations

import sys

COMMANDS = {
    "demo": ("wpctrl.demo", "run a ManiSkill control mode on Newton Pandas and report tracking (CPU or GPU)"),
    "train": ("wpctrl.train.cli", "train a PPO policy (rsl-rl) through wpctrl on a vectorised Newton task"),
    "replay": ("wpctrl.tasks.replay", "replay ManiSkill's recorded PushCube / PickCube episodes on Newton"),
    "export": (
        "wpctrl.train.commands:export_main",
        "export a trained PushCube / PickCube policy as TorchScript (and ONNX)",
    ),
    "evaluate": (
        "wpctrl.train.commands:evaluate_main",
        "evaluate an exported policy in the real ManiSkill or on Newton",
    ),
}


def _usage() -> str:
    lines = ["usage: python -m wpctrl <command> [options]", "", "commands:"]
    lines += [f"  {name:8s} {help}" for name, (_, help) in COMMANDS.items()]
    lines += [
        "",
        "python -m wpctrl <command> --help lists a command's options. Every command is quiet unless given "
        "--verbose\n(then Warp prints its banner and a line per kernel module it loads).",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0 if argv else 2
    if argv[0] not in COMMANDS:
        print(f"wpctrl: error: unknown command {argv[0]!r}; expected one of {sorted(COMMANDS)}", file=sys.stderr)
        return 2
    import importlib

    path, _, func = COMMANDS[argv[0]][0].partition(":")  # "module" (its main) or "module:function"
    module = importlib.import_module(path)  # light: warp and torch load once the command's arguments are checked
    try:
        return getattr(module, func or "main")(argv[1:])
    except SystemExit as e:  # argparse and the commands' checks exit 2 with a one-line message
        return e.code if isinstance(e.code, int) else 1


if __name__ == "__main__":
    raise SystemExit(main())
