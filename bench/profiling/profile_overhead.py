"""Where the host time of an eager wpctrl control step goes (per-call Python overhead), on any device.

At small N a control step is launch-bound: this script times each public call and the pieces inside it (the action
conversion, the State/Control checks, the recorded kernel launches) with the same loop as the benchmarks, and adds a
cProfile listing of an eager step loop. The pieces are wpctrl internals (``_engine``, ``_action_array``), read here
only to attribute the time; they may move.

Run ``python bench/profiling/profile_overhead.py --device cpu``; results go to
``<out>/profile_overhead_<device>.{json,md}``.
"""

from __future__ import annotations

import argparse
import cProfile
import inspect
import io
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import torch  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    DEFAULT_OUT,
    Sync,
    build_panda_model,
    fmt_envs,
    fmt_us,
    load_average,
    machine_info,
    md_table,
    measure,
    meta_markdown,
    panda_mode,
    parse_envs,
    real_setup,
    write_results,
)
from bench.step.reference_torch import TorchCombinedController  # noqa: E402


def profile(args, n_envs: int, device, sync: Sync) -> tuple[list[dict], str]:
    from wpctrl.controllers.inputs import _action_array

    model = build_panda_model(n_envs, device)
    setup = real_setup(
        panda_mode(args.mode, args.interpolate), model, actuation="explicit", control_freq=20, sim_freq=100
    )
    ctrl, state, control = setup.ctrl, setup.state, setup.control
    eng = ctrl._engine
    K = ctrl.num_substeps
    tdev = torch.device("cuda", device.ordinal) if device.is_cuda else torch.device("cpu")
    a_t = torch.zeros((n_envs, ctrl.action_dim), device=tdev)
    a_w = wp.from_torch(a_t)
    a_n = np.zeros((n_envs, ctrl.action_dim), np.float32)
    ctrl.reset(state)
    ctrl.set_action(a_t, state)
    ctrl.before_simulation_step(state, control)
    ref = TorchCombinedController(
        panda_mode(args.mode, args.interpolate), setup.layout, state, setup.new_control(), device=tdev
    )
    ref.reset()
    sync()

    # wpctrl >= ab1ab03 caches torch wrappers (engine.wrappers); older versions take no cache argument.
    takes_cache = "cache" in inspect.signature(_action_array).parameters
    cache = [eng.wrappers] if takes_cache and hasattr(eng, "wrappers") else []

    def step():
        ctrl.set_action(a_t, state)
        for _ in range(K):
            ctrl.before_simulation_step(state, control)

    with wp.ScopedCapture(device=device) as cap:
        step()
    graph = cap.graph

    items = [
        ("step: set_action + K before_simulation_step (eager)", step, 1 + K),
        ("step: graph replay (wp.capture_launch)", lambda: wp.capture_launch(graph), 1 + K),
        ("set_action(torch tensor)", lambda: ctrl.set_action(a_t, state), 1),
        ("set_action(wp.array)", lambda: ctrl.set_action(a_w, state), 1),
        ("set_action(numpy)", lambda: ctrl.set_action(a_n, state), 1),
        (
            "  _action_array(torch tensor), wrapper cache as set_action uses it",
            lambda: _action_array(a_t, eng.num_envs, eng.action_dim, eng.device, eng.action_buffer, *cache),
            0,
        ),
        (
            "  _action_array(torch tensor), no cache: a new zero-copy wp.array each call",
            lambda: _action_array(a_t, eng.num_envs, eng.action_dim, eng.device, eng.action_buffer),
            0,
        ),
        (
            "  _action_array(wp.array)",
            lambda: _action_array(a_w, eng.num_envs, eng.action_dim, eng.device, eng.action_buffer),
            0,
        ),
        ("  _check_state", lambda: ctrl._check_state(state, "x"), 0),
        ("  recorded set_action launch (Launch.launch)", lambda: eng._launch_set_action.launch(), 1),
        ("before_simulation_step", lambda: ctrl.before_simulation_step(state, control), 1),
        (
            "  _check_state + _check_control",
            lambda: (ctrl._check_state(state, "x"), ctrl._check_control(control, "x")),
            0,
        ),
        ("  _Engine.substep (bind x5 + launch)", lambda: eng.substep(state, control), 1),
        ("  recorded substep launch (Launch.launch)", lambda: eng._launch_substep.launch(), 1),
        ("torch baseline: set_action", lambda: ref.set_action(a_t), None),
        ("torch baseline: before_simulation_step", ref.before_simulation_step, None),
    ]
    rows = []
    for name, fn, launches in items:
        r = measure(fn, sync, repeats=args.repeats, min_time=args.min_time, warmup=20, clock=args.clock)
        rows.append(
            {
                "envs": n_envs,
                "item": name,
                "us": r["median_s"] * 1e6,
                "launches": launches,
                "samples_us": [x * 1e6 for x in r["samples_s"]],
            }
        )
        print(f"[{fmt_envs(n_envs)}] {name:<60} {r['median_s'] * 1e6:9.2f} us", flush=True)

    pr = cProfile.Profile()
    loops = args.profile_steps
    pr.enable()
    for _ in range(loops):
        step()
    sync()
    pr.disable()
    buf = io.StringIO()
    st = pstats.Stats(pr, stream=buf)
    st.sort_stats("tottime").print_stats(15)
    text = f"cProfile of {loops} eager steps at N={n_envs} (sorted by own time; cProfile inflates small calls):\n"
    text += "\n".join(line for line in buf.getvalue().splitlines() if line.strip())
    return rows, text


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--envs", default="1", help="comma list (default 1: pure overhead)")
    p.add_argument("--mode", default="pd_joint_target_delta_pos")
    p.add_argument("--interpolate", action="store_true")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--min-time", type=float, default=0.02)
    p.add_argument("--profile-steps", type=int, default=2000)
    p.add_argument(
        "--clock",
        default=None,
        choices=["wall", "thread"],
        help="default: thread CPU time on the CPU device (1 torch thread), wall time on CUDA",
    )
    p.add_argument("--out", default=str(DEFAULT_OUT))
    p.add_argument("--tag", default=None)
    args = p.parse_args(argv)
    wp.init()
    device = wp.get_device(args.device)
    if args.clock is None:
        args.clock = "wall" if device.is_cuda else "thread"
    if not device.is_cuda:
        torch.set_num_threads(1)
    sync = Sync(device)
    meta = machine_info(device)
    meta.update({"args": vars(args), "loadavg_start": load_average()})
    print(meta_markdown(meta), flush=True)
    rows, texts = [], []
    t0 = time.perf_counter()
    for n in parse_envs(args.envs):
        r, t = profile(args, n, device, sync)
        rows += r
        texts.append(t)
    meta["wall_s"] = time.perf_counter() - t0
    meta["loadavg_end"] = load_average()
    md = [
        "# Host overhead of an eager wpctrl control step\n",
        meta_markdown(meta) + "\n",
        f"Mode `{args.mode}`, explicit actuation, interpolate={args.interpolate}, K = 5. Clock: {args.clock} "
        f"time per call, median of {args.repeats}. Indented rows are parts of the row above them.\n\n",
    ]
    md.append(
        md_table(
            ["envs", "call", "µs/call", "kernel launches"],
            [
                [
                    fmt_envs(r["envs"]),
                    r["item"].replace("  ", "↳ "),
                    fmt_us(r["us"] * 1e-6),
                    "–" if r["launches"] is None else r["launches"],
                ]
                for r in rows
            ],
        )
    )
    for t in texts:
        md.append("\n```\n" + t + "\n```\n")
    tag = args.tag or ("cuda" if device.is_cuda else "cpu")
    j, m = write_results(args.out, f"profile_overhead_{tag}", meta, rows, "".join(md))
    print(f"wrote {j} and {m}", flush=True)


if __name__ == "__main__":
    main()
