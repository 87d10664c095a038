"""Open-loop replay of ManiSkill's recorded episodes on Newton: every episode's initial state dict is loaded into
its own env (reset with the episode's seed first), its actions are replayed step by step (all episodes of a file at
once, one env each; episodes of different lengths step together and each is read up to its own last step), and
success and the main object's position are compared with ManiSkill's at every step.

The episode format is ManiSkill's recording of the tasks (a JSON file, plain or gzip-compressed ``.json.gz``, with
``header`` (``task``, ``control_mode``, optionally ``main_object``) and ``episodes``: ``seed``, ``init_state_dict``,
``actions``, ``info["success"]`` and the main object's pose per step, ``actor_poses[main_object]`` or ``cube_pose``,
...), ManiSkill's trajectory files (:mod:`wpctrl.tasks.maniskill_trajectory`) or policy-driven episodes as numpy
arrays (``<Task>__<control_mode>__policy.npz``: :mod:`wpctrl.tasks.policy_episodes`). The main object is the
header's ``main_object``, else the task's (:func:`wpctrl.tasks.names.main_object`: the cube of the cube tasks).
``python -m wpctrl replay FILE.json`` runs it from the command line: every file is read and checked
(:func:`load_episodes`) before any env is built or any state written, so a wrong file is refused at once,
with a :class:`~wpctrl.ConfigError` naming the file, the field, what was expected and what came; only the last check,
the action width against the control mode's controller configs, loads the robot's description (Newton), every other
refusal comes before Warp, Newton or torch is imported.
"""

from __future__ import annotations

import argparse
import functools
import gzip
import json
import sys
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..config import ConfigError
from . import maniskill_trajectory as trajectory
from . import policy_episodes
from .names import CONTROL_MODES, TASK_ACTORS, TASK_IDS, main_object

__all__ = ["FIRST_ACTIONS", "EpisodeResult", "ReplayReport", "load_episodes", "main", "replay"]


@dataclass
class EpisodeResult:
    """One episode replayed: ManiSkill's outcome next to Newton's."""

    seed: int
    success_recorded: list[bool]
    """ManiSkill's ``info["success"]`` after each step (t = 1 .. T)."""
    success: list[bool]
    """Newton's, after each step."""
    cube_error: list[float]
    """||main object's position on Newton - ManiSkill's|| after each step [m] (the cube of the cube tasks; the
    report's ``main_object``)."""
    success_at_end_recorded: bool
    success_at_end: bool
    is_grasped_recorded: list[bool] | None = None
    """PickCube: ManiSkill's ``info["is_grasped"]`` after each step."""
    is_grasped: list[bool] | None = None

    @property
    def agrees(self) -> bool:
        return self.success_at_end == self.success_at_end_recorded

    @property
    def success_once(self) -> bool:
        """Newton's success at any step (ManiSkill's ``success_once``)."""
        return any(self.success)

    @property
    def success_once_recorded(self) -> bool:
        return any(self.success_recorded)

    @property
    def final_cube_error(self) -> float:
        return self.cube_error[-1]


