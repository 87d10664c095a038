"""Training a policy through wpctrl: rsl-rl's PPO on vectorised Newton tasks (``python -m wpctrl train``).

Needs the ``train`` extra (rsl-rl-lib, torch); imported only by that command. :class:`~wpctrl.train.reach.ReachEnv`
is the reach task as an rsl-rl ``VecEnv`` whose whole step is one CUDA graph on a GPU.
"""
