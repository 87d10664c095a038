"""``python -m wpctrl evaluate --policy policy.ts --task PickCube-v1 --sim maniskill|newton --episodes N``: an exported
policy (``wpctrl export``) of any task of :mod:`wpctrl.tasks`' registry on fresh episodes of either simulator, with
the same metrics.

- ``--sim newton``: :func:`wpctrl.tasks.make`'s env (MuJoCo-Warp, any device), ``--envs`` episodes at a time.
- ``--sim maniskill``: the real ManiSkill env on its CPU PhysX (one env, its rendering stubbed out:
  :mod:`wpctrl.tasks.maniskill_side`), one episode after another, ``env.reset(seed=seed + i)`` for episode i.

Every episode runs the task's ``max_episode_steps`` control steps (the registry's: 50, PegInsertionSide-v1 100;
success does not end it, as ManiSkill's PPO evaluates); reported: the
success rate (success at any step, ManiSkill's ``success_once``), the success rate at the last step
(``success_at_end``), the mean return of the normalized dense reward and the mean first success step.

``--record FILE`` (``--sim maniskill``) also saves the episodes in the format ``wpctrl replay`` reads
(:mod:`.record`), so that they replay open-loop on Newton.
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

import torch

from .command_args import check_evaluate_args, evaluate_parser, record_refusal

__all__ = ["PolicyError", "evaluate", "evaluate_maniskill", "load_policy", "main"]

SAPIEN_VULKAN_NOTE = "Failed to find system libvulkan"
"""SAPIEN's warning, on import, that it falls back to its own Vulkan library: not shown (unless ``--verbose``), as the
evaluation's ManiSkill env renders nothing."""


class PolicyError(ValueError):
    """A policy file that cannot drive the requested task (the message says what differs)."""


def load_policy(path, task: str | None = None, device="cpu"):
    """An exported policy (``policy.ts``) and its metadata; checks it against ``task`` (None: the policy's own)."""
    from wpctrl.tasks import TASKS

    from .export import EXTRA_FILE

    p = Path(path)
    if not p.is_file():
        raise PolicyError(f"--policy: no file {str(p)!r} (export a run with `python -m wpctrl export RUN_DIR`)")
    extra = {EXTRA_FILE: ""}
    try:
        module = torch.jit.load(str(p), map_location=device, _extra_files=extra)
    except Exception as e:  # noqa: BLE001  (torch raises several kinds for a file that is not TorchScript)
        raise PolicyError(f"--policy: {str(p)!r} is not a TorchScript module ({type(e).__name__})") from e
    meta = json.loads(extra[EXTRA_FILE]) if extra[EXTRA_FILE] else {}
    if task is None:
        task = meta.get("task")
        if task is None:
            raise PolicyError(f"--task: {str(p)!r} does not name its task; pass --task")
    if task not in TASKS:
        raise PolicyError(f"--task: expected one of {sorted(TASKS)}, got {task!r}")
    obs_dim = TASKS[task].obs_dim
    if meta.get("task", task) != task:
        raise PolicyError(f"--policy: {str(p)!r} was trained on {meta['task']} (observations of {meta['obs_dim']}); "
                          f"--task is {task} (observations of {obs_dim})")  # fmt: skip
    if "obs_dim" in meta and int(meta["obs_dim"]) != obs_dim:
        raise PolicyError(f"--policy: {str(p)!r} takes observations of {meta['obs_dim']}, {task}'s are {obs_dim}")
    if not meta:  # a foreign module: probe its widths
        try:
            with torch.inference_mode():
                out = module(torch.zeros(1, obs_dim, device=device))
        except Exception as e:  # noqa: BLE001
            raise PolicyError(f"--policy: {str(p)!r} does not take {task}'s observations of {obs_dim}: {e}") from e
        meta = {"task": task, "obs_dim": obs_dim, "num_actions": int(out.shape[-1])}
    return module, dict(meta, task=task)


def policy_robot(meta: dict) -> str:
    """The robot a policy learned on: its ``policy.json``'s ``robot_uids``; ``panda`` for a policy exported before
    the robot was recorded (every such policy learned on ``panda``) or a foreign module."""
    return meta.get("robot_uids", "panda")


