"""``wpctrl evaluate --sim maniskill --record FILE``: the ManiSkill episodes an evaluation runs, saved in the episode
format ``wpctrl replay`` reads (:mod:`wpctrl.tasks.replay`), so that the policy's own episodes replay open-loop on
Newton and show where the two simulators part.

Per episode: ``seed``, ``init_state_dict`` (ManiSkill's ``get_state_dict()`` right after ``reset(seed=seed)``),
``actions`` (what the evaluation sent to ``env.step``: the policy's output), ``info`` (every boolean of ManiSkill's
info (``success`` among them), at t = 0 after the reset and after every step), ``info_values`` (its other values),
``cube_pose`` (the task's main object, ``[p, q wxyz]``, t = 0 .. T), ``obs`` (the policy's input, t = 0 .. T),
``reward_normalized_dense``, ``terminated``, ``truncated`` (per step), ``success_once``, ``success_at_end``,
``first_success_step`` and ``n_steps``. The header names the task, control mode, the env's ``gym.make`` arguments,
``max_episode_steps``, the simulation and control rates, the action bounds, the policy file and its metadata, and the
versions of the packages that ran it. Every float is float32, written as the shortest decimal that reads back as the
same float32: ManiSkill, reset with an episode's seed, is in the recorded state, and the recorded actions give the
recorded steps bit for bit. Loading ``init_state_dict`` instead (``set_state_dict``, as a replay elsewhere starts)
agrees to float32 rounding only: setting the Panda's root pose, even to its own value, resets state PhysX keeps for
the articulation.

The file is written once every episode has run, to a temporary file beside it that is then renamed: an interrupted
evaluation leaves no file. A name ending in ``.gz`` is gzip-compressed.
"""

from __future__ import annotations

import gzip
import json
import os
import platform
from importlib import metadata
from pathlib import Path

import numpy as np

__all__ = ["FORMAT", "EpisodeRecorder"]

FORMAT = "wpctrl-evaluate-record-1"
"""``header.format`` of a recording."""

_VERSIONED = ("wpctrl", "mani-skill", "sapien", "torch", "numpy", "gymnasium")


def _floats(x) -> list[float]:
    """``x`` (a tensor or array, any shape) flattened to float32 values, each the shortest decimal of its float32."""
    a = np.asarray(x.detach().cpu() if hasattr(x, "detach") else x, dtype=np.float32).ravel()
    return [float(str(v)) for v in a]


def _versions() -> dict:
    out = {"python": platform.python_version()}
    for name in _VERSIONED:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def _split_info(info: dict) -> tuple[dict, dict]:
    """ManiSkill's info (one env) as its booleans and its other values (the step counter left out)."""
    flags, values = {}, {}
    for key, v in info.items():
        if key == "elapsed_steps" or not hasattr(v, "dtype"):
            continue
        if str(v.dtype) == "torch.bool":
            flags[key] = bool(v.reshape(-1)[0])
        else:
            values[key] = _floats(v[0] if v.ndim > 1 else v)
    return flags, values


