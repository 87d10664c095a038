"""What a training run is: :class:`TrainConfig`, one field per ``wpctrl train`` option (same name, same default),
checked before anything is built, and its defaults that depend on the task and the device.

Light on purpose (no torch, no rsl-rl; Warp only to confirm a device): the command line parses into it and
``from wpctrl.train import TrainConfig`` costs nothing until :class:`~wpctrl.train.trainer.Trainer` runs it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields
from pathlib import Path

from ..tasks.names import CONTROL_MODES as PANDA_MODES
from ..tasks.names import ROBOTS, TASK_MODULES, default_robot
from .command_args import flag, unused_option
from .hidden_inputs import DEFAULT_HIDE_OBS, HIDE_OBS
from .logger import LOGGERS, logger_error
from .ppo_config import batch_error, task_recipe

__all__ = ["CONTROL_MODES", "MANISKILL_TASKS", "TASKS", "TASK_ONLY", "TrainConfig", "TrainConfigError", "flag"]

MANISKILL_TASKS: tuple[str, ...] = tuple(TASK_MODULES)
"""The ManiSkill tasks ``wpctrl train`` trains: every task of the registry (:data:`wpctrl.tasks.names.TASK_MODULES`,
host-only names: importing them loads no Warp)."""
TASKS = ("reach",) + MANISKILL_TASKS
CONTROL_MODES = ("pd_ee_delta_pos", "pd_joint_delta_pos")
"""The reach task's control modes (the ManiSkill tasks take every Panda mode of :data:`wpctrl.tasks.CONTROL_MODES`)."""
PPO_UPDATES = ("captured", "rsl-rl")
OBS_NORMALIZATIONS = ("on", "off")
SAMPLINGS = ("sync-free", "rsl-rl")
"""The rollout's action samplers (:mod:`wpctrl.train.sampling`'s or rsl-rl's ``PPO.act``)."""

REACH_STEPS_PER_ENV = 24
REACH_MINIBATCHES = 4

TASK_ONLY = ("epochs", "minibatches", "substeps", "eval_envs", "time_limit", "ppo_update", "obs_normalization",
             "action_sampling", "no_partial_reset", "hide_obs", "randomize", "robot_uids")  # fmt: skip
"""The options only the ManiSkill tasks use (the reach task refuses them)."""

TASK_LIST = ", ".join(MANISKILL_TASKS)
"""The ManiSkill tasks as the help texts name them."""

_POSITIVE = ("envs", "iterations", "steps_per_env", "eval_episodes", "eval_envs", "epochs", "minibatches", "substeps")
_CHOICES = {"task": TASKS, "logger": LOGGERS, "ppo_update": PPO_UPDATES, "obs_normalization": OBS_NORMALIZATIONS,
            "action_sampling": SAMPLINGS, "hide_obs": HIDE_OBS, "robot_uids": ROBOTS}  # fmt: skip


class TrainConfigError(ValueError):
    """A training configuration that cannot run; the message names the field, what it expects and what it got."""


