"""A recorded episode file read and checked for the replay (:func:`load_episodes`), host only: ManiSkill's episode
JSON (plain or ``.json.gz``), its trajectory files (:mod:`wpctrl.tasks.maniskill_trajectory`) or policy-driven episodes
(:mod:`wpctrl.tasks.policy_episodes`), every field the replay reads checked before any env is built or any state
written, a refusal naming the file, the field, what was expected and what came. Only the last check, the action width
against the control mode's controller configs, loads the robot's description (Newton).
"""

from __future__ import annotations

import functools
import gzip
import json
import zlib
from pathlib import Path

import numpy as np

from ..config import ConfigError
from . import maniskill_trajectory as trajectory
from . import policy_episodes
from .names import CONTROL_MODES, TASK_ACTORS, TASK_IDS, main_object

__all__ = ["EXPECTED", "action_width", "load_episodes", "main_poses", "recorded_robot", "replayed_object"]


EXPECTED = (
    "ManiSkill's episode JSON (an object with 'header' and 'episodes'), plain or gzip-compressed (.json.gz), "
    "or ManiSkill's trajectory file (X.h5 with its X.json), or policy episodes (<Task>__<control_mode>__policy.npz)"
)
"""What a replay file must be, as the refusals say it."""


def _read(path: Path) -> dict:
    """A recording's JSON, from a plain or a gzip-compressed file (told by its first bytes), or ManiSkill's
    trajectory file (a ``.h5``, or the ``.json`` of one: it has ``env_info``) or policy episodes (a ``.npz``:
    :mod:`wpctrl.tasks.policy_episodes`) as the same episode structure."""
    if policy_episodes.is_policy_file(path):
        return policy_episodes.read_policy_episodes(path)
    if trajectory.is_trajectory(path):
        return trajectory.read_trajectory(path)
    with path.open("rb") as f:
        raw = f.read()
    why = "not a readable gzip file"
    try:
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
        why = "not JSON text"
        data = json.loads(raw)
    except (ValueError, OSError, EOFError, zlib.error) as e:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise ConfigError(f"replay: {str(path)!r} is not a recording ({why}); expected {EXPECTED}") from e
    return trajectory.read_trajectory(path, data) if trajectory.is_trajectory_metadata(data) else data


def load_episodes(source) -> dict:
    """A recorded episode file (path: JSON or ``.json.gz``, or ManiSkill's trajectory file, ``.h5`` with its
    ``.json``: see :mod:`wpctrl.tasks.maniskill_trajectory`) or its loaded dict, checked for what the replay reads:
    ManiSkill's format, a task and control mode :func:`wpctrl.tasks.make` builds, every episode's actions (finite,
    the control mode's width), ``info`` flags, seed, initial state (the task's actors and the Panda) and its main
    object's poses (one more than the actions): see :func:`_checked`. Host only (no env is built; the action width
    loads the robot's description)."""
    return _checked(*_load(source))


def _load(source) -> tuple:
    """The recording of ``source`` (a path, or a loaded dict as it is) and how the refusals name it."""
    data = source
    where = ""
    if not isinstance(source, dict):
        path = Path(source)
        if not path.is_file():
            raise FileNotFoundError(f"replay: no episode file {str(path)!r}")
        data = _read(path)
        where = f"{str(path)!r}: "
    return data, where