def evaluate_maniskill(policy, task: str, control_mode: str, episodes: int, seed: int = 0, progress=None,
                       recorder=None, robot_uids: str = "panda") -> dict:  # fmt: skip
    """``policy`` on ``episodes`` episodes of the real ManiSkill (PhysX CPU, one env, the robot ``robot_uids``: the
    one the policy learned on, :func:`policy_robot`); metrics as
    :func:`wpctrl.train.policy_eval.evaluate_policy`, plus per-episode records. ``recorder``: a
    :class:`.record.EpisodeRecorder` that is shown every episode and writes its file once all have run."""
    from wpctrl import console
    from wpctrl.tasks import TASKS
    from wpctrl.tasks.maniskill_side import make_maniskill, no_visuals

    with warnings.catch_warnings():
        if not console.VERBOSE:  # SAPIEN's note on import; the env renders nothing (render_backend="none")
            warnings.filterwarnings("ignore", message=SAPIEN_VULKAN_NOTE, category=UserWarning)
        env = make_maniskill(task, control_mode, reward_mode="normalized_dense", robot_uids=robot_uids)
    # the registry's episode length (ManiSkill's @register_env value: the tasks' tests keep them equal); gym.make's
    # spec carries none for ManiSkill's envs, whose own TimeLimitWrapper holds it
    steps = TASKS[task].max_episode_steps
    t = time.perf_counter()
    records = []
    if recorder is not None:
        recorder.start(env, task, control_mode, steps)
    with torch.inference_mode():
        for i in range(episodes):
            # inside the stub, as the env was built: a task that rebuilds its scene at every reset (ManiSkill's
            # PegInsertionSide-v1 with one env) builds it again
            with warnings.catch_warnings(), no_visuals():
                warnings.simplefilter("ignore")
                obs, info = env.reset(seed=seed + i)
            if recorder is not None:
                recorder.reset(seed + i, obs, info)
            ret, first, success = 0.0, None, False
            for k in range(steps):
                action = policy(obs.to(torch.float32)).to("cpu")
                obs, reward, terminated, truncated, info = env.step(action)
                if recorder is not None:
                    recorder.step(action, obs, reward, terminated, truncated, info)
                ret += float(reward[0])
                success = bool(info["success"][0])
                if success and first is None:
                    first = k + 1
            records.append({"seed": seed + i, "success_once": first is not None, "success_at_end": success,
                            "return": ret, "first_success_step": first})  # fmt: skip
            if recorder is not None:
                recorder.finish_episode()
            if progress:
                progress(i + 1, records)
    env.close()
    result = _summary(records, time.perf_counter() - t)
    if recorder is not None:
        result["record"] = str(recorder.write())
    return result


def _summary(records: list, seconds: float) -> dict:
    n = len(records)
    firsts = [r["first_success_step"] for r in records if r["first_success_step"] is not None]
    return {
        "episodes": n,
        "success_rate": sum(r["success_once"] for r in records) / n,
        "success_at_end_rate": sum(r["success_at_end"] for r in records) / n,
        "mean_episode_reward": sum(r["return"] for r in records) / n,
        "mean_first_success_step": sum(firsts) / len(firsts) if firsts else None,
        "eval_s": seconds,
        "records": records,
    }


class _CountEpisodes:
    """``env`` as :func:`~wpctrl.train.policy_eval.evaluate_policy` uses it, advancing ``bar`` by the episodes that end
    with each round of ``max_episode_steps`` steps (``env.num_envs`` at a time, the last round's share only)."""

    def __init__(self, env, bar, episodes: int):
        self._env, self._bar, self._left, self._k = env, bar, episodes, 0

    def __getattr__(self, name):
        return getattr(self._env, name)

    def step(self, action):
        out = self._env.step(action)
        self._k += 1
        if self._k == self._env.max_episode_steps:
            self._k = 0
            n = min(self._env.num_envs, self._left)
            self._left -= n
            self._bar.update(n)
        return out