@dataclass
class TrainConfig:
    """One training run: PPO (rsl-rl) on the reach task or on one of ManiSkill's tasks (:data:`MANISKILL_TASKS`:
    every task of :mod:`wpctrl.tasks`' registry).

    Every field is the ``wpctrl train`` option of the same name (``steps_per_env`` is ``--steps-per-env``) with the
    same default; None means "the default for this task and device" (:meth:`resolved` fills them in). The fields the
    reach task does not use (:data:`TASK_ONLY`) must stay None / False for it.
    """

    task: str = "reach"
    control_mode: str | None = None
    """ManiSkill's Panda mode (None: ``pd_ee_delta_pos`` for reach, ``pd_joint_delta_pos`` for the tasks)."""
    envs: int | None = None
    """Parallel envs (None: 4096 on CUDA, 64 on the CPU)."""
    iterations: int | None = None
    """PPO iterations (None: reach 200 on CUDA, the tasks 2000; 20 on the CPU); with ``resume``: iterations to add."""
    steps_per_env: int | None = None
    """Rollout length per iteration (None: reach 24; the tasks their recipe's, 4, StackCube-v1 16:
    :data:`wpctrl.train.ppo_config.TASK_RECIPES`)."""
    epochs: int | None = None
    minibatches: int | None = None
    substeps: int | None = None
    no_partial_reset: bool = False
    """Tasks: success does not end an episode (every episode runs its ``max_episode_steps``: 50, PegInsertionSide-v1
    100)."""
    device: str | None = None
    """torch / Warp device (None: ``cuda:0`` if there is one, else ``cpu``)."""
    seed: int = 0
    eval_episodes: int | None = None
    eval_envs: int | None = None
    eval_every: int = 0
    """Also evaluate every N iterations (0: only after training)."""
    target_success: float | None = None
    time_limit: float | None = None
    ppo_update: str | None = None
    obs_normalization: str | None = None
    action_sampling: str | None = None
    hide_obs: str | None = None
    """Tasks: observation entries the policy does not read (:mod:`wpctrl.train.hidden_inputs`; None:
    ``finger_qvel``, the finger joints' velocities)."""
    robot_uids: str | None = None
    """Tasks: the robot, ``panda`` or ``panda_wristcam`` (None: the task's default, as ManiSkill's:
    :func:`wpctrl.tasks.make`)."""
    randomize: str | None = None
    """Tasks: per-env physics drawn at every reset of the training envs (``"on"``, ``"friction=0.7:1.3,..."``:
    :func:`wpctrl.tasks.randomization.from_spec`); None / ``"off"``: none. The evaluation envs never randomise."""
    out: str | Path = "wpctrl-train"
    no_graph: bool = False
    logger: str = "tensorboard"
    resume: str | Path | None = None
    """A run folder to continue from its checkpoint, with its recorded configuration (:mod:`wpctrl.train.resume`)."""
    verbose: bool = False

    @classmethod
    def from_args(cls, args) -> TrainConfig:
        """The configuration an argparse namespace of ``wpctrl train`` holds (its other attributes ignored)."""
        names = [f.name for f in fields(cls) if hasattr(args, f.name)]
        return cls(**{name: getattr(args, name) for name in names})

    def changed(self) -> set[str]:
        """The fields that differ from their defaults (what a Python user set)."""
        default = TrainConfig()
        return {f.name for f in fields(self) if getattr(self, f.name) != getattr(default, f.name)}

    # -- checks ----------------------------------------------------------------------------------------------------

    def problem(self, name=flag, device: bool = True) -> str | None:
        """The first reason this configuration cannot run, naming its field with ``name`` (the command line's option
        by default), or None. ``device``: also confirm the device (Warp's view, unless no NVIDIA driver is in sight)
        and that the rollout fills PPO's mini-batches."""
        for key, choices in _CHOICES.items():
            v = getattr(self, key)
            if (v is not None or key == "task") and v not in choices:
                return f"{name(key)}: expected one of {list(choices)}, got {v!r}"
        if why := logger_error(self.logger):
            return why
        for key in _POSITIVE + ("seed", "eval_every"):
            v = getattr(self, key)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int)):
                return f"{name(key)}: expected an integer, got {v!r} ({type(v).__name__})"
        for key in ("target_success", "time_limit"):
            v = getattr(self, key)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
                return f"{name(key)}: expected a number, got {v!r} ({type(v).__name__})"
        for key in _POSITIVE:
            v = getattr(self, key)
            if v is not None and v < 1:
                return f"{name(key)}: expected a positive number, got {v}"
        if self.eval_every < 0:
            return f"{name('eval_every')}: expected 0 or a positive number of iterations, got {self.eval_every}"
        if self.target_success is not None and not 0.0 < self.target_success <= 1.0:
            return f"{name('target_success')}: expected a success rate in (0, 1], got {self.target_success}"
        if self.target_success is not None and self.eval_every == 0:
            return f"{name('target_success')}: needs {name('eval_every')} N (the evaluations that decide when to stop)"
        if self.randomize is not None:
            from ..config import ConfigError
            from ..tasks.factory import task_physics
            from ..tasks.physics import TaskPhysics
            from ..tasks.randomization import from_spec
            from ..tasks.registry import TASKS

            if not isinstance(self.randomize, str):
                return f"{name('randomize')}: expected 'off', 'on' or name=low:high,..., got {self.randomize!r}"
            try:
                spec = from_spec(self.randomize)
            except ConfigError as e:
                return f"{name('randomize')}: {str(e).removeprefix('randomize: ')}"
            if self.task in TASKS:
                physics = task_physics(self.task, self.substeps)
            else:
                physics = TaskPhysics() if self.substeps is None else TaskPhysics(substeps=self.substeps)
            shortest = min(
                [physics.contact_solref[0], (physics.finger_solref or physics.contact_solref)[0]]
                + [solref[0] for _, _, solref in physics.shape_solref]
            )
            if spec is not None and (why := spec.contact_time_problem(shortest, 0.01 / physics.substeps)):
                return f"{name('randomize')}: {why} (with {name('substeps')} {physics.substeps})"
        if self.time_limit is not None and not self.time_limit > 0:
            return f"{name('time_limit')}: expected a positive number of seconds, got {self.time_limit}"
        if why := self.unused_problem(name):
            return why
        if self.task == "reach" and self.control_mode is not None and self.control_mode not in CONTROL_MODES:
            return f"{name('control_mode')}: expected one of {list(CONTROL_MODES)} for reach, got {self.control_mode!r}"
        if self.task != "reach" and self.control_mode is not None and self.control_mode not in PANDA_MODES:
            return (f"{name('control_mode')}: expected one of the Panda's modes {list(PANDA_MODES)} for {self.task}, "
                    f"got {self.control_mode!r}")  # fmt: skip
        return self.device_problem(name) if device else None

    def unused_problem(self, name=flag) -> str | None:
        """The first option of :data:`TASK_ONLY` set (not None / False) for the reach task, or None."""
        if self.task != "reach":
            return None
        given = {key for key in TASK_ONLY if getattr(self, key) not in (None, False)}
        if key := unused_option(given, TASK_ONLY):
            return f"{name(key)}: only for the ManiSkill tasks {list(MANISKILL_TASKS)}"
        return None

    def device_problem(self, name=flag) -> str | None:
        """The device exists, the captured update has CUDA, and the rollout (``envs`` x ``steps_per_env``) fills PPO's
        mini-batches: checked with the defaults that depend on the device resolved as training resolves them."""
        from ..console import device_refusal

        if why := device_refusal(self.device, name("device")):
            return why
        try:
            device = self.default_device(name)
        except ValueError as e:
            return str(e)
        cuda = device.startswith("cuda")
        if self.ppo_update == "captured" and not cuda:
            return f"{name('ppo_update')}: 'captured' needs a CUDA device, got {name('device')} {device}"
        envs = self.envs or (4096 if cuda else 64)
        if self.task in MANISKILL_TASKS:
            # ManiSkill's PPO normalises the advantages per mini-batch: 2 samples at least for a defined std
            recipe = task_recipe(self.task)
            return batch_error(envs, self.steps_per_env or recipe["steps_per_env"],
                               self.minibatches or recipe["minibatches"], 2, name("minibatches"), name)  # fmt: skip
        # the reach task normalises them over the whole batch: every one of its mini-batches needs a sample
        return batch_error(envs, self.steps_per_env or REACH_STEPS_PER_ENV, REACH_MINIBATCHES, 1, None, name)

    def check(self) -> TrainConfig:
        """Raise :class:`TrainConfigError` naming the first field that cannot work (``TrainConfig.<field>: ...``);
        returns self."""
        why = self.problem(name=lambda key: key)
        if why is not None:
            raise TrainConfigError(f"TrainConfig.{why}")
        return self

    # -- defaults --------------------------------------------------------------------------------------------------

    def default_device(self, name=flag) -> str:
        """``device``, or ``cuda:0`` where Warp sees a CUDA device, else ``cpu`` (Warp asked only where an NVIDIA
        driver may be present). Raises ValueError for a device this machine does not have."""
        from ..console import cuda_absent

        if cuda_absent():
            return self.device or "cpu"
        import warp as wp

        from ..config import ConfigError
        from ..console import quiet_warp
        from ..devices import check_device

        with quiet_warp(self.verbose):
            if self.device is not None:
                try:
                    check_device(self.device, name("device"))
                except ConfigError as e:
                    raise ValueError(str(e)) from e
            return str(self.device or ("cuda:0" if wp.is_cuda_available() else "cpu"))

    def resolved(self) -> TrainConfig:
        """A copy with every None default filled in for this task and device."""
        device = self.default_device()
        cuda = device.startswith("cuda")
        reach = self.task == "reach"
        envs = self.envs or (4096 if cuda else 64)
        task_values = {}
        steps = self.steps_per_env or REACH_STEPS_PER_ENV
        if not reach:
            recipe = task_recipe(self.task)
            steps = self.steps_per_env or recipe["steps_per_env"]
            eval_envs = self.eval_envs or min(envs, 512)
            task_values = dict(
                eval_envs=eval_envs,
                epochs=self.epochs or recipe["epochs"],
                minibatches=self.minibatches or recipe["minibatches"],
                ppo_update=self.ppo_update or ("captured" if cuda else "rsl-rl"),
                obs_normalization=self.obs_normalization or "off",
                action_sampling=self.action_sampling or "sync-free",
                hide_obs=self.hide_obs or DEFAULT_HIDE_OBS,
                randomize=self.randomize or "off",
                robot_uids=self.robot_uids or default_robot(self.task),
            )
        return dataclasses.replace(
            self,
            device=device,
            envs=envs,
            control_mode=self.control_mode or ("pd_ee_delta_pos" if reach else "pd_joint_delta_pos"),
            iterations=self.iterations or ((200 if reach else 2000) if cuda else 20),
            steps_per_env=steps,
            eval_episodes=self.eval_episodes or (envs if reach else task_values["eval_envs"]),
            **task_values,
        )