class EpisodeRecorder:
    """Collects the episodes of one ManiSkill evaluation and writes them to ``path`` (:meth:`write`).

    The evaluation calls :meth:`start` once with its env, then per episode :meth:`reset` after ``env.reset`` and
    :meth:`step` after every ``env.step``. The recorder only reads the env (its state dict and the values the calls
    return), so the episodes run as they would unrecorded."""

    def __init__(self, path, policy_file, policy_meta: dict):
        self.path = Path(path)
        self.policy_file = str(policy_file)
        self.policy_meta = dict(policy_meta)
        self.header: dict = {}
        self.episodes: list[dict] = []
        self._env = None
        self._main = "cube"

    def start(self, env, task: str, control_mode: str, max_episode_steps: int) -> None:
        """The header, from the env the episodes run in (``gym.make``'s env: its ``unwrapped`` is ManiSkill's)."""
        from wpctrl.tasks.names import main_object

        u = env.unwrapped
        self._env, self._main = u, main_object(task)
        kwargs = {k: v for k, v in dict(env.spec.kwargs).items() if isinstance(v, (str, int, float, bool))}
        space = u.single_action_space
        self.header = {
            "format": FORMAT,
            "task": task,
            "control_mode": control_mode,
            "env_kwargs": {**kwargs, "robot_uids": str(u.robot_uids)},
            "max_episode_steps": int(max_episode_steps),
            "sim_freq": int(u.sim_freq),
            "control_freq": int(u.control_freq),
            "action_space": {"low": _floats(space.low), "high": _floats(space.high)},
            "actor_names": sorted(u.get_state_dict()["actors"]),
            "main_object": self._main,
            "joint_names": [j.name for j in u.agent.robot.active_joints],
            "policy": self.policy_file,
            "policy_metadata": self.policy_meta,
            "source": "wpctrl evaluate --sim maniskill: one PhysX CPU env, rendering stubbed out, "
            "env.reset(seed=seed + i) for episode i, the policy's action sent to env.step unchanged",
            "reproduce": "in ManiSkill: env.reset(seed=seed), then the actions, gives every recorded step bit for "
            "bit; set_state_dict(init_state_dict) after the reset agrees to float32 rounding",
            "float_format": "float32 values, each written as the shortest decimal that reads back as the same float32",
            "versions": _versions(),
        }

    def _pose(self) -> list[float]:
        return _floats(self._env.get_state_dict()["actors"][self._main][0, :7])

    def reset(self, seed: int, obs, info: dict) -> None:
        """A new episode, right after ``env.reset(seed=seed)`` returned ``obs, info``."""
        state = self._env.get_state_dict()
        flags, values = _split_info(info)
        self.episodes.append({
            "seed": int(seed),
            "control_mode": self.header["control_mode"],
            "init_state_dict": {group: {name: _floats(v[0]) for name, v in state[group].items()}
                                for group in ("actors", "articulations")},
            "actions": [],
            "obs": [_floats(obs[0])],
            "reward_normalized_dense": [],
            "info": {k: [v] for k, v in flags.items()},
            "info_values": {k: [v] for k, v in values.items()},
            "cube_pose": [self._pose()],
            "terminated": [],
            "truncated": [],
        })  # fmt: skip

    def step(self, action, obs, reward, terminated, truncated, info: dict) -> None:
        """One step of the current episode: ``action`` as sent to ``env.step``, and what it returned."""
        ep = self.episodes[-1]
        ep["actions"].append(_floats(action[0]))
        ep["obs"].append(_floats(obs[0]))
        ep["reward_normalized_dense"].append(_floats(reward)[0])
        ep["terminated"].append(bool(terminated.reshape(-1)[0]))
        ep["truncated"].append(bool(truncated.reshape(-1)[0]))
        flags, values = _split_info(info)
        for k, v in flags.items():
            ep["info"].setdefault(k, []).append(v)
        for k, v in values.items():
            ep["info_values"].setdefault(k, []).append(v)
        ep["cube_pose"].append(self._pose())

    def finish_episode(self) -> dict:
        """The current episode's outcome fields, filled in from its per-step ``success``."""
        ep = self.episodes[-1]
        success = ep["info"].get("success", [False])[1:]
        first = next((k + 1 for k, s in enumerate(success) if s), None)
        ep.update(n_steps=len(ep["actions"]), success_once=first is not None,
                  success_at_end=bool(success[-1]) if success else False, first_success_step=first)  # fmt: skip
        return ep

    def write(self) -> Path:
        """All episodes to ``path`` (gzip-compressed if it ends in ``.gz``), through a temporary file beside it that is
        renamed once complete."""
        header = {**self.header, "seeds": [ep["seed"] for ep in self.episodes], "n_episodes": len(self.episodes)}
        raw = json.dumps({"header": header, "episodes": self.episodes}, separators=(",", ":")).encode()
        if self.path.name.endswith(".gz"):
            raw = gzip.compress(raw, mtime=0)
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.part")
        try:
            with open(tmp, "wb") as f:
                f.write(raw)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        return self.path
