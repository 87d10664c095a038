"""The task registry and the base class a task module subclasses (host only: importing this pulls in no Warp).

A task is one module (``push_cube.py``, ``pick_cube.py``): a :class:`Task` subclass decorated with
:func:`register_task`, as ManiSkill's ``@register_env`` class. It declares its scene (``actors``: free bodies and goal
markers, in ManiSkill's state-dict order), its observation (``obs_extra``: the fields after the Panda's qpos and
qvel, in ManiSkill's order), ``evaluate()``'s keys and its reward's maximum, and names three device functions
(``@wp.func``, written against :mod:`wpctrl.tasks.funcs`): ``initialize`` (``_initialize_episode``), ``evaluate``
and ``dense_reward``. The shared kernels (:mod:`wpctrl.tasks.kernels`) are generated from these declarations.

:data:`TASKS` lists the built-in tasks (:data:`wpctrl.tasks.names.TASK_MODULES`) and any registered since; it imports
a task's module on first use.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping
from types import MappingProxyType

import numpy as np

from ..config import ConfigError
from .definitions import PANDA_DOF, TABLE_REST_QPOS, Actor, Box, Marker, ObsField
from .names import ROBOTS, TASK_MODULES
from .physics import physics_from

__all__ = ["TASKS", "Task", "get_task", "register_task"]

AGENT_FIELDS = (ObsField("agent", "qpos", PANDA_DOF), ObsField("agent", "qvel", PANDA_DOF))
"""The Panda's part of every task's observation (``_get_obs_agent``): qpos, then qvel."""


class Task:
    """What a task declares (class attributes of the subclass; the registry holds one instance of it)."""

    env_id: str = ""
    """Set by :func:`register_task`."""
    max_episode_steps: int = 0
    """Set by :func:`register_task` (``@register_env(..., max_episode_steps=...)``)."""
    actors: tuple[Actor | Marker, ...] = ()
    """The task's actors besides the table, in ManiSkill's state-dict order."""
    contact_actors: tuple[str, ...] = ()
    """The actors whose contact forces on the Panda's fingers are measured (``agent.is_grasping(actor)``), in their
    declared order: contact column j (``funcs.is_grasping(sim, env, j)``) is the j-th of them."""
    obs_extra: tuple[ObsField, ...] = ()
    """``_get_obs_extra``'s fields, in its dict order, each with its device function."""
    info_keys: tuple[str, ...] = ()
    """``evaluate()``'s keys besides ``success`` (and ``elapsed_steps`` added by ``get_info``)."""
    max_reward: float = 1.0
    """``compute_normalized_dense_reward`` divides by it; a success step's dense reward is set to it."""
    initialize = None
    """``@wp.func (Sim, env, rng)``: place the actors and markers of env ``env`` for a new episode (the Panda is
    already placed and every actor's velocity zeroed)."""
    evaluate = None
    """``@wp.func (Sim, env)``: write ``success`` and the ``info_keys`` flags into ``sim.info[env]``."""
    dense_reward = None
    """``@wp.func (Sim, env) -> float``: ``compute_dense_reward`` before success sets it to ``max_reward``."""
    robot_uids: str = "panda"
    """ManiSkill's default robot of the task (its env's ``__init__(robot_uids=...)``), one of
    :data:`wpctrl.tasks.names.ROBOTS`: what :func:`wpctrl.tasks.make` builds unless given ``robot_uids``."""
    rest_qpos: tuple[float, ...] | None = None
    """The Panda's qpos before the initialisation noise, where the task's ``_initialize_episode`` sets its own; None:
    ``TableSceneBuilder.initialize``'s for the robot built (:meth:`robot_rest_qpos`)."""
    physics: Mapping[str, object] = MappingProxyType({})
    """Where the task's contacts need MuJoCo settings other than :class:`~wpctrl.tasks.TaskPhysics`'s defaults:
    field -> value. The task's default physics (:func:`wpctrl.tasks.task_physics`) is ``TaskPhysics(**physics)``;
    empty for most tasks. The task module says why, measured beside PhysX."""

    # -- a scene drawn from the seed (ManiSkill's ``_load_scene`` with ``_batched_episode_rng``) ----------------------
    episode_params: tuple[str, ...] = ()
    """Names of the per-env numbers a task draws when its scene is (re)configured, ManiSkill's ``_load_scene`` draws
    from ``_batched_episode_rng``; the device functions read them with ``funcs.param(sim, env, k)``."""

    def draw_episode_params(self, seeds: np.ndarray) -> np.ndarray:
        """(num_envs, len(episode_params)) float64: each env's numbers, drawn from its own episode seed as ManiSkill's
        ``_batched_episode_rng`` (one ``np.random.RandomState(seed)`` per env) draws them."""
        return np.zeros((len(seeds), len(self.episode_params)))

    def episode_shapes(self, params: np.ndarray) -> dict[str, tuple[Box, ...]]:
        """The collision shapes of the actors whose geometry follows one env's ``params`` (by actor name; the same
        count and kinds as the declared ones). Empty: every env keeps the declared shapes."""
        return {}

    def reconfiguration_freq(self, num_envs: int) -> int:
        """ManiSkill's default ``reconfiguration_freq`` for ``num_envs``: every how many ``reset()`` calls the scene is
        drawn again (0: only when asked, ``options={"reconfigure": True}``)."""
        return 0

    def robot_rest_qpos(self, robot_uids: str) -> tuple[float, ...]:
        """The qpos a reset draws the noise around for the robot ``robot_uids``: :attr:`rest_qpos`, else the table
        scene's for that robot (:data:`~wpctrl.tasks.definitions.TABLE_REST_QPOS`)."""
        return self.rest_qpos if self.rest_qpos is not None else TABLE_REST_QPOS[robot_uids]

    @property
    def obs_fields(self) -> tuple[ObsField, ...]:
        return AGENT_FIELDS + tuple(self.obs_extra)

    @property
    def obs_dim(self) -> int:
        return sum(f.size for f in self.obs_fields)

    def obs_slices(self) -> dict[str, dict[str, slice]]:
        """``{group: {name: slice}}`` into the flattened observation."""
        out: dict[str, dict[str, slice]] = {}
        start = 0
        for f in self.obs_fields:
            out.setdefault(f.group, {})[f.name] = slice(start, start + f.size)
            start += f.size
        return out

    @property
    def bodies(self) -> tuple[Actor, ...]:
        """The free bodies, in declared order (the device functions' actor indices)."""
        return tuple(a for a in self.actors if isinstance(a, Actor))

    @property
    def markers(self) -> tuple[Marker, ...]:
        return tuple(a for a in self.actors if isinstance(a, Marker))

    @property
    def goal_name(self) -> str | None:
        """The first goal marker's state-dict name (None without one)."""
        return self.markers[0].name if self.markers else None

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.env_id!r})"


