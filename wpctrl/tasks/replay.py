"""Open-loop replay of ManiSkill's recorded episodes on Newton: every episode's initial state dict is loaded into
its own env, its actions are replayed step by step (all episodes of a file at once, one env each), and success and
the cube's position are compared with ManiSkill's at every step.

The episode format is ManiSkill's recording of the tasks (a JSON file, plain or gzip-compressed ``.json.gz``, with
``header`` (``task``, ``control_mode``) and ``episodes``: ``init_state_dict``, ``actions``, ``info["success"]`` and
``cube_pose`` per step, ...). ``python -m wpctrl replay FILE.json`` runs it from the command line: every file is
read and checked before Warp, Newton or torch is imported, so a wrong file is refused at once.
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..config import ConfigError
from . import maniskill_trajectory as trajectory
from .names import CONTROL_MODES, TASK_IDS

__all__ = ["EpisodeResult", "ReplayReport", "load_episodes", "main", "replay"]


@dataclass
class EpisodeResult:
    """One episode replayed: ManiSkill's outcome next to Newton's."""

    seed: int
    success_recorded: list[bool]
    """ManiSkill's ``info["success"]`` after each step (t = 1 .. T)."""
    success: list[bool]
    """Newton's, after each step."""
    cube_error: list[float]
    """||cube position on Newton - ManiSkill's|| after each step [m]."""
    success_at_end_recorded: bool
    success_at_end: bool
    is_grasped_recorded: list[bool] | None = None
    """PickCube: ManiSkill's ``info["is_grasped"]`` after each step."""
    is_grasped: list[bool] | None = None

    @property
    def agrees(self) -> bool:
        return self.success_at_end == self.success_at_end_recorded

    @property
    def final_cube_error(self) -> float:
        return self.cube_error[-1]


@dataclass
class ReplayReport:
    """All episodes of one file: per-episode results and the summary a user reads."""

    task: str
    control_mode: str
    episodes: list[EpisodeResult] = field(default_factory=list)

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
    def median_final_cube_error(self) -> float:
        return float(np.median([e.final_cube_error for e in self.episodes])) if self.episodes else float("nan")

    def summary(self) -> dict:
        return {
            "task": self.task,
            "control_mode": self.control_mode,
            "episodes": len(self.episodes),
            "success_agreement": self.success_agreement,
            "outcome_agreement": self.outcome_agreement,
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
                f"first success step {first} ({first_rec}), cube error final {100 * e.final_cube_error:.2f} cm, "
                f"max {100 * max(e.cube_error):.2f} cm"
            )
        s = self.summary()
        lines.append(
            f"  successful ManiSkill episodes that succeed on Newton: {100 * s['success_agreement']:.0f} %; "
            f"same outcome: {100 * s['outcome_agreement']:.0f} %; median final cube error "
            f"{100 * s['median_final_cube_error_m']:.2f} cm"
        )
        return "\n".join(lines)


EXPECTED = (
    "ManiSkill's episode JSON (an object with 'header' and 'episodes'), plain or gzip-compressed (.json.gz), "
    "or ManiSkill's trajectory file (X.h5 with its X.json)"
)
"""What a replay file must be, as the refusals say it."""


