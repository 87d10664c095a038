"""Host-side checks of what a user hands the tasks' envs (actions, env selections, seeds, state dicts), before any
launch. Nothing here imports Warp, Newton or torch at import time: the replay checks its files' state dicts with
:func:`state_dict_arrays` before anything heavy loads."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..config import ConfigError
from .names import ROBOTS

__all__ = [
    "STATE_ACTOR_WIDTH",
    "STATE_ROBOT_WIDTH",
    "action_tensor",
    "env_mask",
    "reset_options",
    "row_vectors",
    "seed_value",
    "state_dict_arrays",
    "state_field",
    "state_robot",
]

STATE_ACTOR_WIDTH = 13
"""An actor's entry of ManiSkill's state dict: p (3), q wxyz (4), linear velocity (3), angular velocity (3)."""
STATE_ROBOT_WIDTH = 31
"""The robot's entry (``panda`` or ``panda_wristcam``): root pose (7), root velocity (6), qpos (9), qvel (9)."""


def action_tensor(action, num_envs: int, action_dim: int, device):
    """``action`` as a float32 torch tensor of shape (num_envs, action_dim) on ``device`` (a single env's
    (action_dim,) action is accepted when num_envs is 1). NaN / Inf values pass: the controller holds the previous
    targets of such an env (its NaN policy)."""
    import torch

    if isinstance(action, dict):
        raise ConfigError("step: expected an action array, got a dict (the tasks have one agent)")
    t = action if isinstance(action, torch.Tensor) else torch.as_tensor(np.asarray(action, dtype=np.float32))
    if t.ndim == 1 and num_envs == 1:
        t = t[None]
    if tuple(t.shape) != (num_envs, action_dim):
        raise ConfigError(f"step: action expected shape ({num_envs}, {action_dim}), got {tuple(t.shape)}")
    if t.dtype.is_complex or t.dtype == torch.bool:
        raise ConfigError(f"step: action expected real numbers, got dtype {t.dtype}")
    return t.to(device=device, dtype=torch.float32)


def env_mask(env_idx, num_envs: int, device):
    """A device bool mask (``wp.array``) of ``env_idx``: env indices (int, sequence, numpy or torch) or a bool mask
    of num_envs."""
    import warp as wp

    a = env_idx.detach().cpu().numpy() if hasattr(env_idx, "detach") else np.asarray(env_idx)
    if a.dtype == np.bool_:
        if a.shape != (num_envs,):
            raise ConfigError(f"env_idx: a bool mask must have shape ({num_envs},), got {a.shape}")
        mask = a
    else:
        if a.size and not np.issubdtype(a.dtype, np.integer):
            raise ConfigError(f"env_idx: expected env indices (integers) or a bool mask, got dtype {a.dtype}")
        ids = a.reshape(-1).astype(np.int64)
        if ids.size and (ids.min() < 0 or ids.max() >= num_envs):
            raise ConfigError(f"env_idx: indices must be in [0, {num_envs}), got {sorted(set(ids.tolist()))}")
        mask = np.zeros(num_envs, np.bool_)
        mask[ids] = True
    return wp.array(mask, dtype=wp.bool, device=device)


def row_vectors(value, name: str, rows: int, width: int, who: str) -> np.ndarray:
    """``value`` (numpy, torch or nested lists) as a float32 (rows, width) array, one row per env selected; a
    (width,) vector stands for every row. Refused unless numbers, of that shape, finite; ``who`` and ``name`` open
    each message."""
    v = value.detach().to("cpu") if hasattr(value, "detach") else value
    try:
        a = np.asarray(v)
    except (ValueError, TypeError):
        a = np.asarray(None)
    if a.dtype.kind not in "iuf":
        raise ConfigError(f"{who}: {name} expected an array of numbers, got {type(value).__name__}")
    if a.shape == (width,):
        a = np.broadcast_to(a, (rows, width))
    if a.shape != (rows, width):
        raise ConfigError(f"{who}: {name} expected shape ({rows}, {width}) or ({width},), got {tuple(np.shape(v))} "
                          f"(a row per env selected, or one for all)")  # fmt: skip
    if not np.isfinite(a).all():
        raise ConfigError(f"{who}: {name} holds non-finite values (expected finite numbers)")
    return np.ascontiguousarray(a, np.float32)


def seed_value(seed) -> int:
    """A reset seed as a non-negative int32 (ManiSkill takes any int; Warp's RNG a 32-bit one)."""
    if isinstance(seed, (list, tuple, np.ndarray)):
        raise ConfigError("reset: seed expected one int for all envs (per-env seed lists are not supported), got a "
                          f"sequence of {len(seed)}")  # fmt: skip
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ConfigError(f"reset: seed expected an int, got {seed!r}")
    return int(seed) % (2**31)


def reset_options(options, known: tuple[str, ...]) -> dict:
    """``reset``'s ``options`` as a dict (None: empty); a key outside ``known`` is refused (it would be ignored)."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ConfigError(f"reset: options expected a dict with keys from {list(known)} or None, got "
                          f"{type(options).__name__}")  # fmt: skip
    unknown = sorted((k for k in options if k not in known), key=str)
    if unknown:
        raise ConfigError(f"reset: unknown options key(s) {unknown}; expected keys from {list(known)}")
    return options


def state_robot(state: dict) -> str:
    """The robot of a state dict checked by :func:`state_dict_arrays`: its one articulation's name."""
    return next(iter(state["articulations"]))


