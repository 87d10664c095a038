"""ManiSkill's own trajectory files, read for the replay on Newton, so a user's demos replay without conversion.

ManiSkill writes a recording as a pair of files of one base name (``RecordEpisode``, the demo downloads, and
``mani_skill.trajectory.replay_trajectory`` all use it):

- ``X.json``: ``env_info`` (``env_id``, ``env_kwargs`` the env was made with, ``max_episode_steps``) and
  ``episodes[]`` (``episode_id``, ``episode_seed``, ``reset_kwargs`` with the reset's ``seed``, ``control_mode``,
  ``elapsed_steps`` and the last step's ``success`` / ``fail``);
- ``X.h5``: one group ``traj_<episode_id>`` per episode with ``actions`` (T, A), ``env_states`` (the state dict of
  every step, t = 0 after the reset up to T: ``actors/<name>`` (T+1, 13), ``articulations/<name>`` (T+1, D)),
  ``success`` / ``fail`` / ``terminated`` / ``truncated`` (T) after each step, and, when recorded, ``obs`` and
  ``rewards``.

:func:`read_trajectory` turns the pair into the episode structure :func:`wpctrl.tasks.recording.load_episodes` returns
for the project's JSON recordings: ``init_state_dict`` (``env_states`` at t = 0), ``actions``, ``info["success"]``
per step (t = 0 .. T; ManiSkill does not record the reset's, so t = 0 is False) and ``cube_pose`` (the pose of the
task's main object, :func:`wpctrl.tasks.names.main_object`, from ``env_states``, per step). Everything is checked on
the host before Warp or Newton loads, and refused with a :class:`~wpctrl.ConfigError` naming the field: a task or
control mode wpctrl does not build, a ``.json`` and ``.h5`` that disagree, a truncated or corrupt ``.h5``, states
without the task's actors. h5py (a dependency of mani-skill) is imported only when a ``.h5`` is read.
"""

from __future__ import annotations

import gzip
import json
import zlib
from pathlib import Path

import numpy as np

from ..config import ConfigError
from ._validate import STATE_ACTOR_WIDTH, STATE_ROBOT_WIDTH
from .names import CONTROL_MODES, ROBOTS, TASK_ACTORS, TASK_IDS, default_robot, main_object

__all__ = ["MAIN_OBJECT", "STATE_ACTORS", "by_length", "is_trajectory", "is_trajectory_metadata", "read_trajectory"]

MAIN_OBJECT = "cube"
"""The actor a replay follows when a task names none (:func:`wpctrl.tasks.names.main_object`)."""

STATE_ACTORS: dict[str, tuple[str, ...]] = {task: actors.state for task, actors in TASK_ACTORS.items()}
"""The actors of each task's ManiSkill state dict (besides the robot's articulation), from
:data:`wpctrl.tasks.names.TASK_ACTORS`: a trajectory's ``env_states`` must hold them all, since the replay loads them
as the initial state."""


def is_trajectory_metadata(data) -> bool:
    """Whether a loaded JSON is ManiSkill's trajectory metadata (it has ``env_info``), not the project's recording."""
    return isinstance(data, dict) and "env_info" in data and "header" not in data


def is_trajectory(path) -> bool:
    """Whether ``path`` names ManiSkill's trajectory data (a ``.h5`` file)."""
    return str(path).endswith(".h5")


def _pair(path: Path) -> tuple[Path, Path]:
    """The (``.json``, ``.h5``) pair of a trajectory, from either file, as ManiSkill names them (one base name)."""
    name = str(path)
    if name.endswith(".h5"):
        return Path(name[: -len(".h5")] + ".json"), path
    base = name[: -len(".gz")] if name.endswith(".gz") else name
    return path, Path(base[: -len(".json")] + ".h5")


def _load_json(path: Path) -> dict:
    raw = path.read_bytes()
    try:
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
        return json.loads(raw)
    except (ValueError, OSError, EOFError, zlib.error) as e:
        raise ConfigError(f"replay: {str(path)!r} is not ManiSkill's trajectory metadata (not JSON text: {e})") from e


