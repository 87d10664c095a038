"""``make``: a ManiSkill task on Newton, its arguments checked on the host before anything is built."""

from __future__ import annotations

from ..config import ConfigError
from .definitions import TASKS
from .physics import TaskPhysics

OBS_MODES = ("state", "state_dict")
SIM_BACKENDS = ("mujoco",)
CONTROLLER_SEMANTICS = ("physx_cpu", "physx_cuda")


def _control_modes() -> tuple[str, ...]:
    from ..robots import panda_control_modes

    return tuple(m for m in panda_control_modes() if m.startswith("pd_"))  # ManiSkill's own, not wpctrl's torque modes


CONTROL_MODES = _control_modes()
"""The Panda's ManiSkill control modes (``pd_joint_delta_pos``, ManiSkill's default, first)."""


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
):
    """A ManiSkill task on Newton (:class:`~wpctrl.tasks.env.TaskEnv`), ``num_envs`` copies on ``device``.

    Args:
        env_id: ``"PushCube-v1"`` or ``"PickCube-v1"`` (the Panda).
        num_envs: Parallel envs (separate Newton worlds).
        device: Warp device (``"cpu"``, ``"cuda:0"``); the torch tensors in and out live there. A device this machine
            does not have is refused (:class:`~wpctrl.config.ConfigError` listing those it has).
        control_mode: One of the Panda's ManiSkill control modes (:data:`CONTROL_MODES`).
        obs_mode: ``"state"`` (ManiSkill's flattened state vector) or ``"state_dict"`` (the nested dict).
        reward_mode: ``"normalized_dense"`` (ManiSkill's default), ``"dense"``, ``"sparse"`` (success) or ``"none"``.
        sim_backend: ``"mujoco"`` (Newton's MuJoCo-Warp solver).
        seed: Seed of the episode draws (:meth:`~wpctrl.tasks.env.TaskEnv.reset` takes a new one).
        auto_reset: Reset finished envs inside ``step`` (``ManiSkillVectorEnv``'s switch).
        ignore_terminations: Episodes end only at the time limit (success does not terminate).
        physics: Contact, friction and joint-limit settings (:class:`TaskPhysics`).
        controller_semantics: Which ManiSkill sim's controller semantics the end-effector modes follow:
            ``"physx_cpu"`` (SAPIEN's iterative CLIK, as ManiSkill on its CPU sim) or ``"physx_cuda"`` (one damped
            least-squares step, as ManiSkill's GPU sim). Joint modes are the same on both.
        asset_dir: A copy of ``mani_skill/assets`` to read the Panda from (default: the installed mani-skill).
        graph: Capture the step in a graph and replay it (default: True, on CUDA and the CPU).
    """
    if env_id not in TASKS:
        raise ConfigError(f"make: unknown env_id {env_id!r}; expected one of {sorted(TASKS)}")
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
    if physics is None:
        physics = TaskPhysics()
    elif not isinstance(physics, TaskPhysics):
        raise ConfigError(f"make: physics expected a TaskPhysics, got {type(physics).__name__}")
    from ..devices import check_device
    from ._validate import seed_value

    device = check_device(device, "make: device")
    options = (bool(auto_reset), bool(ignore_terminations), physics, controller_semantics, asset_dir, graph)
    return TaskEnv(TASKS[env_id], num_envs, device, control_mode, obs_mode, reward_mode, seed_value(seed), *options)
