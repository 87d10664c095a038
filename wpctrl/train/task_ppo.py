"""PPO (rsl-rl) on ManiSkill's ``PushCube-v1`` / ``PickCube-v1`` through wpctrl: ManiSkill's PPO baseline settings
mapped onto rsl-rl, the rollout with ManiSkill's bootstrapping at episode ends, and evaluations of the deterministic
policy on fresh episodes (``python -m wpctrl train --task PushCube-v1``; :mod:`wpctrl.train.cli` parses).

ManiSkill's baseline (``examples/baselines/ppo/ppo_fast.py`` and its ``baselines.sh``: 4,096 envs, 4 steps per env
and iteration, 8 epochs of 32 mini-batches, gamma 0.8, lambda 0.9, learning rate 3e-4, clip 0.2, no value clipping,
no entropy bonus, gradient norm 0.5, advantages normalised per mini-batch, 3 x 256 tanh actor and critic with
orthogonal initialisation, log-std parameter starting at 0) is :func:`maniskill_ppo_cfg`; docs/training.md lists
what transfers to rsl-rl and what does not.
"""

from __future__ import annotations

import math
import sys
import time

import torch

from ..console import compile_notice
from .ppo_config import MANISKILL_EPOCHS as EPOCHS
from .ppo_config import MANISKILL_MINIBATCHES as MINIBATCHES
from .ppo_config import MANISKILL_STEPS_PER_ENV as STEPS_PER_ENV
from .ppo_config import runner_cfg
from .ppo_update import CapturedUpdate
from .sampling import SAMPLINGS, act, sync_free
from .task_env import TaskVecEnv

__all__ = ["Collector", "checkpoint_infos", "evaluate_policy", "maniskill_init", "maniskill_ppo_cfg", "train"]


def maniskill_ppo_cfg(
    num_steps_per_env: int = STEPS_PER_ENV,
    num_learning_epochs: int = EPOCHS,
    num_mini_batches: int = MINIBATCHES,
    seed: int = 0,
    obs_normalization: bool = False,
) -> dict:
    """rsl-rl's configuration with ManiSkill's PPO baseline settings (see the module docstring).

    ManiSkill's value loss is ``vf_coef (0.5) * 0.5 * MSE``; rsl-rl's ``value_loss_coef * MSE``: 0.25 is the same
    loss. The learning rate is fixed as ManiSkill's (rsl-rl's adaptive schedule off); ManiSkill's early stop of an
    update at an approximate KL of 0.1 has no rsl-rl counterpart. The networks read the observations raw, as
    ManiSkill's do; with ``obs_normalization`` they are normalised by rsl-rl's running normaliser (the exported
    policy carries it), with which PPO stalls on PushCube (docs/training.md).
    """
    mlp = {"class_name": "MLPModel", "hidden_dims": [256, 256, 256], "activation": "tanh",
           "obs_normalization": obs_normalization}  # fmt: skip
    return runner_cfg(
        seed=seed,
        num_steps_per_env=num_steps_per_env,
        algorithm={
            "num_learning_epochs": num_learning_epochs,
            "num_mini_batches": num_mini_batches,
            "learning_rate": 3.0e-4,
            "schedule": "fixed",
            "desired_kl": None,
            "gamma": 0.8,
            "lam": 0.9,
            "entropy_coef": 0.0,
            "max_grad_norm": 0.5,
            "value_loss_coef": 0.25,
            "use_clipped_value_loss": False,
            "clip_param": 0.2,
            "normalize_advantage_per_mini_batch": True,
        },
        mlp=mlp,
        distribution={"init_std": 1.0, "std_type": "log"},
    )


