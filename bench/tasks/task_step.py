"""ManiSkill's tasks on Newton: env-steps/s of a whole ``TaskEnv.step`` (graph replay, no policy: a fixed action
tensor), next to the bare MuJoCo-Warp step of the same scene, and the controller's and the task kernels' shares.

For every (task, N, substeps):

- ``env step``: ``env.step(action)`` as a user calls it (the action copy, the captured graph, the output clones);
- ``physics``: a captured graph of the K x substeps ``solver.step`` calls alone on the same model and state (the
  contacts and Newton's contact sensor of the last solver step included, as in the env);
- ``controller``: a captured graph of ``set_action`` + K ``before_simulation_step`` (implicit actuation: only
  ``set_action`` launches);
- ``task kernels``: a captured graph of the observation / evaluation / reward / episode / reset launches.

``env-steps/s`` = N / seconds per control step (a control step = 5 physics steps of ManiSkill's 10 ms).
Run ``python bench/tasks/task_step.py --help``; results go to ``<out>/task_step_<device>.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torch  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    DEFAULT_OUT,
    Sync,
    capture_graph,
    fmt_envs,
    fmt_us,
    machine_info,
    md_table,
    measure,
    measure_interleaved,
    meta_markdown,
    parse_envs,
    solver_load,
    task_step_parts,
    write_results,
)


def bench_one(task: str, n: int, device, substeps: int, control_mode: str, arm_drive: str | None = None) -> dict:
    import wpctrl.tasks as T

    changes = {"substeps": substeps} if arm_drive is None else {"substeps": substeps, "arm_drive": arm_drive}
    env = T.make(task, num_envs=n, device=device, control_mode=control_mode, physics=T.task_physics(task, **changes))
    env.reset(seed=0)
    sync = Sync(device)
    dev = wp.get_device(device)
    action = torch.zeros((n, env.ctrl.action_dim), device=env.device)
    action[:, -1] = 1.0  # gripper open: the arm holds its pose, the cube rests on the table
    physics, controller = task_step_parts(env)

    def task_kernels():
        env._bookkeep()

    graphs = {name: capture_graph(fn, dev) for name, fn in (("physics", physics), ("controller", controller),
                                                         ("task kernels", task_kernels))}  # fmt: skip
    env.reset(seed=0)
    row = {"task": task, "envs": n, "substeps": substeps, "control_mode": control_mode,
           "arm_drive": env.physics.arm_drive}
    # the env step and its bare physics take their samples in turns: both advance the same state, so the solver's
    # load (contacts, constraint rows, iterations), which changes as a freshly reset scene settles, is the same for both
    timed = measure_interleaved({"env step": lambda: env.step(action),
                                 "physics": lambda: wp.capture_launch(graphs["physics"])}, sync)  # fmt: skip
    row["env step"], row["physics"] = timed["env step"]["median_s"], timed["physics"]["median_s"]
    row["contacts"] = solver_load(env)
    for name in ("controller", "task kernels"):
        row[name] = measure(lambda g=graphs[name]: wp.capture_launch(g), sync)["median_s"]
    row["env_steps_per_s"] = n / row["env step"]
    row["physics_steps_per_s"] = n / row["physics"]
    row["controller_share"] = row["controller"] / row["env step"]
    row["task_share"] = row["task kernels"] / row["env step"]
    row["vs_physics"] = row["physics"] / row["env step"]
    return row


def _load(row: dict) -> str:
    c = row.get("contacts")
    return f"{c['contacts']:,} / {c['constraint_rows']:,}" if c else ""


def render(meta: dict, rows: list[dict]) -> str:
    header = ["task", "envs", "substeps", "arm drive", "env step [µs]", "env-steps/s", "physics [µs]", "env / physics",
              "controller [µs] (share)", "task kernels [µs] (share)",
              "contacts / rows"]  # fmt: skip
    body = [[r["task"], fmt_envs(r["envs"]), r["substeps"], r.get("arm_drive", ""), fmt_us(r["env step"]),
             f"{r['env_steps_per_s']:,.0f}",
             fmt_us(r["physics"]), f"{r['vs_physics'] * 100:.1f} %",
             f"{fmt_us(r['controller'])} ({100 * r['controller_share']:.2f} %)",
             f"{fmt_us(r['task kernels'])} ({100 * r['task_share']:.2f} %)", _load(r)] for r in rows]  # fmt: skip
    return (
        "# Task env step vs the bare MuJoCo-Warp step\n\n" + meta_markdown(meta) + "\n\n" + md_table(header, body)
        + "\n`env / physics`: the bare physics' share of the whole env step (the rest is the controller, the task "
        "kernels, the action copy and the output tensors), the two timed in turns from the same state. "
        "`contacts / rows`: MuJoCo-Warp's contacts and constraint rows over all worlds after the last timed step.\n"
    )  # fmt: skip


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cuda:0" if wp.get_cuda_device_count() else "cpu")
    p.add_argument("--envs", default=None, help="e.g. 1k,4k (default: 4k on CUDA, 16 on the CPU)")
    p.add_argument("--tasks", default="PushCube-v1,PickCube-v1")
    p.add_argument("--substeps", default="8", help="MuJoCo steps per physics step, e.g. 4,8")
    p.add_argument("--control-mode", default="pd_joint_delta_pos")
    p.add_argument("--arm-drive", default=None, help="TaskPhysics.arm_drive values to time in turn, e.g. "
                   "physx_tgs,mujoco (default: the task's own)")
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--tag", default=None)
    args = p.parse_args(argv)
    device = wp.get_device(args.device)
    envs = parse_envs(args.envs or ("4k" if device.is_cuda else "16"))
    t0 = time.perf_counter()
    meta = machine_info(device)
    rows = []
    for task in args.tasks.split(","):
        for sub in (int(s) for s in args.substeps.split(",")):
            for n, drive in ((n, d) for n in envs for d in (args.arm_drive.split(",") if args.arm_drive else [None])):
                row = bench_one(task, n, device, sub, args.control_mode, drive)
                rows.append(row)
                print(f"{task} {fmt_envs(n)} envs, {sub} substeps, {row['arm_drive']}: "
                      f"env step {fmt_us(row['env step'])} µs "
                      f"({row['env_steps_per_s']:,.0f} env-steps/s), physics {fmt_us(row['physics'])} µs, "
                      f"controller {100 * row['controller_share']:.2f} %, task kernels "
                      f"{100 * row['task_share']:.2f} %", flush=True)  # fmt: skip
    meta["wall_s"] = time.perf_counter() - t0
    tag = args.tag or ("cuda" if device.is_cuda else "cpu")
    j, m = write_results(args.out, f"task_step_{tag}", meta, rows, render(meta, rows))
    print(f"wrote {j} and {m}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