@dataclass
class ReplayReport:
    """All episodes of one file: per-episode results and the summary a user reads."""

    task: str
    control_mode: str
    episodes: list[EpisodeResult] = field(default_factory=list)
    main_object: str = "cube"
    """The actor whose position ``cube_error`` follows."""

    @property
    def success_agreement(self) -> float:
        """Fraction of ManiSkill's successful episodes (success at the end) that also end in success on Newton."""
        ok = [e for e in self.episodes if e.success_at_end_recorded]
        return float(np.mean([e.success_at_end for e in ok])) if ok else float("nan")

    @property
    def outcome_agreement(self) -> float:
        """Fraction of all episodes whose success at the end is the same on both."""
        return float(np.mean([e.agrees for e in self.episodes])) if self.episodes else float("nan")

    @property
    def once_agreement(self) -> float:
        """Fraction of all episodes whose success at any step (``success_once``) is the same on both."""
        same = [e.success_once == e.success_once_recorded for e in self.episodes]
        return float(np.mean(same)) if same else float("nan")

    @property
    def median_final_cube_error(self) -> float:
        return float(np.median([e.final_cube_error for e in self.episodes])) if self.episodes else float("nan")

    def summary(self) -> dict:
        return {
            "task": self.task,
            "control_mode": self.control_mode,
            "main_object": self.main_object,
            "episodes": len(self.episodes),
            "success_agreement": self.success_agreement,
            "outcome_agreement": self.outcome_agreement,
            "once_agreement": self.once_agreement,
            "median_final_cube_error_m": self.median_final_cube_error,
            "max_final_cube_error_m": max((e.final_cube_error for e in self.episodes), default=float("nan")),
        }

    def to_json(self) -> dict:
        return {"summary": self.summary(), "episodes": [asdict(e) for e in self.episodes]}

    def format(self) -> str:
        lines = [f"{self.task} {self.control_mode}: {len(self.episodes)} episodes replayed on Newton"]
        for e in self.episodes:
            first = next((i + 1 for i, s in enumerate(e.success) if s), None)
            first_rec = next((i + 1 for i, s in enumerate(e.success_recorded) if s), None)
            lines.append(
                f"  seed {e.seed:4d}: success at end {e.success_at_end!s:5} "
                f"(ManiSkill {e.success_at_end_recorded!s:5}), "
                f"first success step {first} ({first_rec}), {self.main_object} error final "
                f"{100 * e.final_cube_error:.2f} cm, "
                f"max {100 * max(e.cube_error):.2f} cm"
            )
        s = self.summary()
        lines.append(
            f"  successful ManiSkill episodes that succeed on Newton: {100 * s['success_agreement']:.0f} %; "
            f"same outcome: {100 * s['outcome_agreement']:.0f} % (success once: {100 * s['once_agreement']:.0f} %); "
            f"median final {self.main_object} error "
            f"{100 * s['median_final_cube_error_m']:.2f} cm"
        )
        return "\n".join(lines)


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


INFO_READ = ("success", "is_grasped")
"""The per-step flags of ``info`` the replay reads (``success`` required), each t = 0 .. T."""


def _checked(data, where: str) -> dict:
    """``data`` after the checks of :func:`load_episodes`; ``where`` prefixes the refusals. Every check of a
    recording is here, each refusal naming the field, the expected and the received value, before any env is built
    or any state written: the header's task and control mode; per episode its actions (numbers, finite, one row of
    the control mode's action width per step), ``n_steps``, the ``info`` flags the replay reads (one per step and
    one for the reset), the seed, ``init_state_dict`` (the task's actors of :data:`wpctrl.tasks.names.TASK_ACTORS`,
    the ``panda`` articulation, widths 13 and 31, finite: :func:`wpctrl.tasks._validate.state_dict_arrays`, the
    checks ``set_state_dict`` makes) and the main object's poses. The action width is the last check (it reads the
    control mode's controller configs, which loads the robot's description): a file refused for anything else is
    refused before Warp or Newton loads."""
    from ._validate import state_dict_arrays

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
    main = _main_object(header)
    declared = TASK_ACTORS.get(task)
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
                          f"replay: {where}", root=f"episodes[{i}].init_state_dict", dotted=True)  # fmt: skip
        if main not in ep["init_state_dict"]["actors"]:
            have = sorted(ep["init_state_dict"]["actors"])
            raise ConfigError(f"replay: {where}episode {i}: the main object {main!r} is not an actor of its "
                              f"init_state_dict ({have!r})")  # fmt: skip
        poses = _main_poses(ep, main)
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
    """The per-step flags the replay reads (:data:`INFO_READ`): ``success`` required, each ``steps + 1`` long
    (t = 0 after the reset, then after every step), booleans."""
    if not isinstance(info, dict) or "success" not in info:
        got = sorted(info) if isinstance(info, dict) else type(info).__name__
        raise ConfigError(f"{name} expected an object with 'success' (a flag per step), got {got}")
    for key in INFO_READ:
        if key not in info:
            continue
        flags = info[key]
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


def _main_object(header: dict) -> str:
    """The actor a replay follows: the header's ``main_object``, else the task's."""
    return header.get("main_object") or main_object(header["task"])


def _main_poses(ep: dict, main: str):
    """The main object's recorded poses (t = 0 .. T): ``actor_poses[main]``, else ``cube_pose``."""
    poses = ep.get("actor_poses") or {}
    return poses[main] if main in poses else ep.get("cube_pose")


def _max_steps(task: str, longest: int) -> int:
    """The env's ``max_episode_steps`` for a replay: the task's, or the longest episode where that is longer (the
    motion-planning demos run past the registered limit, as ManiSkill's ``gym.make(..., max_episode_steps=N)``)."""
    from .registry import TASKS

    return max(int(TASKS[task].max_episode_steps), int(longest))


