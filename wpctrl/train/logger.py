"""TensorBoard (and W&B) scalars of a training run, tagged as rsl-rl's ``Logger`` tags them, so that a run of
``python -m wpctrl train`` reads like an rsl-rl run in TensorBoard.

rsl-rl's own ``Logger`` is not used as a whole: its ``process_env_step`` reads the done flags back to the host at every
env step (a device sync inside the rollout, which wpctrl's loops avoid: the envs count their episode statistics on the
device, read once per iteration) and its ``log`` prints a console block per iteration. Its writers are used: torch's
``SummaryWriter`` for ``tensorboard`` (what rsl-rl's ``Logger`` makes for its default) and rsl-rl's ``WandbLogWriter``
for ``wandb`` (TensorBoard event files plus the W&B run).

Tags (x axis: the iteration, 0-based, as rsl-rl's):

- rsl-rl's: ``Loss/value``, ``Loss/surrogate``, ``Loss/entropy``, ``Loss/learning_rate``, ``Policy/mean_std``,
  ``Perf/total_fps`` (env steps per second of collection and update), ``Perf/collection_time``,
  ``Perf/learning_time``; where episodes finished in the iteration ``Train/mean_reward`` and (tasks)
  ``Train/mean_episode_length``, and ``Train/mean_reward/time`` against the run's wall time [s];
- wpctrl's: ``Perf/collection_fps`` (env steps per second of the collection alone), ``Train/mean_step_reward``,
  ``Train/episodes`` (finished in the iteration), ``Train/success_rate`` (success at any step of the finished
  episodes), ``Train/success_at_end_rate`` (tasks), ``Train/mean_reward/env_steps`` and
  ``Train/success_rate/env_steps`` against the env steps collected; the evaluations of the deterministic policy
  ``Eval/success_rate``, ``Eval/success_at_end_rate`` (tasks), ``Eval/mean_episode_reward`` at the iteration they
  followed (-1: the untrained policy) and ``Eval/success_rate/env_steps``.

rsl-rl's ``Train/mean_reward`` averages its last 100 finished episodes; here it is the mean of the episodes that
finished in the iteration (the value ``train.json`` records), since the envs sum their statistics per iteration.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

__all__ = ["LOGGERS", "RunLogger", "logger_error"]

LOGGERS = ("tensorboard", "wandb", "none")
WANDB_INSTALL = "pip install wandb"


def logger_error(kind: str) -> str | None:
    """Why ``--logger kind`` cannot run here (the install line), or None."""
    if kind == "wandb" and importlib.util.find_spec("wandb") is None:
        return f"--logger wandb: the wandb package is not installed ({WANDB_INSTALL}); or --logger tensorboard"
    return None


class RunLogger:
    """Writes a run's scalars into ``log_dir`` (TensorBoard event files) through the writer ``kind`` names
    (:data:`LOGGERS`); ``none`` writes nothing. ``start_iteration``: the first iteration this command trains (a
    resumed run's events past it, from a run cut short after its checkpoint, are dropped: ``purge_step``)."""

    def __init__(self, kind: str, log_dir: Path, *, cfg: dict, env_cfg: dict, start_iteration: int = 0,
                 project: str = "wpctrl"):  # fmt: skip
        if kind not in LOGGERS:
            raise ValueError(f"logger: expected one of {LOGGERS}, got {kind!r}")
        if why := logger_error(kind):
            raise ValueError(why)
        self.writer = None
        purge = start_iteration if start_iteration > 0 else None
        if kind == "tensorboard":
            from torch.utils.tensorboard import SummaryWriter

            self.writer = SummaryWriter(log_dir=str(log_dir), flush_secs=10, purge_step=purge)
        elif kind == "wandb":
            from rsl_rl.utils.wandb_log_writer import WandbLogWriter

            self.writer = WandbLogWriter(log_dir=str(log_dir), project_name=project)
            self.writer.store_config(env_cfg, cfg)
        self.kind = kind

    def _add(self, tag: str, value, step: int) -> None:
        if value is not None:
            self.writer.add_scalar(tag, float(value), step)

    def iteration(self, row: dict, learning_rate: float) -> None:
        """One row of ``train.json``'s ``history`` (needs its ``env_steps``, cumulative)."""
        if self.writer is None:
            return
        it, add = row["iteration"], self._add
        for key, value in row["losses"].items():
            add(f"Loss/{key}", value, it)
        add("Loss/learning_rate", learning_rate, it)
        add("Policy/mean_std", row["action_std"], it)
        batch = row["collection_env_steps_per_s"] * row["collect_s"]
        add("Perf/total_fps", int(batch / (row["collect_s"] + row["learn_s"])), it)
        add("Perf/collection_fps", row["collection_env_steps_per_s"], it)
        add("Perf/collection_time", row["collect_s"], it)
        add("Perf/learning_time", row["learn_s"], it)
        add("Train/mean_step_reward", row["mean_step_reward"], it)
        add("Train/episodes", row["episodes"], it)
        if row["episodes"]:
            add("Train/mean_reward", row["mean_episode_reward"], it)
            add("Train/mean_episode_length", row.get("mean_episode_length"), it)
            add("Train/success_rate", row["success_rate"], it)
            add("Train/success_at_end_rate", row.get("success_at_end_rate"), it)
            add("Train/mean_reward/time", row["mean_episode_reward"], int(row["wall_s"]))
            add("Train/mean_reward/env_steps", row["mean_episode_reward"], row["env_steps"])
            add("Train/success_rate/env_steps", row["success_rate"], row["env_steps"])

    def evaluation(self, ev: dict) -> None:
        """One of ``train.json``'s ``evaluations`` (with its ``iteration`` and ``env_steps``)."""
        if self.writer is None:
            return
        it = ev["iteration"]
        self._add("Eval/success_rate", ev["success_rate"], it)
        self._add("Eval/success_at_end_rate", ev.get("success_at_end_rate"), it)
        self._add("Eval/mean_episode_reward", ev["mean_episode_reward"], it)
        self._add("Eval/success_rate/env_steps", ev["success_rate"], ev["env_steps"])

    def close(self) -> None:
        if self.writer is None:
            return
        if hasattr(self.writer, "stop"):  # rsl-rl's LogWriter (W&B): also finishes the W&B run
            self.writer.flush()
            self.writer.stop()
        self.writer.close()
        self.writer = None
