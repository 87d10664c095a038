"""One PPO training loop (rsl-rl's ``OnPolicyRunner`` algorithm) for the reach task and every ManiSkill task:
:class:`Trainer` takes a :class:`~wpctrl.train.train_config.TrainConfig` and writes a run directory.

What differs between the tasks lives in their training objects (:class:`~wpctrl.train.reach_ppo.ReachTraining`,
:class:`~wpctrl.train.task_ppo.ManiSkillTraining`): the env(s), the PPO settings, the rollout, the evaluation. The
loop itself collects, updates, logs a row per iteration, evaluates every ``eval_every`` iterations, stops at the
iteration count, the target success rate or the time limit, and writes into ``out``: ``train.json`` (per iteration:
mean episode reward and success rate of the episodes finished in it, collection env-steps/s, wall time; the
evaluations), ``learning_curve.png`` (:mod:`.outputs`), TensorBoard event files (:mod:`.logger`) and ``policy.pt``
(the runner's checkpoint, which ``resume`` continues: :mod:`.resume`).

Importing this module imports neither torch nor rsl-rl; :meth:`Trainer.run` does.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import time
from pathlib import Path

from .train_config import TrainConfig

__all__ = ["Trainer"]


def _training(cfg: TrainConfig):
    if cfg.task == "reach":
        from .reach_ppo import ReachTraining

        return ReachTraining(cfg)
    from .task_ppo import ManiSkillTraining

    return ManiSkillTraining(cfg)


def _say(msg: str) -> None:
    print(msg, flush=True)


def _evaluation_text(ev: dict) -> str:
    at_end = f" (at the end {ev['success_at_end_rate']:.3f})" if "success_at_end_rate" in ev else ""
    return (f"success {ev['success_rate']:.3f}{at_end} over {ev['episodes']} episodes, return "
            f"{ev['mean_episode_reward']:.2f}")  # fmt: skip


class Trainer:
    """Train a policy with PPO on a vectorised Newton task; the same loop behind ``wpctrl train``.

    Example::

        from wpctrl.train import TrainConfig, Trainer

        run = Trainer(TrainConfig(task="PushCube-v1", device="cpu", envs=64, iterations=20, out="runs/push")).run()

    Args:
        cfg: The run (checked here: :class:`~wpctrl.train.train_config.TrainConfigError` names a field that cannot
            work). With ``cfg.resume`` the recorded configuration of that run fills the fields left at their
            defaults; a changed field that contradicts it is refused.
        resumed: The resumed run's ``train.json`` where ``cfg`` already holds its configuration (the command line
            resolves it while parsing); None: read from ``cfg.resume``.
        started: The ``time.perf_counter()`` the run's clock starts at (default: when :meth:`run` is called):
            ``time_limit`` and the summary's timings count from it.
    """

    def __init__(self, cfg: TrainConfig, *, resumed: dict | None = None, started: float | None = None):
        if not isinstance(cfg, TrainConfig):
            raise TypeError(f"Trainer: cfg: expected a TrainConfig, got {type(cfg).__name__}")
        cfg = dataclasses.replace(cfg)
        if cfg.resume is not None and resumed is None:
            from .resume import ResumeError, apply_resume
            from .train_config import TrainConfigError

            try:
                resumed = apply_resume(cfg, cfg.changed())
            except ResumeError as e:
                raise TrainConfigError(f"TrainConfig.{str(e).lstrip('-')}") from e
        self.cfg = cfg.check()
        self.resumed = resumed
        self.started = started

    @property
    def run_dir(self) -> Path:
        """Where the run writes ``train.json``, ``learning_curve.png``, ``policy.pt`` (and the event files)."""
        return Path(self.cfg.out)

    @property
    def checkpoint(self) -> Path:
        return self.run_dir / "policy.pt"

    def summary(self) -> dict:
        """The finished run's ``train.json``."""
        return json.loads((self.run_dir / "train.json").read_text())

    def export(self, out_dir=None, onnx: bool = True) -> dict:
        """The trained policy of a ManiSkill-task run as TorchScript (and ONNX): :func:`wpctrl.train.export.export`."""
        from .export import export

        return export(self.run_dir, out_dir, onnx=onnx)

    def evaluate(self, sim: str = "newton", episodes: int = 100, seed: int = 0, **kwargs) -> dict:
        """The exported policy (``policy.ts``; exported first where missing) on fresh episodes of ``sim``
        (:func:`wpctrl.train.evaluate.evaluate`)."""
        from .evaluate import evaluate

        policy = self.run_dir / "policy.ts"
        if not policy.is_file():
            self.export(onnx=False)
        return evaluate(policy, sim=sim, episodes=episodes, seed=seed, **kwargs)

    def run(self) -> Path:
        """Train, evaluate, save; returns the run directory."""
        import torch
        from rsl_rl.runners import OnPolicyRunner

        from ..console import compile_notice
        from .logger import RunLogger
        from .outputs import fmt, median, plot, write_json

        t_main = time.perf_counter() if self.started is None else self.started
        resumed = self.resumed
        c = self.cfg.resolved()
        task = _training(c)
        cuda = c.device.startswith("cuda")
        torch.manual_seed(c.seed)
        out = Path(c.out)
        out.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        _say(f"wpctrl train: building {task.builds} on {c.device} ...")
        with compile_notice(f"Warp kernels for {c.task} on {c.device}", say=_say):
            task.build()
        ppo = task.ppo_cfg()
        with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints its observation sets and both networks
            runner = OnPolicyRunner(task.env, ppo, log_dir=None, device=c.device)
        alg = runner.alg
        task.init_networks(alg)
        start = 0
        if resumed is not None:  # weights, normaliser, Adam's state and the iteration count of the run's checkpoint
            from .resume import load_checkpoint

            start = load_checkpoint(runner, c.resume, c.device, resumed, captured=task.captured_update)
        task.attach(runner)
        log = RunLogger(c.logger, out, cfg=ppo, env_cfg=task.env.cfg, start_iteration=start)
        setup_s = time.perf_counter() - t0
        _say(f"wpctrl train: {task.describe()}; set up in {setup_s:.1f} s")
        steps, envs = c.steps_per_env, c.envs
        # a resumed run continues its history, evaluations and wall time
        history = list(resumed["history"]) if resumed else []
        evaluations = list(resumed["evaluations"]) if resumed else []
        wall0, n_prev = max([r["wall_s"] for r in history[-1:] + evaluations[-1:]], default=0.0), len(evaluations)
        t_start = time.perf_counter()

        def evaluation(it: int, say: bool = True) -> dict:
            ev = task.evaluate()
            ev.update(iteration=it, wall_s=wall0 + time.perf_counter() - t_start, env_steps=(it + 1) * envs * steps)
            evaluations.append(ev)
            log.evaluation(ev)
            if say:
                _say(f"       evaluation: {_evaluation_text(ev)}")
            return ev

        obs = task.start(c.seed + start)
        if c.eval_every and not resumed and task.evaluates_untrained:
            evaluation(-1)  # the untrained policy: the curve's start
        alg.train_mode()
        stop = None
        for it in range(start, start + c.iterations):
            t_it = time.perf_counter()
            with torch.inference_mode():
                obs = task.rollout(obs, steps)
                if cuda:
                    torch.cuda.synchronize()
                collect_s = time.perf_counter() - t_it
                alg.compute_returns(obs)
            losses = alg.update()
            learn_s = time.perf_counter() - t_it - collect_s
            stats = task.env.take_stats()
            row = {"iteration": it, **{k: v for k, v in stats.items() if k != "env_steps"},
                   "collection_env_steps_per_s": envs * steps / collect_s, "collect_s": collect_s, "learn_s": learn_s,
                   "env_steps": (it + 1) * envs * steps, "iteration_s": time.perf_counter() - t_it,
                   "wall_s": wall0 + time.perf_counter() - t_start,
                   "action_std": float(alg.get_policy().output_std.detach().mean()),
                   "losses": {k: float(v) for k, v in losses.items()}}  # fmt: skip
            history.append(row)
            log.iteration(row, alg.learning_rate)
            _say(f"[{it:4d}] step reward {fmt(row['mean_step_reward'])} episode reward "
                 f"{fmt(row['mean_episode_reward'])} success {fmt(row['success_rate'])} collect "
                 f"{row['collection_env_steps_per_s']:,.0f} env-steps/s  wall {row['wall_s']:.1f} s")  # fmt: skip
            last_it = it + 1 == start + c.iterations
            over = c.time_limit is not None and time.perf_counter() - t_main >= c.time_limit
            if c.eval_every and (it + 1) % c.eval_every == 0 and not last_it and not over:
                ev = evaluation(it)
                if c.target_success is not None and ev["success_rate"] >= c.target_success:
                    stop = "target"
                    break
                obs = task.after_evaluation(obs, c.seed + it + 1)
            if over:
                stop = "time_limit"
                break
        train_s = time.perf_counter() - t_start
        runner.current_learning_iteration = len(history)
        infos = task.checkpoint_infos(ppo)
        runner.save(str(out / "policy.pt"), infos=infos)
        last = evaluations[-1] if evaluations and evaluations[-1]["iteration"] == history[-1]["iteration"] else None
        if last is None:
            last = evaluation(history[-1]["iteration"], say=False)
        _say(f"evaluation: {_evaluation_text(last)}")
        target = c.target_success
        reached = [e for e in evaluations[n_prev:] if target is not None and e["success_rate"] >= target]
        rates = [h["collection_env_steps_per_s"] for h in history[1:] or history]
        summary = {
            "task": c.task,
            "control_mode": c.control_mode,
            "envs": envs,
            "device": c.device,
            "device_name": torch.cuda.get_device_name(torch.device(c.device)) if cuda else "cpu",
            "graph": task.env.graph is not None,
            **task.summary(),
            "seed": c.seed,
            "iterations": len(history),
            "steps_per_env": steps,
            "env_steps": len(history) * envs * steps,
            "stopped_by": stop or "iterations",
            "import_s": t0 - t_main,
            "setup_s": setup_s,
            "train_start_s": t_start - t_main,
            "train_wall_s": train_s,
            "total_s": time.perf_counter() - t_main,
            "collection_env_steps_per_s_median": median(rates),
            "target_success": target,
            "time_to_target_s": (t_start - t_main + reached[0]["wall_s"] - wall0) if reached else None,
            "env_steps_to_target": reached[0]["env_steps"] if reached else None,
            "resumed_from": {"run": str(c.resume), "iteration": start} if resumed else None,
            "logger": c.logger,
            "ppo": ppo,
            **({"checkpoint": infos} if infos is not None else {}),
            "history": history,
            "evaluations": evaluations,
            "evaluation": last,
        }
        write_json(out / "train.json", summary)
        plot(history, evaluations, out / "learning_curve.png",
             f"{c.task}, {envs} envs on {c.device}: {len(history)} iterations in {history[-1]['wall_s']:.0f} s",
             task.success_label, window=envs)  # fmt: skip
        log.close()
        _say(f"wrote {out / 'train.json'}, {out / 'learning_curve.png'}, {out / 'policy.pt'}")
        if reached:
            _say(f"success {reached[0]['success_rate']:.3f} >= {target} after {summary['time_to_target_s']:.1f} s")
        task.close()
        return out
