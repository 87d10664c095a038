"""Mutations: randomness."""

from .model import M

MUTATIONS = [
    M(
        "randomize_ignores_seed",
        "wpctrl/controllers/drive_properties.py",
        'drive.randomize(eng, lo, hi, enabled, mode == "abs", int(seed),',
        'drive.randomize(eng, lo, hi, enabled, mode == "abs", 0,',
        "randomize_drive_properties ignores its seed",
        ("tests/test_actuation.py",),
    ),
    M(
        "randomize_same_draw_every_env",
        "wpctrl/engine/parts/drive_properties.py",
        "state = wp.rand_init(key, env * drive.kp.shape[1] + r)",
        "state = wp.rand_init(key, r)",
        "randomize_drive_properties draws the same values for every env",
        ("tests/test_actuation.py",),
    ),
    M(
        "delay_draw_ignores_seed",
        "wpctrl/kernels/pd.py",
        "st = wp.rand_init(seed, rng_counter_in[0])",
        "st = wp.rand_init(0, rng_counter_in[0])",
        "the per-env delay draw ignores the build's seed",
        ("tests/test_actuation.py",),
    ),
]
