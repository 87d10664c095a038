"""ManiSkill episodes driven by a policy, stored as numpy arrays (``<Task>__<control_mode>__policy.npz``), read as the
replay's episode format, so ``python -m wpctrl replay FILE.npz`` and :func:`wpctrl.tasks.replay` take them as they
are.

The file (one per task and control mode; E episodes of T control steps, index t = 0 right after the reset) holds:

- ``seeds`` (E): the reset's seed;
- ``init_state`` (E, S): the state dict right after the reset, flattened: the task's actors in the order of
  :data:`wpctrl.tasks.names.TASK_ACTORS` without the table (PushCube: ``cube``, ``goal_region``; PickCube: ``cube``,
  ``goal_site``), 13 values each ``[p, q wxyz, linear velocity, angular velocity]``, then the Panda's 31 ``[root
  pose (7), root velocity (6), qpos (9), qvel (9)]``; the table is static (its fixed state is the task's);
- ``action`` (E, T, A): the action sent at step t, the policy's raw output (the controllers clip it to [-1, 1], as
  ManiSkill's do);
- ``success`` (E, T): ``info["success"]`` after step t;
- ``cube`` (E, T+1, 7): the main object's pose per step;
- optionally ``reward`` (E, T), ``qpos`` / ``qvel`` (E, T+1, 9), ``tcp`` / ``f1`` / ``f2`` (E, T+1, 7),
  ``cube_vel`` (E, T+1, 6), ``cube_sd`` / ``goal_sd`` (E, T+1, 13), ``panda_sd`` (E, T+1, 31), ``contacts``
  (E, T, K, 15): checked for shape and finiteness where present, not replayed.

:func:`read_policy_episodes` returns the replay's dict: ``header`` (``task``, ``control_mode`` from the file name,
``main_object`` the task's) and per episode ``seed``, ``init_state_dict``, ``actions``, ``info["success"]`` for
t = 0 .. T (t = 0, the reset, is False: ManiSkill's success at a reset state, which the files do not record; the
tests check it with wpctrl's evaluate) and ``cube_pose``. Everything is checked before anything is built, each
refusal a :class:`~wpctrl.ConfigError` naming the file and the field. Host only: numpy, no Warp, Newton or torch.
``wpctrl.tasks.replay(path, policy=...)`` runs a policy closed-loop from the episodes' initial states instead.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np

from ..config import ConfigError
from .definitions import TABLE
from .names import CONTROL_MODES, TASK_ACTORS, TASK_IDS

__all__ = [
    "OPTIONAL",
    "SUFFIX",
    "is_policy_file",
    "parse_name",
    "read_policy_episodes",
    "table_state",
]

SUFFIX = "__policy.npz"
"""The end of a policy-episode file's name: ``<Task>__<control_mode>__policy.npz``."""

ACTOR = 13
ROBOT = 31
OPTIONAL: dict[str, tuple] = {
    "reward": ("E", "T"),
    "qpos": ("E", "T+1", 9),
    "qvel": ("E", "T+1", 9),
    "tcp": ("E", "T+1", 7),
    "f1": ("E", "T+1", 7),
    "f2": ("E", "T+1", 7),
    "cube_vel": ("E", "T+1", 6),
    "cube_sd": ("E", "T+1", ACTOR),
    "goal_sd": ("E", "T+1", ACTOR),
    "panda_sd": ("E", "T+1", ROBOT),
    "contacts": ("E", "T", "K", 15),
}
"""The arrays the files may hold besides the replayed ones: shape (E, T and T+1 as the file's) and finiteness are
checked, the values are not replayed."""


def is_policy_file(path) -> bool:
    """Whether ``path`` names a policy-episode file (``.npz``)."""
    return str(path).endswith(".npz")


def table_state() -> np.ndarray:
    """The table actor's 13 values (fixed: zero velocities), as :func:`wpctrl.tasks.state_dict.table_state` (which
    imports Warp)."""
    half = 0.5 * TABLE.actor_yaw
    return np.array([*TABLE.actor_position, math.cos(half), 0.0, 0.0, math.sin(half)] + [0.0] * 6, np.float32)


def parse_name(path) -> tuple[str, str]:
    """The task and control mode of ``<Task>__<control_mode>__policy.npz``; a name that does not parse, or a task or
    mode wpctrl does not build, is refused naming the file and the field."""
    name = Path(path).name
    parts = name[: -len(SUFFIX)].split("__") if name.endswith(SUFFIX) else []
    if len(parts) != 2 or not all(parts):
        raise ConfigError(f"replay: {str(path)!r}: the file name expected <Task>__<control_mode>{SUFFIX} (e.g. "
                          f"PushCube-v1__pd_joint_delta_pos{SUFFIX}), got {name!r}")  # fmt: skip
    task, mode = parts
    if task not in TASK_IDS or task not in TASK_ACTORS:
        raise ConfigError(f"replay: {str(path)!r}: task {task!r} (from the file name) is not one wpctrl builds; "
                          f"expected one of {list(TASK_IDS)}")  # fmt: skip
    if mode not in CONTROL_MODES:
        raise ConfigError(f"replay: {str(path)!r}: control mode {mode!r} (from the file name) is not one of the "
                          f"Panda's {list(CONTROL_MODES)}")  # fmt: skip
    return task, mode