_REGISTERED: dict[str, Task] = {}


def register_task(env_id: str, max_episode_steps: int):
    """Class decorator: register a :class:`Task` subclass under ManiSkill's env id (``@register_env``'s twin)."""

    def register(cls: type[Task]) -> type[Task]:
        if not (isinstance(cls, type) and issubclass(cls, Task)):
            raise ConfigError(f"register_task({env_id!r}): expected a Task subclass, got {cls!r}")
        cls.env_id, cls.max_episode_steps = env_id, int(max_episode_steps)
        _check(cls)
        _REGISTERED[env_id] = cls()
        return cls

    return register


def _check(cls: type[Task]) -> None:
    names = [a.name for a in cls.actors]
    where = f"task {cls.env_id}"
    if len(set(names)) != len(names) or not all(isinstance(a, (Actor, Marker)) for a in cls.actors):
        raise ConfigError(f"{where}: actors must be Actor / Marker entries with distinct names, got {names}")
    bodies = {a.name for a in cls.actors if isinstance(a, Actor)}
    for name in cls.contact_actors:
        if name not in bodies:
            raise ConfigError(f"{where}: contact actor {name!r} is not one of its bodies {sorted(bodies)}")
    order = [a.name for a in cls.actors if isinstance(a, Actor) and a.name in cls.contact_actors]
    if list(cls.contact_actors) != order:  # the contact sensor's columns follow the bodies' order in each world
        raise ConfigError(f"{where}: contact_actors must be distinct and in the actors' declared order: {order}")
    if cls.robot_uids not in ROBOTS:
        raise ConfigError(f"{where}: robot_uids expected one of {list(ROBOTS)}, got {cls.robot_uids!r}")
    if cls.rest_qpos is not None and len(cls.rest_qpos) != PANDA_DOF:
        raise ConfigError(f"{where}: rest_qpos expected {PANDA_DOF} values (the Panda's qpos), got "
                          f"{len(cls.rest_qpos)}")
    for hook in ("initialize", "evaluate", "dense_reward"):
        if getattr(cls, hook) is None:
            raise ConfigError(f"{where}: no {hook} device function")
    for f in cls.obs_extra:
        if f.func is None:
            raise ConfigError(f"{where}: observation field {f.group}/{f.name} has no device function")
    physics_from(cls.physics, f"{where}: physics")


class _Registry(Mapping):
    """env id -> :class:`Task`: the built-in tasks (imported on first use) and those registered since."""

    def _ids(self) -> list[str]:
        return list(TASK_MODULES) + [k for k in _REGISTERED if k not in TASK_MODULES]

    def __getitem__(self, env_id: str) -> Task:
        if env_id not in _REGISTERED and env_id in TASK_MODULES:
            importlib.import_module(f"{__package__}.{TASK_MODULES[env_id]}")
        if env_id not in _REGISTERED:
            raise KeyError(unknown_task(env_id))
        return _REGISTERED[env_id]

    def __contains__(self, env_id) -> bool:
        return env_id in TASK_MODULES or env_id in _REGISTERED

    def __iter__(self) -> Iterator[str]:
        return iter(self._ids())

    def __len__(self) -> int:
        return len(self._ids())

    def __repr__(self) -> str:
        return f"TASKS({self._ids()})"


TASKS = _Registry()
"""The tasks :func:`wpctrl.tasks.make` builds, by ManiSkill env id."""


def unknown_task(env_id) -> str:
    return f"unknown task id {env_id!r}; the known ones are {sorted(TASKS)}"


def get_task(env_id: str) -> Task:
    """The registered task of ``env_id``; an unknown id is refused with the list of known ones."""
    if env_id not in TASKS:
        raise ConfigError(unknown_task(env_id))
    return TASKS[env_id]