def evaluate(policy, sim: str = "newton", episodes: int = 100, seed: int = 0, task: str | None = None,
             device="cpu", envs: int | None = None, substeps: int | None = None, video=None,
             progress: bool = True, verbose: bool = False, record=None) -> dict:  # fmt: skip
    """The exported policy in file ``policy`` on ``episodes`` fresh episodes of ``sim`` (``"newton"``: wpctrl's
    task env on ``device``, ``envs`` at a time (default: min(episodes, 256)), ``substeps`` defaulting to the
    policy's training value; ``"maniskill"``: the real ManiSkill, one env on its CPU PhysX); what ``wpctrl
    evaluate`` reports. ``video``: also film env 0's first episodes into this file (Newton only: a ValueError with
    ``sim="maniskill"``). ``record``: also save the ManiSkill episodes in ``wpctrl replay``'s format into this file
    (``.json`` or ``.json.gz``; ManiSkill only: a ValueError with ``sim="newton"``). Raises :class:`PolicyError` for a
    policy that cannot drive ``task``."""
    from .. import console

    if video and sim != "newton":
        raise ValueError(f"video: only sim='newton' is recorded, got sim={sim!r}")
    if record and sim != "maniskill":
        raise ValueError(f"record: only sim='maniskill' is saved for replay, got sim={sim!r}")
    if record and (why := record_refusal(record)):
        raise ValueError(f"record: {why}")

    device = device if sim == "newton" else "cpu"
    model, meta = load_policy(policy, task, device)
    task, control_mode = meta["task"], meta.get("control_mode", "pd_joint_delta_pos")
    if not str(device).startswith("cuda"):
        torch.set_num_threads(1)  # a small network: see wpctrl.train.task_ppo
    if sim == "maniskill":
        bar = console.progress(episodes, f"{task} on ManiSkill", "episode", progress)

        def report(i, records):
            bar.update(1)
            if not progress and (i % 10 == 0 or i == episodes):
                ok = sum(r["success_once"] for r in records)
                print(f"  {i:4d} episodes: {ok} successful", flush=True)

        from .record import EpisodeRecorder

        recorder = EpisodeRecorder(record, policy, meta) if record else None
        result = evaluate_maniskill(model, task, control_mode, episodes, seed, report, recorder, policy_robot(meta))
    else:
        import wpctrl.tasks as T

        from .policy_eval import evaluate_policy
        from .video import open_recorder

        substeps = substeps or meta.get("substeps")
        physics = T.task_physics(task, substeps or None)
        with console.compile_notice(f"Warp kernels for {task} on {device}"):
            env = T.make(task, num_envs=envs or min(episodes, 256), device=device, control_mode=control_mode,
                         seed=seed, auto_reset=False, ignore_terminations=True, physics=physics,
                         verbose=verbose, robot_uids=policy_robot(meta))  # fmt: skip
        bar = console.progress(episodes, f"{task} on Newton", "episode", progress)
        rec = open_recorder(env, video) if video else None  # None, saying why, where no renderer works
        result = evaluate_policy(model, _CountEpisodes(rec or env, bar, episodes), episodes, seed=seed)
        if rec is not None:
            rec.close()
        result["substeps"] = physics.substeps
        env.close()
    bar.close()
    return {"task": task, "sim": sim, "control_mode": control_mode, "robot_uids": policy_robot(meta),
            "policy": str(policy), "seed": seed, **result}


def main(argv=None) -> int:
    p = evaluate_parser()
    args = p.parse_args(argv)
    check_evaluate_args(p, args, argv)  # no torch, Warp or ManiSkill needed (wpctrl evaluate ran them already)
    from .. import console
    from ..config import ConfigError
    from ..devices import check_device

    console.VERBOSE = args.verbose
    if args.sim == "newton":
        console.cli_output(args.verbose)  # Warp quiet unless --verbose (ManiSkill's PhysX needs no Warp)
        try:
            check_device(args.device, "--device")
        except ConfigError as e:
            print(f"wpctrl evaluate: error: {e}", file=sys.stderr)
            return 2
    try:
        result = evaluate(args.policy, args.sim, args.episodes, args.seed, args.task, args.device, args.envs,
                          args.substeps, args.video, args.progress, args.verbose, args.record)  # fmt: skip
    except PolicyError as e:
        print(f"wpctrl evaluate: error: {e}", file=sys.stderr)
        return 2
    print(f"{result['task']} on {args.sim}: success {100 * result['success_rate']:.1f} % (at the end "
          f"{100 * result['success_at_end_rate']:.1f} %) over {result['episodes']} episodes, mean return "
          f"{result['mean_episode_reward']:.2f}")  # fmt: skip
    if args.record:
        print(f"wrote {args.record} ({result['episodes']} episodes; `python -m wpctrl replay {args.record}` replays "
              "them on Newton)")  # fmt: skip
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1))
        print(f"wrote {args.out}")
    return 0
