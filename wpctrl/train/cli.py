"""``python -m wpctrl train``: PPO (rsl-rl's ``OnPolicyRunner``) on a vectorised Newton task through wpctrl.

Writes into ``--out``: ``train.json`` (per iteration: mean episode reward and success rate of the episodes finished in
it, collection env-steps/s, wall time; then the final evaluation), ``learning_curve.png``, and ``policy.pt`` (the
runner's checkpoint).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

TASKS = ("reach",)
CONTROL_MODES = ("pd_ee_delta_pos", "pd_joint_delta_pos")


def train_cfg(num_steps_per_env: int = 24, seed: int = 0) -> dict:
    """rsl-rl's PPO configuration: Isaac Lab's settings for its Franka reach task (``FrankaReachPPORunnerCfg``)."""
    return {
        "seed": seed,
        "num_steps_per_env": num_steps_per_env,
        "save_interval": 10**9,
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "algorithm": {
            "class_name": "PPO",
            "num_learning_epochs": 8,
            "num_mini_batches": 4,
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
        "actor": {
            "class_name": "MLPModel",
            "hidden_dims": [64, 64],
            "activation": "elu",
            "obs_normalization": True,
            "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": 1.0},
        },
        "critic": {
            "class_name": "MLPModel",
            "hidden_dims": [64, 64],
            "activation": "elu",
            "obs_normalization": True,
        },
        "check_for_nan": False,
    }


def parse(argv):
    p = argparse.ArgumentParser(
        prog="wpctrl train",
        description="Train a PPO policy (rsl-rl) through wpctrl on a vectorised Newton task (MuJoCo-Warp physics).",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--task", choices=TASKS, default="reach", help="the task")
    p.add_argument("--control-mode", choices=CONTROL_MODES, default="pd_ee_delta_pos", help="ManiSkill Panda mode")
    p.add_argument("--envs", type=int, default=None, help="parallel envs (default: 4096 on CUDA, 64 on the CPU)")
    p.add_argument("--iterations", type=int, default=None, help="PPO iterations (default: 200 CUDA, 20 CPU)")
    p.add_argument("--steps-per-env", type=int, default=24, help="rollout length per iteration")
    p.add_argument("--device", default=None, help="cuda:0 if available, else cpu")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--eval-episodes", type=int, default=None, help="fresh episodes to evaluate (default: one per env)")
    p.add_argument("--out", default="wpctrl-train", help="output folder")
    p.add_argument("--no-graph", action="store_true", help="on CUDA, run the env step eagerly (no CUDA graph)")
    args = p.parse_args(argv)
    if args.envs is not None and args.envs < 1:
        p.error(f"--envs: expected a positive number of envs, got {args.envs}")
    if args.iterations is not None and args.iterations < 1:
        p.error(f"--iterations: expected a positive number, got {args.iterations}")
    return args


def main(argv=None) -> int:
    args = parse(list(sys.argv[1:] if argv is None else argv))
    try:
        import torch
        from rsl_rl.runners import OnPolicyRunner
    except ImportError as e:
        print(f'wpctrl train: needs the train extra (pip install "wpctrl[train]"): {e}', file=sys.stderr)
        return 2
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    device = args.device or ("cuda:0" if wp.is_cuda_available() else "cpu")
    cuda = device.startswith("cuda")
    envs = args.envs or (4096 if cuda else 64)
    iterations = args.iterations or (200 if cuda else 20)
    torch.manual_seed(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from .reach import ReachEnv

    t0 = time.perf_counter()
    env = ReachEnv(
        envs, device=device, control_mode=args.control_mode, seed=args.seed, graph=cuda and not args.no_graph
    )
    cfg = train_cfg(args.steps_per_env, args.seed)
    runner = OnPolicyRunner(env, cfg, log_dir=None, device=device)
    setup_s = time.perf_counter() - t0
    print(f"wpctrl train: {envs} envs on {device}, {args.control_mode}, set up in {setup_s:.1f} s", flush=True)
    history = []
    env.randomize_episode_phase(args.seed)
    t_start = time.perf_counter()
    obs = env.get_observations()
    runner.alg.train_mode()
    for it in range(iterations):
        t_it = time.perf_counter()
        with torch.inference_mode():
            for _ in range(cfg["num_steps_per_env"]):
                actions = runner.alg.act(obs)
                obs, rewards, dones, extras = env.step(actions)
                runner.alg.process_env_step(obs, rewards, dones, extras)
            if cuda:
                torch.cuda.synchronize()
            collect_s = time.perf_counter() - t_it
            runner.alg.compute_returns(obs)
        losses = runner.alg.update()
        stats = env.take_stats()
        row = {
            "iteration": it,
            "mean_episode_reward": stats["mean_episode_reward"],
            "success_rate": stats["success_rate"],
            "episodes": stats["episodes"],
            "mean_step_reward": stats["mean_step_reward"],
            "collection_env_steps_per_s": envs * cfg["num_steps_per_env"] / collect_s,
            "iteration_s": time.perf_counter() - t_it,
            "wall_s": time.perf_counter() - t_start,
            "losses": {k: float(v) for k, v in losses.items()},
        }
        history.append(row)
        print(
            f"[{it:4d}] step reward {_fmt(row['mean_step_reward'])} episode reward {_fmt(row['mean_episode_reward'])} "
            f"success {_fmt(row['success_rate'])} "
            f"collect {row['collection_env_steps_per_s']:,.0f} env-steps/s  wall {row['wall_s']:.1f} s",
            flush=True,
        )
    runner.save(str(out / "policy.pt"))
    evaluation = evaluate(env, runner, args.eval_episodes or envs, cuda)
    print(f"evaluation: success {evaluation['success_rate']:.3f} over {evaluation['episodes']} episodes", flush=True)
    summary = {
        "task": args.task,
        "control_mode": args.control_mode,
        "envs": envs,
        "device": device,
        "seed": args.seed,
        "iterations": iterations,
        "steps_per_env": cfg["num_steps_per_env"],
        "setup_s": setup_s,
        "train_wall_s": time.perf_counter() - t_start,
        "ppo": cfg,
        "history": history,
        "evaluation": evaluation,
    }
    (out / "train.json").write_text(json.dumps(summary, indent=1, allow_nan=False))
    _plot(history, evaluation, out / "learning_curve.png", envs, device)
    print(f"wrote {out / 'train.json'}, {out / 'learning_curve.png'}, {out / 'policy.pt'}", flush=True)
    return 0


def evaluate(env, runner, episodes: int, cuda: bool) -> dict:
    """The deterministic policy on fresh episodes (every env restarted): their success rate and mean reward."""
    import torch

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
    return {"episodes": done_eps, "success_rate": successes / done_eps, "mean_episode_reward": rewards / done_eps}


def _fmt(x) -> str:
    return "   –  " if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:6.3f}"


def _plot(history, evaluation, path: Path, envs: int, device: str) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("wpctrl train: matplotlib is not installed: no learning_curve.png", file=sys.stderr)
        return
    its = [h["iteration"] for h in history]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8))
    a.plot(its, [h["mean_episode_reward"] for h in history], "-")
    a.set_xlabel("PPO iteration")
    a.set_ylabel("mean episode reward")
    a.grid(alpha=0.3)
    b.plot(its, [h["success_rate"] for h in history], "-", label="training episodes")
    b.axhline(evaluation["success_rate"], color="k", ls="--", lw=1, label="final evaluation")
    b.set_xlabel("PPO iteration")
    b.set_ylabel("success rate (TCP within 2.5 cm)")
    b.set_ylim(-0.02, 1.02)
    b.legend(loc="lower right", fontsize=8)
    b.grid(alpha=0.3)
    fig.suptitle(f"reach, {envs} envs on {device}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
