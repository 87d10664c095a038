"""Mutations: the first hour: refusals, the stability warning, resume and the learning curve."""

from .model import M

MUTATIONS = [
    M(
        "papercut_unknown_reset_option_accepted",
        "wpctrl/tasks/_validate.py",
        '    if unknown:\n        raise ConfigError(f"reset: unknown options key(s)',
        '    if False:\n        raise ConfigError(f"reset: unknown options key(s)',
        "reset(options=...) drops unknown keys silently",
        ("tests/test_papercuts.py::test_task_env_repr_names_the_task_and_reset_refuses_unknown_options",),
    ),
    M(
        "papercut_batch_rule_off_by_one",
        "wpctrl/train/ppo_config.py",
        "    if per >= min_samples:\n",
        "    if per >= min_samples - 1:\n",
        "a mini-batch of one sample (an undefined advantage std) passes the batch check",
        ("tests/test_papercuts.py::test_batch_too_small_for_the_minibatches_is_refused_before_building",),
    ),
    M(
        "stability_damping_term_single",
        "wpctrl/controllers/stability.py",
        "    bad = np.flatnonzero(a + 2.0 * b >= STABILITY_BOUND)\n",
        "    bad = np.flatnonzero(a + b >= STABILITY_BOUND)\n",
        "the explicit-PD stability bound counts the damping term once (Kp dt^2/m + Kd dt/m < 4)",
        ("tests/test_papercuts.py::test_one_dof_diverges_just_past_the_bound_and_not_below",),
    ),
    M(
        "delay_seed_alias_dropped",
        "wpctrl/controllers/build.py",
        "        delay_seed = seed\n",
        "        pass\n",
        "the deprecated seed= no longer seeds the delay draws",
        ("tests/test_papercuts.py::test_delay_seed_names_the_delay_and_seed_is_its_deprecated_alias",),
    ),
    M(
        "resume_conflicting_flag_accepted",
        "wpctrl/train/resume.py",
        "        if name in given and mine != value:\n",
        '        if name in given and mine != value and name == "task":\n',
        "--resume takes a conflicting --envs or --control-mode silently",
        ("tests/test_train_outputs.py::test_resume_refuses_flags_that_contradict_the_run",),
    ),
    M(
        "curve_smoothing_unweighted",
        "wpctrl/train/outputs.py",
        "            w = min(n, need)\n",
        "            w = min(1, need)\n",
        "the learning curve weighs every iteration alike, not by its finished episodes",
        ("tests/test_train_outputs.py::test_success_smoothing_weighs_iterations_by_their_finished_episodes",),
    ),
]
