"""``python -m wpctrl train``: the command line of :class:`~wpctrl.train.trainer.Trainer` (PPO through rsl-rl on
the reach task or on any ManiSkill task of :mod:`wpctrl.tasks`' registry: ``PushCube-v1``, ``PickCube-v1``,
``PullCube-v1``, ...). Every option is the
:class:`~wpctrl.train.train_config.TrainConfig` field of the same name; they are all checked, with the defaults that
depend on the device resolved, before torch, rsl-rl or an env is loaded.
"""

from __future__ import annotations

import argparse
import sys
import time

from ..console import add_output_options
from ..tasks.names import ROBOTS
from .command_args import command_parser, given_flags, missing_train_extra
from .hidden_inputs import HIDE_OBS
from .logger import LOGGERS
from .reach_ppo import evaluate, train_cfg
from .resume import ResumeError, apply_resume
from .train_config import (
    CONTROL_MODES,
    MANISKILL_TASKS,
    OBS_NORMALIZATIONS,
    PPO_UPDATES,
    SAMPLINGS,
    TASK_LIST,
    TASKS,
    TrainConfig,
)

__all__ = ["CONTROL_MODES", "MANISKILL_TASKS", "TASKS", "evaluate", "main", "parse", "parser", "train_cfg"]


class _Help(argparse.HelpFormatter):
    """Each option's default in --help (written out where it depends on the device)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text or any(action.default is x for x in (None, False, argparse.SUPPRESS)):
            return text
        return f"{text} (default: %(default)s)"


def parser() -> argparse.ArgumentParser:
    p = command_parser(
        "train",
        "Train a PPO policy (rsl-rl) through wpctrl on a vectorised Newton task (MuJoCo-Warp physics): "
        f"the reach task, or one of ManiSkill's tasks ({TASK_LIST}; state observations, normalized dense reward, "
        "ManiSkill's PPO baseline settings).",
        formatter_class=_Help,
    )
    p.add_argument("--task", choices=TASKS, default="reach", help="the task: reach, or a ManiSkill task (above)")
    p.add_argument(
        "--control-mode",
        default=None,
        help="ManiSkill Panda mode (default: pd_ee_delta_pos for reach, pd_joint_delta_pos, as ManiSkill's PPO "
        "baseline, for the ManiSkill tasks)",
    )
    p.add_argument("--envs", type=int, default=None, help="parallel envs (default: 4096 on CUDA, 64 on the CPU)")
    p.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="PPO iterations (default: reach 200 on CUDA, 20 on the CPU; the ManiSkill tasks 2000 on CUDA, 20 on "
        "the CPU)",
    )
    p.add_argument(
        "--steps-per-env",
        type=int,
        default=None,
        help="rollout length per iteration (default: reach 24; the tasks ManiSkill's recipe: 4, StackCube-v1 16)",
    )
    p.add_argument("--epochs", type=int, default=None, help="ManiSkill tasks: PPO epochs per iteration (default: 8)")
    p.add_argument(
        "--minibatches", type=int, default=None, help="ManiSkill tasks: mini-batches per epoch (default: 32)"
    )
    p.add_argument(
        "--substeps",
        type=int,
        default=None,
        help="ManiSkill tasks: MuJoCo-Warp steps per 10 ms physics step (default: wpctrl.tasks.TaskPhysics's, 16)",
    )
    p.add_argument(
        "--no-partial-reset",
        action="store_true",
        help="ManiSkill tasks: success does not end an episode (every episode runs its max_episode_steps: 50, "
        "PegInsertionSide-v1 100); default: an episode ends at success and that env alone restarts, as ManiSkill's "
        "PPO trains",
    )
    p.add_argument("--device", default=None, help="torch / Warp device (default: cuda:0 if there is one, else cpu)")
    p.add_argument("--seed", type=int, default=0, help="seeds torch and the envs' episode draws")
    p.add_argument(
        "--eval-episodes",
        type=int,
        default=None,
        help="fresh episodes per evaluation (default: reach one per env; tasks one per evaluation env)",
    )
    p.add_argument(
        "--eval-envs",
        type=int,
        default=None,
        help="ManiSkill tasks: envs of the separate evaluation env (default: --envs, at most 512)",
    )
    p.add_argument(
        "--eval-every", type=int, default=0, help="also evaluate every N iterations (0: only after training)"
    )
    p.add_argument(
        "--target-success",
        type=float,
        default=None,
        help="stop training once an evaluation's success rate reaches this (with --eval-every)",
    )
    p.add_argument(
        "--time-limit",
        type=float,
        default=None,
        help="ManiSkill tasks: stop training once this many seconds have passed since the command started, then "
        "evaluate and save (default: no limit)",
    )
    p.add_argument(
        "--ppo-update",
        choices=PPO_UPDATES,
        default=None,
        help="ManiSkill tasks: 'captured' replays each PPO mini-batch step from one CUDA graph (CUDA only; the default "
        "there), 'rsl-rl' runs rsl-rl's eager update (the default on the CPU)",
    )
    p.add_argument(
        "--obs-normalization",
        choices=OBS_NORMALIZATIONS,
        default=None,
        help="ManiSkill tasks: 'off' feeds the observations raw, as ManiSkill's PPO does (the default); 'on' "
        "normalises them with rsl-rl's running normaliser",
    )
    p.add_argument(
        "--hide-obs",
        choices=HIDE_OBS,
        default=None,
        help="ManiSkill tasks: observation entries the policy does not read: 'finger_qvel' (the default) hides the "
        "finger joints' velocities, which PhysX reports non-zero in a still grip (its solver's artefact) where "
        "Newton reports the fingers' motion; the exported policy zeroes them itself. 'none' hides nothing",
    )
    p.add_argument(
        "--robot-uids",
        choices=ROBOTS,
        default=None,
        help="ManiSkill tasks: the robot: 'panda', or 'panda_wristcam', the Panda with ManiSkill's wrist camera on its "
        "hand (default: the task's, as ManiSkill's: panda_wristcam for StackCube-v1 and PegInsertionSide-v1)",
    )
    p.add_argument(
        "--randomize",
        default=None,
        metavar="SPEC",
        help="ManiSkill tasks: per-env physics drawn at every reset of the training envs: 'on' (friction x0.7-1.3, "
        "contact time constant x1-2, the objects' mass x0.5-1.5), 'name=low:high,...' with names friction, "
        "contact_time, mass, or 'off' (the default). Evaluations run the nominal physics",
    )
    p.add_argument(
        "--action-sampling",
        choices=SAMPLINGS,
        default=None,
        help="ManiSkill tasks: 'sync-free' (the default) draws the rollout's actions as mean + std * N(0, 1), with no "
        "host sync, so the host queues the next env step while the GPU runs this one; 'rsl-rl' samples with "
        "rsl-rl's act (torch.normal, which waits for the GPU each step on CUDA). The same distribution; on the CPU "
        "the same numbers",
    )
    p.add_argument("--out", default="wpctrl-train", help="output folder")
    p.add_argument("--no-graph", action="store_true", help="run the env step eagerly (no CUDA / CPU graph)")
    p.add_argument(
        "--logger",
        choices=LOGGERS,
        default="tensorboard",
        help="where the run's scalars go besides train.json: TensorBoard event files in --out (rsl-rl's tags), "
        "'wandb' (Weights & Biases, and the event files; needs the wandb package), 'none'",
    )
    p.add_argument(
        "--resume",
        default=None,
        metavar="RUN_DIR",
        help="continue the run in RUN_DIR from its policy.pt (weights, normaliser, optimizer, iteration) with its "
        "recorded configuration; --iterations adds iterations; writes into RUN_DIR unless --out is given",
    )
    add_output_options(p)
    return p


def parse(argv):
    """``wpctrl train``'s arguments: parsed, the resumed run's configuration filled in (``args.resumed``: its
    ``train.json``), every check of :meth:`TrainConfig.problem` passed; exits 2 naming the option otherwise."""
    p = parser()
    args = p.parse_args(argv)
    if args.resume is not None:
        try:
            args.resumed = apply_resume(args, given_flags(p, argv))
        except ResumeError as e:
            p.error(str(e))
    if why := TrainConfig.from_args(args).problem():
        p.error(why)
    return args


def main(argv=None) -> int:
    t_main = time.perf_counter()
    args = parse(list(sys.argv[1:] if argv is None else argv))
    if hint := missing_train_extra("train"):
        print(hint, file=sys.stderr)
        return 2
    from ..console import cli_output
    from .trainer import Trainer

    cli_output(args.verbose)  # Warp quiet unless --verbose
    Trainer(TrainConfig.from_args(args), resumed=getattr(args, "resumed", None), started=t_main).run()
    return 0
