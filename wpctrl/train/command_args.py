"""``wpctrl export``'s and ``wpctrl evaluate``'s argument parsers and every check of their arguments that needs no
torch (a missing file, an unknown task, a device this machine cannot have, the train extra not installed): imported
by the light entry points (:mod:`.commands`) and by the commands themselves (:mod:`.export`, :mod:`.evaluate`), and
importing none of them. Also the commands' one rule for options a command (or one of its modes) does not use:
:func:`refuse_unused` refuses them, naming the option and why, instead of ignoring them."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from pathlib import Path

from ..console import add_output_options, device_refusal
from ..extras import install_hint, missing
from ..tasks.names import TASK_IDS

__all__ = [
    "SIMS",
    "check_evaluate_args",
    "check_export_args",
    "command_parser",
    "evaluate_parser",
    "export_parser",
    "flag",
    "given_flags",
    "missing_train_extra",
    "record_refusal",
    "refuse",
    "refuse_unused",
    "unused_option",
]

SIMS = ("maniskill", "newton")
"""``wpctrl evaluate --sim``'s simulators."""

MANISKILL_UNUSED = ("device", "envs", "substeps")
"""``wpctrl evaluate --sim maniskill``: the options of the Newton env only ``--sim newton`` builds."""
MANISKILL_UNRECORDED = ("video",)
"""``wpctrl evaluate --sim maniskill``: the video, which only ``--sim newton`` records."""
NEWTON_UNUSED = ("record",)
"""``wpctrl evaluate --sim newton``: the episode file for ``wpctrl replay``, which only ``--sim maniskill`` writes."""
RECORD_SUFFIXES = (".json", ".json.gz")
"""The names ``wpctrl evaluate --record`` takes (``.gz``: gzip-compressed)."""

TRAIN_EXTRA = ("torch", "rsl_rl")
"""What ``wpctrl train`` imports (``export`` and ``evaluate`` need torch alone)."""


def missing_train_extra(command: str, modules: tuple[str, ...] = TRAIN_EXTRA, load: bool = True) -> str | None:
    """The one-line install hint of ``wpctrl <command>`` when one of ``modules`` does not import, else None.
    ``load=False``: only whether they are installed (found without importing them: milliseconds, not seconds)."""
    for name in modules:
        try:
            if load:
                importlib.import_module(name)
            elif importlib.util.find_spec(name) is None:
                raise ImportError(f"No module named {name!r}")
        except (ImportError, ValueError) as e:
            return missing(f"wpctrl {command}", "train", e, torch=True)
    return None


def flag(name: str) -> str:
    """The command line's option for the setting ``name`` (an argparse destination)."""
    return "--" + name.replace("_", "-")


def given_flags(parser: argparse.ArgumentParser, argv) -> set[str]:
    """The destinations of the options ``argv`` gives (whatever their value: also one equal to its default)."""
    saved = [(a, a.default) for a in parser._actions]
    try:
        for a, _ in saved:
            a.default = argparse.SUPPRESS
        ns, _ = parser.parse_known_args(argv)
    finally:
        for a, d in saved:
            a.default = d
    return set(vars(ns))


def unused_option(given, unused) -> str | None:
    """The first setting of ``unused`` (in its order) that ``given`` holds, or None."""
    return next((name for name in unused if name in given), None)


def refuse_unused(parser: argparse.ArgumentParser, given, unused, why: str) -> None:
    """Exit 2 (``parser.error``) naming the first option of ``unused`` that was ``given`` and ``why`` it has no use
    here: a command's options that the chosen task or mode ignores are refused, not silently dropped."""
    if name := unused_option(given, unused):
        parser.error(f"{flag(name)}: {why}")


def command_parser(command: str, description: str, **kwargs) -> argparse.ArgumentParser:
    """``wpctrl <command>``'s argument parser: its usage line and its errors name the command."""
    return argparse.ArgumentParser(prog=f"wpctrl {command}", description=description, **kwargs)


def export_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "export",
        f"Export the policy of a `wpctrl train --task {' | '.join(TASK_IDS)}` run as TorchScript "
        "(policy.ts, loadable with torch alone) and ONNX (policy.onnx, if the onnx package is importable): "
        "ManiSkill's flattened state observation -> deterministic action, observation normaliser included.",
    )
    p.add_argument("run_dir", help="the training run's --out folder (holds policy.pt)")
    p.add_argument("--out", default=None, help="folder for policy.ts / policy.onnx / policy.json (default: run_dir)")
    p.add_argument("--no-onnx", action="store_true", help="write the TorchScript module only")
    add_output_options(p)
    return p


