"""The light half of ``wpctrl export`` and ``wpctrl evaluate``: their argument parsers and the check for the train
extra, importable without torch, so that ``--help`` works on a base install and a missing torch is reported as the
install line ``wpctrl train`` prints, not as a traceback. The commands themselves live in :mod:`.export` and
:mod:`.evaluate`."""

from __future__ import annotations

import argparse
import importlib
import sys

__all__ = ["SIMS", "evaluate_main", "evaluate_parser", "export_main", "export_parser", "missing_train_extra"]

SIMS = ("maniskill", "newton")
"""``wpctrl evaluate --sim``'s simulators."""

TRAIN_EXTRA = ("torch", "rsl_rl")
"""What ``wpctrl train`` and ``wpctrl export`` import (``evaluate`` needs torch alone)."""


def missing_train_extra(command: str, modules: tuple[str, ...] = TRAIN_EXTRA) -> str | None:
    """The one-line install hint of ``wpctrl <command>`` when one of ``modules`` does not import, else None."""
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as e:
            return f'wpctrl {command}: needs the train extra (pip install "wpctrl[train]"): {e}'
    return None


def export_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m wpctrl export",
        description="Export the policy of a `wpctrl train --task PushCube-v1 | PickCube-v1` run as TorchScript "
        "(policy.ts, loadable with torch alone) and ONNX (policy.onnx, if the onnx package is importable): "
        "ManiSkill's flattened state observation -> deterministic action, observation normaliser included.",
    )
    p.add_argument("run_dir", help="the training run's --out folder (holds policy.pt)")
    p.add_argument("--out", default=None, help="folder for policy.ts / policy.onnx / policy.json (default: run_dir)")
    p.add_argument("--no-onnx", action="store_true", help="write the TorchScript module only")
    return p


def evaluate_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m wpctrl evaluate",
        description="Evaluate an exported policy (policy.ts from `wpctrl export`) on fresh episodes of ManiSkill's "
        "PushCube-v1 / PickCube-v1, in the real ManiSkill (PhysX CPU) or on Newton through wpctrl.",
    )
    p.add_argument("--policy", required=True, help="the exported TorchScript policy (policy.ts)")
    p.add_argument("--task", default=None, help="PushCube-v1 or PickCube-v1 (default: the policy's own)")
    p.add_argument("--sim", choices=SIMS, required=True, help="the simulator")
    p.add_argument("--episodes", type=int, default=100, help="episodes to run (default: 100)")
    p.add_argument("--seed", type=int, default=0, help="episode seeds (ManiSkill: seed + i for episode i)")
    p.add_argument("--device", default="cpu", help="newton: Warp / torch device (default: cpu)")
    p.add_argument("--envs", type=int, default=None, help="newton: envs at a time (default: min(episodes, 256))")
    p.add_argument("--substeps", type=int, default=None, help="newton: MuJoCo-Warp steps per physics step "
                   "(default: the policy's training value, else wpctrl.tasks.TaskPhysics's)")  # fmt: skip
    p.add_argument("--out", default=None, help="write the result (with every episode on ManiSkill) as JSON here")
    return p


def export_main(argv=None) -> int:
    """``wpctrl export``: the arguments parsed (``--help`` included) and the extra checked before torch loads."""
    argv = list(sys.argv[1:] if argv is None else argv)
    export_parser().parse_args(argv)
    if hint := missing_train_extra("export"):
        print(hint, file=sys.stderr)
        return 2
    from .export import main

    return main(argv)


def evaluate_main(argv=None) -> int:
    """``wpctrl evaluate``: the arguments parsed (``--help`` included) and torch checked before it loads."""
    argv = list(sys.argv[1:] if argv is None else argv)
    evaluate_parser().parse_args(argv)
    if hint := missing_train_extra("evaluate", ("torch",)):
        print(hint, file=sys.stderr)
        return 2
    from .evaluate import main

    return main(argv)