def state_field(root: str, dotted: bool = False) -> Callable[..., str]:
    """How the refusals of :func:`state_dict_arrays` name a field: ``field(group)`` and ``field(group, name)``, as
    Python indexing (``state['actors']['cube']``: a dict the caller holds) or, ``dotted``, as a path into a file
    (``episodes[0].init_state_dict.actors['cube']``)."""

    def field(group: str, name: str | None = None) -> str:
        head = f"{root}.{group}" if dotted else f"{root}[{group!r}]"
        return head if name is None else f"{head}[{name!r}]"

    return field


def state_dict_arrays(state, actors: Sequence[str] | None, task: str, who: str, root: str = "state",
                      dotted: bool = False, rows: int | None = None, robot_width: int = STATE_ROBOT_WIDTH,
                      robot: str | None = None) -> dict[str, np.ndarray]:  # fmt: skip
    """The entries of a state dict in ManiSkill's layout (``{"actors": {name: (.., 13)}, "articulations": {"panda":
    (.., 31)}}``) as float32 numpy arrays by name, checked for what a task's env loads: exactly the task's ``actors``
    (``None``: any names; an actor of another task or one missing is refused, naming it), one articulation, the
    robot ``robot`` (``None``: either of :data:`~wpctrl.tasks.names.ROBOTS`; :func:`state_robot` tells which),
    numbers of the right shape, finite. ``rows``: the number of envs set, each entry ``(rows, D)`` or
    ``(D,)`` for all (returned as ``(rows, D)``); ``None``: one env's entry, ``(D,)`` (a recording's
    ``init_state_dict``). The refusals (:class:`~wpctrl.ConfigError`) start with ``who``, name the field from
    ``root`` (:func:`state_field`), the expected and the received value, and ``task``. Host only."""
    field = state_field(root, dotted)
    if not isinstance(state, dict) or "actors" not in state or "articulations" not in state:
        got = sorted(state, key=str) if isinstance(state, dict) else type(state).__name__
        raise ConfigError(f"{who}{root} expected a dict with 'actors' and 'articulations', got {got}")
    for group in ("actors", "articulations"):
        if not isinstance(state[group], dict):
            raise ConfigError(f"{who}{field(group)} expected a dict of {group} by name, got "
                              f"{type(state[group]).__name__}")  # fmt: skip
    arms = sorted(state["articulations"], key=str)
    if robot is None:
        if len(arms) != 1 or arms[0] not in ROBOTS:
            raise ConfigError(f"{who}{field('articulations')} expected one robot of {list(ROBOTS)}, got {arms}")
        robot = arms[0]
    elif robot not in state["articulations"] and len(arms) == 1 and arms[0] in ROBOTS:
        raise ConfigError(f"{who}{field('articulations', arms[0])} is a state of the robot {arms[0]!r}, expected "
                          f"{robot!r} ({task} on {robot!r}; make(..., robot_uids={arms[0]!r}) builds the "
                          f"other)")  # fmt: skip
    wanted = {"actors": None if actors is None else list(actors), "articulations": [robot]}
    for group in ("actors", "articulations"):
        ours = wanted[group]
        theirs = sorted(state[group], key=str)
        extra = [name for name in theirs if ours is not None and name not in ours]
        if extra:
            raise ConfigError(f"{who}{field(group, extra[0])} is not part of {task} (its {group}: {ours}, got "
                              f"{theirs}); a state dict of another task?")  # fmt: skip
        for name in [] if ours is None else ours:
            if name not in state[group]:
                raise ConfigError(f"{who}{field(group)} has no {name!r} entry, which {task} needs (expected {ours}, "
                                  f"got {theirs})")  # fmt: skip
    names = sorted(state["actors"], key=str) if actors is None else wanted["actors"]
    need = [("actors", name, STATE_ACTOR_WIDTH) for name in names]
    out = {}
    for group, name, width in [*need, ("articulations", robot, robot_width)]:
        v = state[group][name]
        v = v.detach().to("cpu") if hasattr(v, "detach") else v
        try:
            a = np.asarray(v)
        except (ValueError, TypeError):  # a ragged list
            a = None
        if a is None or a.dtype.kind not in "iuf":
            got = type(v).__name__ if a is None else f"dtype {a.dtype}"
            raise ConfigError(f"{who}{field(group, name)} expected an array of numbers, got {got}")
        if rows is None and a.shape != (width,):
            raise ConfigError(f"{who}{field(group, name)} expected shape ({width},), got {a.shape}")
        if rows is not None:
            if a.ndim == 1 and a.shape == (width,):
                a = np.broadcast_to(a, (rows, width))
            if a.shape != (rows, width):
                raise ConfigError(f"{who}{field(group, name)} expected shape ({rows}, {width}) ({rows} envs set, "
                                  f"{width} values each) or ({width},), got {tuple(np.shape(v))}")  # fmt: skip
        a = a.astype(np.float32)
        if not np.isfinite(a).all():
            raise ConfigError(f"{who}{field(group, name)} holds non-finite values (expected finite numbers)")
        out[name] = a
    return out
