"""Cost of the joint-space response update (acceleration drives, stable explicit PD) per env-step.

``ctrl`` with ``drive_mode="acceleration"`` on every Panda joint recomputes r = (H^-1)_ii once per control step
(``inertia_update="control"``: forward kinematics, the articulation mass matrix, its inverse, a gather kernel) and,
with implicit actuation, writes the per-env solver gains. This times that update alone (eager and graph-captured)
next to a whole wpctrl control step without it, for a list of N. ``python bench/inertia_update.py --help``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import warp as wp  # noqa: E402

from bench.common import (  # noqa: E402
    DEFAULT_OUT,
    Sync,
    build_panda_model,
    fmt_envs,
    fmt_us,
    machine_info,
    md_table,
    measure,
    meta_markdown,
    parse_envs,
    write_results,
)


def run(n: int, device, repeats: int, sync) -> list[dict]:
    import numpy as np

    import wpctrl
    from wpctrl.robots import PANDA_ARM_JOINTS, PANDA_GRIPPER_JOINTS

    model = build_panda_model(n, device, gravity=False)
    names = PANDA_ARM_JOINTS + PANDA_GRIPPER_JOINTS
    rows = []
    for label, drive_mode, actuation, explicit_pd in (
        ("force, implicit (no update)", "force", "implicit", "naive"),
        ("acceleration, implicit", "acceleration", "implicit", "naive"),
        ("acceleration, explicit stable", "acceleration", "explicit", "stable"),
    ):
        cfg = wpctrl.PDJointPosControllerConfig(
            names, None, None, 1e3, 1e2, 100.0, normalize_action=False, drive_mode=drive_mode
        )
        ctrl = wpctrl.build_controller(cfg, model, 20, 100, actuation=actuation, explicit_pd=explicit_pd)
        state, control = model.state(), model.control()
        ctrl.reset(state)
        act = wp.array(np.tile(model.joint_q.numpy()[:9], (n, 1)), dtype=wp.float32, device=device)

        def step(ctrl=ctrl, act=act, state=state, control=control):
            ctrl.set_action(act, state)
            for _ in range(ctrl.num_substeps):
                ctrl.before_simulation_step(state, control)

        def update(ctrl=ctrl, state=state):
            ctrl._engine.update_response(state)

        for what, fn in (("control step", step), ("response update", update)):
            if what == "response update" and drive_mode == "force":
                continue
            with wp.ScopedCapture(device=device) as cap:
                fn()
            graph = cap.graph
            eager = measure(fn, sync, repeats=repeats)["median_s"]
            replay = measure(lambda g=graph: wp.capture_launch(g), sync, repeats=repeats)["median_s"]
            rows.append(
                {
                    "envs": n,
                    "variant": label,
                    "what": what,
                    "eager_s": eager,
                    "graph_s": replay,
                    "graph_ns_per_env_step": replay / n * 1e9,
                }
            )
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--envs", default="1,64,1k")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", default=str(DEFAULT_OUT))
    args = p.parse_args(argv)
    device = wp.get_device(args.device)
    sync = Sync(device)
    rows = []
    for n in parse_envs(args.envs):
        rows += run(n, device, args.repeats, sync)
        print(f"{fmt_envs(n)} envs done", flush=True)
    meta = machine_info(device)
    table = md_table(
        ["envs", "variant", "timed", "eager µs", "graph µs", "graph ns/env-step"],
        [
            [
                fmt_envs(r["envs"]),
                r["variant"],
                r["what"],
                fmt_us(r["eager_s"]),
                fmt_us(r["graph_s"]),
                f"{r['graph_ns_per_env_step']:.3g}",
            ]
            for r in rows
        ],
    )
    md = (
        "# Joint-space response update (acceleration drives, stable explicit PD)\n"
        + meta_markdown(meta)
        + "\nPanda, all 9 joints, K = 5; 'control step' = set_action (which includes the update) + 5 substeps; "
        "'response update' = the update alone. Wall clock, median of repeats.\n\n" + table + "\n"
    )
    stem = f"inertia_update_{'cuda' if device.is_cuda else 'cpu'}"
    write_results(args.out, stem, meta, rows, md)
    print(md)


if __name__ == "__main__":
    main()