def _check_metadata(meta, where: str) -> tuple[str, str, str, list]:
    """The task, the robot, the control mode and the episodes of ManiSkill's trajectory metadata, checked."""
    env_info = meta.get("env_info")
    if not isinstance(env_info, dict) or "env_id" not in env_info:
        raise ConfigError(f"replay: {where}'env_info' expected an object with 'env_id' (ManiSkill writes null when the "
                          f"env was not made by gym.make, and then the task is unknown), got {env_info!r}")  # fmt: skip
    task = env_info["env_id"]
    if task not in TASK_IDS or task not in STATE_ACTORS:
        known = [t for t in TASK_IDS if t in STATE_ACTORS]
        raise ConfigError(f"replay: {where}env_info.env_id {task!r} is not a task whose trajectories wpctrl replays; "
                          f"expected one of {known}")  # fmt: skip
    kwargs = env_info.get("env_kwargs") or {}
    robot = kwargs.get("robot_uids", default_robot(task))  # absent: the env's default robot
    if robot not in ROBOTS:
        raise ConfigError(f"replay: {where}env_info.env_kwargs.robot_uids expected one of {list(ROBOTS)} (the robots "
                          f"wpctrl's tasks build), got {robot!r}")  # fmt: skip
    episodes = meta.get("episodes")
    if not isinstance(episodes, list) or not episodes:
        raise ConfigError(f"replay: {where}'episodes' expected a non-empty list, got {episodes!r}")
    modes = []
    for i, ep in enumerate(episodes):
        for key in ("episode_id", "control_mode", "elapsed_steps"):
            if not isinstance(ep, dict) or key not in ep:
                raise ConfigError(f"replay: {where}episodes[{i}] has no {key!r}")
        if not isinstance(ep["elapsed_steps"], int) or ep["elapsed_steps"] < 1:
            raise ConfigError(f"replay: {where}episodes[{i}].elapsed_steps expected an integer >= 1, got "
                              f"{ep['elapsed_steps']!r}")  # fmt: skip
        modes.append(ep["control_mode"])
    mode = modes[0]
    if mode not in CONTROL_MODES:
        raise ConfigError(f"replay: {where}episodes[0].control_mode {mode!r} is not one of the Panda's "
                          f"{list(CONTROL_MODES)}")  # fmt: skip
    for i, other in enumerate(modes):
        if other != mode:
            raise ConfigError(f"replay: {where}episodes[{i}].control_mode expected {mode!r} (one control mode per "
                              f"file, as episodes[0]), got {other!r}")  # fmt: skip
    if kwargs.get("control_mode", mode) != mode:
        raise ConfigError(f"replay: {where}env_info.env_kwargs.control_mode {kwargs['control_mode']!r} and the "
                          f"episodes' control_mode {mode!r} differ")  # fmt: skip
    ids = [ep["episode_id"] for ep in episodes]
    if len(set(ids)) != len(ids):
        raise ConfigError(f"replay: {where}episodes[].episode_id expected distinct ids, got {ids}")
    return task, robot, mode, episodes


def _seed(ep: dict, i: int) -> int:
    """The episode's reset seed: ``reset_kwargs["seed"]`` (a one-element list on a batched env), else
    ``episode_seed``."""
    seed = (ep.get("reset_kwargs") or {}).get("seed", ep.get("episode_seed"))
    if isinstance(seed, list) and len(seed) == 1:
        seed = seed[0]
    if seed is not None and not isinstance(seed, int):
        raise ConfigError(f"replay: episodes[{i}].reset_kwargs.seed expected one integer, got {seed!r}")
    return i if seed is None else seed


def _array(group, key: str, where: str, shape: tuple) -> np.ndarray:
    """``group[key]`` as a numpy array of ``shape`` (``None``: any length on that axis)."""
    h5py = _h5py()
    if key not in group:
        raise ConfigError(f"replay: {where}{group.name.lstrip('/')}/{key} is missing")
    node = group[key]
    if not isinstance(node, h5py.Dataset):
        raise ConfigError(f"replay: {where}{node.name.lstrip('/')} expected an array, got a group (dict actions or "
                          f"observations are not the Panda's)")  # fmt: skip
    a = node[()]
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        want = tuple("any" if s is None else s for s in shape)
        raise ConfigError(f"replay: {where}{node.name.lstrip('/')} expected shape {want}, got {a.shape}")
    return a


def _episode(traj, ep: dict, i: int, task: str, robot: str, where: str) -> dict:
    """One ``traj_<id>`` group and its metadata as the project's episode structure."""
    steps = int(ep["elapsed_steps"])
    name = traj.name.lstrip("/")
    actions = _array(traj, "actions", where, (None, None))
    if len(actions) != steps:
        raise ConfigError(f"replay: {where}episodes[{i}].elapsed_steps is {steps}, {name}/actions has "
                          f"{len(actions)} steps")  # fmt: skip
    if "env_states" not in traj:
        raise ConfigError(f"replay: {where}{name}/env_states is missing: the replay starts from the recorded "
                          f"states (record with RecordEpisode(record_env_state=True))")  # fmt: skip
    states = traj["env_states"]
    need = [("actors", a, STATE_ACTOR_WIDTH) for a in STATE_ACTORS[task]]
    init: dict[str, dict[str, list]] = {"actors": {}, "articulations": {}}
    poses = None
    main = main_object(task)
    for group, key, dim in [*need, ("articulations", robot, STATE_ROBOT_WIDTH)]:
        if group not in states:
            raise ConfigError(f"replay: {where}{name}/env_states/{group} is missing (the {task} state has "
                              f"{[k for _, k, _ in need]} and {robot!r})")  # fmt: skip
        a = _array(states[group], key, where, (steps + 1, dim))
        init[group][key] = a[0].tolist()
        if key == main:
            poses = a[:, :7]
    out = {
        "seed": _seed(ep, i),
        "episode_id": ep["episode_id"],
        "reset_kwargs": ep.get("reset_kwargs") or {},
        "init_state_dict": init,
        "actions": actions.astype(np.float32).tolist(),
        "cube_pose": poses.tolist(),
        "info": {},
        "n_steps": steps,
    }
    for key in ("success", "fail"):
        if key in traj:
            flags = _array(traj, key, where, (steps,)).astype(bool)
            out["info"][key] = [False, *flags.tolist()]  # t = 0 (the reset) is not recorded
            if key in ep and steps and bool(ep[key]) != bool(flags[-1]):
                raise ConfigError(f"replay: {where}episodes[{i}].{key} is {ep[key]}, {name}/{key} ends with "
                                  f"{bool(flags[-1])}")  # fmt: skip
    if "success" not in out["info"]:
        raise ConfigError(f"replay: {where}{name}/success is missing (the replay compares ManiSkill's success)")
    out["success_at_end"] = out["info"]["success"][-1]
    for key in ("terminated", "truncated"):
        if key in traj:
            out[key] = _array(traj, key, where, (steps,)).astype(bool).tolist()
    if "obs" in traj and isinstance(traj["obs"], _h5py().Dataset):
        out["obs"] = _array(traj, "obs", where, (steps + 1, None)).tolist()
    return out


