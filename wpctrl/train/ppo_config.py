"""rsl-rl's runner configuration: the one skeleton both PPO setups fill (the reach task's Isaac Lab settings in
:func:`wpctrl.train.reach_ppo.train_cfg`, the ManiSkill tasks' baseline settings in
:func:`wpctrl.train.task_ppo.maniskill_ppo_cfg`), and the ManiSkill tasks' recipe: one for every task, with the
departures of a task from it as data (:data:`TASK_RECIPES`)."""

from __future__ import annotations

MANISKILL_STEPS_PER_ENV = 4
MANISKILL_EPOCHS = 8
MANISKILL_MINIBATCHES = 32
"""ManiSkill's PPO baseline: steps per env and iteration, epochs, mini-batches per epoch (:mod:`.task_ppo`)."""

TASK_RECIPES: dict[str, dict] = {
    "PushCube-v1": {"maniskill_env_steps": 5_000_000},
    "PickCube-v1": {"maniskill_env_steps": 5_000_000},
    "PullCube-v1": {"maniskill_env_steps": 5_000_000},
    "LiftPegUpright-v1": {"maniskill_env_steps": 8_000_000},
    "StackCube-v1": {"steps_per_env": 16, "maniskill_env_steps": 50_000_000},
}
"""Where a task's PPO recipe departs from the one above, as data: ManiSkill's own recipes for its fast PPO
(``scripts/data_generation/rl.sh``: ``ppo_fast.py`` with 4,096 envs, 8 epochs of 32 mini-batches, gamma 0.8, lambda
0.9 for every task here; 4 steps per env and iteration, StackCube-v1 16). ``maniskill_env_steps``: the env steps that
recipe trains for (``--total_timesteps``), recorded for comparison; it sets nothing. A task not listed (a task
registered later, PegInsertionSide-v1, for which ManiSkill publishes no fast recipe) trains with the defaults. The
trainer reads a task's settings through :func:`task_recipe` alone."""

RECIPE_KEYS = ("steps_per_env", "epochs", "minibatches", "maniskill_env_steps")


def task_recipe(task: str) -> dict:
    """``task``'s PPO settings: ``steps_per_env``, ``epochs``, ``minibatches`` (ManiSkill's defaults overridden by
    :data:`TASK_RECIPES`) and ``maniskill_env_steps`` (None where ManiSkill's recipe names none)."""
    recipe = {"steps_per_env": MANISKILL_STEPS_PER_ENV, "epochs": MANISKILL_EPOCHS,
              "minibatches": MANISKILL_MINIBATCHES, "maniskill_env_steps": None}  # fmt: skip
    recipe.update(TASK_RECIPES.get(task, {}))
    return recipe


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


def batch_error(envs: int, steps: int, minibatches: int, min_samples: int, minibatch_flag: str | None,
                name=lambda key: "--" + key.replace("_", "-")) -> str | None:  # fmt: skip
    """Why a rollout of ``envs`` x ``steps`` samples cannot be split into ``minibatches`` mini-batches of at least
    ``min_samples`` samples each (rsl-rl's mini-batch is ``batch // minibatches`` samples), naming the flags that
    fix it (``name``: a setting's name as the caller shows it); None when it can. ``minibatch_flag``: the option
    that sets the mini-batch count, None when fixed."""
    batch = envs * steps
    per = batch // minibatches
    if per >= min_samples:
        return None
    need = min_samples * minibatches
    split = f"{minibatch_flag} {minibatches} mini-batches" if minibatch_flag else f"{minibatches} mini-batches (fixed)"
    if min_samples >= 2:
        why = (
            f"PPO normalises the advantages per mini-batch, and their std needs at least {min_samples} samples per "
            "mini-batch (the std of one sample is undefined: NaN, and training ends in a NaN policy)"
        )
    else:
        why = f"PPO needs at least {min_samples} sample per mini-batch (an empty one makes the losses NaN)"
    envs_, steps_ = name("envs"), name("steps_per_env")
    fixes = [f"raise {envs_} to {-(-need // steps)}", f"{steps_} to {-(-need // envs)}"]
    if minibatch_flag and batch >= min_samples:
        fixes.append(f"lower {minibatch_flag} to {batch // min_samples}")
    return (
        f"{envs_} {envs} x {steps_} {steps} = a batch of {batch} samples per iteration, split into "
        f"{split}, leaves {per} sample{'s' * (per != 1)} per mini-batch; {why}. "
        f"The rule: envs x steps per env >= {min_samples} x mini-batches = {need}. Fix: "
        f"{', or '.join(fixes)}"
    )
