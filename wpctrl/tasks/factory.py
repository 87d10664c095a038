"""``make``: a ManiSkill task on Newton, its arguments checked on the host before anything is built."""

from __future__ import annotations

from ..config import ConfigError
from .names import CONTROL_MODES, OBS_MODES, ROBOTS
from .physics import TaskPhysics, physics_from
from .randomization import TaskRandomization
from .registry import TASKS, unknown_task

SIM_BACKENDS = ("mujoco",)
CONTROLLER_SEMANTICS = ("physx_cpu", "physx_cuda")
__all__ = ["CONTROLLER_SEMANTICS", "CONTROL_MODES", "OBS_MODES", "SIM_BACKENDS", "make", "task_physics"]


def task_physics(env_id: str, substeps: int | None = None, **changes) -> TaskPhysics:
    """The physics a task's env runs with by default: :class:`TaskPhysics`'s defaults with the task's own departures
    (:attr:`Task.physics <wpctrl.tasks.Task.physics>`: PegInsertionSide-v1's fingers, for one), then ``substeps``
    (None: the task's) and ``changes`` (other TaskPhysics fields). ``make(env_id, physics=None)`` uses
    ``task_physics(env_id)``.

    An unknown task id is refused with the known ones; an unknown field or a bad value names the field."""
    if env_id not in TASKS:
        raise ConfigError(f"task_physics: env_id: {unknown_task(env_id)}")
    if substeps is not None:
        changes["substeps"] = substeps
    settings = {**TASKS[env_id].physics, **changes}
    return physics_from(settings, "task_physics")


