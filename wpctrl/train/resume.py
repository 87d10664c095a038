"""``python -m wpctrl train --resume RUN_DIR``: continue a run from its checkpoint.

What comes back: the run's configuration (``RUN_DIR/train.json``: task, control mode, envs, steps per env, and for the
ManiSkill tasks epochs, mini-batches, substeps, partial resets and the observation normaliser; the seed and evaluation
envs unless given), the actor's and critic's weights with the observation normaliser, Adam's state and the iteration
counter (``RUN_DIR/policy.pt``, rsl-rl's checkpoint), and the history and evaluations, which ``train.json`` and the
learning curve continue. A flag that contradicts the recorded configuration is refused, naming both values: a run
resumed with another task, mode or env count would not be the same run. ``--iterations`` counts the iterations to add
(rsl-rl's ``learn(n)`` after ``load``). The outputs go to ``RUN_DIR`` unless ``--out`` names another folder.
"""

from __future__ import annotations

import json
from pathlib import Path

from .command_args import given_flags as explicit_flags

__all__ = ["ResumeError", "apply_resume", "explicit_flags", "load_checkpoint", "read_run", "recorded_config"]


class ResumeError(ValueError):
    """A run folder that cannot be resumed, or flags that contradict it (the message says which)."""


def read_run(run_dir) -> dict:
    """``run_dir``'s ``train.json``, checked to have its checkpoint next to it."""
    run = Path(run_dir)
    if not run.is_dir():
        raise ResumeError(f"--resume: {str(run)!r} is not a folder (a `wpctrl train` run's --out)")
    for name in ("train.json", "policy.pt"):
        if not (run / name).is_file():
            raise ResumeError(f"--resume: no {name} in {str(run)!r} (not a finished `wpctrl train` run's folder)")
    try:
        summary = json.loads((run / "train.json").read_text())
    except ValueError as e:
        raise ResumeError(f"--resume: {str(run / 'train.json')!r} is not JSON ({e})") from e
    if not isinstance(summary, dict) or "task" not in summary or "history" not in summary:
        raise ResumeError(f"--resume: {str(run / 'train.json')!r} is not a `wpctrl train` summary")
    return summary


def recorded_config(summary: dict) -> dict:
    """The flags that define a run (argparse destinations), as ``train.json`` records them."""
    cfg = {"task": summary["task"], "control_mode": summary["control_mode"], "envs": summary["envs"],
           "steps_per_env": summary["steps_per_env"]}  # fmt: skip
    if summary["task"] != "reach":
        alg = summary["ppo"]["algorithm"]
        cfg.update(
            epochs=alg["num_learning_epochs"],
            minibatches=alg["num_mini_batches"],
            substeps=summary["substeps"],
            no_partial_reset=not summary["partial_reset"],
            obs_normalization="on" if summary["ppo"]["actor"].get("obs_normalization") else "off",
            hide_obs=summary.get("hide_obs", "none"),  # a run recorded before the option hid nothing
            randomize=summary.get("randomize", "off"),
            robot_uids=summary.get("robot_uids", "panda"),  # a run recorded before the option trained on panda
        )
    return cfg


def _flag(name: str, value) -> str:
    flag = "--" + name.replace("_", "-")
    return flag if isinstance(value, bool) else f"{flag} {value}"


def apply_resume(args, given: set[str]) -> dict:
    """Fill ``args`` (an argparse namespace or a :class:`~wpctrl.train.train_config.TrainConfig`) with the
    configuration of the run ``args.resume`` names; refuse a setting in ``given`` that contradicts it
    (:class:`ResumeError`). The seed and the evaluation envs default to the run's; the output folder to the run's.
    Returns the run's ``train.json``."""
    summary = read_run(args.resume)
    where = str(Path(args.resume) / "train.json")
    for name, value in recorded_config(summary).items():
        mine = getattr(args, name)
        if name in given and mine != value:
            theirs = f"without {_flag(name, True)}" if value is False else f"with {_flag(name, value)}"
            raise ResumeError(
                f"{_flag(name, mine)}: the resumed run was trained {theirs} ({where}); a resumed run keeps the "
                "task, control mode, envs, rollout, PPO batch and physics it was trained with: drop the flag, or "
                "train a new run"
            )
        setattr(args, name, value)
    if "seed" not in given:
        args.seed = summary["seed"]
    if "eval_envs" not in given and summary.get("eval_envs") is not None:
        args.eval_envs = summary["eval_envs"]
    if "out" not in given:
        args.out = args.resume
    return summary


def load_checkpoint(runner, run_dir, device: str, summary: dict, captured: bool) -> int:
    """rsl-rl's checkpoint ``run_dir/policy.pt`` into ``runner`` (weights, normaliser, optimizer, iteration) on
    ``device``; Adam's step counters put where the update that follows needs them (the device for the captured
    update, whose step runs inside a CUDA graph; the CPU for rsl-rl's). Returns the iteration to continue from."""
    import torch

    runner.load(str(Path(run_dir) / "policy.pt"), map_location=device)
    opt = runner.alg.optimizer
    for group in opt.param_groups:
        group["capturable"] = captured
    for state in opt.state.values():
        if torch.is_tensor(state.get("step")):
            state["step"] = state["step"].to(device if captured else "cpu", torch.float32)
    # a checkpoint of an earlier wpctrl without the counter in it: train.json's count of iterations
    return runner.current_learning_iteration or int(summary["iterations"])
