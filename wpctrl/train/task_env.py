"""ManiSkill's table-top tasks (:mod:`wpctrl.tasks`) as an rsl-rl ``VecEnv``, with the final observation of every
ended episode kept for bootstrapping and the episode statistics summed on the device.

The wrapped env is :func:`wpctrl.tasks.make`'s, with ``ManiSkillVectorEnv``'s semantics: finished envs are reset
inside ``step`` (``auto_reset``), so the observation ``step`` returns for such an env is its new episode's first; the
observation the episode ended with is ``extras["final_observations"]``. With ``partial_reset`` (ManiSkill's PPO
default) an env's episode ends at success (a termination) or after ``max_episode_steps`` (a truncation); without it
success does not end an episode (``ignore_terminations``) and every episode runs to the time limit.

Bootstrapping is left to the training loop (:class:`~wpctrl.train.task_ppo.Collector`): rsl-rl's own ``time_outs``
rule adds ``gamma * V(s_t)`` (the value of the observation *before* the last step) to the reward of a timed-out
step; ManiSkill's PPO adds ``gamma * V(final observation)``, which this env provides. So ``extras`` carries no
``"time_outs"`` key and rsl-rl bootstraps nothing by itself.
"""

from __future__ import annotations

import torch
from rsl_rl.env import VecEnv

STAT_KEYS = ("episodes", "return", "success_once", "success_at_end", "length", "env_steps", "reward")
"""What :meth:`TaskVecEnv.take_stats` sums on the device (index order of its buffer)."""


