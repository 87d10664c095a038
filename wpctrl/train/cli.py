"""``python -m wpctrl train``: PPO (rsl-rl's ``OnPolicyRunner``) on a vectorised Newton task through wpctrl: the reach
task (:mod:`wpctrl.train.reach`) or ManiSkill's ``PushCube-v1`` / ``PickCube-v1`` (:mod:`wpctrl.train.task_ppo`).

Writes into ``--out``: ``train.json`` (per iteration: mean episode reward and success rate of the episodes finished in
it, collection env-steps/s, wall time; the evaluations of the deterministic policy on fresh episodes, periodic with
``--eval-every`` and final), ``learning_curve.png`` (:mod:`.outputs`), TensorBoard event files (:mod:`.logger`) and
``policy.pt`` (the runner's checkpoint, which ``--resume`` continues: :mod:`.resume`).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import time
from pathlib import Path

from ..console import add_output_options, cuda_absent, device_refusal
from ..tasks.names import CONTROL_MODES as TASK_CONTROL_MODES
from .commands import missing_train_extra
from .logger import LOGGERS, logger_error
from .ppo_config import MANISKILL_MINIBATCHES, MANISKILL_STEPS_PER_ENV, batch_error, runner_cfg
from .resume import ResumeError, apply_resume, explicit_flags

MANISKILL_TASKS = ("PushCube-v1", "PickCube-v1")
TASKS = ("reach",) + MANISKILL_TASKS
CONTROL_MODES = ("pd_ee_delta_pos", "pd_joint_delta_pos")
"""The reach task's control modes (the ManiSkill tasks take every Panda mode of :data:`wpctrl.tasks.CONTROL_MODES`)."""


REACH_STEPS_PER_ENV = 24
REACH_MINIBATCHES = 4


def train_cfg(num_steps_per_env: int = REACH_STEPS_PER_ENV, seed: int = 0) -> dict:
    """rsl-rl's PPO configuration: Isaac Lab's settings for its Franka reach task (``FrankaReachPPORunnerCfg``)."""
    return runner_cfg(
        seed=seed,
        num_steps_per_env=num_steps_per_env,
        algorithm={
            "num_learning_epochs": 8,
            "num_mini_batches": REACH_MINIBATCHES,
            "learning_rate": 1.0e-3,
            "schedule": "adaptive",
            "gamma": 0.99,
            "lam": 0.95,
            "entropy_coef": 0.001,
            "desired_kl": 0.01,
            "max_grad_norm": 1.0,
            "value_loss_coef": 1.0,
            "use_clipped_value_loss": True,
            "clip_param": 0.2,
        },
        mlp={"class_name": "MLPModel", "hidden_dims": [64, 64], "activation": "elu", "obs_normalization": True},
        distribution={"init_std": 1.0},
    )


