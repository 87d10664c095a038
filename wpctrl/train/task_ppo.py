"""PPO (rsl-rl) on ManiSkill's tasks through wpctrl (every task of :mod:`wpctrl.tasks`' registry: ``PushCube-v1``,
``PickCube-v1``, ``PullCube-v1``, ``StackCube-v1``, ...): ManiSkill's PPO baseline settings mapped onto rsl-rl, the
rollout with ManiSkill's bootstrapping at episode ends, and evaluations of the deterministic policy on fresh episodes
(``python -m wpctrl train --task PushCube-v1``; :class:`wpctrl.train.trainer.Trainer` runs the loop). Nothing here
depends on the task: its observation width, action space and episode length come from the task's env.

ManiSkill's baseline (``examples/baselines/ppo/ppo_fast.py`` and its ``baselines.sh``: 4,096 envs, 4 steps per env
and iteration, 8 epochs of 32 mini-batches, gamma 0.8, lambda 0.9, learning rate 3e-4, clip 0.2, no value clipping,
no entropy bonus, gradient norm 0.5, advantages normalised per mini-batch, 3 x 256 tanh actor and critic with
orthogonal initialisation, log-std parameter starting at 0) is :func:`maniskill_ppo_cfg`; docs/training.md lists
what transfers to rsl-rl and what does not. A task whose ManiSkill recipe departs from it (StackCube-v1's 16 steps per
env) says so in :data:`wpctrl.train.ppo_config.TASK_RECIPES`, which the configuration's defaults read.
"""

from __future__ import annotations

import math

import torch

from .policy_eval import evaluate_policy
from .ppo_config import MANISKILL_EPOCHS as EPOCHS
from .ppo_config import MANISKILL_MINIBATCHES as MINIBATCHES
from .ppo_config import MANISKILL_STEPS_PER_ENV as STEPS_PER_ENV
from .ppo_config import runner_cfg, task_recipe
from .ppo_update import CapturedUpdate
from .sampling import SAMPLINGS, act, sync_free
from .task_env import TaskVecEnv

__all__ = ["Collector", "ManiSkillTraining", "checkpoint_infos", "evaluate_policy", "maniskill_init",
           "maniskill_ppo_cfg"]  # fmt: skip

EVAL_SEED = 10_000
"""Added to the run's seed for the evaluation env: episodes the training env never draws."""


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


def checkpoint_infos(env: TaskVecEnv, cfg: dict) -> dict:
    """What ``policy.pt`` records besides rsl-rl's state dicts, so that ``wpctrl export`` rebuilds the actor and
    refuses a mismatched task without the env."""
    from wpctrl.tasks import TASKS

    spec = TASKS[env.task]
    return {
        "format": "wpctrl-task-policy-1",
        "task": env.task,
        "control_mode": env.cfg["control_mode"],
        "robot_uids": env.env.robot_uids,
        "obs_dim": env.num_obs,
        "num_actions": env.num_actions,
        "action_low": env.action_low.cpu().tolist(),
        "action_high": env.action_high.cpu().tolist(),
        "obs_fields": [[f.group, f.name, f.size] for f in spec.obs_fields],
        "hidden_obs": list(env.hidden_columns),
        "max_episode_steps": env.max_episode_length,
        "substeps": env.substeps,
        "partial_reset": env.partial_reset,
        "actor": cfg["actor"],
    }


