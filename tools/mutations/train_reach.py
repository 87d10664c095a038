"""Mutations: training: the reach task."""

from .model import M

MUTATIONS = [
    M(
        "reach_success_inverted",
        "wpctrl/train/task_kernels.py",
        "if d < success_radius:",
        "if d > success_radius:",
        "the reach task counts an episode as a success when the TCP ends outside the radius",
        ("tests/test_reach_success.py",),
    ),
    M(
        "reach_success_radius_doubled",
        "wpctrl/train/task_kernels.py",
        "if d < success_radius:",
        "if d < 2.0 * success_radius:",
        "the reach task's success radius is twice the configured one",
        ("tests/test_reach_success.py",),
    ),
    M(
        "reach_episode_one_step_long",
        "wpctrl/train/task_kernels.py",
        "end = n >= max_steps",
        "end = n > max_steps",
        "a reach episode lasts episode_steps + 1 control steps",
        ("tests/test_reach_success.py", "tests/test_train.py"),
    ),
    M(
        "reach_start_noise_ignored",
        "wpctrl/train/task_kernels.py",
        "q = q + noise * (2.0 * wp.randf(rng) - 1.0)",
        "q = q",
        "reach episodes start exactly at the rest pose whatever start_noise says",
        ("tests/test_reach_success.py",),
    ),
    M(
        "reach_seed_ignored",
        "wpctrl/train/task_kernels.py",
        "rng = wp.rand_init(seed, counter[0] * 1000003 + e)",
        "rng = wp.rand_init(0, counter[0] * 1000003 + e)",
        "the reach task's start poses and goals ignore the env's seed",
        ("tests/test_reach_success.py",),
    ),
    M(
        "evaluate_success_unweighted",
        "wpctrl/train/reach_ppo.py",
        'successes += (s["success_rate"] or 0.0) * s["episodes"]',
        'successes += s["success_rate"] or 0.0',
        "the evaluation averages the success rates of its rounds without their episode counts",
        ("tests/test_reach_success.py",),
    ),
    M(
        "coupled_beside_effort_rows_accepted",
        "wpctrl/engine/plan.py",
        "    if a.coupled and (rows.kind == ROW_EFFORT).any():\n",
        "    if a.coupled and False:\n",
        "the coupled drive is accepted beside an effort controller, whose torques it then overwrites",
        ("tests/test_options.py::test_an_effort_controller_beside_an_explicit_drive_keeps_its_torque",),
    ),
]