FIRST_ACTIONS = ("policy", "recorded")
"""How a closed-loop :func:`replay` (``policy=``) takes each episode's first action: the policy's answer to Newton's
observation of the initial state, or the recorded one."""


def replay(source, device="cpu", physics=None, asset_dir: str | None = None, env=None, verbose: bool = False,
           progress=None, policy=None, first_action: str = "policy") -> ReplayReport:  # fmt: skip
    """Replay every episode of ``source`` (a path or a loaded dict) open-loop on Newton, one env per episode.

    Each env is reset with its episode's ``seed`` (a list of seeds, one per env) before the recorded state is loaded,
    so a task whose scene comes from the seed is rebuilt as ManiSkill's was. Episodes of different lengths step
    together: an episode that has ended repeats its last action, and its results are read up to its own last step.

    ``env``: an env of :func:`wpctrl.tasks.make` to reuse (its task, control mode and number of envs must match; with
    ``auto_reset`` its ``max_episode_steps`` must cover the longest episode); otherwise one is built with
    ``auto_reset=False``, ``ignore_terminations=True`` (the recorded episodes keep stepping after success) and
    ``max_episode_steps`` at least the longest episode's length, ``verbose`` passed to ``make``. ``progress``: an
    object with ``update(n)`` (a tqdm bar, say), advanced by one after every step of the episodes.

    ``policy``: run it closed-loop from the recorded initial states instead of replaying the actions: a callable
    from ManiSkill's flattened state observation (a torch tensor on the env's device) to the action, e.g. an
    exported ``policy.ts`` (:func:`wpctrl.train.evaluate.load_policy`); each episode runs as many steps as recorded,
    and the report puts its success and main-object path next to the recorded run's (the same policy on ManiSkill,
    for recordings of a policy). ``first_action="recorded"`` takes each episode's first action from the recording:
    ManiSkill's observation right after a reset of its reused CPU env can hold contact flags of the previous
    episode's last step (PickCube's ``is_grasped``), which no state dict carries.
    """
    import torch

    from .factory import make

    if first_action not in FIRST_ACTIONS:
        raise ConfigError(f"replay: first_action expected one of {list(FIRST_ACTIONS)}, got {first_action!r}")
    if policy is not None and not callable(policy):
        raise ConfigError(f"replay: policy expected a callable (observations -> actions), got {type(policy).__name__}")
    data = load_episodes(source)
    header, episodes = data["header"], data["episodes"]
    n = len(episodes)
    main = _main_object(header)
    lengths = [len(ep["actions"]) for ep in episodes]
    steps = max(lengths)
    if env is None:
        env = make(header["task"], num_envs=n, device=device, control_mode=header["control_mode"],
                   auto_reset=False, ignore_terminations=True, physics=physics, asset_dir=asset_dir,
                   verbose=verbose, max_episode_steps=_max_steps(header["task"], steps))  # fmt: skip
    elif (env.task_spec.env_id, env.control_mode, env.num_envs) != (header["task"], header["control_mode"], n):
        raise ConfigError(f"replay: env is {env.task_spec.env_id} / {env.control_mode} / {env.num_envs} envs, the file "
                          f"{header['task']} / {header['control_mode']} / {n} episodes")  # fmt: skip
    elif env.auto_reset and env.max_episode_steps < steps:
        raise ConfigError(f"replay: env resets its episodes after {env.max_episode_steps} steps, the longest episode "
                          f"has {steps} actions (make it with max_episode_steps={steps} or "
                          f"auto_reset=False)")  # fmt: skip
    state = {}
    for group in ("actors", "articulations"):
        names = episodes[0]["init_state_dict"][group].keys()
        state[group] = {k: torch.tensor([ep["init_state_dict"][group][k] for ep in episodes]) for k in names}
    seeds = [int(ep.get("seed", i)) for i, ep in enumerate(episodes)]
    env.reset(seed=seeds, options={"reconfigure": True})  # a scene drawn from the seed is drawn from the episode's
    env.set_state_dict(state)
    # (n, T, A): an episode shorter than the longest repeats its last action (read only up to its own end)
    actions = np.asarray([ep["actions"] + ep["actions"][-1:] * (steps - len(ep["actions"])) for ep in episodes],
                         np.float32)  # fmt: skip
    recorded = [np.asarray(_main_poses(ep, main), np.float64)[:, :3] for ep in episodes]  # (T_i + 1, 3) each
    success = np.zeros((n, steps), bool)
    grasped = np.zeros((n, steps), bool)
    position = np.zeros((n, steps, 3))
    obs = env.get_obs() if policy is not None else None
    for t in range(steps):
        if policy is None or (t == 0 and first_action == "recorded"):
            action = torch.from_numpy(actions[:, t])
        else:
            with torch.inference_mode():
                action = policy(obs.to(torch.float32))
        obs, _, _, _, info = env.step(action)
        success[:, t] = info["success"].cpu().numpy()
        if "is_grasped" in info:
            grasped[:, t] = info["is_grasped"].cpu().numpy()
        position[:, t] = env.get_state_dict()["actors"][main][:, :3].cpu().numpy()
        if progress is not None:
            progress.update(1)
    report = ReplayReport(task=header["task"], control_mode=header["control_mode"], main_object=main)
    for i, ep in enumerate(episodes):
        k = lengths[i]
        rec = [bool(s) for s in ep["info"]["success"][1:]]
        error = np.linalg.norm(position[i, :k] - recorded[i][1:], axis=1)
        report.episodes.append(
            EpisodeResult(
                seed=seeds[i],
                success_recorded=rec,
                success=success[i, :k].tolist(),
                cube_error=error.tolist(),
                success_at_end_recorded=bool(ep.get("success_at_end", rec[-1])),
                success_at_end=bool(success[i, k - 1]),
                is_grasped_recorded=[bool(g) for g in ep["info"]["is_grasped"][1:]]
                if "is_grasped" in ep["info"]
                else None,
                is_grasped=grasped[i, :k].tolist() if "is_grasped" in ep["info"] else None,
            )
        )
    return report


