"""The main job: N Pandas driven through a ManiSkill control mode by wpctrl inside a real Newton solver.

``python -m wpctrl demo`` (or the ``wpctrl demo`` console script) builds N Pandas in one Newton model, runs a
scripted policy that exercises every part of the chosen control mode (sinusoidal joint motion and a gripper that
opens and closes, expressed in the mode's action space), resets a few random envs now and then, and reports
throughput, the controller's share of a control step and the tracking error against the policy's desired
trajectory. It writes ``summary.json`` (strict JSON: ``null`` for a non-finite number) and ``tracking.png`` into
``--out``.

``--robot`` runs a ManiSkill agent instead (``fetch``: base + arm + gripper, ``allegro_hand_right``,
``unitree_g1_simplified_legs``: floating, standing on a ground plane), loaded by uid with
:func:`wpctrl.maniskill.load_robot`, in any of its ManiSkill control modes: smooth actions across the mode's action
space, scored as the measured joints against wpctrl's drive targets.

Under ``torchrun --nproc-per-node=N -m wpctrl demo ...`` every rank runs ``--envs`` Pandas of its own on its own
device (``--device cuda``: ``cuda:{LOCAL_RANK}``) with its own seed; the statistics are reduced with
torch.distributed and rank 0 prints and writes them (:mod:`wpctrl.distributed`).

Gravity does not act on the Pandas, as in ManiSkill, whose Panda modes keep ``balance_passive_force`` on: with MuJoCo
the controller takes gravity off the robot's links (MuJoCo's per-body gravity compensation); with the other solvers
the demo turns that off and sets the worlds' gravity to zero.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from . import report
from .arguments import SOLVER_LABELS, _check_args, _check_extras, _fail, _parser, supported_combinations
from .run import run


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if any(a == "--task" or a.startswith("--task=") for a in argv):  # ManiSkill's tasks: a demo of their own
        from . import task_demo

        return task_demo.main(argv)
    parser = _parser()
    args = parser.parse_args(argv)
    _check_args(parser, args)
    _check_extras(args)
    from .. import distributed

    if not distributed.launched() or os.environ.get("RANK") == "0":
        print(
            f"wpctrl demo: {args.envs} {'Pandas' if args.robot == 'panda' else args.robot + ' robots'}, "
            f"{args.control_mode}, {args.actuation} actuation, "
            f"{SOLVER_LABELS[args.solver]} at {args.sim_freq} Hz on {args.device}",
            flush=True,
        )
    from ..console import cli_output

    cli_output(args.verbose)  # no banner, no "Module ... load" lines unless --verbose: the demo says what it does

    try:
        ctx = distributed.init(device=args.device, seed=args.seed)
    except (ValueError, ImportError, RuntimeError) as e:
        _fail(parser, str(e))
    try:
        summary = run(args, ctx)
    finally:
        ctx.shutdown()
    if not ctx.is_main:
        return 0 if summary["all_finite"] else 1
    print(report.format_summary(summary))
    if not summary["all_finite"]:
        print(
            f"  the simulation went non-finite at t = {summary['diverged_at_s']} s: {summary['solver']} with "
            f"{summary['actuation']} actuation did not hold the Panda's gains at {summary['sim_freq']} Hz; "
            f"{supported_combinations()} (see docs/solvers.md)",
            file=sys.stderr,
        )
    print(f"  wrote {Path(args.out) / 'summary.json'} and {Path(args.out) / 'tracking.png'}")
    return 0 if summary["all_finite"] else 1