class _Help(argparse.HelpFormatter):
    """Each option's default in --help (written out where it depends on the device)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text or any(action.default is x for x in (None, False, argparse.SUPPRESS)):
            return text
        return f"{text} (default: %(default)s)"


def parse(argv):
    p = argparse.ArgumentParser(
        prog="wpctrl train",
        description="Train a PPO policy (rsl-rl) through wpctrl on a vectorised Newton task (MuJoCo-Warp physics): "
        "the reach task, or ManiSkill's PushCube-v1 / PickCube-v1 (state observations, normalized dense reward, "
        "ManiSkill's PPO baseline settings).",
        formatter_class=_Help,
    )
    p.add_argument("--task", choices=TASKS, default="reach", help="the task")
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
        "--steps-per-env", type=int, default=None, help="rollout length per iteration (default: reach 24, tasks 4)"
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
        help="ManiSkill tasks: success does not end an episode (every episode runs its 50 steps); default: an episode "
        "ends at success and that env alone restarts, as ManiSkill's PPO trains",
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
        choices=("captured", "rsl-rl"),
        default=None,
        help="ManiSkill tasks: 'captured' replays each PPO mini-batch step from one CUDA graph (CUDA only; the default "
        "there), 'rsl-rl' runs rsl-rl's eager update (the default on the CPU)",
    )
    p.add_argument(
        "--obs-normalization",
        choices=("on", "off"),
        default=None,
        help="ManiSkill tasks: 'off' feeds the observations raw, as ManiSkill's PPO does (the default); 'on' "
        "normalises them with rsl-rl's running normaliser",
    )
    p.add_argument(
        "--action-sampling",
        choices=("sync-free", "rsl-rl"),
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
    args = p.parse_args(argv)
    if why := logger_error(args.logger):
        p.error(why)
    if args.resume is not None:
        try:
            args.resumed = apply_resume(args, explicit_flags(p, argv))
        except ResumeError as e:
            p.error(str(e))
    for name in ("envs", "iterations", "steps_per_env", "eval_episodes", "eval_envs", "epochs", "minibatches",
                 "substeps"):  # fmt: skip
        v = getattr(args, name)
        if v is not None and v < 1:
            p.error(f"--{name.replace('_', '-')}: expected a positive number, got {v}")
    if args.eval_every < 0:
        p.error(f"--eval-every: expected 0 or a positive number of iterations, got {args.eval_every}")
    if args.target_success is not None and not 0.0 < args.target_success <= 1.0:
        p.error(f"--target-success: expected a success rate in (0, 1], got {args.target_success}")
    if args.target_success is not None and args.eval_every == 0:
        p.error("--target-success: needs --eval-every N (the evaluations that decide when to stop)")
    if args.time_limit is not None and not args.time_limit > 0:
        p.error(f"--time-limit: expected a positive number of seconds, got {args.time_limit}")
    if args.task == "reach":
        for name in ("epochs", "minibatches", "substeps", "eval_envs", "time_limit", "ppo_update", "obs_normalization",
                     "action_sampling"):  # fmt: skip
            if getattr(args, name) is not None:
                p.error(f"--{name.replace('_', '-')}: only for the ManiSkill tasks {list(MANISKILL_TASKS)}")
        if args.no_partial_reset:
            p.error(f"--no-partial-reset: only for the ManiSkill tasks {list(MANISKILL_TASKS)}")
        if args.control_mode is not None and args.control_mode not in CONTROL_MODES:
            p.error(f"--control-mode: expected one of {list(CONTROL_MODES)} for reach, got {args.control_mode!r}")
    elif args.control_mode is not None and args.control_mode not in TASK_CONTROL_MODES:
        p.error(f"--control-mode: expected one of the Panda's modes {list(TASK_CONTROL_MODES)} for {args.task}, got "
                f"{args.control_mode!r}")  # fmt: skip
    _check_device_and_batch(p, args)
    return args


def _check_device_and_batch(p: argparse.ArgumentParser, args) -> None:
    """The device exists, and the rollout (``--envs`` x ``--steps-per-env``) fills PPO's mini-batches: checked here,
    before any env is built, with the defaults that depend on the device resolved as training resolves them. Without
    Warp where this machine shows no NVIDIA driver (the CPU is then the only device); Warp decides otherwise."""
    if why := device_refusal(args.device, "--device"):
        p.error(why)
    if cuda_absent():
        cuda = False
    else:
        import warp as wp

        from ..config import ConfigError
        from ..console import quiet_warp
        from ..devices import check_device

        with quiet_warp(args.verbose):
            if args.device is not None:
                try:
                    check_device(args.device, "--device")
                except ConfigError as e:
                    p.error(str(e))
            cuda = (args.device or ("cuda:0" if wp.is_cuda_available() else "cpu")).startswith("cuda")
    envs = args.envs or (4096 if cuda else 64)
    if args.task in MANISKILL_TASKS:
        # ManiSkill's PPO normalises the advantages per mini-batch: 2 samples at least for a defined std
        why = batch_error(envs, args.steps_per_env or MANISKILL_STEPS_PER_ENV,
                          args.minibatches or MANISKILL_MINIBATCHES, 2, "--minibatches")  # fmt: skip
    else:  # the reach task normalises them over the whole batch: every one of its mini-batches needs a sample
        why = batch_error(envs, args.steps_per_env or REACH_STEPS_PER_ENV, REACH_MINIBATCHES, 1, None)
    if why:
        p.error(why)


def main(argv=None) -> int:
    t_main = time.perf_counter()
    args = parse(list(sys.argv[1:] if argv is None else argv))
    if hint := missing_train_extra("train"):
        print(hint, file=sys.stderr)
        return 2
    import torch
    import warp as wp
    from rsl_rl.runners import OnPolicyRunner

    from ..console import cli_output

    cli_output(args.verbose)  # Warp quiet unless --verbose
    if args.task in MANISKILL_TASKS:
        from .task_ppo import train

        return train(args, t_main)
    args.control_mode = args.control_mode or "pd_ee_delta_pos"
    args.steps_per_env = args.steps_per_env or REACH_STEPS_PER_ENV
    device = args.device or ("cuda:0" if wp.is_cuda_available() else "cpu")
    cuda = device.startswith("cuda")
    envs = args.envs or (4096 if cuda else 64)
    iterations = args.iterations or (200 if cuda else 20)
    eval_episodes = args.eval_episodes or envs
    torch.manual_seed(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from ..console import compile_notice
    from .outputs import fmt, median, plot, write_json
    from .reach import ReachEnv

    t0 = time.perf_counter()
    print(f"wpctrl train: building {envs} reach envs on {device} ...", flush=True)
    with compile_notice(f"Warp kernels for the reach on {device}", say=lambda msg: print(msg, flush=True)):
        env = ReachEnv(
            envs, device=device, control_mode=args.control_mode, seed=args.seed, graph=cuda and not args.no_graph
        )
    cfg = train_cfg(args.steps_per_env, args.seed)
    with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints its observation sets and both networks
        runner = OnPolicyRunner(env, cfg, log_dir=None, device=device)
    resumed, start = getattr(args, "resumed", None), 0
    if resumed is not None:  # weights, normaliser, Adam's state and the iteration count of the run's checkpoint
        from .resume import load_checkpoint

        start = load_checkpoint(runner, args.resume, device, resumed, captured=False)
    from .logger import RunLogger

    log = RunLogger(args.logger, out, cfg=cfg, env_cfg=env.cfg, start_iteration=start)
    setup_s = time.perf_counter() - t0
    print(f"wpctrl train: {envs} envs on {device}, {args.control_mode}, set up in {setup_s:.1f} s", flush=True)
    # a resumed run continues its history, evaluations and wall time
    history, evaluations = list(resumed["history"]) if resumed else [], list(resumed["evaluations"]) if resumed else []
    wall0, n_prev = max([r["wall_s"] for r in history[-1:] + evaluations[-1:]], default=0.0), len(evaluations)
    t_start = time.perf_counter()
    obs = _start_episodes(env, args.seed + start)
    runner.alg.train_mode()
    for it in range(start, start + iterations):
        t_it = time.perf_counter()
        with torch.inference_mode():  # the loop of OnPolicyRunner.learn, with the env's own episode statistics
            for _ in range(cfg["num_steps_per_env"]):
                actions = runner.alg.act(obs)
                obs, rewards, dones, extras = env.step(actions)
                runner.alg.process_env_step(obs, rewards, dones, extras)
            if cuda:
                torch.cuda.synchronize()
            collect_s = time.perf_counter() - t_it
            runner.alg.compute_returns(obs)
        losses = runner.alg.update()
        learn_s = time.perf_counter() - t_it - collect_s
        stats = env.take_stats()
        row = {
            "iteration": it,
            "mean_episode_reward": stats["mean_episode_reward"],
            "success_rate": stats["success_rate"],
            "episodes": stats["episodes"],
            "mean_step_reward": stats["mean_step_reward"],
            "collection_env_steps_per_s": envs * cfg["num_steps_per_env"] / collect_s,
            "collect_s": collect_s,
            "learn_s": learn_s,
            "env_steps": (it + 1) * envs * cfg["num_steps_per_env"],
            "iteration_s": time.perf_counter() - t_it,
            "wall_s": wall0 + time.perf_counter() - t_start,
            "action_std": float(runner.alg.get_policy().output_std.detach().mean()),
            "losses": {k: float(v) for k, v in losses.items()},
        }
        history.append(row)
        log.iteration(row, runner.alg.learning_rate)
        print(
            f"[{it:4d}] step reward {fmt(row['mean_step_reward'])} episode reward {fmt(row['mean_episode_reward'])} "
            f"success {fmt(row['success_rate'])} "
            f"collect {row['collection_env_steps_per_s']:,.0f} env-steps/s  wall {row['wall_s']:.1f} s",
            flush=True,
        )
        if args.eval_every and (it + 1) % args.eval_every == 0 and it + 1 < start + iterations:
            ev = evaluate(env, runner, eval_episodes)
            ev.update(iteration=it, wall_s=wall0 + time.perf_counter() - t_start, env_steps=row["env_steps"])
            evaluations.append(ev)
            log.evaluation(ev)
            print(f"       evaluation: success {ev['success_rate']:.3f} over {ev['episodes']} episodes", flush=True)
            if args.target_success is not None and ev["success_rate"] >= args.target_success:
                break
            obs = _start_episodes(env, args.seed + it + 1)
            runner.alg.train_mode()
    train_s = time.perf_counter() - t_start
    runner.current_learning_iteration = len(history)
    runner.save(str(out / "policy.pt"))
    last = evaluations[-1] if evaluations and evaluations[-1]["iteration"] == history[-1]["iteration"] else None
    if last is None:
        last = evaluate(env, runner, eval_episodes)
        last.update(iteration=history[-1]["iteration"], wall_s=wall0 + time.perf_counter() - t_start,
                    env_steps=history[-1]["env_steps"])  # fmt: skip
        evaluations.append(last)
        log.evaluation(last)
    print(f"evaluation: success {last['success_rate']:.3f} over {last['episodes']} episodes", flush=True)
    target = args.target_success
    reached = [e for e in evaluations[n_prev:] if target is not None and e["success_rate"] >= target]
    summary = {
        "task": args.task,
        "control_mode": args.control_mode,
        "envs": envs,
        "device": device,
        "device_name": torch.cuda.get_device_name(torch.device(device)) if cuda else "cpu",
        "graph": env.graph is not None,
        "seed": args.seed,
        "iterations": len(history),
        "steps_per_env": cfg["num_steps_per_env"],
        "env_steps": len(history) * envs * cfg["num_steps_per_env"],
        "import_s": t0 - t_main,
        "setup_s": setup_s,
        "train_wall_s": train_s,
        "total_s": time.perf_counter() - t_main,
        "collection_env_steps_per_s_median": median([h["collection_env_steps_per_s"] for h in history[1:] or history]),
        "target_success": target,
        "time_to_target_s": (t_start - t_main + reached[0]["wall_s"] - wall0) if reached else None,
        "resumed_from": {"run": str(args.resume), "iteration": start} if resumed else None,
        "logger": args.logger,
        "ppo": cfg,
        "history": history,
        "evaluations": evaluations,
        "evaluation": last,
    }
    write_json(out / "train.json", summary)
    wall = history[-1]["wall_s"]
    plot(history, evaluations, out / "learning_curve.png",
         f"reach, {envs} envs on {device}: {len(history)} iterations in {wall:.0f} s",
         "success rate (TCP within 2.5 cm)", window=envs)  # fmt: skip
    log.close()
    print(f"wrote {out / 'train.json'}, {out / 'learning_curve.png'}, {out / 'policy.pt'}", flush=True)
    if reached:
        first = reached[0]
        print(f"success {first['success_rate']:.3f} >= {target} after {summary['time_to_target_s']:.1f} s", flush=True)
    return 0


def _start_episodes(env, seed: int):
    """Every env in a new episode at a random step of it (rsl-rl's ``init_at_random_ep_len``); the observations."""
    obs = env.reset()
    env.randomize_episode_phase(seed)
    env.take_stats()
    return obs


def evaluate(env, runner, episodes: int) -> dict:
    """The deterministic policy on fresh episodes (every env restarted): their success rate and mean reward."""
    import torch

    t = time.perf_counter()
    policy = runner.get_inference_policy(device=env.device)
    obs = env.reset()
    env.take_stats()
    done_eps, rewards, successes = 0, 0.0, 0.0
    with torch.inference_mode():
        while done_eps < episodes:
            for _ in range(env.max_episode_length):
                obs, _, _, _ = env.step(policy(obs))
            s = env.take_stats()
            done_eps += s["episodes"]
            rewards += (s["mean_episode_reward"] or 0.0) * s["episodes"]
            successes += (s["success_rate"] or 0.0) * s["episodes"]
    return {
        "episodes": done_eps,
        "success_rate": successes / done_eps,
        "mean_episode_reward": rewards / done_eps,
        "eval_s": time.perf_counter() - t,
    }
