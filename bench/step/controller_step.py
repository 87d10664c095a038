"""Time one control step of wpctrl against a torch baseline and a bandwidth floor, for N parallel Pandas.

One control step = ``set_action`` + K x ``before_simulation_step`` (K = sim_freq // control_freq = 5), Panda mode
``pd_joint_target_delta_pos`` by default (arm: delta on the virtual target, +-0.1 rad; gripper: mimic), explicit
actuation (PD torques into ``Control.joint_f``), interpolation off and on. The solver is not stepped.

Variants (one row each):

* ``wpctrl eager``: the public calls from Python (1 + K kernel launches);
* ``wpctrl graph``: the same calls captured once with ``wp.ScopedCapture`` and replayed with ``wp.capture_launch``
  (CUDA graph on GPU, Warp's APIC replay on CPU);
* ``torch eager``: bench/step/reference_torch.py, ManiSkill's controllers as separate torch ops;
* ``torch graph``: the same captured with ``torch.cuda.graph`` (CUDA only);
* ``floor (copy)``: one device copy moving the bytes the step must read and write (see :func:`traffic_bytes`).

Run ``python bench/step/controller_step.py --help``; results go to ``<out>/controller_step_<device>.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import torch  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    Sync,
    add_run_args,
    build_panda_model,
    finish_run,
    fmt_envs,
    fmt_ratio,
    fmt_us,
    md_table,
    measure_interleaved,
    meta_markdown,
    panda_mode,
    parse_envs,
    parse_run_args,
    real_setup,
    start_run,
    synthetic_setup,
)
from bench.step.reference_torch import TorchCombinedController  # noqa: E402

VARIANTS = ["wpctrl_eager", "wpctrl_graph", "torch_eager", "torch_graph", "floor"]
LABELS = {
    "wpctrl_eager": "wpctrl eager",
    "wpctrl_graph": "wpctrl graph",
    "torch_eager": "torch eager",
    "torch_graph": "torch CUDA graph",
    "floor": "floor (copy)",
}


def traffic_bytes(mode: dict, num_substeps: int, explicit: bool = True) -> dict:
    """Bytes per env that one control step must read and write at the least (float32 everywhere).

    set_action: the action (D); the measured q where the target or the interpolation start needs it (delta from q,
    or interpolation); the previous target of virtual-target rows; the new target (n); the start snapshot (n, only
    with interpolation). Each substep: the target (n) and, with interpolation, the start (n); the written drive target
    ``joint_target_q`` (n); with explicit actuation the measured q and qd (2n) and ``joint_f`` (n). Not counted:
    index tables and per-joint parameters (shared by all envs, cached), a substep counter (a graph can bake k in),
    and velocity targets (0 for position rows: not read, ``joint_target_qd`` not written). Implicit actuation without
    interpolation: the drive targets are constant over the control step, so the floor writes ``joint_target_q``
    once, in set_action, and the substeps move nothing.
    """
    set_action = {"action": 0, "q": 0, "target_read": 0, "target_write": 0, "start_write": 0}
    substep = {"target_read": 0, "start_read": 0, "joint_target_q": 0, "q": 0, "qd": 0, "joint_f": 0}
    for cfg in mode.values():
        n = len(cfg.joint_names)
        mimic = getattr(cfg, "mimic", None)
        d = len({v["joint"] for v in mimic.values()}) if mimic else n
        interp = bool(cfg.interpolate)
        set_action["action"] += 4 * d
        if (cfg.use_delta and not cfg.use_target) or interp:
            set_action["q"] += 4 * n
        if cfg.use_delta and cfg.use_target:
            set_action["target_read"] += 4 * d
        set_action["target_write"] += 4 * n
        if interp:
            set_action["start_write"] += 4 * n
            substep["start_read"] += 4 * n
        substep["target_read"] += 4 * n
        substep["joint_target_q"] += 4 * n
        if explicit:
            substep["q"] += 4 * n
            substep["qd"] += 4 * n
            substep["joint_f"] += 4 * n
    if not explicit and not any(cfg.interpolate for cfg in mode.values()):
        set_action["joint_target_q"] = substep["joint_target_q"]
        substep = dict.fromkeys(substep, 0)
    total = sum(set_action.values()) + num_substeps * sum(substep.values())
    return {"per_env": total, "set_action": set_action, "substep": substep, "num_substeps": num_substeps}


def wpctrl_bytes_estimate(
    mode: dict, num_substeps: int, interp: bool, elided: bool = False, explicit: bool = True
) -> int:
    """Bytes per env that wpctrl's step kernels touch (``wpctrl/kernels/pd_step.py``), for the same-bytes floor.

    set_action: the action row, q and the start snapshot of every position row, the previous target of rows that
    need it (delta on the target, or rows outside the action), the new target, the processed action and the per-env
    step counter. Substep: the per-env counter (read, write), the target and ``joint_target_q`` of every row, with
    interpolation the start, with explicit actuation q, qd, the per-env kp / kd / force limit and ``joint_f``.
    Elided substeps (implicit, no interpolation): set_action also writes ``joint_target_q``; the substeps touch
    nothing.
    """
    n = sum(len(c.joint_names) for c in mode.values())
    d = 0
    t_read = 0
    for c in mode.values():
        mimic = getattr(c, "mimic", None)
        dc = len({v["joint"] for v in mimic.values()}) if mimic else len(c.joint_names)
        d += dc
        if c.use_delta and c.use_target:
            t_read += dc
    sa = 4 * (d + n + n + t_read + n + d) + 4
    if elided:
        return sa + 4 * n
    per_row = 2 + (1 if interp else 0) + (6 if explicit else 0)
    return sa + num_substeps * (8 + 4 * n * per_row)


def _copy_fns(name: str, nbytes: int, tdev, cuda: bool) -> dict:
    """``{name: eager copy, name + "_graph": the same copy replayed from a CUDA graph}`` of a float32 buffer of half
    ``nbytes`` into another (it reads half and writes half, moving ``nbytes`` in all); no graph off CUDA."""
    src = torch.ones(max(1, nbytes // 8), dtype=torch.float32, device=tdev)
    dst = torch.empty_like(src)
    fns = {name: lambda: dst.copy_(src)}
    if cuda:
        g = torch.cuda.CUDAGraph()
        dst.copy_(src)
        torch.cuda.synchronize()
        with torch.cuda.graph(g):
            dst.copy_(src)
        fns[name + "_graph"] = g.replay
    return fns


def run_one(args, setup, mode_name: str, interp: bool, sync: Sync, device) -> list[dict]:
    ctrl, state, control = setup.ctrl, setup.state, setup.control
    n_envs = setup.num_envs
    K = ctrl.num_substeps
    tdev = torch.device("cuda", wp.get_device(device).ordinal) if sync.cuda else torch.device("cpu")
    gen = torch.Generator(device=tdev).manual_seed(0)
    action = torch.rand((n_envs, ctrl.action_dim), generator=gen, device=tdev) * 2 - 1
    mode = panda_mode(mode_name, interp)
    control_t = setup.new_control()
    ref = TorchCombinedController(mode, setup.layout, state, control_t, actuation=args.actuation, device=tdev)
    ctrl.reset(state)
    ref.reset()
    sync()

    # Equal work: one fresh step of each from the same start writes the same drive targets and torques.
    ctrl.set_action(action, state)
    ref.set_action(action)
    for _ in range(K):
        ctrl.before_simulation_step(state, control)
        ref.before_simulation_step()
    sync()
    ci, di = setup.layout.coord_index.reshape(-1), setup.layout.dof_index.reshape(-1)
    check = {
        "max_abs_diff_joint_target_q": float(
            np.abs(control.joint_target_q.numpy()[ci] - control_t.joint_target_q.numpy()[ci]).max()
        ),
        "max_abs_diff_joint_f": float(np.abs(control.joint_f.numpy()[di] - control_t.joint_f.numpy()[di]).max()),
    }

    def wp_step():
        ctrl.set_action(action, state)
        for _ in range(K):
            ctrl.before_simulation_step(state, control)

    def torch_step():
        ref.set_action(action)
        for _ in range(K):
            ref.before_simulation_step()

    traffic = traffic_bytes(mode, K, args.actuation == "explicit")
    floor_bytes = traffic["per_env"] * n_envs
    fns = {}
    if "wpctrl_eager" in args.variants:
        fns["wpctrl_eager"] = wp_step
    if "wpctrl_graph" in args.variants:
        wp_step()
        sync()
        with wp.ScopedCapture(device=device) as cap:
            wp_step()
        graph = cap.graph
        fns["wpctrl_graph"] = lambda: wp.capture_launch(graph)
    if "torch_eager" in args.variants:
        fns["torch_eager"] = torch_step
    if "torch_graph" in args.variants and sync.cuda:
        s = torch.cuda.Stream(device=tdev)
        s.wait_stream(torch.cuda.current_stream(tdev))
        with torch.cuda.stream(s):
            for _ in range(3):
                torch_step()
        torch.cuda.current_stream(tdev).wait_stream(s)
        tgraph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(tgraph):
            torch_step()
        fns["torch_graph"] = tgraph.replay
    same_bytes = n_envs * wpctrl_bytes_estimate(
        mode, K, interp, elided=not ctrl.substep_launch, explicit=args.actuation == "explicit"
    )
    extra = {}
    if "floor" in args.variants:
        # The floor: one copy of the bytes the step must move; "floor_same": of the bytes wpctrl's kernels move
        # (per-env gains, counters, snapshots included). Each eager and, on CUDA, replayed from a graph.
        fns.update(_copy_fns("floor", floor_bytes, tdev, sync.cuda))
        fns.update(_copy_fns("floor_same", same_bytes, tdev, sync.cuda))
    # Samples round-robin over the variants, so that a noisy phase of the machine hits them all alike.
    times = measure_interleaved(
        fns, sync, repeats=args.repeats, min_time=args.min_time, warmup=args.warmup, clock=args.clock
    )
    if "floor_graph" in times:
        fg = times.pop("floor_graph")
        extra["floor_eager_s"] = times["floor"]["median_s"]
        extra["floor_graph_s"] = fg["median_s"]
        if fg["median_s"] < times["floor"]["median_s"]:
            times["floor"] = fg
    t_same = None
    if "floor_same" in times:
        t_same = min(times.pop(k)["median_s"] for k in ("floor_same", "floor_same_graph") if k in times)
        extra["floor_same_bytes_s"] = t_same

    rows = []
    t_torch = times.get("torch_eager", {}).get("median_s")
    t_floor = times.get("floor", {}).get("median_s")
    for name in VARIANTS:
        if name not in times:
            continue
        t = times[name]["median_s"]
        rows.append(
            {
                "envs": n_envs,
                "layout": setup.layout_kind,
                "mode": mode_name,
                "interpolate": interp,
                "actuation": args.actuation,
                "num_substeps": K,
                "variant": name,
                "us_per_step": t * 1e6,
                "ns_per_env_step": t * 1e9 / n_envs,
                "speedup_vs_torch_eager": (t_torch / t) if t_torch else None,
                "x_floor": (t / t_floor) if t_floor else None,
                "floor_bytes_per_env": traffic["per_env"],
                "wpctrl_bytes_per_env_estimate": same_bytes // n_envs,
                "x_floor_same_bytes": (t / t_same) if t_same else None,
                "effective_GBps_at_floor_bytes": floor_bytes / t / 1e9,
                "iters": times[name]["iters"],
                "samples_us": [x * 1e6 for x in times[name]["samples_s"]],
                "clock": args.clock,
                "wall_us_per_step": times[name]["wall_median_s"] * 1e6,
                "thread_cpu_us_per_step": times[name]["thread_median_s"] * 1e6,
                "build_s": setup.build_s,
                "block_dim": getattr(ctrl._engine, "block_dim", None),
                "check": check,
                **({"floor_detail": extra} if name == "floor" and extra else {}),
            }
        )
    return rows


def markdown(meta: dict, rows: list[dict], traffic: dict) -> str:
    out = ["# Control step: wpctrl vs torch (ManiSkill-style) vs a bandwidth floor\n", meta_markdown(meta) + "\n"]
    out.append(
        f"Mode `{rows[0]['mode'] if rows else ''}`, explicit PD torques, K = {traffic['num_substeps']} substeps per "
        f"control step. Floor: one device copy moving {traffic['per_env']} B/env (hold) — see `traffic_bytes`. "
        "'vs torch eager' = torch eager time / this time (higher is better); '× floor' = this time / floor time; "
        "'× same-bytes floor' = this time / one copy of the bytes wpctrl's kernels move (`wpctrl_bytes_estimate`). "
        f"Clock: {rows[0]['clock'] if rows else 'wall'} time, median of {meta['args']['repeats']} samples taken "
        "round-robin over the variants.\n"
    )
    for interp in (False, True):
        sel = [r for r in rows if r["interpolate"] == interp]
        if not sel:
            continue
        out.append(f"\n## interpolate = {interp} (floor {sel[0]['floor_bytes_per_env']} B/env)\n\n")
        body = []
        for r in sel:
            body.append(
                [
                    fmt_envs(r["envs"]) + ("*" if r["layout"] == "synthetic" else ""),
                    LABELS[r["variant"]],
                    fmt_us(r["us_per_step"] * 1e-6),
                    f"{r['ns_per_env_step']:.3g}",
                    fmt_ratio(r["speedup_vs_torch_eager"]),
                    fmt_ratio(r["x_floor"]),
                    fmt_ratio(r.get("x_floor_same_bytes")),
                    str(r["wpctrl_bytes_per_env_estimate"]),
                ]
            )
        out.append(
            md_table(
                ["envs", "variant", "µs/step", "ns/env-step", "vs torch eager", "× floor", "× same-bytes", "B/env"],
                body,
            )
        )
    if any(r["layout"] == "synthetic" for r in rows):
        out.append("\n\\* synthetic layout: a small replicated model's index tables tiled to N worlds (same layout).\n")
    return "".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_args(
        p, envs_help="comma list, k/M suffixes (default: cpu 1,64,1k,4k,16k; cuda up to 1M)", variants=VARIANTS
    )
    p.add_argument("--mode", default="pd_joint_target_delta_pos")
    p.add_argument("--interpolate", default="both", choices=["both", "on", "off"])
    p.add_argument("--actuation", default="explicit", choices=["explicit", "implicit"])
    p.add_argument(
        "--max-real-envs",
        type=int,
        default=4096,
        help="above this N use the synthetic layout instead of replicating N Pandas",
    )
    p.add_argument(
        "--block-dim",
        type=int,
        default=0,
        help="force the CUDA block size of the step kernels (default: wpctrl's choice, launch.step_block_dim)",
    )
    args = parse_run_args(p, argv)
    if args.block_dim:
        import wpctrl.engine.core

        wpctrl.engine.core.step_block_dim = lambda device, num_envs: args.block_dim
    device, sync, meta = start_run(p, args, cpu_envs="1,64,1k,4k,16k", cuda_envs="1,64,1k,4k,16k,64k,256k,1M")
    envs = parse_envs(args.envs)
    interps = {"both": [False, True], "on": [True], "off": [False]}[args.interpolate]

    rows = []
    small_model = None
    t_start = time.perf_counter()
    for n in envs:
        model = None
        if n <= args.max_real_envs:
            t0 = time.perf_counter()
            model = build_panda_model(n, device)
            print(f"[{fmt_envs(n)}] model built in {time.perf_counter() - t0:.1f} s", flush=True)
        elif small_model is None:
            small_model = build_panda_model(2, device)
        for interp in interps:
            mode = panda_mode(args.mode, interp)
            kw = {"actuation": args.actuation, "control_freq": 20, "sim_freq": 100}
            try:
                setup = (
                    real_setup(mode, model, **kw) if model is not None else synthetic_setup(mode, small_model, n, **kw)
                )
                got = run_one(args, setup, args.mode, interp, sync, device)
            except (RuntimeError, MemoryError) as e:  # out of device memory at the largest N
                print(f"[{fmt_envs(n)}] skipped: {type(e).__name__}: {e}", flush=True)
                break
            for r in got:
                print(
                    f"[{fmt_envs(n)}{'*' if r['layout'] == 'synthetic' else ''} interp={int(interp)}] "
                    f"{LABELS[r['variant']]:>16}: {r['us_per_step']:10.2f} us/step {r['ns_per_env_step']:10.3f} "
                    f"ns/env-step  vs torch {fmt_ratio(r['speedup_vs_torch_eager']):>7}  x floor "
                    f"{fmt_ratio(r['x_floor']):>7}",
                    flush=True,
                )
            rows += got
            del setup
        del model
        if device.is_cuda:
            torch.cuda.empty_cache()
    finish_run(
        args,
        device,
        meta,
        rows,
        t_start,
        "controller_step",
        lambda: markdown(meta, rows, traffic_bytes(panda_mode(args.mode, False), 5, args.actuation == "explicit")),
    )


if __name__ == "__main__":
    main()