def _checked(data, where: str) -> dict:
    """``data`` after the checks of :func:`load_episodes`; ``where`` prefixes the refusals. Every check of a
    recording is here, each refusal naming the field, the expected and the received value, before any env is built
    or any state written: the header's task and control mode; per episode its actions (numbers, finite, one row of
    the control mode's action width per step), ``n_steps``, the ``info`` flags the replay reads (one per step and
    one for the reset), the seed, ``init_state_dict`` (the task's actors of :data:`wpctrl.tasks.names.TASK_ACTORS`,
    one robot's articulation, ``panda`` or ``panda_wristcam``, the same in every episode, widths 13 and 31,
    finite: :func:`wpctrl.tasks._validate.state_dict_arrays`, the
    checks ``set_state_dict`` makes) and the main object's poses. The action width is the last check (it reads the
    control mode's controller configs, which loads the robot's description): a file refused for anything else is
    refused before Warp or Newton loads."""
    from ._validate import state_dict_arrays, state_robot

    if not isinstance(data, dict) or "header" not in data or "episodes" not in data:
        raise ConfigError(f"replay: {where}expected ManiSkill's episode format: a dict with 'header' and 'episodes' "
                          f"({EXPECTED})")  # fmt: skip
    header = data["header"]
    if not isinstance(header, dict):
        raise ConfigError(f"replay: {where}header expected an object with 'task' and 'control_mode', got "
                          f"{type(header).__name__}")  # fmt: skip
    for key in ("task", "control_mode"):
        if key not in header:
            raise ConfigError(f"replay: {where}the header has no {key!r}")
    task, mode = header["task"], header["control_mode"]
    if task not in TASK_IDS:
        raise ConfigError(f"replay: {where}task {task!r} is not one wpctrl builds; expected one of "
                          f"{list(TASK_IDS)}")  # fmt: skip
    if mode not in CONTROL_MODES:
        raise ConfigError(f"replay: {where}control mode {mode!r} is not one of the Panda's "
                          f"{list(CONTROL_MODES)}")  # fmt: skip
    if not isinstance(data["episodes"], list):
        raise ConfigError(f"replay: {where}episodes expected a list, got {type(data['episodes']).__name__}")
    if not data["episodes"]:
        raise ConfigError(f"replay: {where}the file holds no episodes")
    main = replayed_object(header)
    declared = TASK_ACTORS.get(task)
    robot = None  # either robot, until the first episode names it
    actions = []
    for i, ep in enumerate(data["episodes"]):
        if not isinstance(ep, dict):
            raise ConfigError(f"replay: {where}episodes[{i}] expected an object, got {type(ep).__name__}")
        for key in ("init_state_dict", "actions", "info"):
            if key not in ep:
                raise ConfigError(f"replay: {where}episode {i} has no {key!r}")
        if not ep["actions"]:
            raise ConfigError(f"replay: {where}episode {i} has no actions")
        actions.append(_actions(ep["actions"], f"replay: {where}episodes[{i}].actions"))
        steps = len(actions[-1])
        if "n_steps" in ep and ep["n_steps"] != steps:
            raise ConfigError(f"replay: {where}episodes[{i}].n_steps is {ep['n_steps']!r}, expected {steps} (the "
                              f"number of actions)")  # fmt: skip
        _check_info(ep["info"], steps, f"replay: {where}episodes[{i}].info")
        seed = ep.get("seed", i)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ConfigError(f"replay: {where}episodes[{i}].seed expected a non-negative integer (the reset's seed), "
                              f"got {seed!r}")  # fmt: skip
        state_dict_arrays(ep["init_state_dict"], None if declared is None else declared.state, task,
                          f"replay: {where}", root=f"episodes[{i}].init_state_dict", dotted=True,
                          robot=robot)  # fmt: skip
        robot = state_robot(ep["init_state_dict"])  # one robot per file: the first episode's
        if main not in ep["init_state_dict"]["actors"]:
            have = sorted(ep["init_state_dict"]["actors"])
            raise ConfigError(f"replay: {where}episode {i}: the main object {main!r} is not an actor of its "
                              f"init_state_dict ({have!r})")  # fmt: skip
        poses = main_poses(ep, main)
        if poses is None:
            raise ConfigError(f"replay: {where}episode {i} has neither 'actor_poses'[{main!r}] nor 'cube_pose' (the "
                              f"main object's pose per step)")  # fmt: skip
        if isinstance(poses, list) and len(poses) != steps + 1:
            raise ConfigError(f"replay: {where}episode {i} has {steps} actions and {len(poses)} poses of "
                              f"{main!r} (expected one more: t = 0 .. T)")  # fmt: skip
        name = "actor_poses" if main in (ep.get("actor_poses") or {}) else "cube_pose"
        _numbers(poses, f"replay: {where}episodes[{i}].{name}" + (f"[{main!r}]" if name == "actor_poses" else ""),
                 (steps + 1, 7))  # fmt: skip
    width = action_width(mode)
    for i, a in enumerate(actions):
        if a.shape[1] != width:
            raise ConfigError(f"replay: {where}episodes[{i}].actions has {a.shape[1]} values per step, control mode "
                              f"{mode!r} takes {width} (its controllers' action space)")  # fmt: skip
    return data


