"""``python -m wpctrl demo --task PushCube-v1 | PickCube-v1``: ManiSkill's task on Newton, solved by the scripted
policy of :mod:`wpctrl.tasks.scripted` in ManiSkill's ``pd_ee_delta_pos`` mode, every env an episode of its own.

Reports the success rate (at the end of the 50 steps and at any step), env-steps/s, and writes ``summary.json`` and
``task.png`` (the cube's height and the TCP-cube distance over the episode, the median env and the spread of all) into
``--out``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from ..console import add_output_options
from ..tasks.names import SCRIPTED_TASKS


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="wpctrl demo --task",
        description="ManiSkill's PushCube-v1 / PickCube-v1 on Newton through wpctrl, solved by a scripted policy in "
        "pd_ee_delta_pos (needs ManiSkill's Panda asset: the [maniskill] extra, or WPCTRL_MANISKILL_ASSETS).",
    )
    p.add_argument("--task", required=True, choices=SCRIPTED_TASKS)
    p.add_argument("--envs", type=int, default=16, help="parallel envs, one episode each (default 16)")
    p.add_argument("--device", default="cpu", help="cpu | cuda | cuda:N (default cpu)")
    p.add_argument("--seed", type=int, default=0, help="episode seed (default 0)")
    p.add_argument("--substeps", type=int, default=None, help="MuJoCo steps per 10 ms physics step (default 16)")
    p.add_argument("--out", default="wpctrl-demo", help="folder for summary.json and task.png (default wpctrl-demo)")
    add_output_options(p)
    return p


def run(args) -> dict:
    import numpy as np
    import torch

    import wpctrl.tasks as T
    from wpctrl.tasks.scripted import policy_for

    device = "cuda:0" if args.device == "cuda" else args.device
    physics = T.task_physics(args.task, args.substeps)
    from ..console import compile_notice

    t0 = time.perf_counter()
    with compile_notice(f"Warp kernels for {args.task} on {device}", say=lambda msg: print(msg, flush=True)):
        env = T.make(args.task, num_envs=args.envs, device=device, control_mode="pd_ee_delta_pos", auto_reset=False,
                     ignore_terminations=True, physics=physics, seed=args.seed, verbose=args.verbose)  # fmt: skip
    build_s = time.perf_counter() - t0
    policy = policy_for(args.task)
    obs, info = env.reset(seed=args.seed)
    s = env.task_spec.obs_slices()["extra"]
    height, dist, success = [], [], []
    t1 = time.perf_counter()
    for _ in range(env.max_episode_steps):
        obs, _, _, _, info = env.step(policy(obs))
        cube = obs[:, s["obj_pose"]][:, :3]
        tcp = obs[:, s["tcp_pose"]][:, :3]
        height.append(cube[:, 2].cpu().numpy())
        dist.append((cube - tcp).norm(dim=1).cpu().numpy())
        success.append(info["success"].cpu().numpy())
    if env.device.type == "cuda":
        torch.cuda.synchronize()
    run_s = time.perf_counter() - t1
    success = np.array(success)
    return {
        "task": args.task,
        "envs": args.envs,
        "device": device,
        "substeps": physics.substeps,
        "success_at_end": float(success[-1].mean()),
        "success_once": float(success.any(axis=0).mean()),
        "env_steps_per_s": args.envs * env.max_episode_steps / run_s,
        "build_s": build_s,
        "run_s": run_s,
        "cube_height": np.array(height).tolist(),
        "tcp_cube_distance": np.array(dist).tolist(),
        "success": success.tolist(),
    }


def plot(path: Path, summary: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    t = np.arange(1, len(summary["cube_height"]) + 1) / 20.0
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, key, label in ((axes[0], "cube_height", "cube height [m]"), (axes[1], "tcp_cube_distance",
                                                                           "TCP-cube distance [m]")):  # fmt: skip
        v = np.array(summary[key])
        ax.fill_between(t, v.min(axis=1), v.max(axis=1), alpha=0.25, label="all envs (min-max)")
        ax.plot(t, np.median(v, axis=1), label="median env")
        ax.set_xlabel("time [s]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    first = np.array(summary["success"]).argmax(axis=0)
    for f, ok in zip(first, np.array(summary["success"]).any(axis=0)):
        if ok:
            axes[0].axvline((f + 1) / 20.0, color="g", alpha=0.15)
    axes[0].legend(loc="upper left")
    rate = 100 * summary["success_at_end"]
    fig.suptitle(f"{summary['task']} on Newton (wpctrl, pd_ee_delta_pos, scripted): success at the end {rate:.0f} % "
                 f"of {summary['envs']} envs (green: first success)")  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv) -> int:
    args = parser().parse_args(argv)
    if args.envs < 1:
        print("wpctrl demo: error: --envs must be at least 1", file=sys.stderr)
        return 2
    from ..console import cli_output, device_refusal

    if why := device_refusal(args.device, "--device"):  # known without Warp
        print(f"wpctrl demo: error: {why}", file=sys.stderr)
        return 2
    print(f"wpctrl demo: {args.task}, {args.envs} envs on {args.device} (scripted pd_ee_delta_pos solve)", flush=True)
    cli_output(args.verbose)
    from ..config import ConfigError
    from ..devices import check_device

    try:
        check_device("cuda:0" if args.device == "cuda" else args.device, "--device")
    except ConfigError as e:
        print(f"wpctrl demo: error: {e}", file=sys.stderr)
        return 2
    summary = run(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary))
    plot(out / "task.png", summary)
    print(
        f"  success at the end of the episode: {100 * summary['success_at_end']:.1f} % of {summary['envs']} envs "
        f"(at some step: {100 * summary['success_once']:.1f} %); {summary['env_steps_per_s']:,.0f} env-steps/s "
        f"({summary['substeps']} MuJoCo steps per physics step); built in {summary['build_s']:.1f} s"
    )
    print(f"  wrote {out / 'summary.json'} and {out / 'task.png'}")
    return 0
