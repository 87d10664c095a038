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
(:func:`wpctrl.tasks.recording.load_episodes`) before any env is built or any state written, so a wrong file is
refused at once, with a :class:`~wpctrl.ConfigError` naming the file, the field, what was expected and what came;
only the last check, the action width against the control mode's controller configs, loads the robot's description
(Newton), every other refusal comes before Warp, Newton or torch is imported.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..config import ConfigError
from .names import TASK_IDS
from .recording import load_episodes, main_poses, recorded_robot, replayed_object

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
    flags_recorded: dict[str, list[bool]] = field(default_factory=dict)
    """ManiSkill's other ``evaluate()`` flags after each step (t = 1 .. T): those of the task's ``info_keys`` the
    recording holds (PickCube's ``is_grasped``, PlaceSphere's ``is_obj_grasped``, ``is_obj_on_bin``, ...)."""
    flags: dict[str, list[bool]] = field(default_factory=dict)
    """Newton's, the same flags after each step."""

    @property
    def agrees(self) -> bool:
        return self.success_at_end == self.success_at_end_recorded

    def flag_matches(self, name: str) -> np.ndarray:
        """(T,) whether Newton's flag ``name`` is ManiSkill's after each step."""
        return np.asarray(self.flags[name]) == np.asarray(self.flags_recorded[name])

    def flag_agreement(self, name: str) -> float:
        """Fraction of the steps at which Newton's flag ``name`` is ManiSkill's."""
        return float(self.flag_matches(name).mean())

    @property
    def first_parting(self) -> dict[str, int]:
        """Per flag that ever differs, the first step (1 .. T) at which Newton's is not ManiSkill's: where to look
        when the outcomes differ."""
        parted = {name: np.flatnonzero(~self.flag_matches(name)) for name in self.flags_recorded}
        return {name: int(steps[0]) + 1 for name, steps in parted.items() if steps.size}

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
    def flag_agreement(self) -> dict[str, float]:
        """Per recorded flag (:attr:`EpisodeResult.flags`), the fraction of all episodes' steps at which Newton's
        agrees with ManiSkill's."""
        names = self.episodes[0].flags if self.episodes else {}
        return {k: float(np.concatenate([e.flag_matches(k) for e in self.episodes]).mean()) for k in names}

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
            "flag_agreement": self.flag_agreement,
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
                + "".join(f", {k} parts at step {t}" for k, t in e.first_parting.items())
            )
        s = self.summary()
        lines.append(
            f"  successful ManiSkill episodes that succeed on Newton: {100 * s['success_agreement']:.0f} %; "
            f"same outcome: {100 * s['outcome_agreement']:.0f} % (success once: {100 * s['once_agreement']:.0f} %); "
            f"median final {self.main_object} error "
            f"{100 * s['median_final_cube_error_m']:.2f} cm"
            + "".join(f"; {k} agrees at {100 * v:.0f} % of steps" for k, v in s["flag_agreement"].items())
        )
        return "\n".join(lines)


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

    ``env``: an env of :func:`wpctrl.tasks.make` to reuse (its task, robot, control mode and number of envs must
    match; with ``auto_reset`` its ``max_episode_steps`` must cover the longest episode); otherwise one is built with
    ``auto_reset=False``, ``ignore_terminations=True`` (the recorded episodes keep stepping after success),
    ``max_episode_steps`` at least the longest episode's length and the recording's robot (its state dicts'
    articulation), ``verbose`` passed to ``make``. ``progress``: an
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
    main = replayed_object(header)
    lengths = [len(ep["actions"]) for ep in episodes]
    steps = max(lengths)
    robot = recorded_robot(data)
    if env is None:
        env = make(header["task"], num_envs=n, device=device, control_mode=header["control_mode"],
                   auto_reset=False, ignore_terminations=True, physics=physics, asset_dir=asset_dir,
                   verbose=verbose, max_episode_steps=_max_steps(header["task"], steps), robot_uids=robot)  # fmt: skip
    elif (env.task_spec.env_id, env.robot_uids, env.control_mode, env.num_envs) != (header["task"], robot,
                                                                                    header["control_mode"], n):
        raise ConfigError(f"replay: env is {env.task_spec.env_id} / {env.robot_uids} / {env.control_mode} / "
                          f"{env.num_envs} envs, the file {header['task']} / {robot} / {header['control_mode']} / "
                          f"{n} episodes")  # fmt: skip
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
    recorded = [np.asarray(main_poses(ep, main), np.float64)[:, :3] for ep in episodes]  # (T_i + 1, 3) each
    success = np.zeros((n, steps), bool)
    # the task's other flags that every episode recorded, read from Newton at every step as well
    names = [k for k in env.info_keys if k != "success" and all(k in ep["info"] for ep in episodes)]
    flags = {k: np.zeros((n, steps), bool) for k in names}
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
        for k in names:
            flags[k][:, t] = info[k].cpu().numpy()
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
                flags_recorded={f: [bool(g) for g in ep["info"][f][1:]] for f in names},
                flags={f: flags[f][i, :k].tolist() for f in names},
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
            recordings.append((path, load_episodes(path)))
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
                       auto_reset=False, ignore_terminations=True, asset_dir=args.asset_dir, verbose=args.verbose,
                       max_episode_steps=_max_steps(header["task"], steps),
                       robot_uids=recorded_robot(data))  # fmt: skip
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