class TaskVecEnv(VecEnv):
    """An env of :func:`wpctrl.tasks.make` (``obs_mode="state"``) for rsl-rl: observation group ``"policy"`` is
    ManiSkill's flattened state vector, its hidden columns zeroed (``hide_obs``).

    Args:
        task: A task id of :data:`wpctrl.tasks.TASKS` (``"PushCube-v1"``, ``"StackCube-v1"``, ...): its observation
            width, action space and ``max_episode_steps`` are the task's own.
        num_envs: Parallel envs.
        device: Warp / torch device.
        control_mode: A Panda control mode of ManiSkill (its PPO baseline uses ``pd_joint_delta_pos``).
        reward_mode: ManiSkill's reward mode (``normalized_dense`` for PPO).
        seed: Seed of the episode draws.
        partial_reset: Success ends an episode (ManiSkill's PPO default); False: episodes end only at the time limit.
        substeps: MuJoCo-Warp steps per physics step (None: the task's physics' own, :func:`wpctrl.tasks.task_physics`).
        graph: Capture the env step in a graph (default: True).
        hide_obs: Observation entries the policy and critic see as zeros (:mod:`wpctrl.train.hidden_inputs`:
            ``"finger_qvel"``, ``"none"``; None: the default, ``"finger_qvel"``).
        randomize: Per-env physics drawn at every reset (:func:`wpctrl.tasks.randomization.from_spec`: ``"on"``,
            ``"friction=0.7:1.3,..."``; None or ``"off"``: none).
    """

    def __init__(
        self,
        task: str,
        num_envs: int,
        device="cpu",
        control_mode: str = "pd_joint_delta_pos",
        reward_mode: str = "normalized_dense",
        seed: int = 0,
        partial_reset: bool = True,
        substeps: int | None = None,
        graph: bool | None = None,
        asset_dir: str | None = None,
        hide_obs: str | None = None,
        randomize: str | None = None,
        robot_uids: str | None = None,
    ):
        import wpctrl.tasks as T
        from wpctrl.tasks.randomization import from_spec

        from .actor import HiddenInputs
        from .hidden_inputs import DEFAULT_HIDE_OBS, hidden_columns

        physics = T.task_physics(task, substeps)
        self.env = T.make(task, num_envs=num_envs, device=device, control_mode=control_mode, obs_mode="state",
                          reward_mode=reward_mode, seed=seed, auto_reset=True,
                          ignore_terminations=not partial_reset, physics=physics, asset_dir=asset_dir,
                          graph=graph, randomization=from_spec(randomize or "off"), robot_uids=robot_uids)  # fmt: skip
        self.task = task
        self.num_envs = self.env.num_envs
        self.num_actions = int(self.env.single_action_space.shape[0])
        self.num_obs = int(self.env.single_observation_space.shape[0])
        self.max_episode_length = int(self.env.max_episode_steps)
        self.device = self.env.device
        self.partial_reset = bool(partial_reset)
        self.physics = physics
        """The env's :class:`~wpctrl.tasks.TaskPhysics`: the task's own (:func:`wpctrl.tasks.task_physics`)."""
        self.substeps = physics.substeps
        self.hide_obs = hide_obs or DEFAULT_HIDE_OBS
        self.hidden_columns = hidden_columns(task, self.hide_obs)
        self.cfg = {"task": task, "num_envs": self.num_envs, "control_mode": control_mode, "reward_mode": reward_mode,
                    "partial_reset": self.partial_reset, "substeps": physics.substeps,
                    "hide_obs": self.hide_obs, "randomize": randomize or "off",
                    "robot_uids": self.env.robot_uids}  # fmt: skip
        self.action_low = torch.as_tensor(self.env.single_action_space.low, device=self.device)
        self.action_high = torch.as_tensor(self.env.single_action_space.high, device=self.device)
        n = self.num_envs
        self._hidden = HiddenInputs(self.num_obs, self.hidden_columns).to(self.device) if self.hidden_columns else None
        self._obs = torch.zeros(n, self.num_obs, device=self.device)
        self._return = torch.zeros(n, device=self.device)
        self._success_once = torch.zeros(n, dtype=torch.bool, device=self.device)
        self._stats = torch.zeros(len(STAT_KEYS), device=self.device, dtype=torch.float64)
        self._n = torch.full((), float(n), device=self.device, dtype=torch.float64)  # no host copy inside step
        self.reset(seed=seed)

    @property
    def graph(self):
        return self.env.graph

    # -- rsl-rl's VecEnv ----------------------------------------------------------------------------------------------

    @property
    def episode_length_buf(self) -> torch.Tensor:
        """(num_envs,) int32 torch view of each env's step in its episode (the buffer the env's kernels count in)."""
        return self.env.elapsed_steps

    @episode_length_buf.setter
    def episode_length_buf(self, value) -> None:
        # rsl-rl's learn(init_at_random_ep_len=True) assigns a new tensor: copy it into the device buffer
        self.env.elapsed_steps.copy_(value)

    def hide(self, obs: torch.Tensor) -> torch.Tensor:
        """``obs`` with the hidden columns zeroed (a new tensor; ``obs`` itself unchanged), by the module the exported
        policy zeroes them with (:class:`~wpctrl.train.actor.HiddenInputs`)."""
        return obs if self._hidden is None else self._hidden(obs)

    def get_observations(self):
        from tensordict import TensorDict

        return TensorDict({"policy": self._obs.clone()}, batch_size=[self.num_envs])

    def reset(self, seed: int | None = None):
        """Every env starts a new episode; their first observations. Episode statistics restart."""
        obs, _ = self.env.reset(seed=seed)
        self._obs.copy_(self.hide(obs))
        self._return.zero_()
        self._success_once.zero_()
        return self.get_observations()

    def step(self, actions: torch.Tensor):
        """One control step of every env (actions clipped to the action space, as ManiSkill's controllers clip them).

        Returns ``obs, rewards, dones, extras``: ``dones`` = terminated or truncated; ``extras["final_observations"]``
        the observation each env's step ended in (before the auto reset; equal to ``obs`` where not done),
        ``extras["terminated"]`` / ``extras["truncated"]``, ``extras["success"]`` (of the state the step ended in).
        """
        from tensordict import TensorDict

        a = torch.max(torch.min(actions, self.action_high), self.action_low)
        obs, reward, terminated, truncated, info = self.env.step(a)
        final = info["final_info"]
        dones = terminated | truncated
        success = final["success"]
        self._return += reward
        self._success_once |= success
        d = dones.to(self._stats.dtype)
        add = torch.stack([
            d.sum(),
            (self._return * d).sum(),
            (self._success_once.to(d.dtype) * d).sum(),
            (success.to(d.dtype) * d).sum(),
            (final["elapsed_steps"].to(d.dtype) * d).sum(),
            self._n,
            reward.to(d.dtype).sum(),
        ])  # fmt: skip
        self._stats += add
        self._return.masked_fill_(dones, 0.0)
        self._success_once.masked_fill_(dones, False)
        obs = self.hide(obs)
        self._obs.copy_(obs)
        extras = {"final_observations": self.hide(info["final_observation"]), "terminated": terminated,
                  "truncated": truncated, "success": success}  # fmt: skip
        return TensorDict({"policy": obs}, batch_size=[self.num_envs]), reward, dones, extras

    def take_stats(self) -> dict:
        """Since the last call (one host read): finished episodes, their mean return, success-once and
        success-at-end rates and mean length; env steps and their mean reward."""
        s = self._stats.cpu().tolist()
        self._stats.zero_()
        v = dict(zip(STAT_KEYS, s))
        n = v["episodes"]
        per = lambda k: v[k] / n if n else None  # noqa: E731
        return {
            "episodes": int(n),
            "mean_episode_reward": per("return"),
            "success_rate": per("success_once"),
            "success_at_end_rate": per("success_at_end"),
            "mean_episode_length": per("length"),
            "env_steps": int(v["env_steps"]),
            "mean_step_reward": v["reward"] / v["env_steps"] if v["env_steps"] else None,
        }

    def close(self) -> None:
        self.env.close()