def _read(path: Path) -> dict:
    """A recording's JSON, from a plain or a gzip-compressed file (told by its first bytes), or ManiSkill's
    trajectory file (a ``.h5``, or the ``.json`` of one: it has ``env_info``) as the same episode structure."""
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
    ManiSkill's format, a task and control mode :func:`wpctrl.tasks.make` builds, equal episode lengths. Host only
    (no Warp, Newton or torch)."""
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
    """``data`` after the checks of :func:`load_episodes`; ``where`` prefixes the refusals."""
    if not isinstance(data, dict) or "header" not in data or "episodes" not in data:
        raise ConfigError(f"replay: {where}expected ManiSkill's episode format: a dict with 'header' and 'episodes' "
                          f"({EXPECTED})")  # fmt: skip
    for key in ("task", "control_mode"):
        if key not in data["header"]:
            raise ConfigError(f"replay: {where}the header has no {key!r}")
    if data["header"]["task"] not in TASK_IDS:
        raise ConfigError(f"replay: {where}task {data['header']['task']!r} is not one wpctrl builds; expected one of "
                          f"{list(TASK_IDS)}")  # fmt: skip
    if data["header"]["control_mode"] not in CONTROL_MODES:
        raise ConfigError(f"replay: {where}control mode {data['header']['control_mode']!r} is not one of the Panda's "
                          f"{list(CONTROL_MODES)}")  # fmt: skip
    if not data["episodes"]:
        raise ConfigError(f"replay: {where}the file holds no episodes")
    for i, ep in enumerate(data["episodes"]):
        for key in ("init_state_dict", "actions", "info", "cube_pose"):
            if key not in ep:
                raise ConfigError(f"replay: {where}episode {i} has no {key!r}")
    lengths = {len(ep["actions"]) for ep in data["episodes"]}
    if len(lengths) != 1:
        raise ConfigError(f"replay: {where}the episodes must have the same number of actions, got {sorted(lengths)} "
                          f"(maniskill_trajectory.by_length splits them; `wpctrl replay` does)")  # fmt: skip
    return data


def replay(source, device="cpu", physics=None, asset_dir: str | None = None, env=None, verbose: bool = False,
           progress=None) -> ReplayReport:  # fmt: skip
    """Replay every episode of ``source`` (a path or a loaded dict) open-loop on Newton, one env per episode.

    ``env``: an env of :func:`wpctrl.tasks.make` to reuse (its task, control mode and number of envs must match);
    otherwise one is built with ``auto_reset=False`` and ``ignore_terminations=True`` (the recorded episodes keep
    stepping after success), ``verbose`` passed to ``make``. ``progress``: an object with ``update(n)`` (a tqdm bar,
    say), advanced by one after every step of the episodes (they all step together).
    """
    import torch

    from .factory import make

    data = load_episodes(source)
    header, episodes = data["header"], data["episodes"]
    n = len(episodes)
    if env is None:
        env = make(header["task"], num_envs=n, device=device, control_mode=header["control_mode"],
                   auto_reset=False, ignore_terminations=True, physics=physics, asset_dir=asset_dir,
                   verbose=verbose)  # fmt: skip
    elif (env.task_spec.env_id, env.control_mode, env.num_envs) != (header["task"], header["control_mode"], n):
        raise ConfigError(f"replay: env is {env.task_spec.env_id} / {env.control_mode} / {env.num_envs} envs, the file "
                          f"{header['task']} / {header['control_mode']} / {n} episodes")  # fmt: skip
    state = {}
    for group in ("actors", "articulations"):
        names = episodes[0]["init_state_dict"][group].keys()
        state[group] = {k: torch.tensor([ep["init_state_dict"][group][k] for ep in episodes]) for k in names}
    env.reset()
    env.set_state_dict(state)
    actions = np.asarray([ep["actions"] for ep in episodes], np.float32)  # (n, T, A)
    recorded_cube = np.asarray([[p[:3] for p in ep["cube_pose"]] for ep in episodes])  # (n, T + 1, 3)
    success = np.zeros((n, actions.shape[1]), bool)
    grasped = np.zeros((n, actions.shape[1]), bool)
    error = np.zeros((n, actions.shape[1]))
    for t in range(actions.shape[1]):
        _, _, _, _, info = env.step(torch.from_numpy(actions[:, t]))
        success[:, t] = info["success"].cpu().numpy()
        if "is_grasped" in info:
            grasped[:, t] = info["is_grasped"].cpu().numpy()
        q = env.get_state_dict()["actors"]["cube"][:, :3].cpu().numpy()
        error[:, t] = np.linalg.norm(q - recorded_cube[:, t + 1], axis=1)
        if progress is not None:
            progress.update(1)
    report = ReplayReport(task=header["task"], control_mode=header["control_mode"])
    for i, ep in enumerate(episodes):
        rec = [bool(s) for s in ep["info"]["success"][1:]]
        report.episodes.append(
            EpisodeResult(
                seed=int(ep.get("seed", i)),
                success_recorded=rec,
                success=success[i].tolist(),
                cube_error=error[i].tolist(),
                success_at_end_recorded=bool(ep.get("success_at_end", rec[-1])),
                success_at_end=bool(success[i, -1]),
                is_grasped_recorded=[bool(g) for g in ep["info"]["is_grasped"][1:]]
                if "is_grasped" in ep["info"]
                else None,
                is_grasped=grasped[i].tolist() if "is_grasped" in ep["info"] else None,
            )
        )
    return report


def _parser() -> argparse.ArgumentParser:
    from ..console import add_output_options

    p = argparse.ArgumentParser(
        prog="wpctrl replay",
        description="Replay ManiSkill's recorded PushCube-v1 / PickCube-v1 episodes open-loop on Newton and compare "
        "success and the cube's trajectory with ManiSkill's.",
    )
    p.add_argument("episodes", nargs="+", help="episode files (ManiSkill's recording format: JSON, or .json.gz; or "
                   "ManiSkill's trajectory files: X.h5 with its X.json)")  # fmt: skip
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
        for path in args.episodes:  # a file's episodes of different lengths: one recording per length
            data, where = _load(path)
            recordings += [(path, _checked(part, where)) for part in trajectory.by_length(data)]
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
        with compile_notice(f"Warp kernels for {header['task']} on {args.device}"):
            from .factory import make

            env = make(header["task"], num_envs=n, device=args.device, control_mode=header["control_mode"],
                       auto_reset=False, ignore_terminations=True, asset_dir=args.asset_dir,
                       verbose=args.verbose)  # fmt: skip
        bar = progress(len(data["episodes"][0]["actions"]), f"{Path(path).name} ({n} episodes)", "step",
                       args.progress)  # fmt: skip
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