def make(
    env_id: str,
    num_envs: int = 1,
    device="cpu",
    control_mode: str = "pd_joint_delta_pos",
    obs_mode: str = "state",
    reward_mode: str = "normalized_dense",
    sim_backend: str = "mujoco",
    seed: int = 0,
    *,
    auto_reset: bool = True,
    ignore_terminations: bool = False,
    physics: TaskPhysics | None = None,
    controller_semantics: str = "physx_cpu",
    asset_dir: str | None = None,
    graph: bool | None = None,
    verbose: bool = False,
    max_episode_steps: int | None = None,
    reconfiguration_freq: int | None = None,
    randomization: TaskRandomization | None = None,
    robot_uids: str | None = None,
):
    """A ManiSkill task on Newton (:class:`~wpctrl.tasks.env.TaskEnv`), ``num_envs`` copies on ``device``.

    Args:
        env_id: A registered task's ManiSkill id (:data:`~wpctrl.tasks.TASKS`: ``"PushCube-v1"``, ``"PickCube-v1"``,
            and any task registered with :func:`~wpctrl.tasks.register_task`); the Panda.
        num_envs: Parallel envs (separate Newton worlds).
        device: Warp device (``"cpu"``, ``"cuda:0"``); the torch tensors in and out live there. A device this machine
            does not have is refused (:class:`~wpctrl.config.ConfigError` listing those it has).
        control_mode: One of the Panda's ManiSkill control modes (:data:`CONTROL_MODES`).
        obs_mode: ``"state"`` (ManiSkill's flattened state vector) or ``"state_dict"`` (the nested dict).
        reward_mode: ``"normalized_dense"`` (ManiSkill's default), ``"dense"``, ``"sparse"`` (success) or ``"none"``.
        sim_backend: ``"mujoco"`` (Newton's MuJoCo-Warp solver).
        seed: Seed of the episode draws, expanded to one seed per env as ManiSkill does
            (:meth:`~wpctrl.tasks.env.TaskEnv.reset` takes a new one, or a list of one per env).
        auto_reset: Reset finished envs inside ``step`` (``ManiSkillVectorEnv``'s switch).
        ignore_terminations: Episodes end only at the time limit (success does not terminate).
        physics: Contact, friction and joint-limit settings (:class:`TaskPhysics`; None: the task's own,
            :func:`task_physics`). A ``TaskPhysics`` given here is used as it is: ``task_physics(env_id, substeps=8)``
            keeps the task's departures and changes one field.
        controller_semantics: Which ManiSkill sim's controller semantics the end-effector modes follow:
            ``"physx_cpu"`` (SAPIEN's iterative CLIK, as ManiSkill on its CPU sim) or ``"physx_cuda"`` (one damped
            least-squares step, as ManiSkill's GPU sim). Joint modes are the same on both.
        asset_dir: A copy of ``mani_skill/assets`` to read the Panda from (default: the installed mani-skill).
        graph: Capture the step in a graph and replay it (default: True, on CUDA and the CPU).
        max_episode_steps: The episodes' time limit in control steps (default: the task's registered one, e.g. 50
            for PushCube-v1), as ``gym.make(env_id, max_episode_steps=N)`` overrides it for ManiSkill's envs:
            ``truncated`` turns True at step N. A positive int.
        reconfiguration_freq: Every how many :meth:`~wpctrl.tasks.env.TaskEnv.reset` calls the scene is drawn again
            from the episode seeds (ManiSkill's argument; None: the task's default, as ManiSkill's: 1 for
            PegInsertionSide-v1 with one env, else 0, never). Only tasks whose geometry comes from the seed change.
        randomization: Per-env friction, contact softness and object mass drawn at every reset
            (:class:`~wpctrl.tasks.randomization.TaskRandomization`; None, the default: none).
        robot_uids: The robot (ManiSkill's argument): ``"panda"`` or ``"panda_wristcam"``, the Panda with
            ManiSkill's wrist camera on its hand (:data:`wpctrl.tasks.names.ROBOTS`); None: the task's default, as
            ManiSkill's (``panda_wristcam`` for StackCube-v1 and PegInsertionSide-v1, else ``panda``). The state
            dict's articulation carries its name.
        verbose: Let Warp print what it does while the env is built: its start-up banner and a
            ``Module ... load on device ...`` line per kernel module. By default (``False``) ``make`` prints nothing:
            for the duration of the call it raises ``warp.config.log_level`` to ``warp.LOG_WARNING`` (and puts your
            value back before it returns), and if Warp is not initialised yet it initialises it without the native
            "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver" line, which on a machine without a GPU
            says nothing you need (asking for a CUDA device there is refused with a :class:`~wpctrl.config.ConfigError`
            anyway). Warp's warnings and errors still show. No other Warp setting is touched. Also on under
            ``wpctrl``'s command line with ``--verbose``.
    """
    if env_id not in TASKS:
        raise ConfigError(f"make: env_id: {unknown_task(env_id)}")
    if control_mode not in CONTROL_MODES:
        raise ConfigError(f"make: unknown control_mode {control_mode!r} for the Panda; expected one of "
                          f"{list(CONTROL_MODES)}")  # fmt: skip
    if obs_mode not in OBS_MODES:
        raise ConfigError(f"make: unsupported obs_mode {obs_mode!r}; expected one of {OBS_MODES} (no cameras)")
    from .env import REWARD_MODES, TaskEnv

    if reward_mode not in REWARD_MODES:
        raise ConfigError(f"make: unknown reward_mode {reward_mode!r}; expected one of {REWARD_MODES}")
    if sim_backend not in SIM_BACKENDS:
        raise ConfigError(f"make: unknown sim_backend {sim_backend!r}; expected one of {SIM_BACKENDS}")
    if controller_semantics not in CONTROLLER_SEMANTICS:
        raise ConfigError(f"make: controller_semantics expected one of {CONTROLLER_SEMANTICS}, got "
                          f"{controller_semantics!r}")  # fmt: skip
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ConfigError(f"make: num_envs expected a positive int, got {num_envs!r}")
    if max_episode_steps is not None and (isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, int)
                                          or max_episode_steps < 1):  # fmt: skip
        raise ConfigError(f"make: max_episode_steps expected a positive int (or None: the task's "
                          f"{TASKS[env_id].max_episode_steps}), got {max_episode_steps!r}")  # fmt: skip
    if reconfiguration_freq is not None and (isinstance(reconfiguration_freq, bool)
                                             or not isinstance(reconfiguration_freq, int) or reconfiguration_freq < 0):
        raise ConfigError(f"make: reconfiguration_freq expected an int >= 0 (or None: the task's default), got "
                          f"{reconfiguration_freq!r}")  # fmt: skip
    if robot_uids is not None and robot_uids not in ROBOTS:
        raise ConfigError(f"make: robot_uids expected one of {list(ROBOTS)} (or None: the task's "
                          f"{TASKS[env_id].robot_uids!r}), got {robot_uids!r}")  # fmt: skip
    if physics is None:
        physics = task_physics(env_id)
    elif not isinstance(physics, TaskPhysics):
        raise ConfigError(f"make: physics expected a TaskPhysics, got {type(physics).__name__}")
    if randomization is not None and not isinstance(randomization, TaskRandomization):
        raise ConfigError(f"make: randomization expected a TaskRandomization (or None), got "
                          f"{type(randomization).__name__}")  # fmt: skip
    try:  # the env's tensors are torch's
        import torch  # noqa: F401
    except ImportError as e:
        from ..extras import missing

        raise ImportError(missing("wpctrl.tasks.make", "tasks", e, torch=True)) from e
    from ..console import quiet_warp
    from ..devices import check_device
    from ._validate import seed_value

    with quiet_warp(verbose):  # the banner, the CUDA-driver line and the module-load lines: only when asked for
        device = check_device(device, "make: device")
        options = (bool(auto_reset), bool(ignore_terminations), physics, controller_semantics, asset_dir, graph,
                   max_episode_steps, reconfiguration_freq, randomization, robot_uids)  # fmt: skip
        return TaskEnv(TASKS[env_id], num_envs, device, control_mode, obs_mode, reward_mode, seed_value(seed),
                       *options)  # fmt: skip
