"""A policy on fresh episodes of a :func:`wpctrl.tasks.make` env: the evaluation ``wpctrl train`` runs on the
ManiSkill tasks and ``wpctrl evaluate --sim newton`` runs on an exported policy. Needs torch alone (no rsl-rl)."""

from __future__ import annotations

import time

import torch

__all__ = ["evaluate_policy"]


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