def _parser() -> argparse.ArgumentParser:
    from ..console import add_output_options

    p = argparse.ArgumentParser(
        prog="wpctrl replay",
        description="Replay ManiSkill's recorded episodes (its recordings, trajectory files and motion-planning demos "
        f"of {' / '.join(TASK_IDS)}) open-loop on Newton and compare success and the main object's trajectory with "
        "ManiSkill's.",
    )
    p.add_argument("episodes", nargs="+", help="episode files (ManiSkill's recording format: JSON, or .json.gz; or "
                   "ManiSkill's trajectory files: X.h5 with its X.json; or policy episodes: "
                   "<Task>__<control_mode>__policy.npz)")  # fmt: skip
    p.add_argument("--device", default="cpu", help="Warp device (default: cpu)")
    p.add_argument("--out", default=None, help="write the full report (every step of every episode) as JSON here")
    p.add_argument("--asset-dir", default=None, help="a copy of mani_skill/assets (default: the installed package)")
    add_output_options(p, progress=True)
    return p


def _refuse(message: str) -> int:
    print(f"wpctrl replay: error: {message.removeprefix('replay: ')}", file=sys.stderr)
    return 2


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    from ..console import cli_output, compile_notice, device_refusal, progress

    if why := device_refusal(args.device, "--device"):  # no Warp needed to know
        return _refuse(why)
    try:  # every file read and checked before anything heavy is imported
        recordings = []
        for path in args.episodes:  # a file's episodes of different lengths step together, each read to its end
            data, where = _load(path)
            recordings.append((path, _checked(data, where)))
    except (ConfigError, FileNotFoundError) as e:
        return _refuse(str(e))
    cli_output(args.verbose)
    from ..devices import check_device

    try:
        check_device(args.device, "--device")
    except ConfigError as e:
        return _refuse(str(e))
    reports = []
    for path, data in recordings:
        header, n = data["header"], len(data["episodes"])
        steps = max(len(ep["actions"]) for ep in data["episodes"])
        with compile_notice(f"Warp kernels for {header['task']} on {args.device}"):
            from .factory import make

            env = make(header["task"], num_envs=n, device=args.device, control_mode=header["control_mode"],
                       auto_reset=False, ignore_terminations=True, asset_dir=args.asset_dir,
                       verbose=args.verbose, max_episode_steps=_max_steps(header["task"], steps))  # fmt: skip
        bar = progress(steps, f"{Path(path).name} ({n} episodes)", "step", args.progress)
        try:
            report = replay(data, env=env, progress=bar)
        except ConfigError as e:
            return _refuse(str(e))
        finally:
            bar.close()
            env.close()
        print(report.format(), flush=True)
        reports.append(report)
    if args.out:
        Path(args.out).write_text(json.dumps([r.to_json() for r in reports], indent=1))
        print(f"wrote {args.out}")
    return 0