def maniskill_init(model, last_gain: float) -> None:
    """ManiSkill's ``layer_init``: orthogonal weights (gain sqrt 2; ``last_gain`` for the output layer), zero biases."""
    linears = [m for m in model.mlp if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for i, layer in enumerate(linears):
            torch.nn.init.orthogonal_(layer.weight, gain=last_gain if i == len(linears) - 1 else math.sqrt(2.0))
            torch.nn.init.zeros_(layer.bias)


class Collector:
    """One rollout of PPO on a :class:`TaskVecEnv`: rsl-rl's ``act`` / ``process_env_step`` around the env step, with
    ManiSkill's bootstrapping: the reward of a step that ends an episode (truncated at the time limit, or terminated at
    success with partial resets, where ManiSkill's PPO bootstraps too: success is not an absorbing state of the task)
    gets ``gamma * V(final observation)``, the critic's value of the state the episode ended in, and the episode's
    return stops there (rsl-rl's ``dones``). Branch-free: the critic runs on every env's final observation (equal to
    the next observation where nothing ended). With ``sampling="sync-free"`` (:mod:`wpctrl.train.sampling`) the
    actions are drawn without rsl-rl's host sync, so nothing inside the rollout waits for the GPU: the host queues
    the next step while the GPU runs the current one."""

    def __init__(self, env: TaskVecEnv, alg, sampling: str = "sync-free"):
        if sampling not in SAMPLINGS:
            raise ValueError(f"Collector: sampling expected one of {SAMPLINGS}, got {sampling!r}")
        if sampling == "sync-free" and (why := sync_free(alg)):
            raise ValueError(f"Collector: sync-free sampling does not support {why}; use sampling='rsl-rl'")
        self.env = env
        self.alg = alg
        self.sampling = sampling
        self._act = (lambda obs: act(alg, obs)) if sampling == "sync-free" else alg.act

    def rollout(self, obs, steps: int):
        from tensordict import TensorDict

        alg, env = self.alg, self.env
        for _ in range(steps):
            actions = self._act(obs)
            obs, rewards, dones, extras = env.step(actions)
            final = TensorDict({"policy": extras["final_observations"]}, batch_size=[env.num_envs])
            value = alg.critic(final).squeeze(-1)
            rewards = rewards + alg.gamma * value * dones.to(value.dtype)
            alg.process_env_step(obs, rewards, dones, {})
        return obs


def evaluate_policy(policy, env, episodes: int, seed: int | None = None) -> dict:
    """``policy`` (flattened observations -> actions, torch) on fresh episodes of ``env`` (an env of
    :func:`wpctrl.tasks.make` with ``auto_reset=False`` and ``ignore_terminations=True``: every episode runs its
    ``max_episode_steps``, as ManiSkill's PPO evaluates), ``env.num_envs`` episodes at a time, until ``episodes`` have
    run. Returns the success rate (success at any step: ManiSkill's ``success_once``), the success rate at the last
    step (``success_at_end``), the mean return (sum of the env's rewards) and the mean first success step."""
    n = env.num_envs
    done, once, at_end, ret, first = 0, 0.0, 0.0, 0.0, []
    t = time.perf_counter()
    rounds = 0
    with torch.inference_mode():
        while done < episodes:
            obs, _ = env.reset(seed=None if seed is None else seed + rounds)
            rounds += 1
            hit = torch.zeros(n, dtype=torch.bool, device=env.device)
            first_step = torch.full((n,), -1, dtype=torch.int64, device=env.device)
            total = torch.zeros(n, device=env.device)
            for k in range(env.max_episode_steps):
                obs, reward, _, _, info = env.step(policy(obs))
                total += reward
                new = info["success"] & ~hit
                first_step = torch.where(new, k + 1, first_step)
                hit |= info["success"]
            m = min(n, episodes - done)
            once += float(hit[:m].float().sum())
            at_end += float(info["success"][:m].float().sum())
            ret += float(total[:m].sum())
            first += [s for s in first_step[:m].tolist() if s > 0]
            done += m
    return {
        "episodes": done,
        "success_rate": once / done,
        "success_at_end_rate": at_end / done,
        "mean_episode_reward": ret / done,
        "mean_first_success_step": sum(first) / len(first) if first else None,
        "eval_s": time.perf_counter() - t,
    }


def checkpoint_infos(env: TaskVecEnv, cfg: dict) -> dict:
    """What ``policy.pt`` records besides rsl-rl's state dicts, so that ``wpctrl export`` rebuilds the actor and
    refuses a mismatched task without the env."""
    from wpctrl.tasks import TASKS

    spec = TASKS[env.task]
    return {
        "format": "wpctrl-task-policy-1",
        "task": env.task,
        "control_mode": env.cfg["control_mode"],
        "obs_dim": env.num_obs,
        "num_actions": env.num_actions,
        "action_low": env.action_low.cpu().tolist(),
        "action_high": env.action_high.cpu().tolist(),
        "obs_fields": [[f.group, f.name, f.size] for f in spec.obs_fields],
        "substeps": env.substeps,
        "partial_reset": env.partial_reset,
        "actor": cfg["actor"],
    }


def train(args, t_main: float) -> int:
    """``python -m wpctrl train --task PushCube-v1 | PickCube-v1`` (``args`` from :func:`wpctrl.train.cli.parse`)."""
    import contextlib
    import io
    from pathlib import Path

    import warp as wp
    from rsl_rl.runners import OnPolicyRunner
    from tensordict import TensorDict

    import wpctrl.tasks as T

    from .logger import RunLogger
    from .outputs import fmt, median, plot, write_json
    from .resume import load_checkpoint

    device = args.device or ("cuda:0" if wp.is_cuda_available() else "cpu")
    cuda = device.startswith("cuda")
    envs = args.envs or (4096 if cuda else 64)
    iterations = args.iterations or (2000 if cuda else 20)
    steps = args.steps_per_env or STEPS_PER_ENV
    eval_envs = args.eval_envs or min(envs, 512)
    eval_episodes = args.eval_episodes or eval_envs
    control_mode = args.control_mode or "pd_joint_delta_pos"
    if control_mode not in T.CONTROL_MODES:
        print(f"wpctrl train: --control-mode: expected one of the Panda's modes {list(T.CONTROL_MODES)}, got "
              f"{control_mode!r}", file=sys.stderr)  # fmt: skip
        return 2
    ppo_update = args.ppo_update or ("captured" if cuda else "rsl-rl")
    if ppo_update == "captured" and not cuda:
        print(f"wpctrl train: --ppo-update: 'captured' needs a CUDA device, got --device {device}", file=sys.stderr)
        return 2
    sampling = args.action_sampling or "sync-free"
    if not cuda:
        # the networks' matrices are small: one thread, since OpenMP workers spin-waiting for a busy core slow each
        # update down tens of times on a shared CPU
        torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    t0 = time.perf_counter()
    graph = not args.no_graph
    print(f"wpctrl train: building {envs} {args.task} envs and {eval_envs} evaluation envs on {device} ...", flush=True)
    with compile_notice(f"Warp kernels for {args.task} on {device}", say=lambda msg: print(msg, flush=True)):
        env = TaskVecEnv(args.task, envs, device=device, control_mode=control_mode, seed=args.seed,
                         partial_reset=not args.no_partial_reset, substeps=args.substeps, graph=graph)  # fmt: skip
        eval_env = T.make(args.task, num_envs=eval_envs, device=device, control_mode=control_mode,
                          seed=args.seed + 10_000, auto_reset=False, ignore_terminations=True,
                          physics=T.TaskPhysics(substeps=env.substeps), graph=graph)  # fmt: skip
    cfg = maniskill_ppo_cfg(steps, args.epochs or EPOCHS, args.minibatches or MINIBATCHES, args.seed,
                            obs_normalization=args.obs_normalization == "on")  # fmt: skip
    with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl prints its observation sets and both networks
        runner = OnPolicyRunner(env, cfg, log_dir=None, device=device)
    alg = runner.alg
    maniskill_init(alg.actor, 0.01 * math.sqrt(2.0))
    maniskill_init(alg.critic, math.sqrt(2.0))
    for group in alg.optimizer.param_groups:
        group["eps"] = 1e-5  # ManiSkill's Adam
    resumed = getattr(args, "resumed", None)
    start = 0
    if resumed is not None:  # weights, normaliser, Adam's state and the iteration count of the run's checkpoint
        start = load_checkpoint(runner, args.resume, device, resumed, captured=ppo_update == "captured")
    if ppo_update == "captured":
        alg.update = CapturedUpdate(alg, graph=True)
    collector = Collector(env, alg, sampling)
    log = RunLogger(args.logger, out, cfg=cfg, env_cfg=env.cfg, start_iteration=start)
    setup_s = time.perf_counter() - t0
    print(f"wpctrl train: {args.task}, {envs} envs on {device} ({env.substeps} MuJoCo steps per physics step), "
          f"{control_mode}, evaluation on {eval_envs} envs, PPO update {ppo_update}, {sampling} action sampling; "
          f"set up in {setup_s:.1f} s",
          flush=True)  # fmt: skip

    def deterministic(obs):
        return alg.actor(TensorDict({"policy": obs}, batch_size=[obs.shape[0]]))

    eval_seed = args.seed + 10_000  # held-out episodes: a seed the training env never draws from

    def evaluation(it: int) -> dict:
        ev = evaluate_policy(deterministic, eval_env, eval_episodes, seed=eval_seed)
        ev.update(iteration=it, wall_s=wall0 + time.perf_counter() - t_start, env_steps=(it + 1) * envs * steps)
        evaluations.append(ev)
        log.evaluation(ev)
        print(f"       evaluation: success {ev['success_rate']:.3f} (at the end {ev['success_at_end_rate']:.3f}) "
              f"over {ev['episodes']} episodes, return {ev['mean_episode_reward']:.2f}", flush=True)  # fmt: skip
        return ev

    # a resumed run continues its history, evaluations and wall time
    history, evaluations = list(resumed["history"]) if resumed else [], list(resumed["evaluations"]) if resumed else []
    wall0, n_prev = max([r["wall_s"] for r in history[-1:] + evaluations[-1:]], default=0.0), len(evaluations)
    t_start = time.perf_counter()
    obs = env.get_observations()
    if args.eval_every and not resumed:
        evaluation(-1)  # the untrained policy: the curve's start
    alg.train_mode()
    stop = None
    for it in range(start, start + iterations):
        t_it = time.perf_counter()
        with torch.inference_mode():
            obs = collector.rollout(obs, steps)
            if cuda:
                torch.cuda.synchronize()
            collect_s = time.perf_counter() - t_it
            alg.compute_returns(obs)
        losses = alg.update()
        learn_s = time.perf_counter() - t_it - collect_s
        stats = env.take_stats()
        row = {"iteration": it, **{k: stats[k] for k in ("mean_episode_reward", "success_rate", "success_at_end_rate",
                                                          "mean_episode_length", "episodes", "mean_step_reward")},
               "collection_env_steps_per_s": envs * steps / collect_s, "collect_s": collect_s, "learn_s": learn_s,
               "env_steps": (it + 1) * envs * steps, "iteration_s": time.perf_counter() - t_it,
               "wall_s": wall0 + time.perf_counter() - t_start,
               "action_std": float(alg.get_policy().output_std.detach().mean()),
               "losses": {k: float(v) for k, v in losses.items()}}  # fmt: skip
        history.append(row)
        log.iteration(row, alg.learning_rate)
        print(f"[{it:4d}] step reward {fmt(row['mean_step_reward'])} episode reward {fmt(row['mean_episode_reward'])} "
              f"success {fmt(row['success_rate'])} collect {row['collection_env_steps_per_s']:,.0f} env-steps/s  "
              f"wall {row['wall_s']:.1f} s", flush=True)  # fmt: skip
        last_it = it + 1 == start + iterations
        over = args.time_limit is not None and time.perf_counter() - t_main >= args.time_limit
        if args.eval_every and (it + 1) % args.eval_every == 0 and not last_it and not over:
            ev = evaluation(it)
            if args.target_success is not None and ev["success_rate"] >= args.target_success:
                stop = "target"
                break
        if over:
            stop = "time_limit"
            break
    train_s = time.perf_counter() - t_start
    runner.current_learning_iteration = len(history)
    infos = checkpoint_infos(env, cfg)
    runner.save(str(out / "policy.pt"), infos=infos)
    last = evaluations[-1] if evaluations and evaluations[-1]["iteration"] == history[-1]["iteration"] else None
    if last is None:
        last = evaluation(history[-1]["iteration"])
    target = args.target_success
    reached = [e for e in evaluations[n_prev:] if target is not None and e["success_rate"] >= target]
    summary = {
        "task": args.task,
        "control_mode": control_mode,
        "envs": envs,
        "eval_envs": eval_envs,
        "device": device,
        "device_name": torch.cuda.get_device_name(torch.device(device)) if cuda else "cpu",
        "graph": env.graph is not None,
        "ppo_update": ppo_update,
        "action_sampling": sampling,
        "substeps": env.substeps,
        "partial_reset": env.partial_reset,
        "seed": args.seed,
        "iterations": len(history),
        "steps_per_env": steps,
        "env_steps": len(history) * envs * steps,
        "stopped_by": stop or "iterations",
        "import_s": t0 - t_main,
        "setup_s": setup_s,
        "train_wall_s": train_s,
        "total_s": time.perf_counter() - t_main,
        "collection_env_steps_per_s_median": median([h["collection_env_steps_per_s"] for h in history[1:] or history]),
        "target_success": target,
        "time_to_target_s": (t_start - t_main + reached[0]["wall_s"] - wall0) if reached else None,
        "env_steps_to_target": reached[0]["env_steps"] if reached else None,
        "resumed_from": {"run": str(args.resume), "iteration": start} if resumed else None,
        "logger": args.logger,
        "ppo": cfg,
        "checkpoint": infos,
        "history": history,
        "evaluations": evaluations,
        "evaluation": last,
    }
    write_json(out / "train.json", summary)
    plot(history, evaluations, out / "learning_curve.png",
         f"{args.task}, {envs} envs on {device}: {len(history)} iterations in {history[-1]['wall_s']:.0f} s",
         "success rate (success at any step)", window=envs)  # fmt: skip
    log.close()
    print(f"wrote {out / 'train.json'}, {out / 'learning_curve.png'}, {out / 'policy.pt'}", flush=True)
    if reached:
        first = reached[0]
        print(f"success {first['success_rate']:.3f} >= {target} after {summary['time_to_target_s']:.1f} s", flush=True)
    env.close()
    eval_env.close()
    return 0
