"""Mutations: PPO on the ManiSkill tasks, export, evaluate."""

from .model import M

MUTATIONS = [
    M(
        "rollout_bootstraps_the_next_episode",
        "wpctrl/train/task_ppo.py",
        'final = TensorDict({"policy": extras["final_observations"]}, batch_size=[env.num_envs])',
        'final = TensorDict({"policy": obs}, batch_size=[env.num_envs])',
        "an episode end is bootstrapped with the value of the next episode's first observation, not its final one",
        (
            "tests/test_train_tasks.py::test_rollout_bootstraps_every_episode_end_with_the_critics_value_of_its_final_observation",
        ),
    ),
    M(
        "rollout_bootstraps_only_time_outs",
        "wpctrl/train/task_ppo.py",
        "rewards = rewards + alg.gamma * value * dones.to(value.dtype)",
        'rewards = rewards + alg.gamma * value * extras["truncated"].to(value.dtype)',
        "a successful episode's end is not bootstrapped (ManiSkill's PPO bootstraps every end under partial resets)",
        (
            "tests/test_train_tasks.py::test_rollout_bootstraps_every_episode_end_with_the_critics_value_of_its_final_observation",
        ),
    ),
    M(
        "captured_update_skips_advantage_normalisation",
        "wpctrl/train/ppo_update.py",
        "if alg.normalize_advantage_per_mini_batch:",
        "if False:",
        "the captured PPO step skips the per-mini-batch advantage normalisation rsl-rl's update does",
        ("tests/test_ppo_update.py::test_eager_update_is_rsl_rls_on_the_cpu",),
    ),
    M(
        "captured_update_clips_the_actor_only",
        "wpctrl/train/ppo_update.py",
        "torch.nn.utils.clip_grad_norm_(alg.critic.parameters(), alg.max_grad_norm)",
        "pass",
        "the captured PPO step leaves the critic's gradient norm unclipped",
        ("tests/test_ppo_update.py::test_eager_update_is_rsl_rls_on_the_cpu",),
    ),
    M(
        "sync_free_sampling_ignores_the_std",
        "wpctrl/train/sampling.py",
        "t.actions = (mean + actor.distribution.std * torch.randn_like(mean)).detach()",
        "t.actions = (mean + torch.randn_like(mean)).detach()",
        "the sync-free sampler draws with unit standard deviation instead of the policy's",
        ("tests/test_sampling.py::test_act_stores_rsl_rls_transition",),
    ),
    M(
        "sync_free_sampling_log_prob_of_the_mean",
        "wpctrl/train/sampling.py",
        "t.actions_log_prob = actor.get_output_log_prob(t.actions).detach()",
        "t.actions_log_prob = actor.get_output_log_prob(mean).detach()",
        "the sync-free sampler stores the log-probability of the mean, not of the sampled action",
        ("tests/test_sampling.py::test_act_stores_rsl_rls_transition",),
    ),
    M(
        "collector_always_uses_rsl_rl_sampling",
        "wpctrl/train/task_ppo.py",
        'self._act = (lambda obs: act(alg, obs)) if sampling == "sync-free" else alg.act',
        "self._act = alg.act",
        "the rollout ignores sync-free sampling and keeps rsl-rl's act (a host sync per step on CUDA)",
        ("tests/test_sampling.py::test_sync_free_rollout_never_calls_torch_normal",),
    ),
    M(
        "task_ppo_normalises_observations_by_default",
        "wpctrl/train/train_config.py",
        'obs_normalization=self.obs_normalization or "off",',
        'obs_normalization=self.obs_normalization or "on",',
        "the ManiSkill tasks' PPO normalises observations by default (ManiSkill's PPO reads them raw)",
        ("tests/test_train_tasks.py::test_ppo_learns_pushcube_on_the_cpu",),
    ),
    M(
        "task_evaluation_success_at_end_as_once",
        "wpctrl/train/policy_eval.py",
        "once += float(hit[:m].float().sum())",
        'once += float(info["success"][:m].float().sum())',
        "a task evaluation's success rate counts success at the last step, not success at any step",
        ("tests/test_train_tasks.py::test_evaluation_counts_success_at_any_step_and_at_the_last_separately",),
    ),
]