def _h5py():
    try:
        import h5py
    except ImportError as e:
        from ..extras import missing

        raise ImportError(missing("reading ManiSkill's trajectory files (.h5)", "tasks", e, torch=True)) from e
    return h5py


def read_trajectory(path, metadata: dict | None = None) -> dict:
    """ManiSkill's trajectory (``path``: its ``.h5`` or its ``.json``; the other file of the pair lies beside it
    under the same base name) as the replay's episode structure: ``header`` (``task``, ``control_mode``,
    ``env_kwargs``, ``max_episode_steps``, ``source``) and ``episodes``, in the metadata's order. ``metadata``: the
    ``.json`` already loaded. Host only; raises :class:`~wpctrl.ConfigError` (or ``FileNotFoundError`` for a missing
    file of the pair) before anything is built."""
    meta_path, h5_path = _pair(Path(path))
    for p in (meta_path, h5_path):
        if not p.is_file():
            raise FileNotFoundError(f"replay: ManiSkill's trajectory {str(path)!r} needs {str(p)!r} beside it (the "
                                    f"pair X.json + X.h5), which is missing")  # fmt: skip
    meta = _load_json(meta_path) if metadata is None else metadata
    where = f"{str(meta_path)!r}: "
    if not is_trajectory_metadata(meta):
        raise ConfigError(f"replay: {where}expected ManiSkill's trajectory metadata (an object with 'env_info' and "
                          f"'episodes')")  # fmt: skip
    task, robot, mode, meta_episodes = _check_metadata(meta, where)
    h5py = _h5py()
    where = f"{str(h5_path)!r}: "
    try:
        with h5py.File(h5_path, "r") as f:
            groups = sorted(k for k in f.keys() if k.startswith("traj_"))
            wanted = sorted(f"traj_{ep['episode_id']}" for ep in meta_episodes)
            if len(groups) != len(meta_episodes):
                raise ConfigError(f"replay: {where}holds {len(groups)} trajectories (traj_*), {str(meta_path)!r} "
                                  f"lists {len(meta_episodes)} episodes")  # fmt: skip
            if groups != wanted:
                raise ConfigError(f"replay: {where}trajectories {groups} do not match the episode_id of "
                                  f"{str(meta_path)!r}'s episodes ({wanted})")  # fmt: skip
            episodes = [_episode(f[f"traj_{ep['episode_id']}"], ep, i, task, robot, where)
                        for i, ep in enumerate(meta_episodes)]  # fmt: skip
    except (OSError, KeyError, RuntimeError) as e:  # h5py: a truncated or corrupt file, an unreadable object
        raise ConfigError(
            f"replay: {str(h5_path)!r} is not a readable HDF5 trajectory file (truncated or corrupt?): {e}"
        ) from e
    env_info = meta["env_info"]
    header = {
        "task": task,
        "control_mode": mode,
        "env_kwargs": env_info.get("env_kwargs") or {},
        "max_episode_steps": env_info.get("max_episode_steps"),
        "main_object": main_object(task),
        "source": {"format": "maniskill_trajectory", "json": str(meta_path), "h5": str(h5_path)},
    }
    return {"header": header, "episodes": episodes}


def by_length(data) -> list:
    """A loaded recording split into recordings of equally long episodes (the replay steps a file's episodes
    together), shortest first, each episode's order kept; anything else is returned as ``[data]`` untouched."""
    if not isinstance(data, dict) or not isinstance(data.get("episodes"), list):
        return [data]
    groups: dict[int, list] = {}
    for ep in data["episodes"]:
        n = len(ep["actions"]) if isinstance(ep, dict) and isinstance(ep.get("actions"), list) else -1
        groups.setdefault(n, []).append(ep)
    if len(groups) <= 1:
        return [data]
    return [{**data, "episodes": groups[n]} for n in sorted(groups)]