class ManiSkillTraining:
    """A ManiSkill task (any of :data:`~wpctrl.train.train_config.MANISKILL_TASKS`) as the trainer's loop drives it
    (``cfg``: a resolved :class:`~wpctrl.train.train_config.TrainConfig`): a :class:`TaskVecEnv` to train on and a
    separate evaluation env (every episode runs the task's ``max_episode_steps``, on held-out seeds), ManiSkill's
    initialisation and Adam, the captured PPO update where asked, and :class:`Collector`'s rollout."""

    success_label = "success rate (success at any step)"
    evaluates_untrained = True

    def __init__(self, cfg):
        self.cfg = cfg
        self.builds = f"{cfg.envs} {cfg.task} envs and {cfg.eval_envs} evaluation envs"
        self.captured_update = cfg.ppo_update == "captured"
        self.env = self.eval_env = self.alg = self.collector = None

    def build(self) -> None:
        import wpctrl.tasks as T

        c = self.cfg
        if not c.device.startswith("cuda"):
            # the networks' matrices are small: one thread, since OpenMP workers spin-waiting for a busy core slow each
            # update down tens of times on a shared CPU
            torch.set_num_threads(1)
        graph = not c.no_graph
        self.env = TaskVecEnv(c.task, c.envs, device=c.device, control_mode=c.control_mode, seed=c.seed,
                              partial_reset=not c.no_partial_reset, substeps=c.substeps, graph=graph,
                              hide_obs=c.hide_obs, randomize=c.randomize, robot_uids=c.robot_uids)  # fmt: skip
        self.eval_env = T.make(c.task, num_envs=c.eval_envs, device=c.device, control_mode=c.control_mode,
                               seed=c.seed + EVAL_SEED, auto_reset=False, ignore_terminations=True,
                               physics=self.env.physics, graph=graph, robot_uids=self.env.env.robot_uids)  # fmt: skip

    def ppo_cfg(self) -> dict:
        c = self.cfg
        return maniskill_ppo_cfg(c.steps_per_env, c.epochs, c.minibatches, c.seed,
                                 obs_normalization=c.obs_normalization == "on")  # fmt: skip

    def init_networks(self, alg) -> None:
        """ManiSkill's orthogonal initialisation and Adam's epsilon (before a resumed run's checkpoint loads)."""
        maniskill_init(alg.actor, 0.01 * math.sqrt(2.0))
        maniskill_init(alg.critic, math.sqrt(2.0))
        for group in alg.optimizer.param_groups:
            group["eps"] = 1e-5  # ManiSkill's Adam

    def attach(self, runner) -> None:
        self.alg = alg = runner.alg
        if self.captured_update:
            alg.update = CapturedUpdate(alg, graph=True)
        self.collector = Collector(self.env, alg, self.cfg.action_sampling)

    def describe(self) -> str:
        c = self.cfg
        return (f"{c.task}, {c.envs} envs on {c.device} ({self.env.substeps} MuJoCo steps per physics step), "
                f"{c.control_mode} on {self.env.env.robot_uids}, "
                f"hiding {c.hide_obs}, randomising {c.randomize}, evaluation on {c.eval_envs} envs, "
                f"PPO update {c.ppo_update}, "
                f"{c.action_sampling} action sampling")  # fmt: skip

    def start(self, seed: int):
        return self.env.get_observations()

    def rollout(self, obs, steps: int):
        return self.collector.rollout(obs, steps)

    def evaluate(self) -> dict:
        from tensordict import TensorDict

        def deterministic(obs):
            return self.alg.actor(TensorDict({"policy": self.env.hide(obs)}, batch_size=[obs.shape[0]]))

        # held-out episodes: a seed the training env never draws from
        return evaluate_policy(deterministic, self.eval_env, self.cfg.eval_episodes, seed=self.cfg.seed + EVAL_SEED)

    def after_evaluation(self, obs, seed: int):
        return obs  # evaluated on its own env: the training episodes go on

    def summary(self) -> dict:
        c = self.cfg
        return {"eval_envs": c.eval_envs, "ppo_update": c.ppo_update, "action_sampling": c.action_sampling,
                "substeps": self.env.substeps, "partial_reset": self.env.partial_reset,
                "max_episode_steps": self.env.max_episode_length, "obs_dim": self.env.num_obs,
                "robot_uids": self.env.env.robot_uids, "hide_obs": c.hide_obs,
                "hidden_obs": list(self.env.hidden_columns), "randomize": c.randomize,
                "recipe": task_recipe(c.task)}  # fmt: skip

    def checkpoint_infos(self, ppo: dict) -> dict:
        return checkpoint_infos(self.env, ppo)

    def close(self) -> None:
        self.env.close()
        self.eval_env.close()
