"""The cost of each actuation option on one control step, for N parallel Pandas: per-env drive properties, command
delay, effort readout, target clamping.

One control step = ``set_action`` + K x ``before_simulation_step`` (K = 5), ManiSkill's Panda mode
``pd_joint_target_delta_pos``, explicit actuation by default (the law reads the per-env gains), interpolation off.
Variants, each its own controller on the same model, timed round-robin (graph-captured replay, and eager):

* ``off``: every option off (the default build);
* ``off, shared gains``: the same, with the gain arrays bound as ``(1, rows)``, the layout before per-env drive
  properties (the kernels' batch rule still accepts them): what per-env drive properties cost;
* ``delay 2`` / ``delay 0-4``: a fixed and a per-env random command delay (ring buffer of 3 / 5 commands);
* ``track_effort``: computed/applied effort and saturation counts written every substep;
* ``clip_targets``: position targets clamped to the joint limits in set_action;
* ``all on``: delay 0-4, track_effort and clip_targets together.

Per-call costs of the new calls (graph-captured, real models only): ``randomize_drive_properties`` of all four
properties for all envs, and ``reset`` of every env with a delay (it refills the history).

Run ``python bench/step/actuation_cost.py --help``; results go to ``<out>/actuation_cost_<device>.{json,md}``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
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

VARIANTS = {
    "off": {},
    "off_shared_gains": {},
    "delay_2": {"delay": 2},
    "delay_0_4": {"delay": (0, 4)},
    "track_effort": {"track_effort": True},
    "clip_targets": {"clip_targets": "joint_limits"},
    "all_on": {"delay": (0, 4), "track_effort": True, "clip_targets": "joint_limits"},
}
LABELS = {
    "off": "off",
    "off_shared_gains": "off, shared gains (before)",
    "delay_2": "delay 2",
    "delay_0_4": "delay 0-4",
    "track_effort": "track_effort",
    "clip_targets": "clip_targets",
    "all_on": "all on",
    "randomize": "randomize_drive_properties (call)",
    "reset_delay": "reset all envs, delay 0-4 (call)",
}


def _share_gains(ctrl) -> None:
    """Bind (1, rows) gain arrays, the layout before per-env drive properties (bench-only, engine internals)."""
    drive = ctrl._engine.part("drive_properties")
    for name in ("kp", "kd", "force_limit"):
        a = getattr(drive, name)
        setattr(drive, name, wp.array(a.numpy()[:1], dtype=wp.float32, device=a.device))


def run_one(args, n_envs, model, small_model, sync, device) -> list[dict]:
    mode = panda_mode(args.mode, args.interpolate)
    kw = {"actuation": args.actuation, "control_freq": 20, "sim_freq": 100}
    setups = {}
    for name, opts in VARIANTS.items():
        if name not in args.variants:
            continue
        if model is not None:
            setups[name] = real_setup(mode, model, **kw, **opts)
        else:
            setups[name] = synthetic_setup(mode, small_model, n_envs, **kw, **opts)
        if name == "off_shared_gains":
            _share_gains(setups[name].ctrl)
    rng = np.random.default_rng(0)
    fns = {}
    for name, su in setups.items():
        ctrl, state, control = su.ctrl, su.state, su.control
        action = wp.array(rng.uniform(-1, 1, (n_envs, ctrl.action_dim)).astype(np.float32), device=device)
        ctrl.reset(state)

        def step(ctrl=ctrl, state=state, control=control, action=action):
            ctrl.set_action(action, state)
            for _ in range(ctrl.num_substeps):
                ctrl.before_simulation_step(state, control)

        step()
        sync()
        with wp.ScopedCapture(device=device) as cap:
            step()
        # the graph replays into these arrays: keep them alive with it (a freed one would be reused or unmapped)
        fns[name + ":graph"] = lambda g=cap.graph, keep=(su, action): wp.capture_launch(g)
        if args.eager:
            fns[name + ":eager"] = step
    if model is not None and "off" in setups:
        su = setups["off"]
        with wp.ScopedCapture(device=device) as cap:
            su.ctrl.randomize_drive_properties(
                stiffness=(0.5, 2.0), damping=(0.5, 2.0), force_limit=(0.8, 1.2), friction=(0.0, 1.0)
            )
        fns["randomize:graph"] = lambda g=cap.graph: wp.capture_launch(g)
    if "delay_0_4" in setups and model is not None:
        su = setups["delay_0_4"]
        mask = wp.ones(n_envs, dtype=wp.bool, device=device)
        with wp.ScopedCapture(device=device) as cap:
            su.ctrl.reset(su.state, env_ids=mask)
        fns["reset_delay:graph"] = lambda g=cap.graph, keep=mask: wp.capture_launch(g)

    times = measure_interleaved(
        fns, sync, repeats=args.repeats, min_time=args.min_time, warmup=args.warmup, clock=args.clock
    )
    rows = []
    base = {k: times.get(f"off:{k}", {}).get("median_s") for k in ("graph", "eager")}
    for key, t in times.items():
        name, how = key.split(":")
        rows.append(
            {
                "envs": n_envs,
                "layout": "real" if model is not None else "synthetic",
                "variant": name,
                "replay": how,
                "actuation": args.actuation,
                "us": t["median_s"] * 1e6,
                "x_off": (t["median_s"] / base[how]) if base.get(how) and name in VARIANTS else None,
                "samples_us": [x * 1e6 for x in t["samples_s"]],
                "iters": t["iters"],
                "clock": args.clock,
            }
        )
    return rows


def markdown(meta: dict, rows: list[dict], args) -> str:
    out = ["# Actuation options: cost per control step\n", meta_markdown(meta) + "\n"]
    out.append(
        f"Mode `{args.mode}`, {args.actuation} actuation, interpolate={args.interpolate}, K = 5. µs per control step "
        "(set_action + 5 substeps), or per call for the two call rows; '× off' = this / the all-off step of the same "
        f"replay kind. Clock: {args.clock}, median of {args.repeats} round-robin samples.\n\n"
    )
    body = []
    for r in rows:
        body.append(
            [
                fmt_envs(r["envs"]) + ("*" if r["layout"] == "synthetic" else ""),
                LABELS[r["variant"]],
                r["replay"],
                fmt_us(r["us"] * 1e-6),
                fmt_ratio(r["x_off"]),
            ]
        )
    out.append(md_table(["envs", "variant", "replay", "µs", "× off"], body))
    if any(r["layout"] == "synthetic" for r in rows):
        out.append("\n\\* synthetic layout (bench/common.py): no model mirror, so the call rows are left out.\n")
    return "".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_run_args(
        p,
        envs_help="comma list, k/M suffixes (default: cpu 1,64,1k,4k; cuda up to 1M)",
        variants=VARIANTS,
        torch_threads=False,
    )
    p.add_argument("--mode", default="pd_joint_target_delta_pos")
    p.add_argument("--interpolate", action="store_true")
    p.add_argument("--actuation", default="explicit", choices=["explicit", "implicit"])
    p.add_argument("--eager", action="store_true", help="also time the eager calls")
    p.add_argument("--max-real-envs", type=int, default=4096)
    args = parse_run_args(p, argv)
    device, sync, meta = start_run(p, args, cpu_envs="1,64,1k,4k", cuda_envs="1,64,1k,4k,64k,256k,1M")
    rows = []
    small_model = None
    t0 = time.perf_counter()
    for n in parse_envs(args.envs):
        model = build_panda_model(n, device) if n <= args.max_real_envs else None
        if model is None and small_model is None:
            small_model = build_panda_model(2, device)
        try:
            got = run_one(args, n, model, small_model, sync, device)
        except (RuntimeError, MemoryError) as e:
            print(f"[{fmt_envs(n)}] skipped: {type(e).__name__}: {e}", flush=True)
            break
        for r in got:
            print(
                f"[{fmt_envs(n)}] {LABELS[r['variant']]:>36} {r['replay']:>5}: {r['us']:10.2f} us  x off "
                f"{fmt_ratio(r['x_off']):>7}",
                flush=True,
            )
        rows += got
        del model
    finish_run(args, device, meta, rows, t0, "actuation_cost", lambda: markdown(meta, rows, args))


if __name__ == "__main__":
    main()