def _numbers(values, name: str, shape: tuple) -> np.ndarray:
    """``values`` as a float64 array of ``shape`` (a letter: any length on that axis), all finite, or a refusal
    naming ``name`` (which starts with the refusals' prefix)."""
    try:
        a = np.asarray(values)
    except (ValueError, TypeError):  # ragged rows
        a = None
    if a is None or a.dtype.kind not in "iuf":
        got = "rows of different lengths" if a is None else f"dtype {a.dtype}"
        raise ConfigError(f"{name} expected an array of numbers, got {got}")
    if a.ndim != len(shape) or any(isinstance(s, int) and s != n for s, n in zip(shape, a.shape)):
        raise ConfigError(f"{name} expected shape ({', '.join(map(str, shape))}), got {a.shape}")
    a = a.astype(np.float64)
    bad = np.argwhere(~np.isfinite(a))
    if len(bad):
        at = "".join(f"[{k}]" for k in bad[0])
        raise ConfigError(f"{name}{at} is {a[tuple(bad[0])]}, expected a finite number")
    return a


def _actions(actions, name: str) -> np.ndarray:
    """An episode's actions as a (T, A) array, numbers, finite (the width is checked against the control mode)."""
    if not isinstance(actions, list):
        raise ConfigError(f"{name} expected a list of per-step actions, got {type(actions).__name__}")
    return _numbers(actions, name, ("T", "A"))


def _check_info(info, steps: int, name: str) -> None:
    """``info``: ManiSkill's ``evaluate()`` flags (``success`` required, and whichever of the task's others were
    recorded: ``is_grasped``, ``is_obj_on_bin``, ...), each ``steps + 1`` booleans (t = 0 after the reset, then after
    every step)."""
    if not isinstance(info, dict) or "success" not in info:
        got = sorted(info) if isinstance(info, dict) else type(info).__name__
        raise ConfigError(f"{name} expected an object with 'success' (a flag per step), got {got}")
    for key, flags in info.items():
        if not isinstance(flags, list) or len(flags) != steps + 1:
            got = f"{len(flags)} entries" if isinstance(flags, list) else type(flags).__name__
            raise ConfigError(f"{name}.{key} expected n_steps + 1 = {steps + 1} flags (t = 0 after the reset, then "
                              f"one per action), got {got}")  # fmt: skip
        odd = next((k for k, f in enumerate(flags) if not isinstance(f, (bool, np.bool_)) and f not in (0, 1)), None)
        if odd is not None:
            raise ConfigError(f"{name}.{key}[{odd}] expected a boolean, got {flags[odd]!r}")


@functools.cache
def action_width(control_mode: str) -> int:
    """The width of the Panda's action in ``control_mode``, as the env's action space has it: the sum of its
    controllers' action widths, from the mode's configs (:func:`wpctrl.robots.panda_control_modes`) through the
    config layer's rows (which do not depend on the joint limits). Imports the robot's description (Newton)."""
    from ..config.rows import config_rows
    from ..robots import panda_control_modes

    configs = panda_control_modes()[control_mode]
    unlimited = lambda c: np.tile(np.float32([[-np.inf, np.inf]]), (len(c.joint_names), 1))  # noqa: E731
    return sum(config_rows(c, unlimited(c)).action_dim for c in configs.values())


def recorded_robot(data: dict) -> str:
    """The robot a checked recording (:func:`load_episodes`) was made on: its episodes' articulation (``panda`` or
    ``panda_wristcam``), the robot its replay builds."""
    from ._validate import state_robot

    return state_robot(data["episodes"][0]["init_state_dict"])


def replayed_object(header: dict) -> str:
    """The actor a replay follows: the header's ``main_object``, else the task's."""
    return header.get("main_object") or main_object(header["task"])


def main_poses(ep: dict, main: str):
    """The main object's recorded poses (t = 0 .. T): ``actor_poses[main]``, else ``cube_pose``."""
    poses = ep.get("actor_poses") or {}
    return poses[main] if main in poses else ep.get("cube_pose")
