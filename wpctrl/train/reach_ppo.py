"""PPO (rsl-rl) on the reach task (:class:`~wpctrl.train.reach.ReachEnv`) as :class:`~wpctrl.train.trainer.Trainer`
runs it: Isaac Lab's settings for its Franka reach (:func:`train_cfg`), rsl-rl's own rollout (its ``time_outs``
bootstrapping), and evaluations of the deterministic policy on the training env's fresh episodes.

Imports nothing heavy until used: :func:`train_cfg` is a plain dict.
"""

from __future__ import annotations

import time

from .ppo_config import runner_cfg
from .train_config import REACH_MINIBATCHES, REACH_STEPS_PER_ENV

__all__ = ["ReachTraining", "evaluate", "train_cfg"]


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


def start_episodes(env, seed: int):
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


class ReachTraining:
    """The reach task as the trainer's loop drives it (``cfg``: a resolved
    :class:`~wpctrl.train.train_config.TrainConfig`). It evaluates on its training env, so every evaluation restarts
    the training episodes after it."""

    success_label = "success rate (TCP within 2.5 cm)"
    captured_update = False
    evaluates_untrained = False

    def __init__(self, cfg):
        self.cfg = cfg
        self.builds = f"{cfg.envs} reach envs"
        self.env = self.alg = self.runner = None

    def build(self) -> None:
        from .reach import ReachEnv

        c = self.cfg
        self.env = ReachEnv(c.envs, device=c.device, control_mode=c.control_mode, seed=c.seed,
                            graph=c.device.startswith("cuda") and not c.no_graph)  # fmt: skip

    def ppo_cfg(self) -> dict:
        return train_cfg(self.cfg.steps_per_env, self.cfg.seed)

    def init_networks(self, alg) -> None:
        """rsl-rl's own initialisation is the reach's."""

    def attach(self, runner) -> None:
        self.runner, self.alg = runner, runner.alg

    def describe(self) -> str:
        return f"{self.cfg.envs} envs on {self.cfg.device}, {self.cfg.control_mode}"

    def start(self, seed: int):
        return start_episodes(self.env, seed)

    def rollout(self, obs, steps: int):
        """rsl-rl's ``OnPolicyRunner.learn`` rollout (its ``time_outs`` bootstrapping)."""
        alg, env = self.alg, self.env
        for _ in range(steps):
            obs, rewards, dones, extras = env.step(alg.act(obs))
            alg.process_env_step(obs, rewards, dones, extras)
        return obs

    def evaluate(self) -> dict:
        return evaluate(self.env, self.runner, self.cfg.eval_episodes)

    def after_evaluation(self, obs, seed: int):
        """The evaluation ran on the training env: new training episodes, the policy back in training mode."""
        obs = start_episodes(self.env, seed)
        self.alg.train_mode()
        return obs

    def summary(self) -> dict:
        return {}

    def checkpoint_infos(self, ppo: dict) -> dict | None:
        return None

    def close(self) -> None:
        pass