def evaluate_parser() -> argparse.ArgumentParser:
    p = command_parser(
        "evaluate",
        "Evaluate an exported policy (policy.ts from `wpctrl export`) on fresh episodes of its ManiSkill task "
        f"({', '.join(TASK_IDS)}), in the real ManiSkill (PhysX CPU) or on Newton through wpctrl.",
    )
    p.add_argument("--policy", required=True, help="the exported TorchScript policy (policy.ts)")
    p.add_argument("--task", default=None, choices=TASK_IDS, help="the task (default: the policy's own)")
    p.add_argument("--sim", choices=SIMS, required=True, help="the simulator")
    p.add_argument("--episodes", type=int, default=100, help="episodes to run (default: 100)")
    p.add_argument("--seed", type=int, default=0, help="episode seeds (ManiSkill: seed + i for episode i)")
    p.add_argument("--device", default="cpu", help="newton: Warp / torch device (default: cpu)")
    p.add_argument("--envs", type=int, default=None, help="newton: envs at a time (default: min(episodes, 256))")
    p.add_argument("--substeps", type=int, default=None, help="newton: MuJoCo-Warp steps per physics step "
                   "(default: the policy's training value, else wpctrl.tasks.TaskPhysics's)")  # fmt: skip
    p.add_argument("--out", default=None, help="write the result (with every episode on ManiSkill) as JSON here")
    p.add_argument("--video", default=None, metavar="FILE", help="newton: also write env 0's first episodes as a video "
                   "(FILE.mp4, .gif; MuJoCo's offscreen renderer; skipped, saying why, where none works)")  # fmt: skip
    p.add_argument("--record", default=None, metavar="FILE", help="maniskill: also save the episodes for `wpctrl "
                   "replay FILE` (FILE.json, or FILE.json.gz gzip-compressed), written once all have run")  # fmt: skip
    add_output_options(p, progress=True)
    return p


def check_export_args(args) -> str | None:
    """Why ``wpctrl export``'s arguments cannot work, known without torch (the run folder and its checkpoint), or
    None."""
    run = Path(args.run_dir)
    if not run.is_dir():
        return f"run dir {str(run)!r} does not exist"
    if not (run / "policy.pt").is_file():
        return f"run dir {str(run)!r} has no policy.pt (the checkpoint `wpctrl train` writes)"
    return None


def record_refusal(path) -> str | None:
    """Why ``path`` cannot take an evaluation's recording (its name, its folder), or None."""
    p = Path(path)
    if not str(p).endswith(RECORD_SUFFIXES):
        return f"expected a file name ending in {' or '.join(RECORD_SUFFIXES)}, got {str(p)!r}"
    if p.is_dir():
        return f"{str(p)!r} is a folder, expected a file name"
    if not p.parent.is_dir():
        return f"no folder {str(p.parent)!r} for {str(p)!r}"
    return None


def refuse(command: str, message: str):
    """Exit 2 with the one line ``wpctrl <command>: error: <message>`` on stderr."""
    print(f"wpctrl {command}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def check_evaluate_args(p: argparse.ArgumentParser, args, argv) -> None:
    """``wpctrl evaluate``'s arguments (parsed from ``argv``), checked without torch, Warp or ManiSkill: exits 2 with
    one line for the first that cannot work (an option ``--sim maniskill`` does not use, ``--video`` included, the
    policy file, the numbers, a device this machine cannot have, the ``--record`` file; Warp confirms the device
    later)."""
    given = given_flags(p, argv)
    if args.sim == "newton":
        refuse_unused(p, given, NEWTON_UNUSED, "only --sim maniskill is recorded for `wpctrl replay` (it replays "
                      "ManiSkill's episodes on Newton)")  # fmt: skip
    if args.sim == "maniskill":
        refuse_unused(p, given, MANISKILL_UNUSED, "not used with --sim maniskill (ManiSkill runs one env at a time "
                      "on its own CPU PhysX)")  # fmt: skip
        refuse_unused(p, given, MANISKILL_UNRECORDED, "only --sim newton is recorded (MuJoCo's renderer draws the "
                      "model Newton's solver built; ManiSkill's env here renders nothing)")  # fmt: skip
    for name in ("episodes", "envs", "substeps"):
        v = getattr(args, name)
        if v is not None and v < 1:
            p.error(f"--{name}: expected a positive number, got {v}")
    policy = Path(args.policy)
    if not policy.is_file():
        what = "a folder" if policy.is_dir() else "no file"
        refuse("evaluate", f"--policy: {what} {str(policy)!r} (export a run with `python -m wpctrl export RUN_DIR`, "
                           "which writes RUN_DIR/policy.ts)")  # fmt: skip
    if args.record is not None and (why := record_refusal(args.record)):
        refuse("evaluate", f"--record: {why}")
    if args.sim == "newton" and (why := device_refusal(args.device, "--device")):
        refuse("evaluate", why)
    if args.sim == "maniskill" and importlib.util.find_spec("mani_skill") is None:
        refuse("evaluate", f"--sim maniskill: needs ManiSkill, the maniskill extra ({install_hint('maniskill', True)})")
