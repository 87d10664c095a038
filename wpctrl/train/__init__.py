"""Training a policy through wpctrl: rsl-rl's PPO on vectorised Newton tasks.

From Python, :class:`TrainConfig` (one field per ``wpctrl train`` option) and :class:`Trainer` (``Trainer(cfg).run()``
returns the run directory); from the shell, ``python -m wpctrl train``. Training needs the ``train`` extra
(rsl-rl-lib, torch); importing this package loads neither: they load when a run starts.
:class:`~wpctrl.train.reach.ReachEnv` is the reach task as an rsl-rl ``VecEnv`` whose whole step is one CUDA graph on
a GPU.
"""

from __future__ import annotations

__all__ = ["TrainConfig", "TrainConfigError", "Trainer"]


def __getattr__(name: str):
    if name in ("TrainConfig", "TrainConfigError"):
        from . import train_config

        return getattr(train_config, name)
    if name == "Trainer":
        from .trainer import Trainer

        return Trainer
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
