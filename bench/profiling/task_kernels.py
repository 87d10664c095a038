"""Which kernels a task's env step spends its device time in, next to the bare MuJoCo-Warp step of the same scene.

``bench/tasks/task_step.py`` times the captured env step and the captured bare physics as wholes. Where the two part
(one task's env step takes far longer than its physics), this script says where: it runs both eagerly, from the
same state, under Warp's kernel timer (``wp.timing_begin(cuda_filter=wp.TIMING_KERNEL)``), sums the device time of
every kernel by name, and lists the kernels whose totals differ most, with MuJoCo-Warp's contact and constraint-row
counts after each. It also times the two captured graphs interleaved (:func:`bench.common.measure_interleaved`),
from the same state, so that a load that drifts over a run cannot make the gap.

Run ``python bench/profiling/task_kernels.py --tasks PegInsertionSide-v1,PushCube-v1``; results go to
``<out>/task_kernels_<device>.{json,md}``. The kernel timer records CUDA events: on the CPU only the graph timings
are filled in.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torch  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    DEFAULT_OUT,
    Sync,
    capture_graph,
    fmt_envs,
    machine_info,
    md_table,
    measure_interleaved,
    meta_markdown,
    parse_envs,
    solver_load,
    task_step_parts,
    write_results,
)


def _kernel_times(fn, calls: int, device) -> dict[str, float]:
    """Seconds of device time per call of ``fn``, summed by kernel name, over ``calls`` eager calls."""
    wp.synchronize_device(device)
    wp.timing_begin(cuda_filter=wp.TIMING_KERNEL)
    for _ in range(calls):
        fn()
    wp.synchronize_device(device)
    results = wp.timing_end()
    out: dict[str, float] = defaultdict(float)
    for r in results:
        out[r.name] += r.elapsed * 1e-3 / calls  # elapsed is in ms
    return dict(out)


def profile(task: str, n: int, device, substeps: int, control_mode: str, calls: int) -> dict:
    import wpctrl.tasks as T

    env = T.make(task, num_envs=n, device=device, control_mode=control_mode, graph=False,
                 physics=T.task_physics(task, substeps))  # fmt: skip
    env.reset(seed=0)
    action = torch.zeros((n, env.ctrl.action_dim), device=env.device)
    action[:, -1] = 1.0
    physics, _ = task_step_parts(env)
    for _ in range(3):
        env.step(action)
    step = {"kernels": _kernel_times(lambda: env.step(action), calls, device), "load": solver_load(env)}
    bare = {"kernels": _kernel_times(physics, calls, device), "load": solver_load(env)}
    # the two as captured graphs, interleaved from the same (drifting) state
    env_graph = capture_graph(env._step_impl, device)
    bare_graph = capture_graph(physics, device)
    sync = Sync(device)
    timed = measure_interleaved({"env step": lambda: wp.capture_launch(env_graph),
                                 "physics": lambda: wp.capture_launch(bare_graph)}, sync)  # fmt: skip
    names = set(step["kernels"]) | set(bare["kernels"])
    diff = sorted(((step["kernels"].get(k, 0.0) - bare["kernels"].get(k, 0.0), k) for k in names), reverse=True)
    top = sorted(((v, k) for k, v in step["kernels"].items()), reverse=True)
    return {
        "task": task, "envs": n, "substeps": substeps, "calls": calls,
        "eager_kernel_sum_s": {"env step": sum(step["kernels"].values()), "physics": sum(bare["kernels"].values())},
        "graph_s": {k: v["median_s"] for k, v in timed.items()},
        "load": {"env step": step["load"], "physics": bare["load"]},
        "largest_differences": [{"kernel": k, "env_step_s": step["kernels"].get(k, 0.0),
                                 "physics_s": bare["kernels"].get(k, 0.0), "difference_s": d} for d, k in diff[:15]],
        "env_step_top": [{"kernel": k, "s": v} for v, k in top[:15]],
    }  # fmt: skip


def render(meta: dict, rows: list[dict]) -> str:
    parts = ["# Where a task's env step spends its device time, next to its bare physics\n", meta_markdown(meta), ""]
    for r in rows:
        g, e, ld = r["graph_s"], r["eager_kernel_sum_s"], r["load"]
        parts.append(f"## {r['task']}, {fmt_envs(r['envs'])} envs, {r['substeps']} substeps\n")
        parts.append(f"Captured, interleaved: env step {g['env step'] * 1e3:.2f} ms, physics "
                     f"{g['physics'] * 1e3:.2f} ms ({g['physics'] / g['env step'] * 100:.1f} %). Eager kernel time per "
                     f"call: env step "
                     f"{e['env step'] * 1e3:.2f} ms, physics {e['physics'] * 1e3:.2f} ms. Contacts / constraint rows "
                     f"after each: {ld['env step']['contacts']:,} / {ld['env step']['constraint_rows']:,}; "
                     f"{ld['physics']['contacts']:,} / {ld['physics']['constraint_rows']:,}.\n")  # fmt: skip
        body = [[x["kernel"], f"{x['env_step_s'] * 1e6:,.0f}", f"{x['physics_s'] * 1e6:,.0f}",
                 f"{x['difference_s'] * 1e6:+,.0f}"] for x in r["largest_differences"]]  # fmt: skip
        parts.append(md_table(["kernel", "env step [µs]", "physics [µs]", "difference [µs]"], body))
    return "\n".join(parts)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--envs", default="4k")
    p.add_argument("--tasks", default="PegInsertionSide-v1,PushCube-v1")
    p.add_argument("--substeps", type=int, default=8)
    p.add_argument("--control-mode", default="pd_joint_delta_pos")
    p.add_argument("--calls", type=int, default=5)
    p.add_argument("--out", default=str(DEFAULT_OUT))
    args = p.parse_args(argv)
    device = wp.get_device(args.device)
    if not device.is_cuda:
        print("the kernel timer records CUDA events only: on the CPU the kernel tables stay empty", flush=True)
    t0 = time.perf_counter()
    meta = machine_info(device)
    rows = []
    for task in args.tasks.split(","):
        for n in parse_envs(args.envs):
            row = profile(task, n, device, args.substeps, args.control_mode, args.calls)
            rows.append(row)
            g = row["graph_s"]
            first = row["largest_differences"][:1]
            print(f"{task} {fmt_envs(n)}: env step {g['env step'] * 1e3:.2f} ms, physics {g['physics'] * 1e3:.2f} ms; "
                  f"largest difference {first}", flush=True)  # fmt: skip
    meta["wall_s"] = time.perf_counter() - t0
    j, m = write_results(args.out, f"task_kernels_{device.alias.replace(':', '')}", meta, rows, render(meta, rows))
    print(f"wrote {j} and {m}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