def _load(path: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as f:
            return {k: f[k] for k in f.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, KeyError) as e:
        raise ConfigError(f"replay: {str(path)!r} is not a readable numpy .npz file of policy episodes "
                          f"({type(e).__name__}: {e})") from e  # fmt: skip


def _array(arrays: dict, key: str, shape: tuple, sizes: dict, where: str, kinds: str = "iuf") -> np.ndarray:
    """``arrays[key]`` checked: dtype of ``kinds``, ``shape`` (ints, or letters bound in ``sizes`` on first use,
    "T+1" one more than "T"), finite; a refusal names the file and the array."""
    if key not in arrays:
        raise ConfigError(f"replay: {where}has no array {key!r} (have {sorted(arrays)})")
    a = arrays[key]
    if a.dtype.kind not in kinds:
        want = {"iu": "integers", "iuf": "numbers", "biu": "booleans (or 0/1 integers)"}[kinds]
        raise ConfigError(f"replay: {where}{key!r} expected {want}, got dtype {a.dtype}")
    expected = []
    for axis, s in enumerate(shape):
        if isinstance(s, str) and a.ndim == len(shape):
            base = s.removesuffix("+1")
            if base not in sizes:
                sizes[base] = a.shape[axis] - (1 if s.endswith("+1") else 0)
            s = sizes[base] + (1 if s.endswith("+1") else 0)
        expected.append(s)
    if a.ndim != len(shape) or tuple(a.shape) != tuple(expected):
        names = ", ".join(map(str, shape))
        want = ", ".join(str(s) for s in expected) if a.ndim == len(shape) else names
        raise ConfigError(f"replay: {where}{key!r} expected shape ({names}) = ({want}), got {tuple(a.shape)}")
    if a.dtype.kind == "f":
        bad = np.argwhere(~np.isfinite(a))
        if len(bad):
            at = "".join(f"[{k}]" for k in bad[0])
            raise ConfigError(f"replay: {where}{key}{at} is {a[tuple(bad[0])]}, expected a finite number")
    return a


def read_policy_episodes(path) -> dict:
    """The episodes of a policy-episode file (see the module docstring) in the replay's format, every array checked
    first (a :class:`~wpctrl.ConfigError` names the file and the array). Host only: numpy. The action width against
    the control mode is the replay's check (:func:`wpctrl.tasks.replay.load_episodes` refuses
    ``episodes[i].actions`` of another width, naming the file; it loads the robot's description)."""
    path = Path(path)
    task, mode = parse_name(path)
    if not path.is_file():
        raise FileNotFoundError(f"replay: no episode file {str(path)!r}")
    where = f"{str(path)!r}: "
    arrays = _load(path)
    actors = [a for a in TASK_ACTORS[task].state if a != TABLE.name]
    sizes: dict[str, int] = {}
    seeds = _array(arrays, "seeds", ("E",), sizes, where, "iu")
    if len(seeds) == 0:
        raise ConfigError(f"replay: {where}the file holds no episodes ('seeds' is empty)")
    if (seeds < 0).any():
        raise ConfigError(f"replay: {where}seeds[{int(np.argmax(seeds < 0))}] is {int(seeds.min())}, expected a "
                          f"non-negative integer (the reset's seed)")  # fmt: skip
    width = ACTOR * len(actors) + ROBOT
    init = _array(arrays, "init_state", ("E", width), sizes, where)
    actions = _array(arrays, "action", ("E", "T", "A"), sizes, where)
    if sizes["T"] < 1:
        raise ConfigError(f"replay: {where}'action' holds no steps (shape {tuple(actions.shape)})")
    success = _array(arrays, "success", ("E", "T"), sizes, where, "biu")
    if success.dtype.kind != "b" and not np.isin(success, (0, 1)).all():
        raise ConfigError(f"replay: {where}'success' expected booleans (or 0/1), got values "
                          f"{sorted(set(np.unique(success).tolist()) - {0, 1})[:3]}")  # fmt: skip
    poses = _array(arrays, "cube", ("E", "T+1", 7), sizes, where)
    for key, shape in OPTIONAL.items():
        if key in arrays:
            _array(arrays, key, shape, sizes, where)
    table = table_state().tolist()
    main = TASK_ACTORS[task].main
    episodes = []
    for i in range(len(seeds)):
        state = init[i].astype(np.float64)
        sd_actors = {TABLE.name: table}
        for k, name in enumerate(actors):
            sd_actors[name] = state[ACTOR * k : ACTOR * (k + 1)].tolist()
        flags = [False] + [bool(s) for s in success[i]]
        episodes.append({
            "seed": int(seeds[i]),
            "init_state_dict": {"actors": sd_actors, "articulations": {"panda": state[-ROBOT:].tolist()}},
            "actions": actions[i].astype(np.float64).tolist(),
            "info": {"success": flags},
            "cube_pose": poses[i].astype(np.float64).tolist(),
            "success_at_end": flags[-1],
        })  # fmt: skip
    return {
        "header": {"task": task, "control_mode": mode, "main_object": main, "source": "policy episodes (.npz)"},
        "episodes": episodes,
    }
