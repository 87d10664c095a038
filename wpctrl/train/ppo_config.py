"""rsl-rl's runner configuration: the one skeleton both PPO setups fill (the reach task's Isaac Lab settings in
:func:`wpctrl.train.cli.train_cfg`, the ManiSkill tasks' baseline settings in
:func:`wpctrl.train.task_ppo.maniskill_ppo_cfg`)."""

from __future__ import annotations


def runner_cfg(*, seed: int, num_steps_per_env: int, algorithm: dict, mlp: dict, distribution: dict) -> dict:
    """rsl-rl's ``OnPolicyRunner`` configuration: PPO with ``algorithm``'s settings, actor and critic the same
    ``mlp`` (the actor with the Gaussian ``distribution``), both reading the ``policy`` observations; no periodic
    checkpoints (the training commands save their own), no NaN check."""
    return {
        "seed": seed,
        "num_steps_per_env": num_steps_per_env,
        "save_interval": 10**9,
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "algorithm": {"class_name": "PPO", **algorithm},
        "actor": dict(mlp, distribution_cfg={"class_name": "GaussianDistribution", **distribution}),
        "critic": dict(mlp),
        "check_for_nan": False,
    }
